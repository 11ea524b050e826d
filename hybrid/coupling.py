"""The membrane coupled to MuJoCo rigid bodies at step time (paper 3.5; docs/architecture.md).

The rigid part is built at model time (`hybrid.rigid.build_rigid`, called by
`compile_scene`: the scene's MJCF with one attachment site per linked point and the
points' masses on their bodies). `Coupling` (made by `Simulation` for such scenes)
owns this run's MuJoCo model and data and hands them to the one compiled step loop
(`hybrid.loop.run_steps`, whose docstring gives the coupled step's order) as its
`RigidPack`. The loop calls MuJoCo's C `mj_step1`/`mj_step2` directly, at the
addresses the pack carries (`MjViews.fn_step`, ...), so the loop's cached code names no
symbol and is the same for every scene.

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

import mujoco
import numpy as np

from .errors import RigidError, SimulationDiverged
from .loop import CtrlArrays, LinkArrays, MjViews, RigidPack, SlideArrays, WallArrays, WrenchHistory
from .rigid import CoupledRigid, mj_step_ctypes, mj_wall_addresses
from .rigid.modes import implicit_joint_damping
from .sites import site_vel_kernel
from .step import S_TIME, T_GRAVITY
from .step_work import MembraneState
from .wall_coupling import carry_wall

__all__ = ["Coupling"]

_RK4 = int(mujoco.mjtIntegrator.mjINT_RK4)
# what a checkpoint keeps of MuJoCo: every quantity its step reads (`hybrid.State`)
_INTEGRATION = int(mujoco.mjtState.mjSTATE_INTEGRATION)
_DSBL_GRAVITY = int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)


# MuJoCo's C step functions for the compiled loop: (mj_step, mj_step1, mj_step2)' addresses
_MJ_FUNCTIONS = tuple(ctypes.cast(fn, ctypes.c_void_p).value for fn in mj_step_ctypes())


class Coupling:
    """The rigid half of a `Simulation` whose scene has a `Rigid` part.

    Owns its own copy of the model's `MjModel` (`mj_model`: change its parameters
    freely, the `Model` and other runs keep theirs) and its own `MjData`. Set
    `record_wrenches = True` before stepping to keep, per step, the `xfrc_applied`
    used, the lungs' implicit correction as a generalized force and the `qpos` after the step
    (`wrench_history()`, `qfrc_history()`, `qpos_history()`); with `initial_state`
    (`mjSTATE_FULLPHYSICS` at reset) they replay through MuJoCo alone
    (`hybrid.rigid.replay_states`; `replay_wrenches` for a scene without lungs).
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
        self._qfrc_hist: list[np.ndarray] = []
        self.initial_state: np.ndarray | None = None
        mjm = self.system.model
        self._no_hist = WrenchHistory(np.empty((0, mjm.nbody, 6)), np.empty((0, mjm.nq)), np.empty((0, mjm.nv)))
        # 1 where the user's program sets a driven actuator's ctrl (`hybrid.Control`)
        self.ctrl_user = np.zeros(self.system.ctrl_act.size, np.uint8)
        self._mj_time = 0.0  # MuJoCo's time when the loop's last `pack` was made

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
        self._ctrls = CtrlArrays(sys.ctrl_act, sys.ctrl_sched, self.ctrl_user, np.zeros(3))
        nc = sys.wall_point.size
        self._wall = WallArrays(
            sys.wall_point,
            sys.wall_weight,
            sys.wall_rest,
            sys.wall_site_rest,
            sys.wall_site_id,
            sys.wall_site_body,
            sys.wall_site_root,
            np.zeros((nc, 3)),
            np.zeros((nc, 3)),
            *self._wall_scratch(nc, self._lungs()),
        )
        self._slides = SlideArrays(
            sys.slide_vert,
            sys.slide_site_id,
            sys.slide_site_body,
            sys.slide_stiffness,
            np.zeros((sys.slide_vert.size, 3)),
        )
        d = sys.data
        self._mj = MjViews(
            *sys.pointers(),
            *_MJ_FUNCTIONS,
            *(mj_wall_addresses() if self._lungs() else (0, 0, 0, 0)),
            d.site_xpos,
            d.site_xmat,
            d.xipos,
            d.xfrc_applied,
            d.cvel,
            d.subtree_com,
            d.qpos,
            d.qvel,
            d.qfrc_applied,
            d.xpos,
            d.xquat,
            d.ctrl,
        )
        self.initial_state = sys.state()
        self._xfrc_hist.clear()
        self._qpos_hist.clear()
        self._qfrc_hist.clear()
        state.vert_pos[self.link_vert] = sys.site_pos()
        state.vert_vel[self.link_vert] = sys.site_vel()
        self._place_wall(state)

    def _lungs(self) -> bool:
        """Whether the scene has lungs, whose load on the bodies the step takes implicitly
        (`hybrid.wall_coupling`)."""
        return self.model.arrays.lung_face.shape[0] > 0

    def _wall_scratch(self, nc: int, lungs: bool) -> tuple:
        """WallArrays' implicit coupling (`hybrid.loop.WallArrays`, `hybrid.wall_coupling`): empty
        without lungs. The damping is MuJoCo's joint damping where its Euler step takes it implicitly."""
        mjm, sys = self.system.model, self.system
        nv = mjm.nv if lungs else 0
        damping = implicit_joint_damping(mjm)[:nv]
        nvert = self.model.arrays.vert_mass.shape[0]
        face = self.model.arrays.lung_face
        # the cavity's rigid-borne points (cavity indices: a membrane point is itself, a wall point
        # nvert + its row): the linked points on it, then the carried wall's entries
        on = np.isin(self.link_vert, face) & lungs
        points = np.concatenate([self.link_vert[on], nvert + sys.wall_point]).astype(np.int64)
        site = np.concatenate([sys.site_id[on], sys.wall_site_id]).astype(np.int64)
        body = np.concatenate([sys.site_body[on], sys.wall_site_body]).astype(np.int64)
        site.flags.writeable = body.flags.writeable = False  # as the sites' (one build of `add_point_wrench_kernel`)
        weight = np.concatenate([np.ones(int(on.sum())), sys.wall_weight]).astype(float)
        nbody = mjm.nbody if lungs else 0
        return (
            damping,
            points,
            site,
            body,
            weight,
            np.array([_INTEGRATION], np.int32),
            np.zeros((points.size, 3)),
            np.zeros((nbody, 6)),
            np.zeros(nv),
            np.zeros(nv),
            np.zeros((nv, nv)),
            np.zeros(nv),
            np.zeros(mujoco.mj_stateSize(mjm, _INTEGRATION) if lungs else 0),
            np.zeros(nv),
        )

    def _place_wall(self, state: MembraneState) -> None:
        """The lungs' carried wall points onto their bodies (as the step loop places them)."""
        sys, wall = self.system, self._wall
        if wall.point.size:
            d = sys.data
            site_vel_kernel(d.site_xpos, d.cvel, d.subtree_com, wall.site_id, wall.site_body, wall.site_root, wall.vel)
            carry_wall(wall, d.site_xpos, state.lung_wall_pos, state.lung_wall_vel)

    def _rk4(self) -> bool:
        """Whether MuJoCo integrates with RK4 (read at every call: `mj_model` may change)."""
        return int(self.system.model.opt.integrator) == _RK4

    def pack(self, nstep: int) -> RigidPack:
        """The step loop's rigid half (`hybrid.loop.RigidPack`) for the next nstep steps:
        with a wrench history of nstep rows when recording. `finish` after the loop."""
        mjm = self.system.model
        record = bool(self.record_wrenches)
        hist = (
            WrenchHistory(np.empty((nstep, mjm.nbody, 6)), np.empty((nstep, mjm.nq)), np.empty((nstep, mjm.nv)))
            if record
            else self._no_hist
        )
        self._mj_time = self.system.data.time
        return RigidPack(True, self._links, self._ctrls, self._mj, self._wall, self._slides, self._rk4(), record, hist)

    def finish(self, rig: RigidPack, state: MembraneState, step0: int, done: int) -> None:
        """After the loop ran `done` steps from step0 with `rig`: keep the recorded wrenches,
        and raise if MuJoCo reset its state meanwhile (`_check_not_reset`)."""
        if rig.record:
            self._xfrc_hist.append(rig.hist.xfrc[:done])
            self._qpos_hist.append(rig.hist.qpos[:done])
            self._qfrc_hist.append(rig.hist.qfrc[:done])
        self._check_not_reset(state, self._mj_time, step0, done)

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

    # -- checkpoints (`hybrid.State`)
    def mj_state(self) -> np.ndarray:
        """MuJoCo's integration state (`mjSTATE_INTEGRATION`), a copy."""
        m, d = self.system.model, self.system.data
        out = np.empty(mujoco.mj_stateSize(m, _INTEGRATION))
        mujoco.mj_getState(m, d, out, _INTEGRATION)
        return out

    def set_mj_state(self, vec: np.ndarray) -> None:
        """MuJoCo back to an integration state (`mj_state`), every derived quantity
        recomputed from it (the step loop reads the sites' kinematics before stepping)."""
        m, d = self.system.model, self.system.data
        mujoco.mj_setState(m, d, np.asarray(vec, float), _INTEGRATION)
        mujoco.mj_forward(m, d)

    # -- records
    def link_forces(self) -> np.ndarray:
        """(n, 3) N: the force sent to each linked point's site in the last step (a copy),
        in site order (`link_vert`)."""
        return self._force.copy()

    def slide_forces(self) -> np.ndarray:
        """(ns, 3) N: each sliding point's plane's force on it in the last step (a copy), in
        `slide_vert` order; its body took the opposite, at the point."""
        return self._slides.force.copy()

    def wall_forces(self) -> np.ndarray:
        """(nc, 3) N: the lungs' load on each carried wall point in the last step (a copy), in
        `system.wall_point` order; its body took `system.wall_weight` times it at its site."""
        return self._wall.force.copy()

    def wall_correction_wrenches(self) -> np.ndarray:
        """(nbody, 6) [N, N m]: the lungs' implicit correction in the last step (`hybrid.wall_coupling`)
        as each body's wrench, its force and its torque about the body's centre of mass where the
        step started (a copy; zero without lungs, or when the step took none). Its generalized
        force is the step's row of `qfrc_history`."""
        w = self._wall.wrench
        return w.copy() if w.shape[0] else np.zeros((self.system.model.nbody, 6))

    def wrench_history(self) -> np.ndarray:
        """(nstep, nbody, 6) [N, N m]: `xfrc_applied` of every recorded step."""
        nb = self.system.model.nbody
        return np.concatenate(self._xfrc_hist) if self._xfrc_hist else np.zeros((0, nb, 6))

    def qfrc_history(self) -> np.ndarray:
        """(nstep, nv) [N, N m]: the lungs' implicit correction as a generalized force in every
        recorded step (`hybrid.wall_coupling`; 0 without lungs): with `wrench_history` as
        `qfrc_applied`, MuJoCo alone takes the steps the run took (`hybrid.rigid.replay_states`)."""
        nv = self.system.model.nv
        return np.concatenate(self._qfrc_hist) if self._qfrc_hist else np.zeros((0, nv))

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
        self._qfrc_hist.clear()
        state.vert_pos[self.link_vert] = sys.site_pos()
        state.vert_vel[self.link_vert] = sys.site_vel()
        self._place_wall(state)
