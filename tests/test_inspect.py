"""`hybrid inspect SCENE | MJCF [--json]` (hybrid.inspection): bodies at qpos0, joints,
actuators and keyframes of a model; regions, terms, nails, links and the stable step
of a scene; one line and status 2 for what cannot be read."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hybrid.cli import main
from hybrid.mesh import vertex_area
from hybrid.model import compile_scene
from hybrid.resolve import resolve_scene
from hybrid.rigid import TRUNK_XML

XML = """<mujoco><option timestep="0.005" integrator="RK4"/>
<worldbody><body name="torso" pos="0 0 1"><freejoint name="root"/><geom size="0.1" mass="5"/>
<body name="arm" pos="0.1 0 0" euler="0 0 90"><joint name="shoulder" axis="0 1 0" range="-1 1"/>
<geom type="capsule" size="0.03" fromto="0 0 0 0.3 0 0" mass="1"/></body></body></worldbody>
<actuator><motor name="m_shoulder" joint="shoulder" ctrlrange="-5 5" ctrllimited="true"/></actuator>
<keyframe><key name="bent" qpos="0 0 1.2 1 0 0 0 0.4"/></keyframe></mujoco>"""


def _json(capsys, *argv) -> dict:
    assert main(["inspect", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_an_mjcf_file(tmp_path, capsys):
    path = tmp_path / "arm.xml"
    path.write_text(XML)
    r = _json(capsys, str(path))["model"]
    assert (r["timestep_s"], r["integrator"], r["nq"], r["nu"]) == (0.005, "RK4", 8, 1)
    bodies = {b["name"]: b for b in r["bodies"]}
    assert bodies["arm"]["pos_m"] == pytest.approx([0.1, 0, 1]) and bodies["arm"]["parent"] == "torso"
    assert bodies["torso"]["mass_kg"] == pytest.approx(5.0)
    joints = {j["name"]: j for j in r["joints"]}
    assert joints["root"]["type"] == "free" and joints["root"]["qpos0"] == [0, 0, 1, 1, 0, 0, 0]
    assert joints["shoulder"]["type"] == "hinge" and joints["shoulder"]["range"] == pytest.approx(np.radians([-1, 1]))
    assert r["actuators"] == [{"name": "m_shoulder", "target": "joint:shoulder", "ctrlrange": [-5.0, 5.0]}]
    assert r["keyframes"][0]["name"] == "bent" and r["keyframes"][0]["qpos"][2] == 1.2
    assert main(["inspect", str(path)]) == 0
    text = capsys.readouterr().out
    assert "arm  parent torso  1 kg  at (0.1, 0, 1)" in text and "keyframes (1): bent" in text


def test_a_scene_with_its_regions_nails_links_and_stable_step(capsys):
    r = _json(capsys, "breathing", "--set", 'rigid.hold=["*"]')
    model = compile_scene(resolve_scene("breathing"))
    area = vertex_area(model.mesh.vert_pos, model.mesh.face_vert)
    assert set(r["regions"]) == set(model.regions)
    for name, idx in model.regions.items():
        assert r["regions"][name]["points"] == idx.size
        assert r["regions"][name]["area_m2"] == pytest.approx(area[idx].sum(), rel=1e-12)
    assert r["membrane"]["area_m2"] == pytest.approx(area.sum(), rel=1e-12)
    assert r["dt_stable_s"] == model.dt_stable_s and r["dt_s"] == model.dt_s
    assert [t["name"] for t in r["terms"]] == [t.name for t in (*model.scene.forces, *model.scene.constraints)]
    assert {n["name"] for n in r["nails"]} == {c.name for c in model.scene.constraints if c.toml_type == "nailed"}
    assert sum(k["points"] for k in r["links"]) == model.link_vert.size
    assert {k["body"] for k in r["links"]} == {k.body for k in model.scene.rigid.links}
    assert r["rigid"]["settings"]["held"] == ["rib_left_hinge", "rib_right_hinge"]
    assert {b["name"] for b in r["rigid"]["model"]["bodies"]} >= {"world", "spine", "rib_left", "rib_right"}
    assert main(["inspect", "breathing"]) == 0
    text = capsys.readouterr().out
    assert "stable-step estimate" in text and "the step is larger" not in text
    assert main(["inspect", "breathing", "--set", f"dt_s={2 * model.dt_stable_s}"]) == 0
    assert "the step is larger" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, words",
    [
        (["no_such.xml"], ["MJCF file 'no_such.xml': no such file"]),
        (["no_such_scene"], ["no such scene"]),
        (["breathing", "--set", 'rigid.fix=["spnie"]'], ["rigid.fix[0]", "'spnie'", "close body names: spine"]),
        ([str(TRUNK_XML), "--set", "dt_s=1"], ["apply to a scene"]),
    ],
)
def test_what_cannot_be_read_is_one_line_and_status_2(capsys, argv, words):
    assert main(["inspect", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hybrid: error: ")
    for w in words:
        assert w in err
