"""The step kernels' switches: which term kernels a model's compiled step holds.

A switch is an argument of the step kernels (`hybrid.step.membrane_forces`,
`hybrid.step.membrane_advance`, `hybrid.loop.run_steps`): None for a term the model lacks,
whose branch numba then prunes when the kernel compiles, so that a first run compiles only the
kernels its scene uses; True compiles the branch and the model's flag (`term_on`) decides at
run time: the same arithmetic either way.
"""

from __future__ import annotations

from .model import MembraneArrays
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
    PassiveFibres,
    Prescribed,
    Pressure,
    ShapeMemory,
    SoftVolume,
    Volume,
)
from .terms.fibres import MuscleFibres

__all__ = [
    "FORCE_SWITCHES",
    "ADVANCE_SWITCHES",
    "step_par",
    "force_switches",
    "advance_switches",
    "step_switches",
]

#: each term's flag in MembraneArrays.term_on and its call counter (the step's names for the ids)
T_GRAVITY, T_DAMPING = Gravity.id, Damping.id
T_SHAPE_MEMORY, T_MEMBRANE, T_APPLIED, T_ATTRACTION = ShapeMemory.id, Membrane.id, AppliedForce.id, Attraction.id
T_MASS_SPRING, T_MUSCLE, T_SOFT_VOLUME, T_PRESSURE = MassSpring.id, Muscle.id, SoftVolume.id, Pressure.id
T_MUSCLE_FIBRES, T_PASSIVE_FIBRES, T_LUNGS = MuscleFibres.id, PassiveFibres.id, Lungs.id
T_PRESCRIBED, T_KEEP_IN, T_VOLUME = Prescribed.id, KeepIn.id, Volume.id


def step_par(arrays: MembraneArrays):
    """The step kernels' `par` argument for a model: None when it never runs the
    multi-core build (`arrays.parallel` false): a None argument prunes that branch
    when the kernel compiles, so a first run compiles the serial passes only; else
    True, both builds compiled and `arrays.parallel` choosing."""
    return True if arrays.parallel else None


# after `par`: one per term kernel (or pass) that a model may lack, in the order of the
# kernels' parameters (module docstring)
FORCE_SWITCHES = {
    "shape_memory": T_SHAPE_MEMORY,
    "membrane": T_MEMBRANE,
    "applied": T_APPLIED,
    "attraction": T_ATTRACTION,
    "mass_spring": T_MASS_SPRING,
    "muscle": T_MUSCLE,
    "soft_volume": T_SOFT_VOLUME,
    "pressure": T_PRESSURE,
    "fibres": T_MUSCLE_FIBRES,
    "passive": T_PASSIVE_FIBRES,
    "lungs": T_LUNGS,
}
# shake: the volume projection's direction where the step starts (`volume_shake`)
# lungs_held: the occluded airway's projection (the lungs' `project_occluded`)
ADVANCE_SWITCHES = {
    "prescribed": T_PRESCRIBED,
    "keep_in": T_KEEP_IN,
    "volume": T_VOLUME,
    "shake": T_VOLUME,
    "lungs_held": T_LUNGS,
}


def _switches(arrays: MembraneArrays, names: dict) -> tuple:
    """One switch per name: True when the model has the term (and, for shake, projects
    along the step's start), else None."""
    on = arrays.term_on.tolist()
    return tuple(True if on[i] and (name != "shake" or arrays.volume_shake) else None for name, i in names.items())


def force_switches(arrays: MembraneArrays) -> tuple:
    """`membrane_forces`' arguments after (m, s, t) for a model: (par, then one per
    `FORCE_SWITCHES`, None for a term the model lacks)."""
    return (step_par(arrays),) + _switches(arrays, FORCE_SWITCHES)


def advance_switches(arrays: MembraneArrays) -> tuple:
    """`membrane_advance`'s arguments after (m, s, t, step) for a model: (par, then
    one per `ADVANCE_SWITCHES`)."""
    return (step_par(arrays),) + _switches(arrays, ADVANCE_SWITCHES)


def step_switches(arrays: MembraneArrays) -> tuple:
    """The whole loops' (`run_membrane`, `hybrid.coupling.run_coupled`, their frame
    versions) last arguments for a model: `force_switches`, then `advance_switches`
    without its `par`."""
    return force_switches(arrays) + _switches(arrays, ADVANCE_SWITCHES)
