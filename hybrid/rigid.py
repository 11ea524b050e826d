"""The rigid part: MuJoCo ribs and spine, composed with `mujoco.MjSpec`, driven by wrenches.

This is the only module of `hybrid` that imports mujoco; the rest of the package
imports it lazily, so that a membrane-only scene never loads MuJoCo.

The coupling (paper section 3.5, DESIGN.md) goes through *attachment sites*: each
linked membrane point i gets a site `f"{prefix}{i}"` on its rigid body, placed at the
point's rest position (`attach_points`). Every step, `RigidSystem.apply_point_forces`
turns the points' forces into one wrench per body, applied at the body's centre of
mass (`mjData.xfrc_applied`); `RigidSystem.step` advances MuJoCo; `site_pos` and
`site_vel` give the new positions and velocities that the linked points take.

`RigidSystem.step` runs `mj_step2` then `mj_step1` (`mj_step` then `mj_step1` for
RK4), so that after a step every kinematic quantity (`site_xpos`, `xipos`, `cvel`)
belongs to the *new* state; after a bare `mj_step` they would lag one step behind.
The trajectory is bit-for-bit that of `mj_step` with the same `xfrc_applied`, which
`replay_wrenches` (`mujoco.rollout`) reproduces.

Compiled path: `point_wrench_kernel` and `site_vel_kernel` are numba kernels on the
raw `MjData` arrays, and `mj_step_ctypes` gives MuJoCo's C `mj_step`, `mj_step1`,
`mj_step2`, callable from inside `@numba.njit` code with `model._address` and
`data._address`; a whole coupled step can then run without returning to Python.

Units: SI (m, kg, s, N, N m). Arrays: `(n, 3)` float64, world frame unless stated.
"""

from __future__ import annotations

import ctypes
import logging
from collections.abc import Sequence
from functools import cache
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout as _rollout

from hybrid.errors import RigidError
from hybrid.kernel import jit
from hybrid.scenefile import packaged_model

__all__ = [
    "TRUNK_XML",
    "STATE_SPEC",
    "load_spec",
    "attach_points",
    "RigidSystem",
    "get_state",
    "replay_wrenches",
    "free_body_spec",
    "point_wrench_kernel",
    "site_vel_kernel",
    "mj_step_ctypes",
]

_mujoco_log = logging.getLogger("hybrid.mujoco")


def _log_mujoco_warning(message: str) -> None:
    _mujoco_log.warning("MuJoCo: %s", message)


# MuJoCo's default warning handler prints and appends to MUJOCO_LOG.TXT in the working
# folder; its warnings go to the logger "hybrid.mujoco" instead (printed on stderr
# unless logging is set up otherwise), unless the program has its own handler
if mujoco.get_mju_user_warning() is None:
    mujoco.set_mju_user_warning(_log_mujoco_warning)

#: The packaged trunk model (spine fixed to the world, two hinged ribs, sternum spring).
TRUNK_XML: Path = packaged_model("trunk.xml")

#: The state signature used for snapshots and replays (`mjSTATE_FULLPHYSICS`).
STATE_SPEC: int = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)

_RK4 = int(mujoco.mjtIntegrator.mjINT_RK4)


def load_spec(path_or_xml: str | Path) -> mujoco.MjSpec:
    """Load an MJCF model into a `mujoco.MjSpec`.

    Parameters
    ----------
    path_or_xml : a path to an MJCF file, or the MJCF text itself (a string whose
        first non-blank character is '<').

    Raises
    ------
    RigidError : the file does not exist, or MuJoCo cannot parse it (the message
        names the file and carries MuJoCo's own message).
    """
    if isinstance(path_or_xml, str) and path_or_xml.lstrip().startswith("<"):
        try:
            return mujoco.MjSpec.from_string(path_or_xml)
        except ValueError as exc:
            raise RigidError(f"MJCF text: MuJoCo cannot parse it: {_one_line(exc)}") from exc
    path = Path(path_or_xml)
    if not path.is_file():
        raise RigidError(f"MJCF file {str(path)!r}: no such file")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise RigidError(f"MJCF file {str(path)!r}: MuJoCo cannot parse it: {_one_line(exc)}") from exc


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def _compile(spec: mujoco.MjSpec) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:
        raise RigidError(f"MJCF model {spec.modelname!r}: MuJoCo cannot compile it: "
                         f"{_one_line(exc)}") from exc


def _spec_body_names(spec: mujoco.MjSpec) -> list[str]:
    return [b.name for b in spec.bodies]


def attach_points(spec: mujoco.MjSpec, body_names: Sequence[str], point_pos: np.ndarray,
                  prefix: str = "hybrid_link_") -> list[str]:
    """Add one site per linked point to its body, at the point's world rest position.

    The spec is compiled once to get the bodies' world poses at `qpos0`; each point is
    converted into its body's frame, so that the site sits exactly at the point when
    the model is at `qpos0`. The spec is modified in place (sites added).

    Parameters
    ----------
    spec : the model to modify.
    body_names : (n,) the body each point is linked to ("world" fixes it in space).
    point_pos : (n, 3) m, the points' world rest positions.
    prefix : site i is named f"{prefix}{i}".

    Returns
    -------
    (n,) the site names, in point order.

    Raises
    ------
    RigidError : shapes differ, a position is not finite, a body name is unknown (the
        message lists the available bodies), or a site name is already taken.
    """
    pos = np.asarray(point_pos, dtype=float)
    names = list(body_names)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise RigidError(f"point_pos: expected shape (n, 3), got {pos.shape}")
    if len(names) != pos.shape[0]:
        raise RigidError(f"body_names: expected {pos.shape[0]} names (one per point), "
                         f"got {len(names)}")
    if not np.all(np.isfinite(pos)):
        bad = int(np.flatnonzero(~np.isfinite(pos).all(axis=1))[0])
        raise RigidError(f"point_pos[{bad}]: expected finite coordinates, got {pos[bad]}")
    available = _spec_body_names(spec)
    unknown = sorted({n for n in names if spec.body(n) is None})
    if unknown:
        raise RigidError(f"unknown body name(s) {unknown}; available bodies: {available}")
    site_names = [f"{prefix}{i}" for i in range(len(names))]
    taken = [s for s in site_names if spec.site(s) is not None]
    if taken:
        raise RigidError(f"site name(s) already in the model: {taken[:5]}"
                         f"{' ...' if len(taken) > 5 else ''}; choose another prefix than "
                         f"{prefix!r}")

    model = _compile(spec)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    for i, (name, p) in enumerate(zip(names, pos)):
        bid = model.body(name).id
        rot = data.xmat[bid].reshape(3, 3)
        local = rot.T @ (p - data.xpos[bid])
        spec.body(name).add_site(name=site_names[i], pos=local.tolist(),
                                 size=[0.002, 0.002, 0.002], group=4)
    return site_names


@jit(_nrt=False)
def point_wrench_kernel(site_xpos, xipos, site_id, site_body, forces, xfrc):  # pragma: no cover
    """Set the wrench of the point forces on each attachment body (compiled).

    # Data in:  site_xpos (nsite, 3) m, xipos (nbody, 3) m, forces (n, 3) N
    # Model:    site_id (n,) int, site_body (n,) int
    # Data out: xfrc (nbody, 6) [N, N m]: rows site_body replaced by
    #           sum_i [F_i, (site_xpos_i - xipos_b) x F_i]; other rows untouched.
    """
    n = site_id.shape[0]
    for i in range(n):
        b = site_body[i]
        for k in range(6):
            xfrc[b, k] = 0.0
    for i in range(n):
        s = site_id[i]
        b = site_body[i]
        rx = site_xpos[s, 0] - xipos[b, 0]
        ry = site_xpos[s, 1] - xipos[b, 1]
        rz = site_xpos[s, 2] - xipos[b, 2]
        fx, fy, fz = forces[i, 0], forces[i, 1], forces[i, 2]
        xfrc[b, 0] += fx
        xfrc[b, 1] += fy
        xfrc[b, 2] += fz
        xfrc[b, 3] += ry * fz - rz * fy
        xfrc[b, 4] += rz * fx - rx * fz
        xfrc[b, 5] += rx * fy - ry * fx


@jit(_nrt=False)
def site_vel_kernel(site_xpos, cvel, subtree_com, site_id, site_body, site_root,
                    out):  # pragma: no cover
    """World linear velocities of sites, as mj_objectVelocity(flg_local=0) (compiled).

    # Data in:  site_xpos (nsite, 3) m, cvel (nbody, 6) [rad/s, m/s], subtree_com (nbody, 3) m
    # Model:    site_id, site_body, site_root (n,) int (root = body_rootid of the body)
    # Data out: out (n, 3) m/s = v_c + w x (site_xpos - subtree_com[root])
    """
    for i in range(site_id.shape[0]):
        s = site_id[i]
        b = site_body[i]
        c = site_root[i]
        rx = site_xpos[s, 0] - subtree_com[c, 0]
        ry = site_xpos[s, 1] - subtree_com[c, 1]
        rz = site_xpos[s, 2] - subtree_com[c, 2]
        wx, wy, wz = cvel[b, 0], cvel[b, 1], cvel[b, 2]
        out[i, 0] = cvel[b, 3] + wy * rz - wz * ry
        out[i, 1] = cvel[b, 4] + wz * rx - wx * rz
        out[i, 2] = cvel[b, 5] + wx * ry - wy * rx


@cache
def mj_step_ctypes() -> tuple[ctypes._CFuncPtr, ctypes._CFuncPtr, ctypes._CFuncPtr]:
    """`(mj_step, mj_step1, mj_step2)` of MuJoCo's C library, callable from numba.

    Call them inside an `@numba.njit` function with `model._address` and
    `data._address` (ints); the numpy arrays of `MjData` (`data.xfrc_applied`, ...) are
    views of its memory and can be passed to the same function. The library is the
    one the Python bindings are linked against, so results are bit-for-bit those of
    `mujoco.mj_step`. Python's call overhead (about 0.5 us a call) disappears.
    """
    folder = Path(mujoco.__file__).resolve().parent
    candidates = sorted(folder.glob("libmujoco.so*")) + sorted(folder.glob("libmujoco*.dylib")) \
        + sorted(folder.glob("mujoco.dll"))
    if not candidates:
        raise RigidError(f"MuJoCo's C library: not found in {str(folder)!r}")
    lib = ctypes.CDLL(str(candidates[0]))
    fns = (lib.mj_step, lib.mj_step1, lib.mj_step2)
    for fn in fns:
        fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        fn.restype = None
    return fns


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

    def __init__(self, spec: mujoco.MjSpec, site_names: Sequence[str] = (), *,
                 timestep: float | None = None):
        model = _compile(spec)
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
        point_wrench_kernel(d.site_xpos, d.xipos, self.site_id, self.site_body,
                            self._check_forces(forces), d.xfrc_applied)

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
        site_vel_kernel(d.site_xpos, d.cvel, d.subtree_com, self.site_id, self.site_body,
                        self.site_root, out)
        return out

    def reset(self) -> None:
        """Back to the model's initial state (`qpos0`, zero velocity, time 0, no wrench)."""
        mujoco.mj_resetData(self._model, self._data)
        mujoco.mj_forward(self._model, self._data)


def replay_wrenches(model: mujoco.MjModel, initial_state: np.ndarray, xfrc: np.ndarray, *,
                    data: mujoco.MjData | None = None) -> np.ndarray:
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
        raise RigidError(f"initial_state: expected shape ({nstate},) "
                         f"(mjSTATE_FULLPHYSICS), got {state0.shape}")
    x = np.asarray(xfrc, dtype=float)
    if x.ndim != 3 or x.shape[1:] != (model.nbody, 6):
        raise RigidError(f"xfrc: expected shape (nstep, {model.nbody}, 6), got {x.shape}")
    nstep = x.shape[0]
    if data is None:
        data = mujoco.MjData(model)
    control = np.ascontiguousarray(x.reshape(1, nstep, model.nbody * 6))
    state, _ = _rollout.rollout(model, data, state0[None, :], control,
                                control_spec=int(mujoco.mjtState.mjSTATE_XFRC_APPLIED))
    return state[0, :, 1:1 + model.nq].copy()


def free_body_spec(mass: float, inertia: Sequence[float], point: Sequence[float],
                   force: Sequence[float], *, integrator: str = "RK4",
                   timestep: float = 1e-3) -> mujoco.MjSpec:
    """A single free rigid body, no gravity, no contact, pushed by a body-fixed point force.

    The body frame is its principal frame at the centre of mass, so that `qpos[0:3]`
    is the centre of mass and `qpos[3:7]` the orientation (w, x, y, z). The force is a
    `motor` actuator on a site at `point` whose gear is the force direction in the body
    frame: with `data.ctrl[0] = |force|` (N) MuJoCo itself evaluates the force within
    each step (at every stage of RK4), so the run converges at the integrator's own
    order. Set `ctrl` after compiling; it is 0 by default.

    Parameters
    ----------
    mass : kg (> 0).
    inertia : (3,) kg m^2, principal moments about the centre of mass.
    point : (3,) m, the point of application in the body frame.
    force : (3,) N, the force in the body frame.
    integrator : a MuJoCo integrator name ("Euler", "RK4", "implicit", "implicitfast").
    timestep : s.
    """
    f = np.asarray(force, dtype=float)
    fnorm = float(np.linalg.norm(f))
    spec = mujoco.MjSpec()
    spec.modelname = "free_body"
    spec.option.gravity = [0.0, 0.0, 0.0]
    spec.option.timestep = float(timestep)
    names = {"euler": "mjINT_EULER", "rk4": "mjINT_RK4", "implicit": "mjINT_IMPLICIT",
             "implicitfast": "mjINT_IMPLICITFAST"}
    if integrator.lower() not in names:
        raise RigidError(f"integrator: expected one of {sorted(names)}, got {integrator!r}")
    spec.option.integrator = getattr(mujoco.mjtIntegrator, names[integrator.lower()])
    body = spec.worldbody.add_body(name="body", mass=float(mass),
                                   inertia=[float(v) for v in inertia],
                                   explicitinertial=True)
    body.add_freejoint(name="free")
    body.add_site(name="push", pos=[float(v) for v in point])
    direction = f / fnorm if fnorm > 0 else np.array([1.0, 0.0, 0.0])
    act = spec.add_actuator(name="push", target="push",
                            trntype=mujoco.mjtTrn.mjTRN_SITE)
    act.gear = [*direction.tolist(), 0.0, 0.0, 0.0]
    return spec


# ---------------------------------------------------------------- benchmarks

def bare_stepper(path: str | Path):
    """A timer of bare `mj_step` calls (from Python) on the MJCF at `path`:
    returns f(nstep) -> seconds per step."""
    import time
    model = _compile(load_spec(path))
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)

    def timed(nstep: int) -> float:
        mujoco.mj_resetData(model, data)
        t0 = time.perf_counter()
        for _ in range(nstep):
            mujoco.mj_step(model, data)
        return (time.perf_counter() - t0) / nstep

    return timed


def flex_sphere_run(vert_pos: np.ndarray, face_vert: np.ndarray, *, duration_s: float = 1.0,
                    total_kg: float = 4.0, young_pa: float = 3e4, thickness_m: float = 0.01,
                    timestep_s: float = 1e-3) -> dict:
    """MuJoCo's own closed 2D flex sphere (elastic shell) dropped on a plane under gravity.

    vert_pos (n, 3) m around the origin, face_vert (nface, 3) outward. Returns
    {"nvert", "us_per_step", "volume_change"} with the relative volume change
    after `duration_s`; MuJoCo has no volume constraint. Raises RigidError if
    MuJoCo reset the simulation (a blow-up).
    """
    import time
    pts = " ".join(f"{x:.6f}" for x in np.asarray(vert_pos, float).ravel())
    el = " ".join(str(int(i)) for i in np.asarray(face_vert).ravel())
    z0 = float(-np.min(vert_pos[:, 2])) + 0.005
    xml = f"""<mujoco>
  <option timestep="{timestep_s}" integrator="Euler" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <flexcomp name="ball" type="direct" dim="2" pos="0 0 {z0}" radius="0.004" mass="{total_kg}"
              point="{pts}" element="{el}">
      <contact selfcollide="none"/>
      <elasticity young="{young_pa}" poisson="0.3" thickness="{thickness_m}" damping="0.002" elastic2d="both"/>
    </flexcomp>
  </worldbody>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    elem = model.flex_elem[: model.flex_elemnum[0] * 3].reshape(-1, 3)

    def vol(x):
        a, b, c = x[elem[:, 0]], x[elem[:, 1]], x[elem[:, 2]]
        return float(np.einsum("ij,ij->i", a - x.mean(0), np.cross(b - x.mean(0), c - x.mean(0))).sum() / 6.0)

    v0 = vol(data.flexvert_xpos.copy())
    nstep = int(round(duration_s / timestep_s))
    t0 = time.perf_counter()
    for _ in range(nstep):
        mujoco.mj_step(model, data)
    wall = time.perf_counter() - t0
    if sum(int(w.number) for w in data.warning):
        raise RigidError("flex sphere: MuJoCo reported a blow-up and reset the simulation; "
                         "expected a stable run (lower the time step or the stiffness)")
    return {"nvert": int(model.nflexvert), "us_per_step": wall / nstep * 1e6,
            "volume_change": (vol(data.flexvert_xpos.copy()) - v0) / v0}
