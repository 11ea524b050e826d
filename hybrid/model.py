"""Compile a scene into a model: immutable arrays, only the terms it has.

`compile_scene(scene)` validates the scene against its mesh, evaluates the
regions, spreads the masses, computes every rest quantity once (shape-memory
coordinates, spring rest lengths, muscle pairs, rest volume) and packs them
into `MembraneArrays`, the one structure the compiled step reads. Terms a
scene lacks are empty arrays with their flag off, and are never computed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from . import forces as _forces
from . import regions as _regions
from . import schedule as _sched
from .constraints import SHAPE_BALL, SHAPE_BOX, SHAPE_HALF_SPACE
from .errors import SceneError
from .kernel import use_parallel
from .mesh import Mesh
from .scene import (INTEGRATORS, AppliedForce, Attraction, Damping, Gravity, KeepIn, MassSpring,
                    Masses, MeshSpec, Muscle, Nailed, Prescribed, Scene, ShapeMemory, SoftVolume,
                    Volume)
from .stability import max_stable_dt

__all__ = ["TERMS", "MembraneArrays", "Model", "compile_scene", "build_mesh"]

# Term ids, the index of each term's flag and call counter.
TERMS = ("gravity", "applied_force", "attraction", "damping", "shape_memory", "mass_spring",
         "muscle", "soft_volume", "prescribed", "keep_in", "volume")
(T_GRAVITY, T_APPLIED, T_ATTRACTION, T_DAMPING, T_SHAPE_MEMORY, T_MASS_SPRING, T_MUSCLE,
 T_SOFT_VOLUME, T_PRESCRIBED, T_KEEP_IN, T_VOLUME) = range(len(TERMS))
INTEGRATOR_ID = {"explicit_euler": 0, "symplectic_euler": 1}


class MembraneArrays(NamedTuple):
    """What the compiled step reads. Shapes and units:

    face_vert (nface, 3) int32; ring_ptr (nvert+1,), ring_vert int32, ring_closed (nvert,) uint8;
    vert_rest (nvert, 3) m; vert_mass (nvert,) kg; vert_free (nvert,) uint8 (1 = integrated);
    vert_weight (nvert,) 1/kg (volume projection weight, 0 for points not integrated);
    term_on (nterm,) uint8; accel (3,) m/s^2; app_*: applied forces; att_*: attraction;
    damp_coef (nvert,) N s/m; sm_*: shape memory; spring_*: mass-spring; mus_*: muscle;
    soft_stiff N/m; pre_*: prescribed; kin_*, shape_*: keep-in; vol_ref (3,) m, vol0 m^3;
    sched: ScheduleTable; dt s; integrator 0 explicit / 1 symplectic;
    runaway_disp m: a step moving a point farther than this has run away;
    max_speed m/s: so has a point faster than this; parallel: the per-point
    passes run their multi-core build (hybrid.kernel).
    """
    face_vert: np.ndarray
    ring_ptr: np.ndarray
    ring_vert: np.ndarray
    ring_closed: np.ndarray
    vert_rest: np.ndarray
    vert_mass: np.ndarray
    vert_free: np.ndarray
    vert_weight: np.ndarray
    term_on: np.ndarray
    accel: np.ndarray
    app_vert: np.ndarray
    app_sched: np.ndarray
    att_vert: np.ndarray
    att_stiff: np.ndarray
    att_target: np.ndarray
    att_sched: np.ndarray
    damp_coef: np.ndarray
    sm_vert: np.ndarray
    sm_stiff: np.ndarray
    sm_coef: np.ndarray
    spring_vert: np.ndarray
    spring_stiff: np.ndarray
    spring_rest: np.ndarray
    mus_vert: np.ndarray
    mus_nbr: np.ndarray
    mus_sched: np.ndarray
    soft_stiff: float
    pre_vert: np.ndarray
    pre_rest: np.ndarray
    pre_sched: np.ndarray
    kin_vert: np.ndarray
    kin_shape: np.ndarray
    shape_kind: np.ndarray
    shape_par: np.ndarray
    vol_ref: np.ndarray
    vol0: float
    sched: _sched.ScheduleTable
    dt: float
    integrator: int
    runaway_disp: float
    max_speed: float
    parallel: bool


@dataclass(frozen=True)
class Model:
    """A compiled scene. Immutable: a run's changing state lives in `Simulation`.

    scene: the source; mesh: the surface; regions: name -> sorted vertex
    indices; arrays: what the compiled step reads; terms: names of the terms
    present; python_schedules: [(row, fn)] evaluated in Python each step;
    vert_stiffness (nvert,) N/m: each point's elastic stiffness (for damping
    and stability); dt_stable_s: the largest step the per-point linear
    analysis deems stable (s); rigid: the rigid part, or None.
    """
    scene: Scene
    mesh: Mesh
    regions: dict
    arrays: MembraneArrays
    terms: tuple
    python_schedules: tuple
    vert_stiffness: np.ndarray
    dt_stable_s: float
    rigid: object = None
    link_vert: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))

    @property
    def nvert(self) -> int:
        return self.mesh.nvert

    @property
    def dt_s(self) -> float:
        return self.arrays.dt

    def with_dt(self, dt_s: float, integrator: str | None = None) -> "Model":
        """The same model with another time step (no file is read again)."""
        _check_dt(dt_s)
        integ = self.arrays.integrator if integrator is None else _integrator_id(integrator)
        arrays = self.arrays._replace(dt=float(dt_s), integrator=integ)
        scene = dataclasses.replace(self.scene, dt_s=float(dt_s), integrator=INTEGRATORS[integ])
        dt_stable = _stable_dt(arrays, self.vert_stiffness)
        return Model(scene, self.mesh, self.regions, arrays, self.terms, self.python_schedules,
                     self.vert_stiffness, dt_stable, self.rigid, self.link_vert)


def _check_dt(dt):
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise SceneError(f"dt_s: expected a time step > 0 s, received {dt!r}")


def _integrator_id(name):
    if name not in INTEGRATOR_ID:
        raise SceneError(f"integrator: expected one of {list(INTEGRATORS)}, received {name!r}")
    return INTEGRATOR_ID[name]


def _positive(value, name, *, allow_zero=False):
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
        and (value >= 0 if allow_zero else value > 0)
    if not ok:
        raise SceneError(f"{name}: expected a number {'>=' if allow_zero else '>'} 0, received {value!r}")
    return float(value)


def _vec3(v, name):
    a = np.asarray(v, dtype=float) if v is not None and not isinstance(v, str) else None
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
        raise SceneError(f"{name}: expected a 3-vector of finite floats, received {v!r}")
    return a


def build_mesh(scene: Scene) -> Mesh:
    """The scene's surface: a given Mesh, a mesh file, or a generator."""
    from . import mesh as _mesh
    spec = scene.mesh
    if isinstance(spec, Mesh):
        return spec
    if not isinstance(spec, MeshSpec):
        raise SceneError(f"mesh: expected a MeshSpec or a hybrid.mesh.Mesh, received {type(spec).__name__}")
    center = _vec3(spec.center_m, "mesh.center_m")
    if spec.path is not None:
        path = scene.resolve(spec.path)
        m = Mesh.load(path)
        scale = _positive(spec.unit_scale, "mesh.unit_scale")
        return Mesh.from_arrays(m.vert_pos * scale + center, m.face_vert, name=m.name)
    radius = _positive(spec.radius_m, "mesh.radius_m")
    gen = spec.generator
    if gen == "uv_sphere":
        for key in ("segments", "rings"):
            val = getattr(spec, key)
            if not isinstance(val, int) or val < 3:
                raise SceneError(f"mesh.{key}: expected an integer >= 3, received {val!r}")
        return _mesh.uv_sphere(radius, spec.segments, spec.rings, center=tuple(center))
    if gen == "icosphere":
        if not isinstance(spec.subdivisions, int) or not 0 <= spec.subdivisions <= 7:
            raise SceneError(f"mesh.subdivisions: expected an integer in 0..7, received {spec.subdivisions!r}")
        return _mesh.icosphere(spec.subdivisions, radius, center=tuple(center))
    if gen == "icosahedron":
        return _mesh.icosahedron(radius, center=tuple(center))
    raise SceneError(f"mesh: expected a path or a generator in ['uv_sphere', 'icosphere', 'icosahedron'], "
                     f"received generator={gen!r}")


def _vert_area(mesh: Mesh) -> np.ndarray:
    """Each vertex's share of the surface area: a third of its faces' areas (m^2)."""
    p = mesh.vert_pos[mesh.face_vert]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    out = np.zeros(mesh.nvert)
    for c in range(3):
        np.add.at(out, mesh.face_vert[:, c], area / 3.0)
    return out


def _masses(spec: Masses, mesh: Mesh, regions: dict) -> np.ndarray:
    given = [k for k in ("total_kg", "density_kg_per_m2", "per_vertex_kg") if getattr(spec, k) is not None]
    if len(given) != 1:
        raise SceneError(f"masses: expected exactly one of total_kg, density_kg_per_m2, per_vertex_kg, "
                         f"received {given or 'none'}")
    area = _vert_area(mesh)
    if spec.total_kg is not None:
        total = _positive(spec.total_kg, "masses.total_kg")
        return total * area / area.sum()
    if spec.per_vertex_kg is not None:
        m = np.asarray(spec.per_vertex_kg, dtype=float)
        if m.shape != (mesh.nvert,):
            raise SceneError(f"masses.per_vertex_kg: expected {mesh.nvert} values, received shape {m.shape}")
        bad = np.nonzero(~(m > 0) | ~np.isfinite(m))[0]
        if bad.size:
            raise SceneError(f"masses.per_vertex_kg: expected masses > 0 kg, received {float(m[bad[0]])!r} "
                             f"at vertices {bad[:8].tolist()}")
        return m.copy()
    dens = spec.density_kg_per_m2
    if not isinstance(dens, dict) or not dens:
        raise SceneError(f"masses.density_kg_per_m2: expected {{region: kg/m^2}}, received {dens!r}")
    m = np.full(mesh.nvert, np.nan)
    for name, rho in dens.items():
        rho = _positive(rho, f"masses.density_kg_per_m2[{name!r}]")
        idx = _regions.select(name, mesh.vert_pos, name=f"masses.density_kg_per_m2[{name!r}]", regions=regions)
        m[idx] = rho * area[idx]
    missing = np.nonzero(np.isnan(m))[0]
    if missing.size:
        raise SceneError(f"masses.density_kg_per_m2: vertices {missing[:8].tolist()} ({missing.size} in all) "
                         f"lie in none of the regions {list(dens)}; expected every vertex covered")
    return m


def _region(sel, mesh, regions, what):
    return _regions.select(sel, mesh.vert_pos, name=what, regions=regions, border_vert=mesh.border_vert)


def compile_scene(scene: Scene) -> Model:
    """Validate `scene` and build its immutable model (see the module docstring)."""
    if not isinstance(scene, Scene):
        raise SceneError(f"scene: expected a hybrid.scene.Scene, received {type(scene).__name__}")
    _check_dt(scene.dt_s)
    integrator = _integrator_id(scene.integrator)
    mesh = build_mesh(scene)
    nvert = mesh.nvert

    regions: dict[str, np.ndarray] = {}
    if not isinstance(scene.regions, dict):
        raise SceneError(f"regions: expected a mapping name -> selector, received {type(scene.regions).__name__}")
    for name, sel in scene.regions.items():
        regions[name] = _region(sel, mesh, regions, name)
    vert_mass = _masses(scene.masses, mesh, regions)

    names = scene.term_names()
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SceneError(f"terms: expected unique names, received {dup} more than once; give each a `name`")

    vert_free = np.ones(nvert, np.uint8)
    term_on = np.zeros(len(TERMS), np.uint8)
    scheds: list = []

    def add_sched(value, what, ncomp):
        scheds.append(_sched.as_schedule(value, name=what, ncomp=ncomp))
        return len(scheds) - 1

    empty_f = np.zeros(0)
    empty_3 = np.zeros((0, 3))
    accel = np.zeros(3)
    app_vert, app_sched = [], []
    att_vert, att_stiff, att_target, att_sched = [], [], [], []
    damp_specs = []
    sm_stiff_v = np.zeros(nvert)
    spring_stiff_v = {}
    mus_vert, mus_nbr, mus_sched = [], [], []
    soft_stiff = 0.0
    vert_stiffness = np.zeros(nvert)

    for term in scene.forces:
        what = f"forces[{getattr(term, 'name', None)!r}]"
        if isinstance(term, Gravity):
            accel = accel + _vec3(term.accel_m_s2, f"{what}.accel_m_s2")
            term_on[T_GRAVITY] = 1
        elif isinstance(term, AppliedForce):
            idx = _region(term.region, mesh, regions, f"{what}.region")
            s = add_sched(term.force_n, f"{what}.force_n", 3)
            app_vert += idx.tolist()
            app_sched += [s] * idx.size
            term_on[T_APPLIED] = 1
        elif isinstance(term, Attraction):
            idx = _region(term.region, mesh, regions, f"{what}.region")
            k = _positive(term.stiffness_n_per_m, f"{what}.stiffness_n_per_m")
            if term.target_m is None:
                target = mesh.vert_pos[idx]
            else:
                target = np.asarray(term.target_m, dtype=float)
                if target.shape == (3,):
                    target = np.tile(target, (idx.size, 1))
                if target.shape != (idx.size, 3) or not np.all(np.isfinite(target)):
                    raise SceneError(f"{what}.target_m: expected a 3-vector or {idx.size} 3-vectors, "
                                     f"received shape {np.shape(term.target_m)}")
            s = add_sched(term.offset_m, f"{what}.offset_m", 3)
            att_vert += idx.tolist()
            att_stiff += [k] * idx.size
            att_target += target.tolist()
            att_sched += [s] * idx.size
            vert_stiffness[idx] += k
            term_on[T_ATTRACTION] = 1
        elif isinstance(term, Damping):
            damp_specs.append((term, _region(term.region, mesh, regions, f"{what}.region")))
            term_on[T_DAMPING] = 1
        elif isinstance(term, ShapeMemory):
            idx = _region(term.region, mesh, regions, f"{what}.region")
            sm_stiff_v[idx] = _positive(term.stiffness_n_per_m, f"{what}.stiffness_n_per_m")
            term_on[T_SHAPE_MEMORY] = 1
        elif isinstance(term, MassSpring):
            idx = _region(term.region, mesh, regions, f"{what}.region")
            k = _positive(term.stiffness_n_per_m, f"{what}.stiffness_n_per_m")
            inside = np.zeros(nvert, bool)
            inside[idx] = True
            for e in np.nonzero(inside[mesh.edge_vert].all(axis=1))[0]:
                spring_stiff_v[int(e)] = k
            term_on[T_MASS_SPRING] = 1
        elif isinstance(term, Muscle):
            idx = _region(term.region, mesh, regions, f"{what}.region")
            if (term.toward_m is None) == (term.axis is None):
                raise SceneError(f"{what}: expected exactly one fibre direction, toward_m or axis, received "
                                 f"toward_m={term.toward_m!r} axis={term.axis!r}")
            toward = None if term.toward_m is None else _vec3(term.toward_m, f"{what}.toward_m")
            axis = None if term.axis is None else _vec3(term.axis, f"{what}.axis")
            if axis is not None and not np.linalg.norm(axis) > 0:
                raise SceneError(f"{what}.axis: expected a non-zero vector, received {term.axis!r}")
            if not (0 < term.max_angle_deg < 90):
                raise SceneError(f"{what}.max_angle_deg: expected in (0, 90), received {term.max_angle_deg!r}")
            s = add_sched(term.stiffness, f"{what}.stiffness", 1)
            pv, pn = _forces.muscle_pairs(mesh.vert_pos, mesh.ring_ptr, mesh.ring_vert, idx,
                                          toward=toward, axis=axis, max_angle_deg=term.max_angle_deg)
            if pv.size == 0:
                raise SceneError(f"{what}: no neighbour lies within {term.max_angle_deg} deg of the fibre "
                                 f"direction; widen max_angle_deg or check toward_m/axis")
            peak = _schedule_peak(scheds[s])
            np.add.at(vert_stiffness, pv, peak)
            mus_vert += pv.tolist()
            mus_nbr += pn.tolist()
            mus_sched += [s] * pv.size
            term_on[T_MUSCLE] = 1
        elif isinstance(term, SoftVolume):
            soft_stiff = _positive(term.stiffness_n_per_m, f"{what}.stiffness_n_per_m")
            mesh.require_closed(f"{what} (compressible volume) needs a closed surface")
            term_on[T_SOFT_VOLUME] = 1
        else:
            raise SceneError(f"forces: expected Gravity, Damping, ShapeMemory, MassSpring, Muscle, "
                             f"AppliedForce, Attraction or SoftVolume, received {type(term).__name__}")

    # constraints
    pre_vert, pre_rest, pre_sched = [], [], []
    kin_vert, kin_shape, shape_kind, shape_par = [], [], [], []
    has_volume = False
    for con in scene.constraints:
        what = f"constraints[{getattr(con, 'name', None)!r}]"
        if isinstance(con, Nailed):
            vert_free[_region(con.region, mesh, regions, f"{what}.region")] = 0
        elif isinstance(con, Prescribed):
            idx = _region(con.region, mesh, regions, f"{what}.region")
            s = add_sched(con.displacement_m, f"{what}.displacement_m", 3)
            vert_free[idx] = 0
            pre_vert += idx.tolist()
            pre_rest += mesh.vert_pos[idx].tolist()
            pre_sched += [s] * idx.size
            term_on[T_PRESCRIBED] = 1
        elif isinstance(con, KeepIn):
            idx = _region(con.region, mesh, regions, f"{what}.region")
            kind, par = _keep_in_shape(con, what)
            shape_kind.append(kind)
            shape_par.append(par)
            kin_vert += idx.tolist()
            kin_shape += [len(shape_kind) - 1] * idx.size
            term_on[T_KEEP_IN] = 1
        elif isinstance(con, Volume):
            mesh.require_closed(f"{what}: a constant-volume constraint needs a closed surface")
            has_volume = True
            term_on[T_VOLUME] = 1
        else:
            raise SceneError(f"constraints: expected Nailed, KeepIn, Prescribed or Volume, received "
                             f"{type(con).__name__}")

    # rigid links: linked points follow their sites (issue of the trunk)
    link_vert = np.zeros(0, np.int32)
    rigid = None
    if scene.rigid is not None and scene.rigid.links:
        from .rigid import build_rigid  # imports mujoco, only for scenes that have rigid parts
        rigid, link_vert = build_rigid(scene, mesh, regions, vert_mass)
        vert_free[link_vert] = 0

    # Forces on nailed and prescribed points are never used: leave those
    # points out of every force term (linked points keep theirs: they go to
    # the rigid bodies).
    moving = vert_free > 0
    moving[link_vert] = True

    def keep(verts, *lists):
        ok = moving[np.asarray(verts, dtype=np.int64)] if len(verts) else np.zeros(0, bool)
        return [np.asarray(x)[ok] if len(x) else np.asarray(x) for x in (verts, *lists)]

    app_vert, app_sched = keep(app_vert, app_sched)
    att_vert, att_stiff, att_target, att_sched = keep(att_vert, att_stiff, att_target, att_sched)
    mus_vert, mus_nbr, mus_sched = keep(mus_vert, mus_nbr, mus_sched)

    # shape memory and springs need rest data
    sm_vert = np.nonzero((sm_stiff_v > 0) & moving)[0].astype(np.int32)
    sm_coef = _forces.shape_memory_frame_coef(mesh.vert_pos, mesh.ring_ptr, mesh.ring_vert, mesh.ring_closed,
                                              sm_vert) if sm_vert.size else empty_3
    vert_stiffness += sm_stiff_v
    if spring_stiff_v:
        eidx = np.array(sorted(spring_stiff_v), dtype=np.int64)
        stiff = np.array([spring_stiff_v[int(e)] for e in eidx])
        np.add.at(vert_stiffness, mesh.edge_vert[eidx, 0], stiff)  # each point's own stiffness,
        np.add.at(vert_stiffness, mesh.edge_vert[eidx, 1], stiff)  # whatever its neighbours do
        used = moving[mesh.edge_vert[eidx]].any(axis=1)
        spring_vert = mesh.edge_vert[eidx[used]].astype(np.int32)
        spring_stiff = stiff[used]
        spring_rest = np.linalg.norm(mesh.vert_pos[spring_vert[:, 1]] - mesh.vert_pos[spring_vert[:, 0]], axis=1)
    else:
        spring_vert, spring_stiff, spring_rest = np.zeros((0, 2), np.int32), empty_f, empty_f

    damp_coef = np.zeros(nvert)
    for term, idx in damp_specs:
        what = f"forces[{term.name!r}]"
        if (term.coef_n_s_per_m is None) == (term.critical_fraction is None):
            raise SceneError(f"{what}: expected exactly one of coef_n_s_per_m or critical_fraction, received "
                             f"coef_n_s_per_m={term.coef_n_s_per_m!r} critical_fraction={term.critical_fraction!r}")
        if term.coef_n_s_per_m is not None:
            damp_coef[idx] = _positive(term.coef_n_s_per_m, f"{what}.coef_n_s_per_m", allow_zero=True)
        else:
            frac = _positive(term.critical_fraction, f"{what}.critical_fraction", allow_zero=True)
            soft = idx[vert_stiffness[idx] <= 0]
            if soft.size:
                raise SceneError(f"{what}.critical_fraction: vertices {soft[:8].tolist()} have no elastic "
                                 f"stiffness to define critical damping; give coef_n_s_per_m instead")
            damp_coef[idx] = frac * 2.0 * np.sqrt(vert_stiffness[idx] * vert_mass[idx])

    vert_weight = np.where(vert_free > 0, 1.0 / vert_mass, 0.0)
    if has_volume and not np.any(vert_weight > 0):
        raise SceneError("constraints['volume']: every point is nailed, prescribed or linked; "
                         "expected at least one free point to carry the volume correction")
    sched_table, python_fns = _sched.stack_schedules(scheds)

    def i32(x):
        return np.asarray(x, np.int32).reshape(-1)

    def i64(x):
        return np.asarray(x, np.int64).reshape(-1)

    arrays = MembraneArrays(
        face_vert=np.ascontiguousarray(mesh.face_vert, np.int32),
        ring_ptr=np.ascontiguousarray(mesh.ring_ptr, np.int32),
        ring_vert=np.ascontiguousarray(mesh.ring_vert, np.int32),
        ring_closed=np.ascontiguousarray(mesh.ring_closed, np.uint8),
        vert_rest=np.ascontiguousarray(mesh.vert_pos, np.float64),
        vert_mass=vert_mass, vert_free=vert_free, vert_weight=vert_weight,
        term_on=term_on, accel=accel,
        app_vert=i32(app_vert), app_sched=i64(app_sched),
        att_vert=i32(att_vert), att_stiff=np.asarray(att_stiff, float),
        att_target=np.asarray(att_target, float).reshape(-1, 3), att_sched=i64(att_sched),
        damp_coef=damp_coef,
        sm_vert=sm_vert, sm_stiff=sm_stiff_v[sm_vert].copy(), sm_coef=np.ascontiguousarray(sm_coef),
        spring_vert=spring_vert, spring_stiff=spring_stiff, spring_rest=spring_rest,
        mus_vert=i32(mus_vert), mus_nbr=i32(mus_nbr), mus_sched=i64(mus_sched),
        soft_stiff=float(soft_stiff),
        pre_vert=i32(pre_vert), pre_rest=np.asarray(pre_rest, float).reshape(-1, 3), pre_sched=i64(pre_sched),
        kin_vert=i32(kin_vert), kin_shape=i64(kin_shape), shape_kind=i64(shape_kind),
        shape_par=np.asarray(shape_par, float).reshape(-1, 6),
        vol_ref=mesh.vert_pos.mean(axis=0),
        vol0=float(mesh.volume()) if (has_volume or soft_stiff > 0) else 0.0,
        sched=sched_table, dt=float(scene.dt_s), integrator=integrator,
        runaway_disp=float(np.linalg.norm(np.ptp(mesh.vert_pos, axis=0))),
        max_speed=_positive(scene.max_speed_m_s, "max_speed_m_s"),
        parallel=use_parallel(nvert),
    )
    for arr in arrays:
        if isinstance(arr, np.ndarray):
            arr.flags.writeable = False
    terms = tuple(TERMS[i] for i in range(len(TERMS)) if term_on[i])
    return Model(scene=scene, mesh=mesh, regions=regions, arrays=arrays, terms=terms,
                 python_schedules=tuple(python_fns), vert_stiffness=vert_stiffness,
                 dt_stable_s=_stable_dt(arrays, vert_stiffness), rigid=rigid, link_vert=link_vert)


def _schedule_peak(s) -> float:
    """Largest value a scalar schedule takes (for stability estimates)."""
    if isinstance(s, _sched.Constant):
        return abs(float(np.asarray(s.value).reshape(-1)[0]))
    if isinstance(s, _sched.Breathing):
        return abs(s.peak)
    if isinstance(s, _sched.Table):
        return float(np.max(np.abs(np.asarray(s.value, float))))
    return 0.0  # a Python function: unknown ahead of time


def _stable_dt(arrays: MembraneArrays, vert_stiffness: np.ndarray) -> float:
    """Largest stable step over the integrated points (per-point linear analysis)."""
    # points with neither stiffness nor damping move freely: no step limit
    free = (arrays.vert_free > 0) & ((vert_stiffness > 0) | (arrays.damp_coef > 0))
    if not np.any(free):
        return math.inf
    integ = "explicit_euler" if arrays.integrator == 0 else "symplectic_euler"
    h = max_stable_dt(arrays.vert_mass[free], vert_stiffness[free], arrays.damp_coef[free], integ, h_hi=10.0)
    h_min = float(h.min())
    damped = free & (arrays.damp_coef > 0)
    if arrays.integrator == 0 and arrays.term_on[T_VOLUME] and np.any(damped):
        # explicit Euler + volume projection: the projection cancels the position
        # step h v along the gradient and its velocity correction cancels v, so
        # that component of v is multiplied by -h c/m each step: h < m/c too
        h_min = min(h_min, float(np.min(arrays.vert_mass[damped] / arrays.damp_coef[damped])))
    return h_min


def _keep_in_shape(con: KeepIn, what: str):
    if con.shape == "half_space":
        p = _vec3(con.point_m, f"{what}.point_m")
        n = _vec3(con.normal, f"{what}.normal")
        nn = np.linalg.norm(n)
        if nn == 0:
            raise SceneError(f"{what}.normal: expected a non-zero vector, received {con.normal!r}")
        return SHAPE_HALF_SPACE, np.concatenate([p, n / nn])
    if con.shape == "ball":
        c = _vec3(con.center_m, f"{what}.center_m")
        r = _positive(con.radius_m, f"{what}.radius_m")
        return SHAPE_BALL, np.array([*c, r, 0.0, 0.0])
    if con.shape == "box":
        lo, hi = _vec3(con.lo_m, f"{what}.lo_m"), _vec3(con.hi_m, f"{what}.hi_m")
        if np.any(hi <= lo):
            raise SceneError(f"{what}: expected lo_m < hi_m componentwise, received lo_m={con.lo_m!r} hi_m={con.hi_m!r}")
        return SHAPE_BOX, np.concatenate([lo, hi])
    raise SceneError(f"{what}.shape: expected 'half_space', 'ball' or 'box', received {con.shape!r}")
