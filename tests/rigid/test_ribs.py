"""Articulated ribs added to a loaded model through MjSpec (`rigid.ribs`,
hybrid.rigid.ribs): their geometry and hinges, the scene file's [rigid.ribs] table, a
one-line refusal for every key, and a second existing model (MuJoCo's humanoid, tests/data)
breathing on ribs added to its torso."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import mujoco
import numpy as np
import pytest
from helpers import HUMANOID_XML

from hybrid.errors import RigidError, SceneError
from hybrid.model import compile_scene
from hybrid.regions import Box, Difference, HalfSpace, Intersection
from hybrid.rigid import TRUNK_XML, load_spec
from hybrid.rigid.ribs import add_ribs
from hybrid.scene import (
    Damping,
    Masses,
    MeshSpec,
    Muscle,
    Nailed,
    RibPair,
    Ribs,
    Rigid,
    RigidLink,
    Scene,
    ShapeMemory,
    Volume,
)
from hybrid.scenefile import apply_overrides, scene_from_dict, scene_to_toml
from hybrid.simulation import Simulation

# trunk.xml's left rib, rebuilt on its spine: the head, the anterior end, the arc's width
PAIR = RibPair(
    name="r",
    head_m=(-0.13, 0.025, 0.06),
    front_m=(0.108, 0.029, 0.06),
    half_width_m=0.11,
    axis_angle_deg=35.0,
    stiffness_n_m_per_rad=12.0,
)
RIBS = Ribs(body="spine", pairs=(PAIR,))


def _compiled(ribs: Ribs = RIBS, xml: Path = TRUNK_XML):
    spec = load_spec(xml)
    added = add_ribs(spec, ribs, "trunk")
    return spec.compile(), added


def test_ribs_are_hinged_mirror_images_whose_positive_angle_lifts_them():
    m, added = _compiled()
    assert added.bodies == ["r_left", "r_right"] and added.tendons == ["r_sternum"]
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    front = {s: d.site(f"r_{s}_front").xpos.copy() for s in ("left", "right")}
    np.testing.assert_allclose(front["left"], PAIR.front_m, atol=1e-12)
    np.testing.assert_allclose(front["right"], [0.108, -0.029, 0.06], atol=1e-12)  # mirrored in y = 0
    # the axis at 35 degrees to the mid-sagittal plane, in the transverse plane
    for side, sign in (("left", 1), ("right", -1)):
        j = m.joint(f"r_{side}_hinge").id
        np.testing.assert_allclose(
            m.jnt_axis[j], [sign * np.cos(np.radians(35)), -np.sin(np.radians(35)), 0], atol=1e-12
        )
        d.qpos[m.jnt_qposadr[j]] = 0.01
    mujoco.mj_kinematics(m, d)
    for side in ("left", "right"):
        lift = d.site(f"r_{side}_front").xpos[2] - front[side][2]
        a = np.radians(35)  # the anterior end, 0.238 m ahead of the head and 4 mm out: up by sin(q) (a x r).z
        assert lift == pytest.approx(np.sin(0.01) * (0.238 * np.sin(a) + 0.004 * np.cos(a)), rel=1e-9)
    assert np.atleast_1d(m.tendon_stiffness[m.tendon("r_sternum").id])[0] == 1000.0
    # each capsule of the arc within half_width_m of the midline, the widest at it
    y = [abs(d.geom_xpos[g][1]) for g in range(m.ngeom) if m.geom(g).name.startswith("r_left_")]
    assert len(y) == 6 and max(y) <= 0.11 + 1e-9


def test_a_rib_s_inertia_is_its_solid_rods_and_any_mass_compiles():
    """A rib is rods of the capsule's radius: one straight rod has the solid cylinder's moments
    (m r^2 / 2 about its axis, m (3 r^2 + l^2) / 12 across it, to rounding); an arc's tensor is
    strictly physical (its largest moment below the sum of the other two by m r^2 / 2: thin rods in
    a plane leave it equal, and MuJoCo refused a 0.5 kg rib of this pair by rounding), so that
    every mass the key admits compiles."""
    from hybrid.rigid.ribs import _inertia

    mass, r, ell = 0.3, 0.006, 0.2
    com, tensor = _inertia(np.array([[0.0, 0.0, 0.0], [ell / 2, 0.0, 0.0], [ell, 0.0, 0.0]]), mass, r)
    across = mass * (3 * r**2 + ell**2) / 12
    assert np.allclose(com, [ell / 2, 0.0, 0.0], rtol=0, atol=1e-15)
    assert np.allclose(tensor, np.diag([mass * r**2 / 2, across, across]), rtol=1e-12, atol=0)
    from hybrid.demo import UPPER_RIBS

    radius = RIBS.radius_m
    for kg in (0.05, 0.5, 1.0, 5.0):
        m, _ = _compiled(Ribs(body="spine", pairs=(dataclasses.replace(UPPER_RIBS, name="r", mass_kg=kg),)))
        for side in ("left", "right"):
            a, b, c = sorted(m.body(f"r_{side}").inertia)
            assert m.body(f"r_{side}").mass[0] == pytest.approx(kg, rel=1e-12)
            assert a + b - c == pytest.approx(kg * radius**2 / 2, rel=1e-6)


def test_ribs_hold_their_weight_where_drawn_and_spring_back():
    m, _ = _compiled()
    d = mujoco.MjData(m)
    for _ in range(2000):  # 2 s under gravity, MuJoCo alone: the weight is held at qpos 0
        mujoco.mj_step(m, d)
    assert np.abs(d.qpos).max() < 1e-6
    pulled = dataclasses.replace(RIBS, pairs=(dataclasses.replace(PAIR, reference_angle_deg=2.0),))
    m, _ = _compiled(pulled)
    d = mujoco.MjData(m)
    for _ in range(4000):
        mujoco.mj_step(m, d)
    # the sternal spring resists the bucket-handle part of the swing: below 2 degrees, well lifted
    q = [d.joint(f"r_{s}_hinge").qpos[0] for s in ("left", "right")]
    assert 0.5 < np.degrees(q[0]) <= 2.0 + 1e-6
    assert q[0] == pytest.approx(q[1], rel=1e-6)  # left and right alike


def test_a_keyframe_keeps_its_pose_with_the_ribs_added(tmp_path):
    xml = TRUNK_XML.read_text().replace("</mujoco>", '<keyframe><key name="k" qpos="0.1 -0.05"/></keyframe></mujoco>')
    path = tmp_path / "trunk_key.xml"
    path.write_text(xml)
    m, _ = _compiled(xml=path)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    assert d.joint("rib_left_hinge").qpos[0] == 0.1 and d.joint("rib_right_hinge").qpos[0] == -0.05
    assert d.joint("r_left_hinge").qpos[0] == 0.0 and m.nq == 4


def test_the_scene_file_reads_writes_and_overrides_the_ribs():
    text = """
name = "s"
formulation = "paper"
[mesh]
generator = "icosahedron"
radius_m = 0.1
[masses]
total_kg = 1.0
[rigid]
mjcf = "trunk"
[rigid.ribs]
body = "spine"
[[rigid.ribs.pairs]]
name = "r"
head_m = [-0.13, 0.025, 0.06]
front_m = [0.108, 0.029, 0.06]
half_width_m = 0.11
reference_angle_deg = -3.0
"""
    scene = scene_from_dict(tomllib.loads(text), source="s.toml")
    assert scene.rigid.ribs == Ribs(
        body="spine", pairs=(dataclasses.replace(PAIR, axis_angle_deg=35.0, reference_angle_deg=-3.0),)
    )
    back = scene_from_dict(tomllib.loads(scene_to_toml(scene)), source="back")
    assert back.rigid.ribs == scene.rigid.ribs
    changed = apply_overrides(scene, ["rigid.ribs.pairs.r.stiffness_n_m_per_rad=5", "rigid.ribs.radius_m=0.004"])
    assert changed.rigid.ribs.pairs[0].stiffness_n_m_per_rad == 5.0 and changed.rigid.ribs.radius_m == 0.004


def _pair(**kw):
    return Ribs(body="spine", pairs=(dataclasses.replace(PAIR, **kw),))


@pytest.mark.parametrize(
    "ribs, error, words",
    [
        (Ribs(body="spien", pairs=(PAIR,)), RigidError, ["rigid.ribs.body", "'spien'", "close body names: spine"]),
        (Ribs(body="world", pairs=(PAIR,)), RigidError, ["rigid.ribs.body", "'world'"]),
        (Ribs(body="spine", pairs=()), SceneError, ["rigid.ribs.pairs", "at least one rib pair"]),
        (Ribs(body="spine", pairs=(PAIR, PAIR)), SceneError, ["rigid.ribs.pairs[1].name", "'r' names two"]),
        (Ribs(body="spine", pairs=(PAIR,), anterior=(0, 0, 0)), SceneError, ["rigid.ribs.anterior", "non-zero"]),
        (Ribs(body="spine", pairs=(PAIR,), cranial=(1, 0, 1)), SceneError, ["rigid.ribs.cranial", "perpendicular"]),
        (Ribs(body="spine", pairs=(PAIR,), radius_m=-0.01), SceneError, ["rigid.ribs.radius_m", "-0.01"]),
        (
            Ribs(body="spine", pairs=(PAIR,), sternum_stiffness_n_per_m=0.0),
            SceneError,
            ["rigid.ribs.sternum_stiffness_n_per_m", "> 0"],
        ),
        (
            Ribs(body="spine", pairs=(PAIR,), sternum_damping_n_s_per_m=-1.0),
            SceneError,
            ["rigid.ribs.sternum_damping_n_s_per_m", "[0, "],
        ),
        (Ribs(body="spine", pairs=("r",)), SceneError, ["rigid.ribs.pairs[0]", "RibPair"]),
        (_pair(name="rib"), RigidError, ["rigid.ribs.pairs[0].name", "body 'rib_left'"]),
        (_pair(name="a/b"), SceneError, ["rigid.ribs.pairs[0].name"]),
        (_pair(head_m=(-0.13, -0.025, 0.06)), SceneError, ["rigid.ribs.pairs[0].head_m", "left rib"]),
        (_pair(head_m=(0.0, 0.1)), SceneError, ["rigid.ribs.pairs[0].head_m", "3-vector"]),
        (_pair(front_m=(-0.12, 0.03, 0.06)), SceneError, ["rigid.ribs.pairs[0].front_m", "4 radius_m"]),
        (_pair(half_width_m=0.02), SceneError, ["rigid.ribs.pairs[0].half_width_m", "more than"]),
        (_pair(axis_angle_deg=120.0), SceneError, ["rigid.ribs.pairs[0].axis_angle_deg", "120"]),
        (_pair(stiffness_n_m_per_rad=0.0), SceneError, ["rigid.ribs.pairs[0].stiffness_n_m_per_rad", "> 0"]),
        (_pair(damping_n_m_s_per_rad=-0.1), SceneError, ["rigid.ribs.pairs[0].damping_n_m_s_per_rad", "[0, "]),
        (_pair(reference_angle_deg=100.0), SceneError, ["rigid.ribs.pairs[0].reference_angle_deg", "100"]),
        (_pair(mass_kg=0.0), SceneError, ["rigid.ribs.pairs[0].mass_kg", "> 0"]),
        ("spine", SceneError, ["rigid.ribs", "hybrid.scene.Ribs"]),
    ],
)
def test_each_ribs_key_refuses_a_wrong_name_or_value_in_one_line(ribs, error, words):
    with pytest.raises(error) as info:
        add_ribs(load_spec(TRUNK_XML), ribs, "trunk")
    message = str(info.value)
    assert "\n" not in message
    for w in words:
        assert w in message, message


@pytest.mark.parametrize(
    "table, words",
    [
        ({"body": "spine", "pairs": [{}], "colour": 1}, ["rigid.ribs.colour", "unknown key"]),
        ({"pairs": [{}]}, ["rigid.ribs", "missing required key 'body'"]),
        ({"body": "spine", "pairs": {}}, ["rigid.ribs.pairs", "array of tables"]),
        ({"body": "spine", "pairs": [{"name": "r"}]}, ["rigid.ribs.pairs[0]", "missing required key 'head_m'"]),
        (
            {
                "body": "spine",
                "pairs": [{"name": "r", "head_m": [0, 0, 0], "front_m": [0, 0, 0], "half_width_m": 0.1, "pitch": 1}],
            },
            ["rigid.ribs.pairs[0].pitch", "unknown key"],
        ),
        ({"body": 3, "pairs": [{}]}, ["rigid.ribs.body", "a string"]),
        ({"body": "spine", "anterior": [1, 0], "pairs": [{}]}, ["rigid.ribs.anterior", "3-vector"]),
        (
            {
                "body": "spine",
                "pairs": [
                    {
                        "name": "r",
                        "head_m": [0, 0, 0],
                        "front_m": [0, 0, 0],
                        "half_width_m": 0.1,
                        "reference_angle_deg": "up",
                    }
                ],
            },
            ["rigid.ribs.pairs[0].reference_angle_deg"],
        ),
    ],
)
def test_the_ribs_table_refuses_a_malformed_key_in_one_line(table, words):
    data = {
        "name": "s",
        "mesh": {"generator": "icosahedron"},
        "masses": {"total_kg": 1.0},
        "rigid": {"mjcf": "trunk", "ribs": table},
    }
    with pytest.raises(SceneError) as info:
        scene_from_dict(data, source="s.toml")
    message = str(info.value)
    assert "\n" not in message and message.startswith("s.toml: ")
    for w in words:
        assert w in message, message


def test_gymnasiums_humanoid_breathes_on_ribs_added_to_its_torso():
    """humanoid.xml (x forward, y left, z up; torso at z = 1.4 m on a free root, fixed
    here, its joints held): a rib pair added to `torso`, a small abdomen below it whose
    band is linked to the ribs, its dome contracting: the ribs turn, the volume is exact,
    and the model's file is unchanged."""
    path = HUMANOID_XML
    before = path.read_bytes()
    c = np.array([0.0, 0.0, 1.2])
    ribs = Ribs(
        body="torso",
        pairs=(
            RibPair(
                name="rib",
                head_m=tuple(c + [-0.09, 0.02, 0.03]),
                front_m=tuple(c + [0.08, 0.025, 0.03]),
                half_width_m=0.09,
                axis_angle_deg=60.0,
                stiffness_n_m_per_rad=2.0,
            ),
        ),
    )
    band = Box((-1, -1, c[2] + 0.015), (1, 1, c[2] + 0.045))
    sc = Scene(
        formulation="paper",
        mesh=MeshSpec(generator="uv_sphere", radius_m=0.08, center_m=tuple(c)),
        masses=Masses(total_kg=1.0),
        regions={
            "band": band,
            "left": Intersection(("band", HalfSpace((0, 0, 0), (0, 1, 0)))),
            "right": Difference("band", "left"),
            "dome": HalfSpace((0, 0, c[2] + 0.046), (0, 0, 1)),
            "floor": HalfSpace((0, 0, c[2] - 0.04), (0, 0, -1)),
        },
        forces=(
            ShapeMemory(300.0),
            Damping(critical_fraction=0.3),
            Muscle(stiffness=60.0, region="dome", toward_m=tuple(c + [0, 0, 0.12])),
        ),
        constraints=(Nailed("floor"), Volume()),
        dt_s=1e-3,
        rigid=Rigid(
            str(path),
            fix_root=True,
            hold=("*",),
            ribs=ribs,
            links=(RigidLink("left", "rib_left", "left"), RigidLink("right", "rib_right", "right")),
        ),
    )
    model = compile_scene(sc)
    assert model.rigid.settings()["ribs"]["rib_joints"] == ["rib_left_hinge", "rib_right_hinge"]
    sim = Simulation(model)
    d, m = sim.mj_data, sim.mj_model
    torso0 = d.xpos[m.body("torso").id].copy()
    for _ in range(4):
        sim.step(100)
        assert sim.volume_rel_error < 1e-10
    q = [float(d.joint(f"rib_{s}_hinge").qpos[0]) for s in ("left", "right")]
    assert min(q) > 1e-3, q  # both ribs lifted by the pressurised abdomen, by milliradians
    np.testing.assert_allclose(d.xpos[m.body("torso").id], torso0, atol=1e-12)
    assert path.read_bytes() == before


def test_ribs_rebuilt_on_the_trunks_spine_breathe_as_its_own():
    """models/trunk.xml's rib (its head, anterior end and width, 19 degrees from
    transverse) rebuilt by the builder on its spine and the breathing scene's band linked
    to the rebuilt pair instead: the same rib lift and apex descent within 0.5% over the
    first 0.8 s of inspiration (the arcs' shapes and inertias differ a little)."""
    import hybrid

    scene = hybrid.load_scene("breathing")
    pair = dataclasses.replace(PAIR, axis_angle_deg=70.7)
    rebuilt = dataclasses.replace(
        scene,
        rigid=dataclasses.replace(
            scene.rigid,
            ribs=Ribs(body="spine", pairs=(pair,)),
            load_joints=(),
            links=(RigidLink("rib_left_points", "r_left", "a"), RigidLink("rib_right_points", "r_right", "b")),
        ),
    )
    own, new = (hybrid.run(Simulation(compile_scene(s)), 0.8)["summary"] for s in (scene, rebuilt))
    assert own["rib_lift_mm"] > 1.0
    assert new["rib_lift_mm"] == pytest.approx(own["rib_lift_mm"], rel=5e-3)
    assert new["apex_descent_mm"] == pytest.approx(own["apex_descent_mm"], rel=5e-3)


def test_the_thorax_pitch_is_the_turn_of_its_anterior_axis_toward_cranial():
    from hybrid.readouts import pitch_deg

    anterior, cranial = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])  # myotorso's frame
    left = np.cross(cranial, anterior)
    start = np.array([0.5, 0.5, -0.5, -0.5])  # a body frame turned against the world (myotorso's torso)
    rot0 = np.empty(9)
    mujoco.mju_quat2Mat(rot0, start)
    axis_body = rot0.reshape(3, 3).T @ anterior
    out = []
    for deg, about in ((10.0, -left), (-3.0, -left), (20.0, cranial)):  # back, forward, a yaw
        turn, q = np.r_[np.cos(np.radians(deg) / 2), np.sin(np.radians(deg) / 2) * about], np.empty(4)
        mujoco.mju_mulQuat(q, turn, start)
        out.append(pitch_deg(q[None], axis_body, anterior, cranial)[0])
    np.testing.assert_allclose(out, [10.0, -3.0, 0.0], atol=1e-12)


def test_the_command_line_refuses_a_wrong_ribs_key_in_one_line_with_status_2(tmp_path, capsys):
    import hybrid
    from hybrid.cli import main

    scene = hybrid.load_scene("breathing")
    path = tmp_path / "ribbed.toml"
    path.write_text(scene_to_toml(dataclasses.replace(scene, rigid=dataclasses.replace(scene.rigid, ribs=RIBS))))
    assert (
        main(["run", str(path), "--duration", "0.01", "--out", str(tmp_path / "o"), "--set", "rigid.ribs.body=spnie"])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rigid.ribs.body: no body named 'spnie'" in err[0] and "spine" in err[0]
    assert (
        main(
            [
                "run",
                str(path),
                "--duration",
                "0.01",
                "--out",
                str(tmp_path / "o2"),
                "--set",
                "rigid.ribs.pairs.r.axis_angle_deg=95",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rigid.ribs.pairs[0].axis_angle_deg" in err[0]
