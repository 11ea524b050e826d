"""The compiled rigid system: a MuJoCo model and its data, driven by point forces at
attachment sites, and the compiled site kernels the coupled step shares with it.

The coupling (paper section 3.5; docs/architecture.md) goes through *attachment sites*: each
linked membrane point i has a site on its rigid body at the point's rest position
(`hybrid.rigid.compose`). Every step, `RigidSystem.apply_point_forces` turns the
points' forces into one wrench per body, applied at the body's centre of mass
(`mjData.xfrc_applied`); `RigidSystem.step` advances MuJoCo; `site_pos` and
`site_vel` give the new positions and velocities that the linked points take.

`RigidSystem.step` runs `mj_step2` then `mj_step1` (`mj_step` then `mj_step1` for
RK4), so that after a step every kinematic quantity (`site_xpos`, `xipos`, `cvel`)
belongs to the *new* state; after a bare `mj_step` they would lag one step behind.
The trajectory is bit-for-bit that of `mj_step` with the same `xfrc_applied`, which
`hybrid.rigid.replay_wrenches` (`mujoco.rollout`) reproduces.

Compiled path: `point_wrench_kernel` and `site_vel_kernel` are numba kernels on the
raw `MjData` arrays, and `mj_step_ctypes` gives MuJoCo's C `mj_step`, `mj_step1`,
`mj_step2`, callable from inside `@numba.njit` code with the pointers of
`RigidSystem.pointers`; a whole coupled step can then run without returning to Python.

Units: SI (m, kg, s, N, N m). Arrays: `(n, 3)` float64, world frame unless stated.
"""

from __future__ import annotations

import copy
import ctypes
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import mujoco
import numpy as np

from hybrid.errors import RigidError
from hybrid.schedule import schedule_eval, stack_schedules
from hybrid.sites import point_wrench_kernel, site_vel_kernel

from .controls import Controls
from .mjcf import compile_spec

#: The state signature used for snapshots and replays (`mjSTATE_FULLPHYSICS`).
STATE_SPEC: int = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)

_RK4 = int(mujoco.mjtIntegrator.mjINT_RK4)


@cache
def _library() -> ctypes.CDLL:
    """MuJoCo's C library, the one the Python bindings are linked against."""
    folder = Path(mujoco.__file__).resolve().parent
    candidates = (
        sorted(folder.glob("libmujoco.so*"))
        + sorted(folder.glob("libmujoco*.dylib"))
        + sorted(folder.glob("mujoco.dll"))
    )
    if not candidates:
        raise RigidError(f"MuJoCo's C library: not found in {str(folder)!r}")
    return ctypes.CDLL(str(candidates[0]))


@cache
def mj_step_ctypes() -> tuple[ctypes._CFuncPtr, ctypes._CFuncPtr, ctypes._CFuncPtr]:
    """`(mj_step, mj_step1, mj_step2)` of MuJoCo's C library, callable from numba.

    Call them inside an `@numba.njit` function with the ints of
    `RigidSystem.pointers()`; the numpy arrays of `MjData` (`data.xfrc_applied`, ...) are
    views of its memory and can be passed to the same function. The library is the
    one the Python bindings are linked against, so results are bit-for-bit those of
    `mujoco.mj_step`. Python's call overhead (about 0.5 us a call) disappears.
    """
    lib = _library()
    fns = (lib.mj_step, lib.mj_step1, lib.mj_step2)
    for fn in fns:
        fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        fn.restype = None
    return fns


#: the C functions besides the step that the compiled loop calls at their addresses
#: (`mj_wall_addresses`): the lungs' wall coupled implicitly (`hybrid.wall_coupling`)
WALL_FUNCTIONS = ("mj_applyFT", "mj_fullM", "mj_getState", "mj_setState")


@cache
def mj_wall_addresses() -> tuple[int, ...]:
    """The addresses of `WALL_FUNCTIONS` in the library `mj_step_ctypes` loads."""
    lib = _library()
    return tuple(int(ctypes.cast(getattr(lib, name), ctypes.c_void_p).value) for name in WALL_FUNCTIONS)


def get_state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """The full physics state of `data` (`mjSTATE_FULLPHYSICS`), shape (nstate,)."""
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    return state


class RigidSystem:
    """A compiled MuJoCo model and its data, driven by point forces at attachment sites.

    Parameters
    ----------
    spec : the model; compiled once here (the spec is not modified).
    site_names : (n,) the attachment sites, in point order (as `attach_points`
        returns them); may be empty.
    timestep : s, overrides the model's `opt.timestep` if given (> 0).

    Attributes (read-only arrays, for compiled kernels)
    ---------------------------------------------------
    site_id : (n,) int      MuJoCo site ids of the attachment sites
    site_body : (n,) int    the body id of each site
    site_root : (n,) int    the root body of each site's kinematic tree (for cvel)
    body_id : (nb,) int     the distinct bodies that carry attachment sites
    """

    def __init__(self, spec: mujoco.MjSpec, site_names: Sequence[str] = (), *, timestep: float | None = None):
        model = compile_spec(spec)
        if timestep is not None:
            if not (np.isfinite(timestep) and timestep > 0):
                raise RigidError(f"timestep: expected a finite value > 0 s, got {timestep}")
            model.opt.timestep = float(timestep)
        self._model = model
        self._data = mujoco.MjData(model)
        names = list(site_names)
        all_sites = [model.site(i).name for i in range(model.nsite)]
        missing = [s for s in names if s not in all_sites]
        if missing:
            raise RigidError(f"unknown site name(s) {missing[:5]}; available sites: {all_sites}")
        self._site_names = names
        self.site_id = np.array([model.site(s).id for s in names], dtype=np.int64)
        self.site_body = model.site_bodyid[self.site_id].astype(np.int64)
        self.body_id = np.unique(self.site_body)
        self.site_root = model.body_rootid[self.site_body].astype(np.int64)
        self.start_key = -1  # the keyframe a reset starts from (-1: qpos0)
        mujoco.mj_forward(model, self._data)

    # -- access -------------------------------------------------------------------
    @property
    def model(self) -> mujoco.MjModel:
        """The compiled `mujoco.MjModel` (parameters may be changed between steps)."""
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The `mujoco.MjData` (state and derived quantities of the current state)."""
        return self._data

    @property
    def time(self) -> float:
        """Simulated time, s."""
        return float(self._data.time)

    def pointers(self) -> tuple[int, int]:
        """(mjModel*, mjData*) as ints, for MuJoCo's C functions called from compiled
        code (`mj_step_ctypes`); valid as long as this system lives."""
        return self._model._address, self._data._address

    def body_names(self) -> list[str]:
        """The names of all bodies of the model, indexed by body id ("world" first)."""
        return [self._model.body(i).name for i in range(self._model.nbody)]

    def site_names(self) -> list[str]:
        """The attachment site names, in point order (n,)."""
        return list(self._site_names)

    def state(self) -> np.ndarray:
        """The full physics state (`mjSTATE_FULLPHYSICS`), shape (nstate,), for replays."""
        return get_state(self._model, self._data)

    # -- coupling -----------------------------------------------------------------
    def point_wrenches(self, forces: np.ndarray) -> np.ndarray:
        """The wrench of the point forces on each attachment body, about its centre of mass.

        Parameters
        ----------
        forces : (n, 3) N, the force on each attachment site (world frame).

        Returns
        -------
        (nb, 6): [force (N), torque (N m)] per body of `body_id`, the torque about the
        body's centre of mass `xipos`: sum over its points of (site_xpos - xipos) x F.
        """
        f = self._check_forces(forces)
        xfrc = np.zeros((self._model.nbody, 6))
        d = self._data
        point_wrench_kernel(d.site_xpos, d.xipos, self.site_id, self.site_body, f, xfrc)
        return xfrc[self.body_id]

    def apply_point_forces(self, forces: np.ndarray) -> None:
        """Set `xfrc_applied` of every attachment body to the wrench of its points' forces.

        forces : (n, 3) N at the attachment sites, world frame. The wrenches of the
        attachment bodies are replaced (not accumulated); other bodies are untouched.
        They stay applied at every following step until set again.
        """
        d = self._data
        point_wrench_kernel(
            d.site_xpos, d.xipos, self.site_id, self.site_body, self._check_forces(forces), d.xfrc_applied
        )

    def _check_forces(self, forces: np.ndarray) -> np.ndarray:
        f = np.ascontiguousarray(forces, dtype=float)
        if f.shape != (len(self.site_id), 3):
            raise RigidError(f"forces: expected shape ({len(self.site_id)}, 3), got {f.shape}")
        return f

    def step(self) -> None:
        """Advance one time step; afterwards all kinematics belong to the new state."""
        m, d = self._model, self._data
        if m.opt.integrator == _RK4:  # mj_step2 cannot run RK4
            mujoco.mj_step(m, d)
        else:
            mujoco.mj_step2(m, d)
        mujoco.mj_step1(m, d)

    def forward(self) -> None:
        """Recompute every derived quantity after `qpos`, `qvel` or `ctrl` were set by hand."""
        mujoco.mj_forward(self._model, self._data)

    def site_pos(self) -> np.ndarray:
        """(n, 3) m, world positions of the attachment sites (a copy)."""
        return self._data.site_xpos[self.site_id].copy()

    def site_vel(self) -> np.ndarray:
        """(n, 3) m/s, world linear velocities of the attachment sites.

        Equal to `mj_objectVelocity(..., mjOBJ_SITE, id, res, flg_local=0)[3:]`:
        v = v_c + w x (site_xpos - c), with (w, v_c) = `cvel` of the site's body
        expressed at c, the centre of mass of its kinematic tree (`subtree_com`).
        """
        d = self._data
        out = np.empty((len(self.site_id), 3))
        site_vel_kernel(d.site_xpos, d.cvel, d.subtree_com, self.site_id, self.site_body, self.site_root, out)
        return out

    def reset(self) -> None:
        """Back to the model's initial state (`qpos0`, or the keyframe `start_key`; time 0,
        no wrench)."""
        self._start(self._data)

    def _start(self, data: mujoco.MjData) -> None:
        if self.start_key >= 0:
            mujoco.mj_resetDataKeyframe(self._model, data, self.start_key)
        else:
            mujoco.mj_resetData(self._model, data)
        mujoco.mj_forward(self._model, data)


class CoupledRigid(RigidSystem):
    """The compiled rigid part of a scene: a `RigidSystem` whose attachment sites
    are the linked membrane points.

    Attributes (besides `RigidSystem`'s): link_vert (n,) int32, the linked vertices in
    site order; link_body (n,) names of their bodies; link_mass (n,) kg; mass_added
    (n,) bool, whether each point's mass was added to its body; mjcf_path, the source
    (the MJCF's Path, or the "SCHEME:NAME" string of a package model).
    """

    def __init__(
        self,
        spec,
        site_names,
        *,
        timestep,
        link_vert,
        link_body,
        link_mass,
        mass_added,
        mjcf_path,
        controls: Controls | None = None,
        ribs=None,
        wall: dict | None = None,
        slides: dict | None = None,
    ):
        super().__init__(spec, site_names, timestep=timestep)
        self.controls = Controls() if controls is None else controls
        self.controls.finish(self._model)
        self.start_key = self.controls.key_id
        #: the driven actuators' ids (nc,) and their schedules, read by the coupled step
        self.ctrl_act = np.array([self._model.actuator(a).id for a in self.controls.ctrl_actuators], np.int64)
        self.ctrl_sched = stack_schedules(self.controls.ctrl_schedules)[0]
        self.reset()
        self.link_vert = np.asarray(link_vert, np.int32)
        self.link_body = tuple(link_body)
        self.link_mass = np.asarray(link_mass, float)
        self.mass_added = np.asarray(mass_added, bool)
        self.mjcf_path = mjcf_path
        #: the ribs added to the model (`hybrid.rigid.ribs.RibsAdded`), or None
        self.ribs = ribs
        #: the lungs' wall points the bodies carry (`hybrid.terms.lungs`): wall_point (nc,) their
        #: indices in the wall, wall_weight (nc,) the share of their body's motion, wall_rest
        #: (nc, 3) m, and their sites: wall_site_id, wall_site_body, wall_site_root (nc,),
        #: wall_site_rest (nc, 3) m where each site starts
        w = wall or {
            "site_names": [],
            "point": np.zeros(0, np.int64),
            "weight": np.zeros(0),
            "rest": np.zeros((0, 3)),
            "site_rest": np.zeros((0, 3)),
        }
        mjm = self._model
        self.wall_point = np.asarray(w["point"], np.int64)
        self.wall_weight = np.asarray(w["weight"], float)
        self.wall_rest = np.ascontiguousarray(w["rest"], float).reshape(-1, 3)
        self.wall_site_rest = np.ascontiguousarray(w["site_rest"], float).reshape(-1, 3)
        self.wall_site_id = np.array([mjm.site(n).id for n in w["site_names"]], np.int64)
        self.wall_site_body = mjm.site_bodyid[self.wall_site_id].astype(np.int64)
        self.wall_site_root = mjm.body_rootid[self.wall_site_body].astype(np.int64)
        #: the sliding points (`RigidLink.slide_stiffness_n_per_m3`): slide_vert (ns,) int32, their
        #: vertices; slide_stiffness (ns,) N/m; their planes' sites: slide_site_id, slide_site_body (ns,)
        sl = slides or {"site_names": [], "vert": np.zeros(0, np.int32), "stiffness": np.zeros(0)}
        self.slide_vert = np.asarray(sl["vert"], np.int32)
        self.slide_stiffness = np.asarray(sl["stiffness"], float)
        self.slide_site_id = np.array([mjm.site(n).id for n in sl["site_names"]], np.int64)
        self.slide_site_body = mjm.site_bodyid[self.slide_site_id].astype(np.int64)
        for arr in (
            self.slide_vert,
            self.slide_stiffness,
            self.slide_site_id,
            self.slide_site_body,
            self.link_vert,
            self.link_mass,
            self.mass_added,
            self.site_id,
            self.site_body,
            self.site_root,
            self.body_id,
            self.ctrl_act,
            self.wall_site_id,  # read-only as the links' sites: one build of the kernels given either
            self.wall_site_body,
            self.wall_site_root,
        ):
            arr.flags.writeable = False

    def settings(self) -> dict:
        """What the scene changed in the model and what MuJoCo integrates with (JSON values,
        for the summary; `hybrid.rigid.controls`)."""
        out = {**self.controls.settings, "timestep_s": float(self._model.opt.timestep)}
        if self.ribs is not None:
            out["ribs"] = self.ribs.settings()
        return out

    def reset(self) -> None:
        """`RigidSystem.reset`, then the driven actuators at their schedules' values at t = 0."""
        super().reset()
        self.apply_ctrl(0.0)

    def apply_ctrl(self, t: float) -> None:
        """Set the driven actuators' `ctrl` to their schedules at time t (s)."""
        val = np.zeros(3)
        for j, a in enumerate(self.ctrl_act):
            schedule_eval(self.ctrl_sched, j, float(t), val)
            self._data.ctrl[a] = val[0]

    def fork(self, timestep: float | None = None) -> CoupledRigid:
        """A copy with its own `MjModel` (a full copy: changing its parameters leaves this
        system's alone) and a fresh `MjData`; `timestep` (s) replaces the copy's
        `opt.timestep` if given. The site and link arrays (read-only) are shared."""
        other = copy.copy(self)
        other._model = copy.copy(self._model)  # MjModel's copy is MuJoCo's mj_copyModel: deep
        if timestep is not None:
            other._model.opt.timestep = float(timestep)
        other._data = mujoco.MjData(other._model)
        other.reset()
        return other
