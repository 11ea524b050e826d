"""Replays: recorded applied wrenches through MuJoCo alone (`mujoco.rollout`), the
check that the coupled loop drives MuJoCo exactly as `mj_step` would."""

from __future__ import annotations

import mujoco
import numpy as np
from mujoco import rollout as _rollout

from hybrid.errors import RigidError

from .system import STATE_SPEC


def replay_wrenches(
    model: mujoco.MjModel, initial_state: np.ndarray, xfrc: np.ndarray, *, data: mujoco.MjData | None = None
) -> np.ndarray:
    """Replay recorded applied wrenches through MuJoCo alone (`mujoco.rollout`).

    Step k applies `xfrc[k]` as `xfrc_applied` and calls `mj_step`; controls, applied
    generalized forces and mocap poses stay at the model defaults (as in our coupled
    runs). With the same model this reproduces a `RigidSystem` run bit for bit.

    Parameters
    ----------
    model : the compiled model of the run.
    initial_state : (nstate,) `mjSTATE_FULLPHYSICS` state before the first step
        (`RigidSystem.state()` / `get_state`).
    xfrc : (nstep, nbody, 6) [N, N m], `xfrc_applied` during each step.
    data : scratch `MjData` (a fresh one if None).

    Returns
    -------
    (nstep, nq): qpos after each step.
    """
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    state0 = np.asarray(initial_state, dtype=float)
    if state0.shape != (nstate,):
        raise RigidError(f"initial_state: expected shape ({nstate},) (mjSTATE_FULLPHYSICS), got {state0.shape}")
    x = np.asarray(xfrc, dtype=float)
    if x.ndim != 3 or x.shape[1:] != (model.nbody, 6):
        raise RigidError(f"xfrc: expected shape (nstep, {model.nbody}, 6), got {x.shape}")
    nstep = x.shape[0]
    if data is None:
        data = mujoco.MjData(model)
    control = np.ascontiguousarray(x.reshape(1, nstep, model.nbody * 6))
    state, _ = _rollout.rollout(
        model, data, state0[None, :], control, control_spec=int(mujoco.mjtState.mjSTATE_XFRC_APPLIED)
    )
    return state[0, :, 1 : 1 + model.nq].copy()


def replay_states(
    model: mujoco.MjModel,
    initial_state: np.ndarray,
    xfrc: np.ndarray,
    ctrl: np.ndarray | None = None,
    qfrc: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """`replay_wrenches` with the actuators' controls too: step k applies `xfrc[k]`
    and `ctrl[k]` (nstep, nu) (None: the initial state's ctrl throughout), and `qfrc[k]`
    (nstep, nv) as `qfrc_applied` (None: 0; a run with lungs: `Coupling.qfrc_history`, their
    implicit correction). Returns (qpos (nstep, nq), qvel (nstep, nv)) after each step."""
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    state0 = np.asarray(initial_state, dtype=float)
    if state0.shape != (nstate,):
        raise RigidError(f"initial_state: expected shape ({nstate},) (mjSTATE_FULLPHYSICS), got {state0.shape}")
    x = np.asarray(xfrc, dtype=float)
    if x.ndim != 3 or x.shape[1:] != (model.nbody, 6):
        raise RigidError(f"xfrc: expected shape (nstep, {model.nbody}, 6), got {x.shape}")
    nstep = x.shape[0]
    parts, spec = [x.reshape(nstep, model.nbody * 6)], int(mujoco.mjtState.mjSTATE_XFRC_APPLIED)
    if ctrl is not None and model.nu:
        c = np.asarray(ctrl, dtype=float)
        if c.shape != (nstep, model.nu):
            raise RigidError(f"ctrl: expected shape ({nstep}, {model.nu}), got {c.shape}")
        parts.insert(0, c)  # MuJoCo orders a state's parts by their bit: ctrl, qfrc_applied, xfrc_applied
        spec |= int(mujoco.mjtState.mjSTATE_CTRL)
    if qfrc is not None:
        q = np.asarray(qfrc, dtype=float)
        if q.shape != (nstep, model.nv):
            raise RigidError(f"qfrc: expected shape ({nstep}, {model.nv}), got {q.shape}")
        parts.insert(len(parts) - 1, q)
        spec |= int(mujoco.mjtState.mjSTATE_QFRC_APPLIED)
    control = np.ascontiguousarray(np.concatenate(parts, axis=1)[None])
    state, _ = _rollout.rollout(model, mujoco.MjData(model), state0[None, :], control, control_spec=spec)
    return state[0, :, 1 : 1 + model.nq].copy(), state[0, :, 1 + model.nq : 1 + model.nq + model.nv].copy()
