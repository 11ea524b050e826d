"""The membrane's force and constraint terms, each in one place: its dataclass
(the scene vocabulary and the scene file's keys), its compile function and its
compiled kernel (`hybrid.terms.base` says how they fit together).

Families: `pointwise` (gravity, damping and the step's fused per-point pass),
`shape_memory`, `springs` (mass-spring, applied forces, attractive points),
`muscle`, `fibres` (muscle fibres that pull both ends), `passive_fibres` (a sheet stiffer along its fibres),
`volume` (exact and soft volume, pressure load), `lungs` (the thoracic cavity, lungs and airway), `local` (nailed, prescribed,
keep-in); `tangents` holds the continuum forces' Jacobians for implicit Euler (no term of its own).
`order_terms` below registers them: a new term is its module and
one entry there.
"""

from .base import CONSTRAINT_TYPES, FLAGGED, FORCE_TYPES, TERM_CLASSES, Build, Term, order_terms, registered_forces
from .fibres import MuscleFibres
from .local import KeepIn, Nailed, Prescribed
from .lungs import Lungs
from .membrane import Membrane
from .muscle import Muscle
from .passive_fibres import PassiveFibres
from .pointwise import Damping, Gravity
from .resting_tension import RestingTension
from .shape_memory import ShapeMemory
from .soft_volume import SoftVolume
from .springs import AppliedForce, Attraction, MassSpring
from .volume import Pressure, Volume

__all__ = [
    "Term",
    "Build",
    "FORCE_TYPES",
    "CONSTRAINT_TYPES",
    "TERM_CLASSES",
    "FLAGGED",
    "TERMS",
    "STEP_FORCES",
    "Gravity",
    "Damping",
    "ShapeMemory",
    "Membrane",
    "MassSpring",
    "AppliedForce",
    "Attraction",
    "Muscle",
    "SoftVolume",
    "Volume",
    "Nailed",
    "KeepIn",
    "Prescribed",
    "Pressure",
    "MuscleFibres",
    "PassiveFibres",
    "Lungs",
    "RestingTension",
]

order_terms(
    (
        Gravity,
        AppliedForce,
        Attraction,
        Damping,
        ShapeMemory,
        MassSpring,
        Muscle,
        SoftVolume,
        Membrane,
        Pressure,
        MuscleFibres,
        PassiveFibres,
        Nailed,
        Prescribed,
        KeepIn,
        Volume,
        Lungs,
        RestingTension,
    )
)

#: names of the terms with a flag and a kernel, in id order (MembraneArrays.term_on)
TERMS = tuple(cls.toml_type for cls in FLAGGED)
#: ((id, kernel), ...) of the terms the step calls through the registry (`Term.step_force`)
STEP_FORCES = registered_forces()
