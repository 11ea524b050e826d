"""The scene: what to simulate, as plain dataclasses.

A scene names a mesh, how mass is spread on it, named regions, the force
terms, the constraints, the time step and the integrator. It holds no
arrays of its own and is cheap to copy: change a field with
`dataclasses.replace` and compile again to repeat a run. `Scene.without`
drops named terms for ablations. Every term has a `name` (by default its
kind) which is what `--without` refers to.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

from .errors import SceneError
from .regions import Selector
from .schedule import Schedule

__all__ = [
    "MeshSpec", "Masses",
    "Gravity", "Damping", "ShapeMemory", "MassSpring", "Muscle", "AppliedForce", "Attraction",
    "SoftVolume", "Nailed", "KeepIn", "Prescribed", "Volume", "RigidLink", "Rigid", "Scene",
    "INTEGRATORS",
]

INTEGRATORS = ("explicit_euler", "symplectic_euler")


@dataclass(frozen=True)
class MeshSpec:
    """Where the membrane's surface comes from.

    Either a file (`path`: STL, OBJ, PLY or OFF, positions in `unit_scale` m
    per file unit) or a generator: "uv_sphere" (the paper's 80-point sphere at
    13 segments x 7 rings), "icosphere" (`subdivisions`) or "icosahedron".
    The result is translated by `center_m` (generators are centred there).
    """
    generator: Optional[str] = "uv_sphere"
    path: Optional[str] = None
    radius_m: float = 0.12
    segments: int = 13
    rings: int = 7
    subdivisions: int = 3
    center_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    unit_scale: float = 1.0


@dataclass(frozen=True)
class Masses:
    """How the membrane's mass is spread on its points.

    Exactly one of: `total_kg` (spread in proportion to each point's share of
    the surface area), `density_kg_per_m2` ({region name: area density}, the
    last listed region wins where regions overlap; every point must be
    covered) or `per_vertex_kg` (one value per point).
    """
    total_kg: Optional[float] = None
    density_kg_per_m2: Optional[dict] = None
    per_vertex_kg: Optional[tuple] = None


# ------------------------------------------------------------------ forces

@dataclass(frozen=True)
class Gravity:
    accel_m_s2: tuple[float, float, float] = (0.0, 0.0, -9.81)
    name: str = "gravity"


@dataclass(frozen=True)
class Damping:
    """Viscous damping F = -c v on the points of `region`.

    Give `coef_n_s_per_m` (c directly) or `critical_fraction` (c = fraction x
    2 sqrt(k_i m_i) per point, k_i the point's elastic stiffness from shape
    memory and springs; 0.3 is comfortable; on the breathing membrane the
    non-conservative shape-memory force excites itself below 0.15, as
    `hybrid study stability` measures).
    """
    coef_n_s_per_m: Optional[float] = None
    critical_fraction: Optional[float] = None
    region: Selector = "all"
    name: str = "damping"


@dataclass(frozen=True)
class ShapeMemory:
    """Local shape memory (paper 3.4): each point attracted to its ideal place
    in the frame of its neighbours, stiffness in N/m."""
    stiffness_n_per_m: float
    region: Selector = "all"
    name: str = "shape_memory"


@dataclass(frozen=True)
class MassSpring:
    """Springs along the mesh edges within `region` (the paper's comparison model)."""
    stiffness_n_per_m: float
    region: Selector = "all"
    name: str = "mass_spring"


@dataclass(frozen=True)
class Muscle:
    """Muscle (paper 3.4): each point of `region` is attracted to the
    neighbours lying along the fibre direction (within `max_angle_deg`),
    with stiffness k_muscle(t) (N/m) from `stiffness` (a number, a
    `Breathing` waveform, a `Table` or a function of time). Fibres run
    toward the point `toward_m`, or along `axis`."""
    region: Selector
    stiffness: Schedule
    toward_m: Optional[tuple[float, float, float]] = None
    axis: Optional[tuple[float, float, float]] = None
    max_angle_deg: float = 30.0
    name: str = "muscle"


@dataclass(frozen=True)
class AppliedForce:
    """A force (N) on each point of `region`: a 3-vector, a `Table` or a function of time."""
    region: Selector
    force_n: Schedule
    name: str = "applied_force"


@dataclass(frozen=True)
class Attraction:
    """Attractive points (paper 3.3): a spring (N/m) from each point of
    `region` to its ideal position = rest position (or `target_m`) plus
    `offset_m` (a 3-vector, `Table` or function of time, for moving targets)."""
    region: Selector
    stiffness_n_per_m: float
    offset_m: Schedule = (0.0, 0.0, 0.0)
    target_m: Optional[tuple] = None
    name: str = "attraction"


@dataclass(frozen=True)
class SoftVolume:
    """Compressibility (paper 6.2): each point pulled with stiffness (N/m)
    toward the position the exact volume projection would give it."""
    stiffness_n_per_m: float
    name: str = "soft_volume"


# ------------------------------------------------------------ constraints

@dataclass(frozen=True)
class Nailed:
    """Points fixed at their rest positions (spine, pelvis...)."""
    region: Selector
    name: str = "nailed"


@dataclass(frozen=True)
class KeepIn:
    """Points kept inside a half-space (`point_m`, `normal` pointing inside),
    a ball (`center_m`, `radius_m`) or a box (`lo_m`, `hi_m`)."""
    region: Selector
    shape: str  # "half_space" | "ball" | "box"
    point_m: Optional[tuple] = None
    normal: Optional[tuple] = None
    center_m: Optional[tuple] = None
    radius_m: Optional[float] = None
    lo_m: Optional[tuple] = None
    hi_m: Optional[tuple] = None
    name: str = "keep_in"


@dataclass(frozen=True)
class Prescribed:
    """Points that follow rest position + `displacement_m`(t) (m)."""
    region: Selector
    displacement_m: Schedule
    name: str = "prescribed"


@dataclass(frozen=True)
class Volume:
    """The exact constant-volume constraint (paper 4.3); needs a closed surface."""
    name: str = "volume"


# ------------------------------------------------------------ rigid part

@dataclass(frozen=True)
class RigidLink:
    """Points of `region` attached to MuJoCo body `body` (paper 3.5)."""
    region: Selector
    body: str
    name: str = "rigid_link"


@dataclass(frozen=True)
class Rigid:
    """The rigid part: an MJCF file (ours or a user's) and the membrane links to it."""
    mjcf: str
    links: tuple[RigidLink, ...] = ()
    prefix: str = ""
    add_link_mass: bool = True


ForceTerm = Union[Gravity, Damping, ShapeMemory, MassSpring, Muscle, AppliedForce, Attraction,
                  SoftVolume]
ConstraintTerm = Union[Nailed, KeepIn, Prescribed, Volume]


@dataclass(frozen=True)
class Scene:
    """Everything a run needs. SI units. See the module docstring."""
    mesh: object = MeshSpec()  # MeshSpec or a hybrid.mesh.Mesh
    masses: Masses = Masses(total_kg=1.0)
    regions: dict = field(default_factory=dict)  # name -> selector, evaluated in order
    forces: tuple = ()
    constraints: tuple = ()
    rigid: Optional[Rigid] = None
    dt_s: float = 1e-3
    integrator: str = "symplectic_euler"
    duration_s: float = 1.0
    max_speed_m_s: float = 50.0  # a point faster than this has run away (tissue moves at cm/s)
    name: str = "scene"
    base_dir: Optional[str] = None  # relative paths (mesh, MJCF) resolve here

    def term_names(self) -> list[str]:
        """Names of all force terms, constraints and rigid links, in order."""
        # getattr: a non-term in the lists must reach compile_scene's type check
        names = [getattr(t, "name", repr(t)) for t in (*self.forces, *self.constraints)]
        if self.rigid is not None:
            names += [link.name for link in self.rigid.links]
        return names

    def without(self, *names: str) -> "Scene":
        """A copy with the named force terms / constraints / rigid links removed."""
        known = self.term_names()
        for n in names:
            if n not in known:
                raise SceneError(f"without: no term named {n!r} in scene {self.name!r}; "
                                 f"terms: {known}")
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
