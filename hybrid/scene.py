"""The scene: what to simulate, as plain dataclasses.

A scene names a mesh, how mass is spread on it, named regions, the force
terms and the constraints (`hybrid.terms`, re-exported here), the rigid part,
the time step and the integrator. It holds no
arrays of its own and is cheap to copy: change a field with
`dataclasses.replace` and compile again to repeat a run. `Scene.without`
drops named terms for ablations. Every term has a `name` (by default its
kind) which is what `--without` refers to.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import checks
from .errors import SceneError
from .integrators import NAMES
from .terms import (
    AppliedForce,
    Attraction,
    Damping,
    Gravity,
    KeepIn,
    Lungs,
    MassSpring,
    Membrane,
    Muscle,
    MuscleFibres,
    Nailed,
    PassiveFibres,
    Prescribed,
    Pressure,
    RestingTension,
    ShapeMemory,
    SoftVolume,
    Volume,
)
from .terms.base import FORMULATIONS, param

__all__ = [
    "MeshSpec",
    "Masses",
    "Gravity",
    "Damping",
    "ShapeMemory",
    "Membrane",
    "MassSpring",
    "Muscle",
    "AppliedForce",
    "Attraction",
    "SoftVolume",
    "Nailed",
    "KeepIn",
    "Prescribed",
    "Volume",
    "RigidLink",
    "RibPair",
    "Ribs",
    "Rigid",
    "Scene",
    "INTEGRATORS",
    "FORMULATIONS",
    "Pressure",
    "MuscleFibres",
    "PassiveFibres",
    "Lungs",
    "RestingTension",
]

INTEGRATORS = NAMES  # hybrid.integrators
#: the step of a scene without a rigid part that sets no dt_s (s)
DEFAULT_DT_S = 1e-3
#: how the membrane's parameters are meant (hybrid.terms.base.FORMULATIONS): "paper", the
#: per-point model of Promayon et al. 1997 kept exactly; "continuum", material parameters
#: that mean the same on every mesh, internal forces that obey action and reaction
FORMULATIONS = FORMULATIONS
MESH_GENERATORS = ("uv_sphere", "ring_sphere", "fibonacci_sphere", "icosphere", "icosahedron")


@dataclass(frozen=True)
class MeshSpec:
    """Where the membrane's surface comes from.

    Either a file (`path`: STL, OBJ, PLY or OFF, positions in `unit_scale` m
    per file unit) or a generator: "uv_sphere" (the paper's 80-point sphere at
    13 segments x 7 rings), "ring_sphere" (pole-free: even circles of
    latitude), "fibonacci_sphere" (pole-free: the spiral lattice), "icosphere"
    (`subdivisions`) or "icosahedron".
    The result is translated by `center_m` (generators are centred there).
    `level` K refines the two sphere families together for convergence studies:
    about 80 x 2^K points (the paper's 80-point sphere at K = 0), the spacing
    divided by sqrt(2) at each level; on a UV sphere it sets segments and rings
    (13 and 7 times 2^(K/2), rounded), on the pole-free spheres the point count
    (the UV sphere's at the same level, about that on a ring sphere; 80 without
    a level). `conform_z_m` (m above the centre): latitudes that are circles of
    the UV or ring sphere at every level, so that regions bounded there (the
    anatomy's parts) are bounded by edges and converge without a mesh-dependent
    jagged edge (a generator's option: a file mesh keeps its own points).
    `conform_azimuth_deg` (degrees from +x toward +y about the vertical axis
    through the centre): azimuths that are columns of points of the UV or ring
    sphere, so that wedges bounded there (`wedge` regions) are bounded by edges;
    a set symmetric about 0 makes the mesh there mirror-symmetric about the
    x-z plane. A ring sphere's circles too small to hold them (near the poles,
    and every circle of the coarsest levels) keep their own points.
    On a file mesh, `level` K splits every face into four K times (about 4^K
    times the points, the spacing halved a level), the new points on the
    surface the file samples: the sphere through the file's points when they
    are on one; else, for a closed surface, the smooth surface through them (the
    Loop limit surface that interpolates them, `hybrid.mesh.refine`), so that
    the file's points keep their places and numbers at every level and the
    levels sample one surface ever more finely. A level of an open surface off
    a sphere is refused. A body more than 10 m across (`hybrid.model.MAX_BODY_M`:
    a file drawn in millimetres, a radius meant in them) is refused, naming the
    scale that would make it a trunk's.
    """

    generator: str | None = param("choice", "uv_sphere", choices=MESH_GENERATORS)
    path: str | None = param("text", None)
    radius_m: float = param("positive", 0.12, hi=checks.MAX_LENGTH_M)
    segments: int = param("integer", 13, lo=3)
    rings: int = param("integer", 7, lo=2)
    subdivisions: int = param("integer", 3, lo=0, hi=7)
    level: int | None = param("integer", None, lo=0, hi=16)
    conform_z_m: tuple = param("floats", ())
    conform_azimuth_deg: tuple = param("floats", ())
    center_m: tuple[float, float, float] = param("vec3", (0.0, 0.0, 0.0))
    unit_scale: float = param("positive", 1.0, hi=checks.MAX_LENGTH_M, unit="m per file unit")


@dataclass(frozen=True)
class Masses:
    """How the membrane's mass is spread on its points.

    Exactly one of: `total_kg` (spread in proportion to each point's share of
    the surface area), `density_kg_per_m2` ({region name: area density}, the
    last listed region wins where regions overlap; every point must be
    covered) or `per_vertex_kg` (one value per point).
    """

    total_kg: float | None = None
    density_kg_per_m2: dict | None = None
    per_vertex_kg: tuple | None = None


# ------------------------------------------------------------ rigid part


@dataclass(frozen=True)
class RigidLink:
    """Points of `region` attached to MuJoCo body `body` (paper 3.5).

    With `slide_stiffness_n_per_m3` 0 (the default) each point follows its site on the body.
    Above 0 each point slides: it stays a free membrane point, held to the plane tangent to
    the membrane at its rest position, which the body carries, by a normal force of this
    stiffness times the point's share of the surface (the gap g along the plane's normal n
    gives -k g n on the point and its reaction on the body at the point); free in the plane,
    as the diaphragm's zone of apposition slides along the inner rib cage. The stiffness is a
    penalty: a load of pressure p on the sheet leaves a gap of p / stiffness."""

    region: object
    body: str
    name: str = "rigid_link"
    slide_stiffness_n_per_m3: float = param("nonneg", 0.0, hi=checks.MAX_STIFFNESS_N_PER_M * 1e3)


@dataclass(frozen=True)
class RibPair:
    """A left rib and its mirror image in the mid-sagittal plane, each a body hinged at its
    costovertebral joint (`head_m`) on the thoracic body, drawn as capsules along an arc
    from the head out to `half_width_m` from the midline and forward to its anterior end
    (`front_m`), the two anterior ends joined by a sternal spring (`Ribs`). Positions are
    the left rib's, in the world where the model starts. The hinge axis lies in the
    transverse plane at `axis_angle_deg` to the mid-sagittal plane (Wilson et al. 1987:
    about 35 degrees at the upper ribs): 90 turns the rib about a transverse axis, a pure
    pump handle (the anterior end rises), 0 about an antero-posterior axis, a pure bucket
    handle (the lateral part rises); a positive joint angle lifts the rib. The hinge spring
    holds the rib's own weight (MuJoCo's gravity) where it is drawn, and rests
    `reference_angle_deg` beyond that. Bodies `NAME_left`, `NAME_right`, joints
    `NAME_left_hinge`, `NAME_right_hinge`, sites `NAME_left_front`, `NAME_right_front`,
    tendon `NAME_sternum`. With `muscle_gear_n_m` > 0, the rib cage's inspiratory muscles
    on the pair (parasternal intercostals, scalenes): a motor on each hinge,
    `NAME_left_muscle` and `NAME_right_muscle`, whose control in [0, 1] (an activation, driven
    by `rigid.ctrl`) times the gear is its torque (N m), lifting the rib."""

    name: str = param("name")
    head_m: tuple = param("vec3")
    front_m: tuple = param("vec3")
    half_width_m: float = param("positive", hi=checks.MAX_LENGTH_M)
    axis_angle_deg: float = param("nonneg", 35.0, hi=90.0)
    stiffness_n_m_per_rad: float = param("positive", 12.0, hi=checks.MAX_STIFFNESS_N_PER_M)
    damping_n_m_s_per_rad: float = param("nonneg", 0.05, hi=checks.MAX_STIFFNESS_N_PER_M)
    reference_angle_deg: float = 0.0  # the hinge spring's rest angle beyond the drawn pose, in [-90, 90]
    mass_kg: float = param("positive", 0.2, hi=1e3)
    muscle_gear_n_m: float = param("nonneg", 0.0, hi=checks.MAX_STIFFNESS_N_PER_M)


@dataclass(frozen=True)
class Ribs:
    """Articulated ribs added to the loaded model (`hybrid.rigid.ribs`, through MjSpec; the
    model's files are only read): pairs of rib bodies hinged on the thoracic body `body`,
    added after the control keys (so that `hold`/`lock` patterns name the model's own
    joints) and before the membrane's links, which may name the rib bodies. `anterior` and
    `cranial`: the model's directions (perpendicular); left is cranial x anterior. The
    mid-sagittal plane passes through `body`'s origin where the model starts. Each pair's
    anterior ends are joined by a spatial tendon, a spring of `sternum_stiffness_n_per_m` at
    its rest length (the costal cartilage and sternum): a compliant link, as a rigid one
    (an equality) would lock two hinges whose axes differ. The thorax's pitch change is
    reported for this body (`thorax_pitch_change_deg_max`)."""

    body: str = param("text")
    pairs: tuple = ()  # RibPair tables ([[rigid.ribs.pairs]])
    anterior: tuple = param("vec3", (1.0, 0.0, 0.0))
    cranial: tuple = param("vec3", (0.0, 0.0, 1.0))
    radius_m: float = param("positive", 0.006, hi=checks.MAX_LENGTH_M)
    sternum_stiffness_n_per_m: float = param("positive", 1000.0, hi=checks.MAX_STIFFNESS_N_PER_M)
    sternum_damping_n_s_per_m: float = param("nonneg", 0.5, hi=checks.MAX_STIFFNESS_N_PER_M)


#: MuJoCo's integrators, as `rigid.integrator` names them
MUJOCO_INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")


@dataclass(frozen=True)
class Rigid:
    """The rigid part: an MJCF file (ours or a user's), the membrane links to it, and
    what the scene changes in the model (`hybrid.rigid.controls`): bodies fixed or
    welded to the world, joints held by stiff springs or locked, the keyframe it
    starts from, actuators driven by schedules, MuJoCo's integrator. Names of joints
    and actuators may be glob patterns ("lumbar*", "*"). The model's file is only read;
    MuJoCo reads, as its own, every file an `<include file="...">` in it names, any XML
    file the account can read: compose models only from files you trust.
    """

    mjcf: str
    links: tuple[RigidLink, ...] = ()
    prefix: str = ""
    add_link_mass: bool = True
    keyframe: str | None = param("text", None)
    fix: tuple = ()  # body names: their joints removed, each fixed to its parent where it starts
    fix_root: bool = False  # every free-floating root body fixed where it starts
    weld: tuple = ()  # body names: welded to the world where they start (a MuJoCo weld)
    hold: tuple = ()  # joint names or patterns: held where they start by springs
    hold_stiffness_nm_per_rad: float = param("positive", 1e3, hi=checks.MAX_STIFFNESS_N_PER_M)
    hold_damping_nms_per_rad: float = param("nonneg", 10.0, hi=checks.MAX_STIFFNESS_N_PER_M)
    lock: tuple = ()  # hinge or slide joint names or patterns: locked where they start
    ctrl: dict = field(default_factory=dict)  # actuator name or pattern -> schedule
    integrator: str | None = param("choice", None, choices=MUJOCO_INTEGRATORS)
    load_joints: tuple = ()  # joint names: the points the loads' moments are taken about (hybrid.loads)
    ribs: Ribs | None = None  # articulated ribs added to the model (hybrid.rigid.ribs)


@dataclass(frozen=True)
class Scene:
    """Everything a run needs. SI units. See the module docstring."""

    mesh: object = MeshSpec()  # MeshSpec or a hybrid.mesh.Mesh
    masses: Masses = Masses(total_kg=1.0)
    regions: dict = field(default_factory=dict)  # name -> selector, evaluated in order
    forces: tuple = ()
    constraints: tuple = ()
    rigid: Rigid | None = None
    # None: the MJCF's own timestep for a scene with a rigid part, else DEFAULT_DT_S;
    # "auto": half the model's stable-step estimate, rounded down (hybrid.model.auto_dt; for
    # implicit Euler, 4 times symplectic Euler's: auto_dt_implicit)
    dt_s: float | None = param("step", None, hi=checks.MAX_DT_S)
    integrator: str = param("choice", "symplectic_euler", choices=INTEGRATORS)
    formulation: str = param("choice", "continuum", choices=FORMULATIONS)
    # implicit Euler's Newton solve (hybrid.implicit): converged when the residual force is at
    # most this fraction of the forces, within this many iterations
    implicit_tol: float = param("positive", 1e-6, hi=0.1, unit="of the forces")
    implicit_max_iter: int = param("integer", 50, lo=1, hi=1000)
    duration_s: float = param("positive", 1.0, hi=checks.MAX_DURATION_S)
    # a point faster than this has run away (tissue moves at cm/s); at most the speed of
    # light, so that the guard can never be switched off by a huge value
    max_speed_m_s: float = param("positive", 50.0, hi=checks.MAX_SPEED_M_S)
    name: str = param("name", "scene")
    base_dir: str | None = None  # relative paths (mesh, MJCF) resolve here

    def __post_init__(self):
        # the containers' kinds, before anything iterates them (one term for a tuple of
        # terms, a list of regions for a table of them)
        for key in ("forces", "constraints"):
            value = getattr(self, key)
            if not isinstance(value, (tuple, list)):
                raise SceneError(
                    f"Scene.{key}: expected a tuple of terms, received {type(value).__name__}"
                    + (f"; write ({type(value).__name__}(...),)" if hasattr(value, "name") else "")
                )
        if not isinstance(self.regions, dict):
            raise SceneError(
                f"Scene.regions: expected a dict of name -> selector, received {type(self.regions).__name__}"
            )
        from .regions import check_region_names

        check_region_names(self.regions)
        volumes = [c for c in (*self.forces, *self.constraints) if isinstance(c, Volume)]
        if len(volumes) > 1:  # two exact constraints on one volume: the projection has no meaning
            raise SceneError(
                f"constraints: expected at most one volume constraint, received {len(volumes)} "
                f"({', '.join(repr(getattr(v, 'name', 'volume')) for v in volumes)})"
            )
        for link in getattr(self.rigid, "links", None) or ():
            if getattr(link, "body", None) == "world":
                raise SceneError(
                    f"rigid.links[{getattr(link, 'name', '?')!r}].body: expected a body that moves, received "
                    f"'world' (MuJoCo's fixed frame); hold the region still with a nailed constraint instead"
                )

    def term_names(self) -> list[str]:
        """Names of all force terms, constraints and rigid links, in order."""
        # getattr: a non-term in the lists must reach compile_scene's type check
        names = [getattr(t, "name", repr(t)) for t in (*self.forces, *self.constraints)]
        if self.rigid is not None:
            names += [link.name for link in self.rigid.links]
        return names

    def without(self, *names: str) -> Scene:
        """A copy with the named force terms / constraints / rigid links removed."""
        known = self.term_names()
        for n in names:
            if n not in known:
                raise SceneError(f"without: no term named {n!r} in scene {self.name!r}; terms: {known}")
        drop = set(names)
        rigid = self.rigid
        if rigid is not None:
            rigid = dataclasses.replace(rigid, links=tuple(k for k in rigid.links if k.name not in drop))
        return dataclasses.replace(
            self,
            forces=tuple(t for t in self.forces if t.name not in drop),
            constraints=tuple(c for c in self.constraints if c.name not in drop),
            rigid=rigid,
        )

    def resolve(self, path: str) -> Path:
        p = Path(path).expanduser()
        if not p.is_absolute() and self.base_dir is not None:
            p = Path(self.base_dir) / p
        return p


def body_axes(scene: Scene) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The body's anterior and cranial directions in the scene's frame (unit vectors, cranial made
    perpendicular to anterior): its added rib pairs' (`rigid.ribs`, the model's own directions)
    when it has them, else +x and +z (the packaged trunk's and the paper's frame). The pictures
    turn the body by them, so that their views and their mid-sagittal section are the body's own
    on any model (`hybrid.pictures.frames`)."""
    ribs = scene.rigid.ribs if scene.rigid is not None else None
    if ribs is None:
        return (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    a = np.asarray(ribs.anterior, float)
    a = a / np.linalg.norm(a)
    c = np.asarray(ribs.cranial, float)
    c = c - (c @ a) * a
    c = c / np.linalg.norm(c)
    return (float(a[0]), float(a[1]), float(a[2])), (float(c[0]), float(c[1]), float(c[2]))
