"""Spec composition (hybrid.rigid.compose): attachment sites at the linked points' rest
positions, the points' masses added to their bodies with the parallel-axis theorem,
errors that name the link, and composition with an MJCF written by others (MuJoCo's
humanoid, vendored from gymnasium in tests/data), read-only."""

from __future__ import annotations

import dataclasses
import hashlib

import mujoco
import numpy as np
import pytest
from helpers import HUMANOID_XML

from hybrid import rigid
from hybrid.errors import RigidError, SceneError
from hybrid.model import compile_scene
from hybrid.regions import Box, HalfSpace, Intersection
from hybrid.scene import Damping, Masses, MeshSpec, Muscle, Nailed, Rigid, RigidLink, Scene, ShapeMemory, Volume
from hybrid.schedule import Breathing
from hybrid.simulation import Simulation


def test_attach_points_puts_sites_at_the_rest_positions():
    spec = rigid.load_spec(rigid.TRUNK_XML)
    points = np.array([[0.0, 0.104, 0.06], [0.09, 0.052, 0.06], [0.0, -0.104, 0.06], [-0.13, 0.0, -0.1]])
    names = rigid.attach_points(spec, ["rib_left", "rib_left", "rib_right", "world"], points)
    assert names == [f"hybrid_link_{i}" for i in range(4)]
    system = rigid.RigidSystem(spec, names)
    np.testing.assert_allclose(system.site_pos(), points, atol=1e-12)
    assert system.site_names() == names
    assert list(system.site_body) == [system.model.body(b).id for b in ("rib_left", "rib_left", "rib_right", "world")]


def test_attach_points_unknown_body_lists_the_available_names():
    spec = rigid.load_spec(rigid.TRUNK_XML)
    with pytest.raises(RigidError) as info:
        rigid.attach_points(spec, ["rib_left", "sternum_body"], np.zeros((2, 3)))
    message = str(info.value)
    assert "sternum_body" in message
    for name in ("world", "spine", "rib_left", "rib_right"):
        assert name in message


def test_attach_points_bad_shapes_and_duplicates():
    spec = rigid.load_spec(rigid.TRUNK_XML)
    with pytest.raises(RigidError, match=r"point_pos: expected shape \(n, 3\)"):
        rigid.attach_points(spec, ["rib_left"], np.zeros(3))
    with pytest.raises(RigidError, match="body_names: expected 2 names"):
        rigid.attach_points(spec, ["rib_left"], np.zeros((2, 3)))
    rigid.attach_points(spec, ["rib_left"], np.zeros((1, 3)))
    with pytest.raises(RigidError, match="already in the model"):
        rigid.attach_points(spec, ["rib_left"], np.zeros((1, 3)))


def test_attach_to_a_user_model_through_a_frame_with_a_prefix():
    user = mujoco.MjSpec.from_string(
        '<mujoco><option timestep="0.001"/><worldbody><body name="torso" pos="0 0 1">'
        '<geom size="0.1"/>'
        "</body></worldbody></mujoco>"
    )
    trunk = rigid.load_spec(rigid.TRUNK_XML)
    frame = user.body("torso").add_frame(pos=[0.0, 0.0, 0.2])
    frame.attach_body(trunk.body("spine"), "trunk/", "")
    m = user.compile()
    assert m.body("trunk/rib_left").id > 0 and m.tendon("trunk/sternum").id == 0


def test_link_masses_are_added_with_the_parallel_axis_theorem(breathing):
    model = compile_scene(breathing)
    bare = mujoco.MjModel.from_xml_path(str(rigid.TRUNK_XML))
    mjm = model.rigid.model
    d = mujoco.MjData(mjm)
    mujoco.mj_kinematics(mjm, d)
    vm = model.arrays.vert_mass
    for name in ("rib_left", "rib_right"):
        b = mjm.body(name).id
        mine = model.link_vert[np.array(model.rigid.link_body) == name]
        assert mjm.body_mass[b] == pytest.approx(bare.body_mass[b] + vm[mine].sum(), rel=1e-12)

        # world inertia about the world origin: the bare rib's plus the point masses'
        def about_origin(mass, com, rot, principal):
            return rot @ np.diag(principal) @ rot.T + mass * (com @ com * np.eye(3) - np.outer(com, com))

        d0 = mujoco.MjData(bare)
        mujoco.mj_kinematics(bare, d0)
        expect = about_origin(bare.body_mass[b], d0.xipos[b], d0.ximat[b].reshape(3, 3), bare.body_inertia[b])
        for i in mine:
            p = model.mesh.vert_pos[i]
            expect += vm[i] * (p @ p * np.eye(3) - np.outer(p, p))
        got = about_origin(mjm.body_mass[b], d.xipos[b], d.ximat[b].reshape(3, 3), mjm.body_inertia[b])
        np.testing.assert_allclose(got, expect, rtol=1e-9, atol=1e-12)


def small_rib_scene(**rigid_kw) -> Scene:
    ring = Box((-1, -1, 0.07), (1, 1, 0.08))
    links = rigid_kw.pop(
        "links", (RigidLink(Intersection((ring, HalfSpace((0, 0.001, 0), (0, 1, 0)))), "rib_left", name="left"),)
    )
    return Scene(
        formulation="paper",
        mesh=MeshSpec("uv_sphere", radius_m=0.12),
        masses=Masses(total_kg=4.0),
        regions={"top": HalfSpace((0, 0, 0.07), (0, 0, 1))},
        forces=(ShapeMemory(500.0), Damping(critical_fraction=0.3)),
        constraints=(Nailed(HalfSpace((0, 0, -0.1), (0, 0, -1)), name="base"), Volume()),
        rigid=Rigid(rigid_kw.pop("mjcf", "trunk"), links=links, **rigid_kw),
        name="small",
    )


def test_unknown_body_names_the_link_and_lists_bodies_and_sites():
    scene = small_rib_scene(links=(RigidLink("top", "rib_middle", name="x"),))
    with pytest.raises(RigidError) as err:
        compile_scene(scene)
    msg = str(err.value)
    assert "rigid.links[0].body" in msg and "'rib_middle'" in msg and "rib_left" in msg
    assert "rib_left_attach" in msg and "\n" not in msg


def test_a_link_may_name_a_site_and_its_body_carries_the_points():
    model = compile_scene(small_rib_scene(links=(RigidLink("top", "spine_base", name="s"),)))
    assert set(model.rigid.link_body) == {"spine"}


def test_mjcf_errors_and_conflicting_links():
    with pytest.raises(RigidError, match="nope.xml"):
        compile_scene(small_rib_scene(mjcf="nope.xml"))
    twice = (RigidLink("top", "rib_left", name="a"), RigidLink("top", "rib_right", name="b"))
    with pytest.raises(SceneError, match=r"rigid.links\[1\].region.*already linked"):
        compile_scene(small_rib_scene(links=twice))
    scene = small_rib_scene(links=(RigidLink(HalfSpace((0, 0, -0.1), (0, 0, -1)), "rib_left", name="a"),))
    with pytest.raises(SceneError, match=r"constraints\['base'\].region.*also linked"):
        compile_scene(scene)


def test_site_names_that_clash_ask_for_another_prefix(tmp_path):
    xml = rigid.TRUNK_XML.read_text().replace(
        '<site name="spine_base" pos="0 0 -0.15"/>',
        '<site name="spine_base" pos="0 0 -0.15"/><site name="hybrid_link_15"/>',
    )
    (tmp_path / "mine.xml").write_text(xml)
    scene = dataclasses.replace(small_rib_scene(mjcf="mine.xml"), base_dir=str(tmp_path))
    with pytest.raises(RigidError, match="rigid.prefix.*hybrid_link_15"):
        compile_scene(scene)
    scene = dataclasses.replace(small_rib_scene(mjcf="mine.xml", prefix="m_"), base_dir=str(tmp_path))
    assert compile_scene(scene).rigid.site_names()[0] == "m_hybrid_link_15"


def test_without_link_mass_the_bodies_keep_their_mass():
    model = compile_scene(small_rib_scene(add_link_mass=False))
    bare = mujoco.MjModel.from_xml_path(str(rigid.TRUNK_XML))
    np.testing.assert_array_equal(model.rigid.model.body_mass, bare.body_mass)
    sim = Simulation(model)
    sim.step(200)
    assert sim.volume_rel_error <= 1e-12


HUMANOID = HUMANOID_XML


def test_membrane_linked_to_a_third_party_humanoid_torso(tmp_path):
    before = hashlib.sha256(HUMANOID.read_bytes()).hexdigest()
    # the abdomen under the humanoid's torso: its top ring rides on the torso
    centre = (0.0, 0.0, 1.12)
    ring = Box((-1, -1, centre[2] + 0.07), (1, 1, centre[2] + 0.08))
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec("uv_sphere", radius_m=0.12, center_m=centre),
        masses=Masses(total_kg=4.0),
        regions={"top": HalfSpace((0, 0, centre[2] + 0.07), (0, 0, 1))},
        forces=(
            ShapeMemory(3000.0),
            Damping(critical_fraction=0.3),
            Muscle("top", Breathing(4.0, 0.4, 60.0), toward_m=(0, 0, centre[2] + 0.12)),
        ),
        constraints=(Volume(),),
        rigid=Rigid(str(HUMANOID), links=(RigidLink(ring, "torso", name="ribs"),), prefix="membrane_"),
        dt_s=1e-3,
        name="humanoid_abdomen",
    )
    model = compile_scene(scene)
    mjm = model.rigid.model
    assert mjm.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4 and mjm.opt.timestep == 1e-3
    assert all(mjm.site(int(s)).name.startswith("membrane_hybrid_link_") for s in model.rigid.site_id)
    # humanoid.xml takes inertias from geoms: the point masses became geoms on the torso
    bare = mujoco.MjModel.from_xml_path(str(HUMANOID))
    torso = mjm.body("torso").id
    link_mass = model.arrays.vert_mass[model.link_vert].sum()
    assert mjm.body_mass[torso] == pytest.approx(bare.body_mass[torso] + link_mass, rel=1e-9)
    sim = Simulation(model)
    sim.step(1000)
    torso_drop = 1.4 - sim.rigid.mj_data.xpos[torso, 2]
    assert torso_drop > 0.05  # the humanoid (no control) falls
    pos = sim.state.vert_pos
    assert np.all(np.isfinite(pos)) and sim.volume_rel_error <= 1e-10
    np.testing.assert_array_equal(pos[model.link_vert], sim.rigid.mj_data.site_xpos[model.rigid.site_id])
    assert np.mean(pos[:, 2]) < centre[2] - 0.5 * torso_drop  # the membrane came along
    assert hashlib.sha256(HUMANOID.read_bytes()).hexdigest() == before
