"""The membrane coupled to MuJoCo rigid bodies (paper 3.5, DESIGN.md).

`build_rigid` (called by `compile_scene` for scenes with a `Rigid` part) loads the
scene's MJCF (ours, "trunk", or any user's file, which is read and never written, or
a model an installed package builds in memory, e.g. "myo_sim:myotorso"), adds one attachment site per linked membrane point on its body, optionally adds the
linked points' masses to their bodies, and compiles the model once. `Coupling` (made
by `Simulation` for such scenes) runs the coupled step, in this order:

1. the membrane forces at t (only the terms the scene has);
2. every linked point's membrane force, plus the pressure force of the last volume
   projection p grad_i V (how the incompressible abdomen pushes on the ribs), plus
   its weight, goes to its body as a wrench applied at its site (`xfrc_applied`);
3. MuJoCo steps (`mj_step2` then `mj_step1`, or `mj_step` + `mj_step1` for RK4, so
   that the site kinematics belong to the new state; bit for bit `mj_step`);
4. the linked points take their sites' positions and velocities;
5. the free points integrate, the local constraints and the exact volume projection
   apply (`membrane_advance`).

The whole loop, n steps at a time, is one numba function that calls MuJoCo's C
`mj_step1`/`mj_step2` directly (their addresses are registered with LLVM as
external symbols, so the function is cached on disk like the other kernels).

Link masses and weight: with `Rigid.add_link_mass` (the default) each linked point's
mass m_i is added to its body at the site (the paper's rigid region carries its
points' masses; light ribs under explicit force transfer are unstable otherwise).
MuJoCo then applies that mass's weight m_i g_mujoco itself; the coupling adds
m_i (a_scene - g_mujoco) at the site so that a linked point weighs what a free
membrane point weighs, m_i a_scene (zero for a scene without a gravity term, whose
membrane feels no gravity). Without `add_link_mass` the point's weight m_i a_scene is
transmitted as a force and its inertia is neglected.

Attachment sites are named f"{Rigid.prefix}hybrid_link_{i}", i the vertex index.
"""

from __future__ import annotations

import copy
import ctypes
from pathlib import Path

import llvmlite.binding as _llvm
import numpy as np
from numba import types

from . import regions as _regions
from . import rigid as _rigid
from .kernel import kernel
from .errors import RigidError, SceneError, SimulationDiverged
from .scene import Nailed, Prescribed, Rigid, RigidLink, Scene
from .model import T_GRAVITY
from .step import (OK, S_PRESSURE, S_TIME, Frames, MembraneState, capture_frame, membrane_advance,
                         membrane_forces)

__all__ = ["BUILTIN_MJCF", "PACKAGE_MJCF", "resolve_mjcf", "load_rigid_spec", "build_rigid", "CoupledRigid", "Coupling",
           "run_coupled"]

#: MJCF names a scene may use instead of a path.
BUILTIN_MJCF = {"trunk": _rigid.TRUNK_XML, "builtin:trunk": _rigid.TRUNK_XML}



def _myo_sim_spec(name: str):
    import myo_sim
    return myo_sim.load_spec(name)


#: Models built in memory by an installed package instead of read from a file:
#: rigid.mjcf = "SCHEME:NAME" -> (import name, what to install, builder of an editable
#: MjSpec from NAME). The package's files are only read; our sites and masses are added
#: to the returned MjSpec. "myo_sim:myotorso" is MyoSuite's torso (myo_sim.load_spec).
PACKAGE_MJCF = {"myo_sim": ("myo_sim", "pip install 'hybrid[myo]' (or myo-sim)", _myo_sim_spec)}

_SITE_STEM = "hybrid_link_"
_RK4 = int(_rigid.mujoco.mjtIntegrator.mjINT_RK4)
_DSBL_GRAVITY = int(_rigid.mujoco.mjtDisableBit.mjDSBL_GRAVITY)
_INERTIA_FROM_GEOM_TRUE = _rigid.mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
_POINT_GEOM_RADIUS = 1e-4  # m: the geoms that carry point masses (inertia 0.4 m r^2, negligible)


# ----------------------------------------------------------------- MuJoCo from numba

def _register_mujoco_symbols() -> None:
    """Make MuJoCo's C step functions callable from cached numba code.

    The addresses of `mj_step`, `mj_step1`, `mj_step2` of the library the bindings
    use are registered with LLVM under private names; compiled code refers to them by
    name, so a cached function links again in a new process (where the addresses
    differ) as long as this ran first (it runs when this module is imported).
    """
    for name, fn in zip(("step", "step1", "step2"), _rigid.mj_step_ctypes()):
        _llvm.add_symbol(f"hybrid_mj_{name}", ctypes.cast(fn, ctypes.c_void_p).value)


_register_mujoco_symbols()
_SIG = types.void(types.intp, types.intp)
_mj_step = types.ExternalFunction("hybrid_mj_step", _SIG)
_mj_step1 = types.ExternalFunction("hybrid_mj_step1", _SIG)
_mj_step2 = types.ExternalFunction("hybrid_mj_step2", _SIG)


# ----------------------------------------------------------------- building

def resolve_mjcf(scene: Scene) -> Path:
    """The MJCF file of `scene.rigid`: "trunk" / "builtin:trunk" is the packaged
    `hybrid/data/trunk.xml`; anything else is a path, relative to the scene's folder."""
    mjcf = scene.rigid.mjcf
    if not isinstance(mjcf, (str, Path)) or not str(mjcf).strip():
        raise SceneError(f"rigid.mjcf: expected 'trunk' or the path of an MJCF file, received {mjcf!r}")
    if str(mjcf) in BUILTIN_MJCF:
        return BUILTIN_MJCF[str(mjcf)]
    if _package_model(str(mjcf)) is not None:
        raise RigidError(f"rigid.mjcf: {str(mjcf)!r} is built in memory by a package, it has no file; "
                         f"use hybrid.coupling.load_rigid_spec")
    path = scene.resolve(str(mjcf))
    if not path.is_file():
        raise RigidError(f"rigid.mjcf: no such file {str(path)!r}; expected 'trunk' or the path of an MJCF file")
    return path


def _package_model(mjcf: str):
    scheme, sep, name = mjcf.partition(":")
    return (scheme, name) if sep and scheme in PACKAGE_MJCF else None


def load_rigid_spec(scene: Scene):
    """(MjSpec, label, source) of `scene.rigid.mjcf`: a file read by MuJoCo (source its
    Path), or "SCHEME:NAME" of `PACKAGE_MJCF` built by its package (source the string).
    Raises RigidError naming the package and how to install it when it is absent."""
    mjcf = scene.rigid.mjcf
    pkg = _package_model(str(mjcf)) if isinstance(mjcf, (str, Path)) else None
    if pkg is None:
        path = resolve_mjcf(scene)
        return _rigid.load_spec(path), path.name, path
    scheme, name = pkg
    module, install, builder = PACKAGE_MJCF[scheme]
    try:
        __import__(module)
    except ImportError as exc:
        raise RigidError(f"rigid.mjcf {str(mjcf)!r}: needs the package {module!r}, which is not installed "
                         f"({exc}); {install}") from exc
    try:
        spec = builder(name)
    except (ValueError, KeyError) as exc:
        raise RigidError(f"rigid.mjcf {str(mjcf)!r}: {module} cannot build {name!r}: "
                         f"{' '.join(str(exc).split())}") from exc
    return spec, str(mjcf), str(mjcf)


class CoupledRigid(_rigid.RigidSystem):
    """The compiled rigid part of a scene: a `RigidSystem` whose attachment sites
    are the linked membrane points.

    Attributes (besides `RigidSystem`'s): link_vert (n,) int32, the linked vertices in
    site order; link_body (n,) names of their bodies; link_mass (n,) kg; mass_added
    (n,) bool, whether each point's mass was added to its body; mjcf_path, the source
    (the MJCF's Path, or the "SCHEME:NAME" string of a package model).
    """

    def __init__(self, spec, site_names, *, timestep, link_vert, link_body, link_mass, mass_added,
                 mjcf_path):
        super().__init__(spec, site_names, timestep=timestep)
        self.link_vert = np.asarray(link_vert, np.int32)
        self.link_body = tuple(link_body)
        self.link_mass = np.asarray(link_mass, float)
        self.mass_added = np.asarray(mass_added, bool)
        self.mjcf_path = mjcf_path
        for arr in (self.link_vert, self.link_mass, self.mass_added, self.site_id, self.site_body,
                    self.site_root, self.body_id):
            arr.flags.writeable = False

    def fork(self, timestep: float | None = None) -> "CoupledRigid":
        """A copy with its own fresh `MjData`, sharing the `MjModel` (parameters) unless
        `timestep` (s) differs from the model's, in which case the model is copied."""
        other = copy.copy(self)
        if timestep is not None and float(timestep) != float(self._model.opt.timestep):
            other._model = copy.deepcopy(self._model)
            other._model.opt.timestep = float(timestep)
        other._data = _rigid.mujoco.MjData(other._model)
        _rigid.mujoco.mj_forward(other._model, other._data)
        return other


def build_rigid(scene: Scene, mesh, regions: dict, vert_mass: np.ndarray):
    """Load and compile the rigid part of `scene`; returns (CoupledRigid, link_vert).

    mesh: the membrane (`hybrid.mesh.Mesh`, rest positions in m); regions: evaluated
    regions {name: vertex indices}; vert_mass (nvert,) kg. link_vert (n,) int32 are the
    linked vertices, sorted, each with a site `f"{prefix}hybrid_link_{i}"` at its rest
    position on its body. Raises SceneError (malformed links, a point linked twice or
    also nailed/prescribed) or RigidError (missing or unparsable MJCF, unknown body,
    taken site name, a model MuJoCo cannot compile), each a one-line message.
    """
    rig = scene.rigid
    if not isinstance(rig, Rigid):
        raise SceneError(f"rigid: expected a hybrid.scene.Rigid, received {type(rig).__name__}")
    if not isinstance(rig.prefix, str):
        raise SceneError(f"rigid.prefix: expected a string, received {rig.prefix!r}")
    if not isinstance(rig.add_link_mass, bool):
        raise SceneError(f"rigid.add_link_mass: expected true or false, received {rig.add_link_mass!r}")
    spec, label, source = load_rigid_spec(scene)
    bodies = [b.name for b in spec.bodies]
    sites = [s.name for s in spec.sites if s.name]

    owner: dict[int, int] = {}  # vertex -> link index
    link_body_of: dict[int, str] = {}
    for k, link in enumerate(rig.links):
        what = f"rigid.links[{k}]"
        if not isinstance(link, RigidLink):
            raise SceneError(f"{what}: expected a hybrid.scene.RigidLink, received {type(link).__name__}")
        body = _link_body(spec, link.body)
        if body is None:
            raise RigidError(f"{what}.body: no body or site named {link.body!r} in {label}; "
                             f"available bodies: {bodies}; sites: {sites}")
        idx = _regions.select(link.region, mesh.vert_pos, name=f"{what}.region", regions=regions,
                              border_vert=mesh.border_vert)
        twice = [int(i) for i in idx if int(i) in owner]
        if twice:
            raise SceneError(f"{what}.region: vertices {twice[:8]} are already linked by "
                             f"rigid.links[{owner[twice[0]]}]; expected each point linked to one body")
        for i in idx:
            owner[int(i)] = k
            link_body_of[int(i)] = body
    link_vert = np.array(sorted(owner), dtype=np.int32)
    _check_not_constrained(scene, mesh, regions, link_vert)

    # Body poses at qpos0 (to place the sites) and compiled inertias (to add masses).
    model0 = _compile(spec, label)
    data0 = _rigid.mujoco.MjData(model0)
    _rigid.mujoco.mj_kinematics(model0, data0)
    body_names = [link_body_of[int(i)] for i in link_vert]
    site_names = [f"{rig.prefix}{_SITE_STEM}{int(i)}" for i in link_vert]
    taken = [s for s in site_names if spec.site(s) is not None]
    if taken:
        raise RigidError(f"rigid.prefix: site name(s) {taken[:3]} already exist in {label}; "
                         f"choose another prefix than {rig.prefix!r}")
    local = np.empty((link_vert.size, 3))
    for j, (i, name) in enumerate(zip(link_vert, body_names)):
        bid = model0.body(name).id
        rot = data0.xmat[bid].reshape(3, 3)
        local[j] = rot.T @ (mesh.vert_pos[i] - data0.xpos[bid])
        spec.body(name).add_site(name=site_names[j], pos=local[j].tolist(),
                                 size=[0.002, 0.002, 0.002], group=4)

    link_mass = np.asarray(vert_mass, float)[link_vert]
    mass_added = np.zeros(link_vert.size, bool)
    if rig.add_link_mass:
        mass_added = np.array([n != "world" and model0.body(n).id != 0 for n in body_names])
        _add_point_masses(spec, model0, body_names, local, link_mass, mass_added)

    system = CoupledRigid(spec, site_names, timestep=float(scene.dt_s), link_vert=link_vert,
                          link_body=body_names, link_mass=link_mass, mass_added=mass_added,
                          mjcf_path=source)
    return system, link_vert


def _link_body(spec, name):
    """The body a link names: a body, or the body that carries the named site."""
    if not isinstance(name, str) or not name:
        return None
    if spec.body(name) is not None:
        return name
    site = spec.site(name)
    if site is not None:
        return site.parent.name
    return None


def _compile(spec, label):
    try:
        return spec.compile()
    except ValueError as exc:
        raise RigidError(f"MJCF {label}: MuJoCo cannot compile it: {' '.join(str(exc).split())}") from exc


def _check_not_constrained(scene, mesh, regions, link_vert):
    linked = set(link_vert.tolist())
    for k, con in enumerate(scene.constraints):
        if isinstance(con, (Nailed, Prescribed)):
            idx = _regions.select(con.region, mesh.vert_pos, name=f"constraints[{con.name!r}].region",
                                  regions=regions, border_vert=mesh.border_vert)
            both = sorted(linked.intersection(idx.tolist()))
            if both:
                raise SceneError(f"constraints[{con.name!r}].region: vertices {both[:8]} are also linked to a "
                                 f"rigid body; expected a point either {type(con).__name__.lower()} or linked")


def _add_point_masses(spec, model0, body_names, local, mass, added):
    """Add point masses (kg) at body-frame positions `local` (m) to their bodies.

    When the model takes every inertia from its geoms (`inertiafromgeom="true"`), each
    point becomes a tiny massive sphere geom that does not collide; otherwise the
    body's inertial is made explicit: its compiled mass, centre of mass and inertia
    combined with the points' (parallel-axis theorem).
    """
    by_body: dict[str, list[int]] = {}
    for j, name in enumerate(body_names):
        if added[j]:
            by_body.setdefault(name, []).append(j)
    from_geoms = spec.compiler.inertiafromgeom == _INERTIA_FROM_GEOM_TRUE
    for name, js in by_body.items():
        body = spec.body(name)
        if from_geoms:
            for j in js:
                body.add_geom(name=f"{name}_{_SITE_STEM}mass_{j}", size=[_POINT_GEOM_RADIUS, 0, 0],
                              pos=local[j].tolist(), mass=float(mass[j]), contype=0, conaffinity=0,
                              group=5, rgba=[0, 0, 0, 0])
            continue
        bid = model0.body(name).id
        m_b = float(model0.body_mass[bid])
        c_b = model0.body_ipos[bid].copy()
        rot = np.empty(9)
        _rigid.mujoco.mju_quat2Mat(rot, model0.body_iquat[bid])
        rot = rot.reshape(3, 3)
        tensor = rot @ np.diag(model0.body_inertia[bid]) @ rot.T
        pts, mp = local[js], mass[js]
        m_tot = m_b + mp.sum()
        com = (m_b * c_b + (mp[:, None] * pts).sum(axis=0)) / m_tot

        def shifted(m, r):
            return m * (r @ r * np.eye(3) - np.outer(r, r))

        tensor = tensor + shifted(m_b, c_b - com)
        for p, m in zip(pts, mp):
            tensor = tensor + shifted(m, p - com)
        body.explicitinertial = True
        body.mass = float(m_tot)
        body.ipos = com.tolist()
        body.fullinertia = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2], tensor[1, 2]]
        body.inertia = [0.0, 0.0, 0.0]  # a diagonal inertia given by the MJCF would conflict (myotorso's)


# ----------------------------------------------------------------- the coupled step

@kernel
def run_coupled(m, s, link_vert, site_id, site_body, site_root, link_extra, link_force, link_vel,
                site_xpos, xipos, xfrc, cvel, subtree_com, qpos, m_ptr, d_ptr, rk4, nstep, step0,
                record, xfrc_hist, qpos_hist):
    """nstep coupled steps (module docstring, steps 1-5). Returns the steps done
    (< nstep when the membrane fails; its status is in s.status).

    # Model: m (MembraneArrays); link_vert (n,) int32; site_id, site_body, site_root (n,) int64;
    #        link_extra (n, 3) N (weight correction); m_ptr, d_ptr: mjModel*, mjData*; rk4: bool
    # Data in/out: s (MembraneState); the MjData arrays site_xpos, xipos, xfrc (xfrc_applied),
    #        cvel, subtree_com, qpos (views of the MjData at d_ptr)
    # Scratch: link_force, link_vel (n, 3)
    # Out: xfrc_hist (nstep, nbody, 6), qpos_hist (nstep, nq) when record
    """
    h = m.dt
    t0 = s.scal[S_TIME]
    pos, vel, frc, grad = s.vert_pos, s.vert_vel, s.vert_force, s.grad
    n = link_vert.shape[0]
    for k in range(nstep):
        t = t0 + k * h
        membrane_forces(m, s, t)
        p = s.scal[S_PRESSURE]
        for j in range(n):
            i = link_vert[j]
            for a in range(3):
                link_force[j, a] = frc[i, a] + p * grad[i, a] + link_extra[j, a]
        _rigid.point_wrench_kernel(site_xpos, xipos, site_id, site_body, link_force, xfrc)
        if record:  # element-wise: a slice copy would allocate
            for b in range(xfrc.shape[0]):
                for a in range(6):
                    xfrc_hist[k, b, a] = xfrc[b, a]
        if rk4:
            _mj_step(m_ptr, d_ptr)
        else:
            _mj_step2(m_ptr, d_ptr)
        _mj_step1(m_ptr, d_ptr)
        if record:
            for a in range(qpos.shape[0]):
                qpos_hist[k, a] = qpos[a]
        _rigid.site_vel_kernel(site_xpos, cvel, subtree_com, site_id, site_body, site_root, link_vel)
        for j in range(n):
            i = link_vert[j]
            sid = site_id[j]
            for a in range(3):
                pos[i, a] = site_xpos[sid, a]
                vel[i, a] = link_vel[j, a]
        if membrane_advance(m, s, t, step0 + k) != OK:
            return k
        s.scal[S_TIME] = t0 + (k + 1) * h
    return nstep


@kernel
def run_coupled_frames(m, s, link_vert, site_id, site_body, site_root, link_extra, link_force, link_vel,
                       site_xpos, xipos, xfrc, cvel, subtree_com, qpos, xpos, xquat, m_ptr, d_ptr, rk4,
                       stops, step0, xfrc_hist, qpos_hist, frame_pos, frame_scal, frame_body_pos,
                       frame_body_quat):
    """`run_coupled` to each step index of stops, capturing a frame at each (the
    membrane's, and the bodies' poses from the MjData views xpos, xquat, world
    excluded); returns the frames captured (fewer than stops when a step fails)."""
    done = step0
    for i in range(stops.shape[0]):
        n = stops[i] - done
        k = run_coupled(m, s, link_vert, site_id, site_body, site_root, link_extra, link_force, link_vel,
                        site_xpos, xipos, xfrc, cvel, subtree_com, qpos, m_ptr, d_ptr, rk4, n, done,
                        False, xfrc_hist, qpos_hist)
        done += k
        if k < n:
            return i
        capture_frame(m, s, frame_pos[i], frame_scal[i])
        for b in range(frame_body_pos.shape[1]):
            for a in range(3):
                frame_body_pos[i, b, a] = xpos[b + 1, a]
            for a in range(4):
                frame_body_quat[i, b, a] = xquat[b + 1, a]
    return stops.shape[0]


class Coupling:
    """The rigid half of a `Simulation` whose scene has a `Rigid` part.

    Owns its own `MjData` (the `MjModel` is the compiled model's, shared). Set
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
        self._no_hist = (np.empty((0, mjm.nbody, 6)), np.empty((0, mjm.nq)))

    # -- MuJoCo access
    @property
    def mj_model(self):
        """The compiled `mujoco.MjModel` (with the attachment sites and link masses)."""
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
        self._extra = self.link_extra_force()
        d = sys.data  # views of the MjData's memory, valid as long as the MjData lives
        self._views = (d.site_xpos, d.xipos, d.xfrc_applied, d.cvel, d.subtree_com, d.qpos)
        self.initial_state = sys.state()
        self._xfrc_hist.clear()
        self._qpos_hist.clear()
        state.vert_pos[self.link_vert] = sys.site_pos()
        state.vert_vel[self.link_vert] = sys.site_vel()

    def step(self, state: MembraneState, t: float, step_index: int) -> int:
        """One coupled step from time t; returns 0 or the simulation's status code."""
        done = self.run(state, 1, step_index)
        return OK if done == 1 else int(state.status[0])

    def run(self, state: MembraneState, nstep: int, step0: int) -> int:
        """nstep coupled steps in one compiled call; returns the steps done."""
        sys = self.system
        mjm, d = sys.model, sys.data
        rk4 = int(mjm.opt.integrator) == _RK4
        record = bool(self.record_wrenches)
        if record:
            xh = np.empty((nstep, mjm.nbody, 6))
            qh = np.empty((nstep, mjm.nq))
        else:
            xh, qh = self._no_hist
        site_xpos, xipos, xfrc, cvel, subtree_com, qpos = self._views
        mj_time = d.time
        done = run_coupled(self.model.arrays, state, self.link_vert, sys.site_id, sys.site_body,
                           sys.site_root, self._extra, self._force, self._vel, site_xpos, xipos,
                           xfrc, cvel, subtree_com, qpos, mjm._address, d._address,
                           rk4, int(nstep), int(step0), record, xh, qh)
        if record:
            self._xfrc_hist.append(xh[:done])
            self._qpos_hist.append(qh[:done])
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
                f"stiffer rigid bodies, or more damping", time_s=float(state.scal[S_TIME]),
                step=int(step0 + done), vert=int(self.link_vert[0]) if self.link_vert.size else 0,
                dt_suggested_s=0.5 * float(self.model.arrays.dt))

    def run_frames(self, state: MembraneState, stops: np.ndarray, step0: int, frames: Frames) -> int:
        """`run` to each step index of stops in one compiled call, capturing a frame at
        each into frames; returns the frames captured. (Without wrench recording.)"""
        sys = self.system
        mjm, d = sys.model, sys.data
        rk4 = int(mjm.opt.integrator) == _RK4
        xh, qh = self._no_hist
        site_xpos, xipos, xfrc, cvel, subtree_com, qpos = self._views
        mj_time = d.time
        count = run_coupled_frames(self.model.arrays, state, self.link_vert, sys.site_id, sys.site_body,
                                   sys.site_root, self._extra, self._force, self._vel, site_xpos, xipos,
                                   xfrc, cvel, subtree_com, qpos, d.xpos, d.xquat, mjm._address, d._address,
                                   rk4, stops, int(step0), xh, qh, frames.pos, frames.scal, frames.body_pos,
                                   frames.body_quat)
        # a reset anywhere in these frames makes none of them trustworthy (frames.count stays 0)
        self._check_not_reset(state, mj_time, step0, (int(stops[count - 1]) if count else int(step0)) - int(step0))
        return count

    # -- records
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
