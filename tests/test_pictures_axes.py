"""The pictures draw a body in its own axes (x anterior, y left, z cranial) whatever the model's
frame (`hybrid.pictures.frames.turned`, `hybrid.scene.body_axes`): a model whose anterior is -y
(myo-sim's) is cut at its mid-sagittal plane, not a frontal one."""

from __future__ import annotations

import importlib.util

import mujoco
import numpy as np
import pytest

from hybrid.cli import main
from hybrid.pictures.figure import sagittal_section
from hybrid.pictures.frames import Frames, frames_from_recording, turned


def test_turning_moves_the_points_and_the_bodies_alike():
    """A point fixed in a body lands where the turn puts it, through the bodies' turned
    positions and orientations as through the model-frame ones."""
    rng = np.random.default_rng(3)
    quat = rng.standard_normal((2, 3, 4))
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    fr = Frames(
        scene="s",
        t=np.zeros(2),
        pos=rng.standard_normal((2, 5, 3)),
        face_vert=np.zeros((0, 3), int),
        vert_rgba=np.zeros((5, 4)),
        body_pos=rng.standard_normal((2, 3, 3)),
        body_quat=quat,
    )
    anterior, cranial = (0.0, -1.0, 0.0), (0.0, 0.0, 1.0)  # myo-sim's torso
    out = turned(fr, anterior, cranial)
    rot = np.array([anterior, np.cross(cranial, anterior), cranial])
    np.testing.assert_allclose(out.pos, fr.pos @ rot.T, atol=1e-15)
    assert out.left == (1.0, 0.0, 0.0)  # left = cranial x anterior: the model's +x
    local = np.array([0.03, -0.02, 0.05])
    for k in range(2):
        for b in range(3):
            was, now = np.zeros(3), np.zeros(3)
            mujoco.mju_rotVecQuat(was, local, fr.body_quat[k, b])
            mujoco.mju_rotVecQuat(now, local, out.body_quat[k, b])
            np.testing.assert_allclose(now + out.body_pos[k, b], rot @ (was + fr.body_pos[k, b]), atol=1e-14)
    assert turned(fr, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)) is fr  # the packaged trunk's frame: as it was


@pytest.mark.skipif(importlib.util.find_spec("myo_sim") is None, reason="myo_sim (pip install -e '.[myo]') absent")
def test_the_fitted_torso_is_cut_at_its_mid_sagittal_plane(tmp_path):
    """myotorso_breathing (-y anterior, +x left): its recording's frames are turned, and the
    section the figure draws lies across the abdomen's depth (front to back), not its width."""
    assert main(["run", "myotorso_breathing", "--duration", "0.02", "--out", str(tmp_path / "run")]) == 0
    fr = frames_from_recording(tmp_path / "run" / "run.mcap")
    assert fr.left == (1.0, 0.0, 0.0)
    rest = fr.pos[0]
    cut, _ = sagittal_section(rest, fr.face_vert, float(rest[:, 1].mean()))
    span = np.ptp(cut[:, :, 0])
    depth, width = np.ptp(rest[:, 0]), np.ptp(rest[:, 1])  # the body's axes now
    # measured 0.124 m at the midline (the spine indents the back), depth 0.176, width 0.251: a
    # frontal cut (the model's y = const, the pictures' plane before) spans the width
    assert span <= depth and span < 0.8 * width and width > 1.2 * depth, (span, depth, width)


@pytest.mark.skipif(importlib.util.find_spec("myo_sim") is None, reason="myo_sim (pip install -e '.[myo]') absent")
def test_the_figure_draws_the_models_bones_where_they_are(tmp_path):
    """The model's mesh geoms (myo-sim's bones) are recorded as points of their meshes and drawn
    as dots: each dot, turned back into the model's frame, is one of MuJoCo's world mesh vertices
    at the run's start (to the recording's 0.1 mm rounding), and the skeleton the dots draw is the
    model's: the spine behind the membrane in the mid-sagittal section."""
    from scipy.spatial import cKDTree

    import hybrid
    from hybrid.pictures.figure import BONE_SLAB_M, bone_points
    from hybrid.record import MESH_POINTS

    assert main(["run", "myotorso_breathing", "--duration", "0.02", "--out", str(tmp_path / "run")]) == 0
    fr = frames_from_recording(tmp_path / "run" / "run.mcap")
    dots, _ = bone_points(fr, 0)
    meshes = sum(1 for g in fr.geoms if "points" in g)
    assert meshes > 10 and MESH_POINTS <= len(dots) <= MESH_POINTS + 50 * meshes
    sim = hybrid.load("myotorso_breathing")
    m, d = sim.mj_model, sim.mj_data
    mujoco.mj_forward(m, d)
    world = []
    for g in range(m.ngeom):
        if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            k = m.geom_dataid[g]
            vert = m.mesh_vert[m.mesh_vertadr[k] : m.mesh_vertadr[k] + m.mesh_vertnum[k]]
            world.append(d.geom_xpos[g] + vert @ d.geom_xmat[g].reshape(3, 3).T)
    rot = np.array([(0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)])  # the turn: anterior, left, cranial
    gap, _ = cKDTree(np.concatenate(world)).query(dots @ rot)
    assert gap.max() <= 1e-4 * np.sqrt(3) + 1e-9, gap.max()
    # behind the membrane at the midline: the vertebral bodies the plane cuts
    y0 = float(fr.pos[0][:, 1].mean())
    cut = dots[np.abs(dots[:, 1] - y0) <= BONE_SLAB_M]
    assert len(cut) > 50 and np.median(cut[:, 0]) < fr.pos[0][:, 0].min() + 0.05
