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
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from . import checks
from . import regions as _regions
from . import schedule as _sched
from .body import MAX_BODY_M as MAX_BODY_M  # re-exported: tests and MeshSpec's docs name it here
from .body import build_mesh, point_masses
from .errors import SceneError
from .integrators import BY_NAME, EXPLICIT_EULER_ID, INTEGRATORS, NAMES
from .kernel import use_parallel
from .mesh import Mesh
from .scene import DEFAULT_DT_S, FORMULATIONS, Scene
from .stability import max_stable_dt
from .terms import CONSTRAINT_TYPES, FORCE_TYPES, TERM_CLASSES, TERMS, Build, Volume
from .terms.base import check_value

__all__ = ["TERMS", "MembraneArrays", "Model", "compile_scene", "build_mesh"]

# What the compiled step reads besides the terms' own arrays (hybrid.terms),
# name -> meaning; MembraneArrays is these, then every term class's arrays.
_CORE_BEFORE = {
    "face_vert": "(nface, 3) int32",
    "ring_ptr": "(nvert+1,) int32, ring_vert int32, ring_closed (nvert,) uint8: the ordered one-ring fans",
    "ring_vert": "",
    "ring_closed": "",
    "vert_rest": "(nvert, 3) m",
    "vert_mass": "(nvert,) kg",
    "vert_free": "(nvert,) uint8, 1 = integrated",
    "vert_weight": "(nvert,) 1/kg, the volume projection's weight, 0 for points not integrated",
    "term_on": "(nterm,) uint8, the flags of the terms present (hybrid.terms.TERMS)",
}
_CORE_AFTER = {
    "vol0": "m^3, the rest volume (0 without a volume term)",
    "sched": "ScheduleTable",
    "dt": "s",
    "integrator": "0 explicit Euler, 1 symplectic Euler, 2 implicit Euler (hybrid.implicit)",
    "implicit_tol": "implicit Euler's Newton tolerance, a fraction of the forces",
    "implicit_max_iter": "implicit Euler's Newton iteration cap",
    "max_speed": "m/s: a point faster than this has run away",
    "volume_shake": "bool: the volume projection's direction is the gradient where the step starts (SHAKE: "
    "symplectic; the continuum formulation), else at the predicted positions (the paper's)",
    "parallel": "bool: the per-point passes run their multi-core build (hybrid.kernel); in a model, that "
    "they may: the simulation times both builds as it runs (hybrid.builds)",
}
_TERM_ARRAYS = {name: default for cls in TERM_CLASSES for name, default in cls.arrays.items()}

if TYPE_CHECKING:
    from .rigid.system import CoupledRigid
    from .schedule import ScheduleTable

    class MembraneArrays(NamedTuple):
        """What the type checker sees: the core fields above with their types; the
        terms' arrays (listed at import from hybrid.terms) as attributes of any name."""

        face_vert: np.ndarray
        ring_ptr: np.ndarray
        ring_vert: np.ndarray
        ring_closed: np.ndarray
        vert_rest: np.ndarray
        vert_mass: np.ndarray
        vert_free: np.ndarray
        vert_weight: np.ndarray
        term_on: np.ndarray
        vol0: float
        sched: ScheduleTable
        dt: float
        integrator: int
        implicit_tol: float
        implicit_max_iter: int
        max_speed: float
        volume_shake: bool
        parallel: bool

        def __getattr__(self, name: str) -> Any: ...

else:
    MembraneArrays = NamedTuple("MembraneArrays", [(k, object) for k in (*_CORE_BEFORE, *_TERM_ARRAYS, *_CORE_AFTER)])
MembraneArrays.__doc__ = (
    "What the compiled step reads, built by `compile_scene`: "
    + "; ".join(f"{k} {v}" for k, v in {**_CORE_BEFORE, **_CORE_AFTER}.items() if v)
    + "; and the arrays of each term (hybrid.terms), empty when the scene lacks it."
)


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
    rigid: CoupledRigid | None = None
    link_vert: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    vert_viscosity: np.ndarray | None = None  # N s/m: the membrane's Kelvin-Voigt share per point
    # the inputs a step reads, one per schedule row: (scene key, components), e.g.
    # ("forces['muscle_fibres'].tension_n_per_m", 1) (`hybrid.Control`)
    control_keys: tuple = ()

    def __setstate__(self, state: dict) -> None:
        # numpy unpickles arrays writable, and an array's flag is part of the compiled
        # loop's signature: a model pickled to a sweep's worker would compile it again
        self.__dict__.update(state)
        _freeze(self.arrays)

    @property
    def nvert(self) -> int:
        return self.mesh.nvert

    @property
    def dt_s(self) -> float:
        return self.arrays.dt

    def with_dt(
        self,
        dt_s: float,
        integrator: str | None = None,
        *,
        implicit_tol: float | None = None,
        implicit_max_iter: int | None = None,
    ) -> Model:
        """The same model with another time step, and with another integrator or implicit
        Euler's Newton settings where given (no file is read again; `hybrid.solvers`' objects
        come here). Each value is checked as the scene's key of that name."""
        _check_dt(dt_s)
        integ = self.arrays.integrator if integrator is None else _integrator_id(integrator, self.scene.formulation)
        scene = dataclasses.replace(self.scene, dt_s=float(dt_s), integrator=INTEGRATORS[integ].name)
        if implicit_tol is not None:
            scene = dataclasses.replace(scene, implicit_tol=implicit_tol)
        if implicit_max_iter is not None:
            scene = dataclasses.replace(scene, implicit_max_iter=implicit_max_iter)
        arrays = self.arrays._replace(
            dt=float(dt_s),
            integrator=integ,
            implicit_tol=_scene_value(scene, "implicit_tol"),
            implicit_max_iter=_scene_value(scene, "implicit_max_iter"),
        )
        dt_stable = _stable_dt(arrays, self.vert_stiffness, self.vert_viscosity)
        return Model(
            scene,
            self.mesh,
            self.regions,
            arrays,
            self.terms,
            self.python_schedules,
            self.vert_stiffness,
            dt_stable,
            self.rigid,
            self.link_vert,
            self.vert_viscosity,
            self.control_keys,
        )

    @property
    def slide_vert(self) -> np.ndarray:
        """(ns,) int32: the points that slide on their bodies (`RigidLink.slide_stiffness_n_per_m3`)."""
        return self.rigid.slide_vert if self.rigid is not None else np.zeros(0, np.int32)

    @property
    def slide_stiffness_n_per_m(self) -> np.ndarray:
        """(ns,) N/m: each sliding point's plane stiffness (the link's N/m^3 times its area), `slide_vert`'s order."""
        return self.rigid.slide_stiffness if self.rigid is not None else np.zeros(0)

    def region_faces(self, name: str) -> np.ndarray:
        """The faces of the named region, by the rule the terms use (`hybrid.regions.faces_of`)."""
        return _regions.faces_on(self.scene.regions[name], self.mesh, self.scene.regions, self.regions[name], name=name)

    def without_speed_limit(self) -> Model:
        """The same model without the runaway test (`max_speed_m_s`): for numerical
        studies of runs that move fast while converging; a run still stops on
        non-finite values."""
        return dataclasses.replace(self, arrays=self.arrays._replace(max_speed=math.inf))


def _check_dt(dt):
    # a bool is an int to Python, not a time step
    if not (checks.is_number(dt) and math.isfinite(dt) and dt > 0):
        raise SceneError(f"dt_s: expected a time step > 0 s, received {checks.show(dt)}")
    checks.positive("dt_s", dt, checks.MAX_DT_S, " s")


def _check_duration(duration, dt):
    """At least one step, at most MAX_DURATION_S."""
    checks.positive("duration_s", duration, checks.MAX_DURATION_S, " s")
    if duration < dt:
        raise SceneError(f"duration_s: expected at least one step of dt_s = {dt:g} s, received {duration:g} s")


def _integrator_id(name, formulation):
    if name not in BY_NAME:
        raise SceneError(f"integrator: expected one of {list(NAMES)}, received {name!r}")
    if BY_NAME[name].needs_hessian and formulation != "continuum":
        # the paper's shape memory and muscle derive from no energy: no Hessian to solve with
        raise SceneError(
            f"integrator: {name!r} needs formulation 'continuum' (forces with a Hessian), "
            f"received formulation {formulation!r}; use 'symplectic_euler' or 'explicit_euler'"
        )
    return BY_NAME[name].id


def _scene_value(scene, name):
    """A Scene field's value checked by the kind its declaration gives."""
    meta = {f.name: f.metadata for f in dataclasses.fields(Scene)}[name]
    return check_value(name, meta["kind"], getattr(scene, name), meta)


def _positive(value, name):
    return checks.number(name, value, lo=0)


def _region(sel, mesh, regions, what):
    return _regions.select_on(sel, mesh, name=what, regions=regions)


#: the share of the stable-step estimate that dt_s = "auto" takes (the estimate is
#: per point and 16-18% optimistic on the breathing membrane: the stability study, docs/validation.md)
AUTO_DT_SHARE = 0.5


def nice_floor(x: float) -> float:
    """The largest 1, 2 or 5 x 10^k at most x (> 0): a step that reads well in tables.
    A step that underflows (x of 0, or too small for 10^k to be a float > 0) is refused."""
    if not (x > 0 and 10.0 ** math.floor(math.log10(x)) > 0):
        raise SceneError(
            f"dt_s: expected a stable-step estimate > 0 s to choose the step from, received {x:g} s "
            f"(masses far too light, or stiffnesses far too high, for any time step)"
        )
    k = math.floor(math.log10(x))
    for mant in (5.0, 2.0, 1.0):
        if mant * 10.0**k <= x * (1 + 1e-12):
            return mant * 10.0**k
    return 10.0**k


def auto_dt(dt_stable_s: float) -> float:
    """The step dt_s = "auto" takes: AUTO_DT_SHARE of the stable-step estimate, rounded
    down by `nice_floor`, and at most MAX_DT_S."""
    return (
        min(nice_floor(AUTO_DT_SHARE * dt_stable_s), checks.MAX_DT_S) if math.isfinite(dt_stable_s) else checks.MAX_DT_S
    )


#: implicit Euler's "auto" step: this many times symplectic Euler's stable-step estimate,
#: at most IMPLICIT_AUTO_MAX_S (the breathing scene at level 4 keeps its figures to the
#: digits `hybrid run` prints at 5 ms, 4 times that estimate; level 2 within 3e-5 at 4 times)
IMPLICIT_AUTO_FACTOR = 4.0
IMPLICIT_AUTO_MAX_S = 0.01


def auto_dt_implicit(dt_stable_explicit_s: float) -> float:
    """The step dt_s = "auto" takes with implicit Euler: IMPLICIT_AUTO_FACTOR times the
    explicit estimate, rounded down by `nice_floor`, at most IMPLICIT_AUTO_MAX_S."""
    if not math.isfinite(dt_stable_explicit_s):
        return IMPLICIT_AUTO_MAX_S
    return min(nice_floor(IMPLICIT_AUTO_FACTOR * dt_stable_explicit_s), IMPLICIT_AUTO_MAX_S)


def _freeze(arrays: MembraneArrays) -> None:
    """The model's arrays read-only: nothing changes a model, and the compiled loop's
    signature holds each array's flag (one build for every model)."""
    for arr in arrays:
        if isinstance(arr, np.ndarray):
            arr.flags.writeable = False


def compile_scene(scene: Scene) -> Model:
    """Validate `scene` and build its immutable model (see the module docstring).
    dt_s = "auto": the step is `auto_dt` of the scene's stable-step estimate, or
    `auto_dt_implicit` of symplectic Euler's for implicit Euler (the model's scene holds
    the number)."""
    if not isinstance(scene, Scene):
        raise SceneError(f"scene: expected a hybrid.scene.Scene, received {type(scene).__name__}")
    return _compile(scene)


def _compile(scene: Scene) -> Model:
    auto = isinstance(scene.dt_s, str) and scene.dt_s == "auto"
    if auto:  # built with the rigid part's own step, the estimate then read and the rigid part built again
        scene = dataclasses.replace(scene, dt_s=None)
    if scene.dt_s is not None:
        _check_dt(scene.dt_s)
        _check_duration(scene.duration_s, scene.dt_s)
    checks.text("name", scene.name)
    checks.text("formulation", scene.formulation, FORMULATIONS)
    if scene.formulation == "continuum":
        _refuse_single_points(scene)
    integrator = _integrator_id(scene.integrator, scene.formulation)
    mesh = build_mesh(scene)
    nvert = mesh.nvert

    regions: dict[str, np.ndarray] = {}
    if not isinstance(scene.regions, dict):
        raise SceneError(f"regions: expected a mapping name -> selector, received {type(scene.regions).__name__}")
    for name, sel in scene.regions.items():
        regions[name] = _region(sel, mesh, regions, name)
    vert_mass = point_masses(scene.masses, mesh, regions)

    names = scene.term_names()
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SceneError(f"terms: expected unique names, received {dup} more than once; give each a `name`")

    b = Build(mesh, regions, vert_mass, len(TERMS))
    b.selectors = dict(scene.regions)
    for section, terms, types in (
        ("forces", scene.forces, FORCE_TYPES),
        ("constraints", scene.constraints, CONSTRAINT_TYPES),
    ):
        for term in terms:
            if type(term) not in types.values():
                raise SceneError(
                    f"{section}: expected {_or(cls.__name__ for cls in types.values())}, received {type(term).__name__}"
                )
            term.check_formulation(scene.formulation, f"{section}[{term.name!r}]")
            term.compile(b, f"{section}[{term.name!r}]")

    # rigid links: linked points follow their sites
    rigid = None
    if scene.rigid is not None and not scene.rigid.links:
        raise SceneError(
            f"rigid.links: expected at least one link of membrane points to a body of "
            f"{scene.rigid.mjcf!r}, received none; add [[rigid.links]] or remove [rigid]"
        )
    if scene.rigid is not None:
        from .rigid import build_rigid  # imports mujoco, only for scenes that have rigid parts

        rigid, b.link_vert = build_rigid(scene, mesh, regions, vert_mass, carried=b.carried)
        b.vert_free[b.link_vert] = 0
        # a sliding point's plane holds it as a spring along the normal (the stable step's estimate)
        np.add.at(b.vert_stiffness, rigid.slide_vert, rigid.slide_stiffness)
    # the step: the scene's, else the MJCF's own (a rigid part), else the default
    dt = scene.dt_s if scene.dt_s is not None else rigid.model.opt.timestep if rigid is not None else DEFAULT_DT_S
    if scene.dt_s is None:
        _check_dt(dt)
        _check_duration(scene.duration_s, dt)
    # linked points keep their forces (they go to the rigid bodies); nailed and
    # prescribed points need none
    b.moving = b.vert_free > 0
    b.moving[b.link_vert] = True
    b.out["vert_weight"] = np.where(b.vert_free > 0, 1.0 / vert_mass, 0.0)
    present = [cls for cls in TERM_CLASSES if any(type(t) is cls for t in (*scene.forces, *scene.constraints))]
    for cls in sorted(present, key=lambda c: c.finish_last):
        cls.finish(b)
    sched_table, python_fns = _sched.stack_schedules(b.schedules)

    arrays = MembraneArrays(
        face_vert=np.ascontiguousarray(mesh.face_vert, np.int32),
        ring_ptr=np.ascontiguousarray(mesh.ring_ptr, np.int32),
        ring_vert=np.ascontiguousarray(mesh.ring_vert, np.int32),
        ring_closed=np.ascontiguousarray(mesh.ring_closed, np.uint8),
        vert_rest=np.ascontiguousarray(mesh.vert_pos, np.float64),
        vert_mass=vert_mass,
        vert_free=b.vert_free,
        term_on=b.term_on,
        **{k: b.out[k] if k in b.out else default(nvert) for k, default in _TERM_ARRAYS.items()},
        vert_weight=b.out["vert_weight"],
        vol0=b.out.get("vol0", 0.0),
        sched=sched_table,
        dt=float(dt),
        integrator=integrator,
        implicit_tol=_scene_value(scene, "implicit_tol"),
        implicit_max_iter=_scene_value(scene, "implicit_max_iter"),
        max_speed=_positive(scene.max_speed_m_s, "max_speed_m_s"),
        volume_shake=scene.formulation == "continuum",
        parallel=use_parallel(nvert),
    )
    dt_stable = _stable_dt(arrays, b.vert_stiffness, b.vert_viscosity)
    if auto:
        dt = _auto_dt(arrays, b.vert_stiffness, b.vert_viscosity, dt_stable)
        _check_dt(dt)
        _check_duration(scene.duration_s, dt)
        scene = dataclasses.replace(scene, dt_s=dt)
        arrays = arrays._replace(dt=dt)
        if rigid is not None:  # its controls' constraints are as stiff as the step allows
            from .rigid import build_rigid

            rigid, _ = build_rigid(scene, mesh, regions, vert_mass, carried=b.carried)
    _freeze(arrays)
    terms = tuple(TERMS[i] for i in range(len(TERMS)) if b.term_on[i])
    return Model(
        scene=scene,
        mesh=mesh,
        regions=regions,
        arrays=arrays,
        terms=terms,
        python_schedules=tuple(python_fns),
        vert_stiffness=b.vert_stiffness,
        dt_stable_s=dt_stable,
        rigid=rigid,
        link_vert=b.link_vert,
        vert_viscosity=b.vert_viscosity,
        control_keys=tuple(b.schedule_keys),
    )


def _auto_dt(arrays: MembraneArrays, vert_stiffness, vert_viscosity, dt_stable_s: float) -> float:
    """The step dt_s = "auto" takes (`compile_scene`): for implicit Euler, which has no bound of
    its own, from symplectic Euler's estimate on the same arrays."""
    if not INTEGRATORS[arrays.integrator].implicit:
        return auto_dt(dt_stable_s)
    explicit = arrays._replace(integrator=BY_NAME["symplectic_euler"].id)
    return auto_dt_implicit(_stable_dt(explicit, vert_stiffness, vert_viscosity))


def _refuse_single_points(scene: Scene) -> None:
    """A continuum scene's regions have a physical size: a `nearest` selector (one
    point, whatever the mesh) is refused, naming where it is used."""
    where = [(f"regions.{k}", sel) for k, sel in scene.regions.items()]
    where += [
        (f"{t.section}[{t.name!r}].region", t.region)
        for t in (*scene.forces, *scene.constraints)
        if "region" in getattr(t, "fields", dict)()
    ]
    if scene.rigid is not None:
        where += [(f"rigid.links[{k.name!r}].region", k.region) for k in scene.rigid.links]
    for what, sel in where:
        if _regions.contains(sel, _regions.Nearest):
            raise SceneError(
                f"{what}: a `nearest` selector picks single points, whose share of the surface "
                f"changes with the mesh; expected a region of physical size in formulation "
                f"'continuum' (a patch of radius_m, a ball, a box, a half-space)"
            )


def _or(names) -> str:
    names = list(names)
    return ", ".join(names[:-1]) + " or " + names[-1]


def _stable_dt(arrays: MembraneArrays, vert_stiffness: np.ndarray, vert_viscosity=None) -> float:
    """Largest stable step over the integrated points (per-point linear analysis);
    vert_viscosity (N s/m): viscous terms outside damp_coef (the membrane's Kelvin-Voigt)."""
    damp = arrays.damp_coef if vert_viscosity is None else arrays.damp_coef + vert_viscosity
    # points with neither stiffness nor damping move freely: no step limit
    free = (arrays.vert_free > 0) & ((vert_stiffness > 0) | (damp > 0))
    if not np.any(free) or INTEGRATORS[arrays.integrator].implicit:  # backward Euler: any step
        return math.inf
    integ = INTEGRATORS[arrays.integrator].name
    h = max_stable_dt(arrays.vert_mass[free], vert_stiffness[free], damp[free], integ, h_hi=10.0)
    h_min = float(h.min())
    damped = free & (arrays.damp_coef > 0)
    if arrays.integrator == EXPLICIT_EULER_ID and arrays.term_on[Volume.id] and np.any(damped):
        # explicit Euler + volume projection: the projection cancels the position
        # step h v along the gradient and its velocity correction cancels v, so
        # that component of v is multiplied by -h c/m each step: h < m/c too
        h_min = min(h_min, float(np.min(arrays.vert_mass[damped] / arrays.damp_coef[damped])))
    return h_min
