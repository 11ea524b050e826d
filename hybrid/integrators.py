"""The membrane's integrators, one registry: the scene's name of each (`Scene.integrator`),
the id the compiled step reads (`MembraneArrays.integrator`) and what it needs.

The step's phase 2 (`hybrid.step.integrate`) integrates with implicit Euler's Newton solve
(`hybrid.implicit.implicit_step`, compiled apart and called at its address, `StepWork.calls`,
with its arrays `hybrid.implicit_work.ImplicitWork`, empty for the other integrators) when the
model's id is implicit Euler's, else with the explicit pair (`hybrid.step._integrate`, the id
saying which of the two).
Each entry has its solver object, the one a program passes to `Simulation`
(`hybrid.solvers`: its settings and its work arrays). Adding an integrator takes its
entry here, its branch there and its class in `hybrid.solvers`.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = [
    "Integrator",
    "INTEGRATORS",
    "NAMES",
    "BY_NAME",
    "is_implicit",
    "EXPLICIT_EULER_ID",
    "SYMPLECTIC_EULER_ID",
    "IMPLICIT_EULER_ID",
]

# the ids the compiled kernels compare with (plain ints: numba freezes them as constants)
EXPLICIT_EULER_ID, SYMPLECTIC_EULER_ID, IMPLICIT_EULER_ID = 0, 1, 2


class Integrator(NamedTuple):
    """An integrator of the membrane's points."""

    name: str  # the scene's name for it
    id: int  # `MembraneArrays.integrator`
    implicit: bool  # a Newton solve each step, with work arrays of its own; stable at any step
    needs_hessian: bool  # its forces' Jacobian: formulation "continuum" only (the paper's terms have none)
    about: str


INTEGRATORS = (
    Integrator(
        "explicit_euler",
        EXPLICIT_EULER_ID,
        False,
        False,
        "the paper's integrator, position and velocity both advanced from the step's start",
    ),
    Integrator(
        "symplectic_euler",
        SYMPLECTIC_EULER_ID,
        False,
        False,
        "the velocity advanced first, then the position with the new velocity; keeps an undamped spring bounded",
    ),
    Integrator(
        "implicit_euler",
        IMPLICIT_EULER_ID,
        True,
        True,
        "backward Euler, the forces taken at the step's end and solved for by Newton's method; stable at any step",
    ),
)
NAMES = tuple(i.name for i in INTEGRATORS)
BY_NAME = {i.name: i for i in INTEGRATORS}
assert all(i.id == k for k, i in enumerate(INTEGRATORS))  # an id indexes INTEGRATORS


def is_implicit(name: str) -> bool:
    """Whether the integrator named `name` solves each step (False for an unknown name,
    which the scene's checks refuse)."""
    return name in BY_NAME and BY_NAME[name].implicit
