"""The step's term ids and its one specialising argument.

Which terms a model has is read at run time, each term's flag in `MembraneArrays.term_on`
(ids below): the one compiled step loop (`hybrid.loop.run_steps`) serves every scene and
every set of terms. Compiling a loop per set of terms (a None argument for a term a model
lacks, which numba prunes) made every new set of terms a new compile of the whole loop, 15
to 50 s; read at run time, a flag costs a branch per term per step. The multi-core build is
the one argument still pruned (`step_par`): a model too small for it never compiles it.
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
    RestingTension,
    ShapeMemory,
    SoftVolume,
    Volume,
)
from .terms.fibres import MuscleFibres

__all__ = ["step_par"]

#: each term's flag in MembraneArrays.term_on and its call counter (the step's names for the ids)
T_GRAVITY, T_DAMPING = Gravity.id, Damping.id
T_SHAPE_MEMORY, T_MEMBRANE, T_APPLIED, T_ATTRACTION = ShapeMemory.id, Membrane.id, AppliedForce.id, Attraction.id
T_MASS_SPRING, T_MUSCLE, T_SOFT_VOLUME, T_PRESSURE = MassSpring.id, Muscle.id, SoftVolume.id, Pressure.id
T_MUSCLE_FIBRES, T_PASSIVE_FIBRES, T_LUNGS = MuscleFibres.id, PassiveFibres.id, Lungs.id
T_PRESCRIBED, T_KEEP_IN, T_VOLUME = Prescribed.id, KeepIn.id, Volume.id
T_RESTING_TENSION = RestingTension.id


def step_par(arrays: MembraneArrays):
    """The step kernels' `par` argument for a model: None when it never runs the
    multi-core build (`arrays.parallel` false): a None argument prunes that branch
    when the kernel compiles, so a first run compiles the serial passes only; else
    True, both builds compiled and `arrays.parallel` choosing."""
    return True if arrays.parallel else None
