"""Replays (hybrid.rigid.replay): recorded wrenches through `mujoco.rollout` give the
trajectory of the run that applied them, exactly."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from hybrid import rigid
from hybrid.errors import RigidError


def test_rollout_replays_a_loop_of_random_wrenches_exactly():
    m = rigid.load_spec(rigid.TRUNK_XML).compile()
    d = mujoco.MjData(m)
    d.qpos[:] = [0.02, -0.01]
    mujoco.mj_forward(m, d)
    state0 = rigid.get_state(m, d)
    rng = np.random.default_rng(3)
    nstep = 1000
    xfrc = rng.normal(scale=0.3, size=(nstep, m.nbody, 6))
    qpos = np.empty((nstep, m.nq))
    for k in range(nstep):
        d.xfrc_applied[:] = xfrc[k]
        mujoco.mj_step(m, d)
        qpos[k] = d.qpos
    replay = rigid.replay_wrenches(m, state0, xfrc)
    assert np.abs(replay - qpos).max() <= 1e-12


def test_rollout_replays_a_rigid_system_run_exactly():
    spec = rigid.load_spec(rigid.TRUNK_XML)
    points = np.array([[0.0, 0.104, 0.06], [0.09, 0.05, 0.06], [0.0, -0.104, 0.06]])
    names = rigid.attach_points(spec, ["rib_left", "rib_left", "rib_right"], points)
    system = rigid.RigidSystem(spec, names)
    state0 = system.state()
    rng = np.random.default_rng(4)
    nstep = 1000
    xfrc = np.empty((nstep, system.model.nbody, 6))
    qpos = np.empty((nstep, system.model.nq))
    for k in range(nstep):
        system.apply_point_forces(rng.normal(scale=1.0, size=(3, 3)))
        xfrc[k] = system.data.xfrc_applied
        system.step()
        qpos[k] = system.data.qpos
    replay = rigid.replay_wrenches(system.model, state0, xfrc)
    assert np.abs(replay - qpos).max() <= 1e-12
    with pytest.raises(RigidError, match="xfrc: expected shape"):
        rigid.replay_wrenches(system.model, state0, xfrc[:, :2])
