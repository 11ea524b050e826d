"""`hybrid study rigid [SCENE] --out DIR` (hybrid.studies.rigid_check): the recorded
wrenches (and driven controls) replay through MuJoCo alone exactly, the point forces
sum to the applied wrench, the paper's rigid algorithm is first order."""

from __future__ import annotations

import importlib.util
import json

import pytest

from hybrid.regions import HalfSpace
from hybrid.scene import Damping, Masses, MeshSpec, Rigid, RigidLink, Scene, ShapeMemory
from hybrid.schedule import Breathing
from hybrid.studies.cli import main_study
from hybrid.studies.rigid_check import replay_check

XML = """<mujoco><option timestep="0.002"/>
<worldbody><body name="torso" pos="0 0 1"><freejoint name="root"/><geom size="0.1" mass="5"/>
<body name="arm" pos="0.1 0 0"><joint name="shoulder" axis="0 1 0"/>
<geom type="capsule" size="0.03" fromto="0 0 0 0.3 0 0" mass="1"/></body></body></worldbody>
<actuator><motor name="m_shoulder" joint="shoulder"/></actuator></mujoco>"""


def test_breathing_replays_exactly_and_the_paper_algorithm_is_first_order(tmp_path, capsys):
    assert main_study(["rigid", "breathing", "--small", "--out", str(tmp_path)]) == 0
    r = json.loads((tmp_path / "rigid.json").read_text())
    assert r["steps"] == 200 and r["qpos_moved_max"] > 1e-4  # the ribs moved
    assert r["replay_max_abs_qpos"] <= 1e-12 and r["replay_max_abs_qvel"] <= 1e-12
    assert r["wrench_rel_error"] <= 1e-12 and r["wrench_max_abs"] > 0
    assert 0.9 <= r["paper_algorithm_order"] <= 1.1
    assert "observed order" in (tmp_path / "rigid.md").read_text()


def test_a_driven_held_model_replays_exactly_with_its_controls(tmp_path):
    path = tmp_path / "arm.xml"
    path.write_text(XML)
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(generator="icosahedron", radius_m=0.05, center_m=(0, 0, 1.0)),
        masses=Masses(total_kg=0.1),
        regions={"top": HalfSpace((0, 0, 1.02), (0, 0, 1))},
        forces=(ShapeMemory(100.0), Damping(critical_fraction=0.3)),
        rigid=Rigid(
            str(path),
            links=(RigidLink("top", "torso"),),
            weld=("torso",),
            hold=("shoulder",),
            ctrl={"m_shoulder": Breathing(period_s=0.2, peak=3.0)},
        ),
    )
    r = replay_check(scene, 100)
    assert r["qpos_moved_max"] > 1e-3
    assert r["replay_max_abs_qpos"] <= 1e-12 and r["replay_max_abs_qvel"] <= 1e-12
    assert r["wrench_rel_error"] <= 1e-12


@pytest.mark.skipif(importlib.util.find_spec("myo_sim") is None, reason="myo_sim (pip install -e '.[myo]') absent")
def test_the_wrench_holds_every_load_the_membrane_puts_on_a_body():
    """On the fitted torso the ribs also carry the lungs' wall and the planes the zone of
    apposition slides on: their loads are in the applied wrench and in the sum (it read 0.87
    of the wrench when the sum held the linked points' forces alone). Implicit Euler and
    symplectic Euler (the packaged scene's integrator and the fit's own)."""
    from hybrid import resolve_scene

    for integrator in ("implicit_euler", "symplectic_euler"):
        scene = resolve_scene("myotorso_breathing", overrides=[f"integrator={integrator}", "dt_s=1e-4"])
        r = replay_check(scene, 20)
        assert r["wrench_rel_error"] <= 1e-12 and r["wrench_max_abs"] > 0, integrator
        assert r["replay_max_abs_qpos"] <= 1e-12, integrator


def test_a_scene_without_rigid_part_is_refused_in_one_line(tmp_path, capsys):
    assert main_study(["rigid", "membrane_demo", "--small", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has no rigid part" in err
