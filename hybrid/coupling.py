"""The membrane coupled to MuJoCo rigid bodies at step time (paper 3.5; docs/architecture.md).

The rigid part is built at model time (`hybrid.rigid.build_rigid`, called by
`compile_scene`: the scene's MJCF with one attachment site per linked point and the
points' masses on their bodies). `Coupling` (made by `Simulation` for such scenes)
runs the coupled step, in this order:

1. the membrane forces at t (only the terms the scene has);
2. every linked point's membrane force, plus the pressure force of the last volume
   projection p grad_i V (how the incompressible abdomen pushes on the ribs), plus
   its weight, goes to its body as a wrench applied at its site (`xfrc_applied`);
3. the actuators the scene drives (`rigid.ctrl`) take their schedules' values at t
   (`mjData.ctrl`); MuJoCo steps (`mj_step2` then `mj_step1`, or `mj_step` + `mj_step1` for RK4, so
   that the site kinematics belong to the new state; bit for bit `mj_step`);
4. the linked points take their sites' positions and velocities;
5. the free points integrate, the local constraints and the exact volume projection
   apply (`membrane_advance`).

The whole loop, n steps at a time, is one numba function that calls MuJoCo's C
`mj_step1`/`mj_step2` directly (their addresses are registered with LLVM as
external symbols, so the function is cached on disk like the other kernels).

Weight of the linked points: with `Rigid.add_link_mass` (the default) each linked
point's mass m_i is on its body (`hybrid.rigid.compose`), and MuJoCo applies its
weight m_i g_mujoco itself; the coupling adds m_i (a_scene - g_mujoco) at the site
so that a linked point weighs what a free membrane point weighs, m_i a_scene (zero
for a scene without a gravity term, whose membrane feels no gravity). Without
`add_link_mass` the point's weight m_i a_scene is transmitted as a force and its
inertia is neglected.

Each `Coupling` steps its own copy of the model's `MjModel`, so that changing one
run's parameters leaves the `Model` and other runs alone.
"""

from __future__ import annotations

import ctypes
from typing import NamedTuple

import llvmlite.binding as _llvm
import mujoco
import numpy as np
from numba import types

from .errors import RigidError, SimulationDiverged
from .kernel import kernel
from .rigid import CoupledRigid, mj_step_ctypes, point_wrench_kernel, site_vel_kernel
from .schedule import schedule_eval
from .step import (
    OK,
    S_PRESSURE,
    S_TIME,
    T_GRAVITY,
    Frames,
    MembraneState,
    capture_frame,
    membrane_advance,
    membrane_forces,
    step_switches,
)

__all__ = ["LinkArrays", "CtrlArrays", "MjViews", "WrenchHistory", "Coupling", "run_coupled"]

_RK4 = int(mujoco.mjtIntegrator.mjINT_RK4)
_DSBL_GRAVITY = int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)


# ----------------------------------------------------------------- MuJoCo from numba


def _register_mujoco_symbols() -> None:
    """Make MuJoCo's C step functions callable from cached numba code.

    The addresses of `mj_step`, `mj_step1`, `mj_step2` of the library the bindings
    use are registered with LLVM under private names; compiled code refers to them by
    name, so a cached function links again in a new process (where the addresses
    differ) as long as this ran first (it runs when this module is imported).
    """
    for name, fn in zip(("step", "step1", "step2"), mj_step_ctypes()):
        _llvm.add_symbol(f"hybrid_mj_{name}", ctypes.cast(fn, ctypes.c_void_p).value)


_register_mujoco_symbols()
_SIG = types.void(types.intp, types.intp)
_mj_step = types.ExternalFunction("hybrid_mj_step", _SIG)
_mj_step1 = types.ExternalFunction("hybrid_mj_step1", _SIG)
_mj_step2 = types.ExternalFunction("hybrid_mj_step2", _SIG)


# ----------------------------------------------------------------- the compiled loop's packs


class LinkArrays(NamedTuple):
    """The n linked points and their attachment sites, in site order.

    Read: vert (n,) int32, the linked membrane vertices; site_id (n,) int64, their
    MuJoCo sites; site_body (n,) int64, each site's body; site_root (n,) int64, the
    root body of its kinematic tree (for `cvel`); extra_force (n, 3) N, added to each
    point's force (the weight correction, module docstring).
    Scratch: force (n, 3) N, the forces sent to the sites; vel (n, 3) m/s, the
    sites' velocities.
    """

    vert: np.ndarray
    site_id: np.ndarray
    site_body: np.ndarray
    site_root: np.ndarray
    extra_force: np.ndarray
    force: np.ndarray
    vel: np.ndarray


class CtrlArrays(NamedTuple):
    """The actuators a scene drives (`rigid.ctrl`): act (nc,) int64, their ids;
    sched, their schedules (`hybrid.schedule.ScheduleTable`, row j for act[j]);
    scratch: val (3,), a schedule's value."""

    act: np.ndarray
    sched: object
    val: np.ndarray


class MjViews(NamedTuple):
    """MuJoCo's model and data as the compiled loop sees them: model_ptr, data_ptr
    (int), the `mjModel*` and `mjData*` for the C step functions, and views of the
    `MjData`'s own arrays (valid as long as it lives), written by MuJoCo's step:
    site_xpos (nsite, 3) m; xipos (nbody, 3) m, the bodies' centres of mass;
    xfrc_applied (nbody, 6) [N, N m]; cvel (nbody, 6) [rad/s, m/s]; subtree_com
    (nbody, 3) m; qpos (nq,); xpos (nbody, 3) m and xquat (nbody, 4) (w, x, y, z),
    the bodies' poses; ctrl (nu,), the actuators' controls."""

    model_ptr: int
    data_ptr: int
    site_xpos: np.ndarray
    xipos: np.ndarray
    xfrc_applied: np.ndarray
    cvel: np.ndarray
    subtree_com: np.ndarray
    qpos: np.ndarray
    xpos: np.ndarray
    xquat: np.ndarray
    ctrl: np.ndarray


class WrenchHistory(NamedTuple):
    """Per step k of a recorded run: xfrc (nstep, nbody, 6) [N, N m], the
    `xfrc_applied` used; qpos (nstep, nq), MuJoCo's qpos after the step. Empty
    (nstep = 0) when not recording."""

    xfrc: np.ndarray
    qpos: np.ndarray


# ----------------------------------------------------------------- the coupled step


@kernel
def run_coupled(
    m,
    s,
    links,
    ctrls,
    mj,
    rk4,
    stops,
    step0,
    record,
    hist,
    frame_pos,
    frame_scal,
    frame_body_pos,
    frame_body_quat,
    par=True,
    shape_memory=True,
    membrane=True,
    applied=True,
    attraction=True,
    mass_spring=True,
    muscle=True,
    soft_volume=True,
    pressure=True,
    fibres=True,
    passive=True,
    prescribed=True,
    keep_in=True,
    volume=True,
    shake=True,
):
    """Coupled steps (module docstring, steps 1-5) to each step index of stops,
    capturing a frame at each (a stop at the current step captures it without
    stepping). Returns the frames captured: fewer than stops when the membrane
    fails, its status then in s.status (s.status[1]: the failing step's index).
    The one compiled loop of the coupled step, for runs by frames and by steps
    alike (`Coupling.run`: one stop), so that a first run compiles it once.

    # Model:    m (MembraneArrays); links.vert, .site_id, .site_body, .site_root,
    #           .extra_force (LinkArrays); rk4: bool, step MuJoCo with mj_step (RK4);
    #           ctrls.act, .sched (CtrlArrays): the driven actuators
    # Data in:  s (MembraneState) at step step0; mj (MjViews): MuJoCo's state;
    #           stops (nframe,) int64 increasing step indices from step0
    # Data out: s and MuJoCo's state (through mj.data_ptr) after the steps done;
    #           mj.xfrc_applied; mj.ctrl[ctrls.act] at each step's start time;
    #           hist.xfrc[j], hist.qpos[j] of step step0 + j when
    #           record; per frame i: frame_pos[i] (nvert, 3) m, frame_scal[i]
    #           (`capture_frame`), frame_body_pos[i] (nbody - 1, 3) m and
    #           frame_body_quat[i] (nbody - 1, 4) from mj.xpos, mj.xquat (world excluded)
    # Scratch:  links.force, links.vel, ctrls.val
    # par:      None: the membrane's serial passes only (`hybrid.step.step_par`)
    # switches: None for a term the model lacks, not compiled (`hybrid.step.step_switches`)
    """
    h = m.dt
    pos, vel, frc, grad = s.vert_pos, s.vert_vel, s.vert_force, s.grad
    link_vert, site_id, link_force, link_vel = links.vert, links.site_id, links.force, links.vel
    xfrc, qpos = mj.xfrc_applied, mj.qpos
    n = link_vert.shape[0]
    done = step0
    for f in range(stops.shape[0]):
        t0 = s.scal[S_TIME]
        for k in range(stops[f] - done):
            t = t0 + k * h
            row = done - step0 + k
            membrane_forces(
                m,
                s,
                t,
                par,
                shape_memory,
                membrane,
                applied,
                attraction,
                mass_spring,
                muscle,
                soft_volume,
                pressure,
                fibres,
                passive,
            )
            p = s.scal[S_PRESSURE]
            for j in range(n):
                i = link_vert[j]
                for a in range(3):
                    link_force[j, a] = frc[i, a] + p * grad[i, a] + links.extra_force[j, a]
            point_wrench_kernel(mj.site_xpos, mj.xipos, site_id, links.site_body, link_force, xfrc)
            for j in range(ctrls.act.shape[0]):
                schedule_eval(ctrls.sched, j, t, ctrls.val)
                mj.ctrl[ctrls.act[j]] = ctrls.val[0]
            if record:  # element-wise: a slice copy would allocate
                for b in range(xfrc.shape[0]):
                    for a in range(6):
                        hist.xfrc[row, b, a] = xfrc[b, a]
            if rk4:
                _mj_step(mj.model_ptr, mj.data_ptr)
            else:
                _mj_step2(mj.model_ptr, mj.data_ptr)
            _mj_step1(mj.model_ptr, mj.data_ptr)
            if record:
                for a in range(qpos.shape[0]):
                    hist.qpos[row, a] = qpos[a]
            site_vel_kernel(mj.site_xpos, mj.cvel, mj.subtree_com, site_id, links.site_body, links.site_root, link_vel)
            for j in range(n):
                i = link_vert[j]
                sid = site_id[j]
                for a in range(3):
                    pos[i, a] = mj.site_xpos[sid, a]
                    vel[i, a] = link_vel[j, a]
            if membrane_advance(m, s, t, done + k, par, prescribed, keep_in, volume, shake) != OK:
                return f
            s.scal[S_TIME] = t0 + (k + 1) * h
        done = stops[f]
        capture_frame(m, s, frame_pos[f], frame_scal[f])
        for b in range(frame_body_pos.shape[1]):
            for a in range(3):
                frame_body_pos[f, b, a] = mj.xpos[b + 1, a]
            for a in range(4):
                frame_body_quat[f, b, a] = mj.xquat[b + 1, a]
    return stops.shape[0]


class Coupling:
    """The rigid half of a `Simulation` whose scene has a `Rigid` part.

    Owns its own copy of the model's `MjModel` (`mj_model`: change its parameters
    freely, the `Model` and other runs keep theirs) and its own `MjData`. Set
    `record_wrenches = True` before stepping to keep, per step, the `xfrc_applied`
    used and the `qpos` after the step (`wrench_history()`, `qpos_history()`); with
    `initial_state` (`mjSTATE_FULLPHYSICS` at reset) they replay through MuJoCo alone
    (`hybrid.rigid.replay_wrenches`).
    """

    def __init__(self, model):
        if model.rigid is None:
            raise RigidError("Coupling: the model has no rigid part")
        self.model = model
        # MuJoCo steps with the membrane's step (Model.with_dt may have changed it)
        self.system: CoupledRigid = model.rigid.fork(timestep=model.arrays.dt)
        self.link_vert = np.ascontiguousarray(model.link_vert, np.int32)
        n = self.link_vert.size
        self._force = np.zeros((n, 3))
        self._vel = np.zeros((n, 3))
        self.record_wrenches = False
        self._xfrc_hist: list[np.ndarray] = []
        self._qpos_hist: list[np.ndarray] = []
        self.initial_state: np.ndarray | None = None
        mjm = self.system.model
        self._no_hist = WrenchHistory(np.empty((0, mjm.nbody, 6)), np.empty((0, mjm.nq)))
        self._frame = Frames(1, model.nvert, mjm.nbody - 1)  # `run`'s frame (scratch)

    # -- MuJoCo access
    @property
    def mj_model(self):
        """This run's `mujoco.MjModel` (with the attachment sites and link masses), a
        copy of the `Model`'s."""
        return self.system.model

    @property
    def mj_data(self):
        """This run's `mujoco.MjData`."""
        return self.system.data

    def link_extra_force(self) -> np.ndarray:
        """(n, 3) N added at each site: the linked point's weight in the scene minus what
        MuJoCo applies to its added mass (module docstring). From the current MjModel."""
        mjm = self.system.model
        g = np.zeros(3) if (mjm.opt.disableflags & _DSBL_GRAVITY) else np.array(mjm.opt.gravity, float)
        comp = 1.0 - mjm.body_gravcomp[self.system.site_body]
        accel = np.asarray(self.model.arrays.accel, float) if self.model.arrays.term_on[T_GRAVITY] else np.zeros(3)
        mass = self.system.link_mass
        extra = mass[:, None] * accel[None, :]
        extra -= (self.system.mass_added * comp * mass)[:, None] * g[None, :]
        return np.ascontiguousarray(extra)

    # -- the hooks Simulation calls
    def reset(self, state: MembraneState) -> None:
        """MuJoCo back to its initial state; the linked points onto their sites."""
        sys = self.system
        sys.reset()
        self._links = LinkArrays(
            self.link_vert, sys.site_id, sys.site_body, sys.site_root, self.link_extra_force(), self._force, self._vel
        )
        self._ctrls = CtrlArrays(sys.ctrl_act, sys.ctrl_sched, np.zeros(3))
        d = sys.data
        self._mj = MjViews(
            *sys.pointers(),
            d.site_xpos,
            d.xipos,
            d.xfrc_applied,
            d.cvel,
            d.subtree_com,
            d.qpos,
            d.xpos,
            d.xquat,
            d.ctrl,
        )
        self.initial_state = sys.state()
        self._xfrc_hist.clear()
        self._qpos_hist.clear()
        state.vert_pos[self.link_vert] = sys.site_pos()
        state.vert_vel[self.link_vert] = sys.site_vel()

    def step(self, state: MembraneState, t: float, step_index: int, arrays=None) -> int:
        """One coupled step from time t; returns 0 or the simulation's status code."""
        done = self.run(state, 1, step_index, arrays)
        return OK if done == 1 else int(state.status[0])

    def _rk4(self) -> bool:
        """Whether MuJoCo integrates with RK4 (read at every call: `mj_model` may change)."""
        return int(self.system.model.opt.integrator) == _RK4

    def run(self, state: MembraneState, nstep: int, step0: int, arrays=None) -> int:
        """nstep coupled steps in one compiled call; returns the steps done. `arrays`:
        the model's arrays with the build to run (`Simulation` chooses), by default the model's."""
        mjm = self.system.model
        record = bool(self.record_wrenches)
        hist = WrenchHistory(np.empty((nstep, mjm.nbody, 6)), np.empty((nstep, mjm.nq))) if record else self._no_hist
        mj_time = self.system.data.time
        a = self.model.arrays if arrays is None else arrays
        f = self._frame
        stop = np.array([step0 + nstep], np.int64)
        count = run_coupled(
            a,
            state,
            self._links,
            self._ctrls,
            self._mj,
            self._rk4(),
            stop,
            int(step0),
            record,
            hist,
            f.pos,
            f.scal,
            f.body_pos,
            f.body_quat,
            *step_switches(a),
        )
        done = int(nstep) if count else int(state.status[1]) - int(step0)
        if record:
            self._xfrc_hist.append(hist.xfrc[:done])
            self._qpos_hist.append(hist.qpos[:done])
        self._check_not_reset(state, mj_time, step0, done)
        return done

    def _check_not_reset(self, state: MembraneState, mj_time: float, step0: int, done: int) -> None:
        """Raise if MuJoCo's clock ran fewer than `done` steps since mj_time: MuJoCo found
        a non-finite or huge qpos/qvel/qacc and reset its data (time 0, qpos0), so the
        ribs jumped back and the run is not to be trusted any more."""
        mjm, d = self.system.model, self.system.data
        if done and d.time < mj_time + (done - 0.5) * mjm.opt.timestep:
            raise SimulationDiverged(
                f"MuJoCo's rigid state diverged between steps {step0} and {step0 + done} "
                f"(t <= {state.scal[S_TIME]:.6g} s) and MuJoCo reset it; try a smaller dt_s, heavier or "
                f"stiffer rigid bodies, or more damping",
                time_s=float(state.scal[S_TIME]),
                step=int(step0 + done),
                vert=int(self.link_vert[0]) if self.link_vert.size else 0,
                dt_suggested_s=0.5 * float(self.model.arrays.dt),
            )

    def run_frames(self, state: MembraneState, stops: np.ndarray, step0: int, frames: Frames, arrays=None) -> int:
        """`run` to each step index of stops in one compiled call, capturing a frame at
        each into frames; returns the frames captured. (Without wrench recording.)"""
        mj_time = self.system.data.time
        a = self.model.arrays if arrays is None else arrays
        count = run_coupled(
            a,
            state,
            self._links,
            self._ctrls,
            self._mj,
            self._rk4(),
            stops,
            int(step0),
            False,
            self._no_hist,
            frames.pos,
            frames.scal,
            frames.body_pos,
            frames.body_quat,
            *step_switches(a),
        )
        # a reset anywhere in these frames makes none of them trustworthy (frames.count stays 0)
        self._check_not_reset(state, mj_time, step0, (int(stops[count - 1]) if count else int(step0)) - int(step0))
        return count

    # -- records
    def link_forces(self) -> np.ndarray:
        """(n, 3) N: the force sent to each linked point's site in the last step (a copy),
        in site order (`link_vert`)."""
        return self._force.copy()

    def wrench_history(self) -> np.ndarray:
        """(nstep, nbody, 6) [N, N m]: `xfrc_applied` of every recorded step."""
        nb = self.system.model.nbody
        return np.concatenate(self._xfrc_hist) if self._xfrc_hist else np.zeros((0, nb, 6))

    def qpos_history(self) -> np.ndarray:
        """(nstep, nq): MuJoCo's qpos after every recorded step."""
        nq = self.system.model.nq
        return np.concatenate(self._qpos_hist) if self._qpos_hist else np.zeros((0, nq))

    # -- a state set by hand
    def set_state(self, state: MembraneState, *, qpos=None, qvel=None, time_s=None) -> None:
        """MuJoCo's `qpos` (nq,), `qvel` (nv,) and time set (checked by
        `Simulation.set_state`), everything derived from them recomputed (mj_forward),
        and the linked points put back onto their sites, as `reset` does. Replays
        start from here: `initial_state` is this state, the histories are cleared."""
        sys = self.system
        d = sys.data
        if qpos is not None:
            d.qpos[:] = qpos
        if qvel is not None:
            d.qvel[:] = qvel
        if time_s is not None:
            d.time = time_s
        sys.forward()
        self.initial_state = sys.state()
        self._xfrc_hist.clear()
        self._qpos_hist.clear()
        state.vert_pos[self.link_vert] = sys.site_pos()
        state.vert_vel[self.link_vert] = sys.site_vel()
