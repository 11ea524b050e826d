"""The membrane's solvers as objects a program chooses: `ExplicitEuler`, `SymplecticEuler`
and `ImplicitEuler(tol, max_iter)`.

>>> sim = hybrid.Simulation(model, solver=hybrid.ImplicitEuler(tol=1e-8))
>>> sim.solver                      # ImplicitEuler(tol=1e-08, max_iter=50)
>>> hybrid.Simulation(model).solver  # the scene's own: its `integrator` key and settings

A solver is one entry of the integrators' registry (`hybrid.integrators`, the id the
compiled step dispatches on) with its settings. It gives the model it steps (the same
model with its id and settings: `Model.with_dt`, nothing compiled again) and makes the
work arrays that it alone uses (implicit Euler's Newton and conjugate-gradient arrays;
the explicit pair has none). Each step of the one loop (`hybrid.loop.run_steps`) asks
`hybrid.step.integrate` for the membrane's step, which runs the solver the arrays name
with that work, and MuJoCo for the rigid part's. The step `h` is the model's
(`Model.with_dt` changes it).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

from .errors import ArgumentError, SceneError
from .implicit_work import ImplicitWork, implicit_work
from .integrators import BY_NAME, INTEGRATORS, NAMES
from .scene import Scene
from .terms.base import check_value

if TYPE_CHECKING:
    from .model import Model
    from .step_work import MembraneState

__all__ = ["Solver", "ExplicitEuler", "SymplecticEuler", "ImplicitEuler", "SOLVERS", "solver_of"]


@dataclass(frozen=True)
class Solver:
    """A membrane solver: its registry entry's name, and its settings as fields."""

    name: ClassVar[str]

    @property
    def implicit(self) -> bool:
        """Whether it solves each step (stable at any step), with work arrays of its own."""
        return BY_NAME[self.name].implicit

    @property
    def about(self) -> str:
        return BY_NAME[self.name].about

    def model_for(self, model: Model) -> Model:
        """`model` stepping with this solver: its integrator id and settings in the arrays
        the compiled step reads, its step unchanged. Refused (ArgumentError) where the model
        cannot take it: implicit Euler needs forces with a Hessian."""
        self._check(model)
        return model.with_dt(model.dt_s, self.name)

    def _check(self, model: Model) -> None:
        formulation = model.scene.formulation
        if BY_NAME[self.name].needs_hessian and formulation != "continuum":
            # the paper's shape memory and muscle derive from no energy: no Hessian to solve with
            raise ArgumentError(
                f"solver: {self!r} needs formulation 'continuum' (forces with a Hessian), received scene "
                f"{model.scene.name!r} of formulation {formulation!r}; use SymplecticEuler() or ExplicitEuler()"
            )

    def new_work(self, model: Model, state: MembraneState) -> ImplicitWork | None:
        """The work arrays this solver alone reads and writes, for `model` (stepping with it)
        and `state`'s lungs' wall; None for the explicit pair."""
        return None


@dataclass(frozen=True)
class ExplicitEuler(Solver):
    """The paper's integrator: position and velocity both advanced from the step's start."""

    name: ClassVar[str] = "explicit_euler"


@dataclass(frozen=True)
class SymplecticEuler(Solver):
    """The velocity advanced first, then the position with the new velocity."""

    name: ClassVar[str] = "symplectic_euler"


def _scene_default(key: str):
    return {f.name: f.default for f in dataclasses.fields(Scene)}[key]


@dataclass(frozen=True)
class ImplicitEuler(Solver):
    """Backward Euler: the forces taken at the step's end, solved for by Newton's method
    (`hybrid.implicit`). tol: converged when the residual force is at most this fraction of
    the forces (the scene's `implicit_tol`); max_iter: the Newton iteration cap
    (`implicit_max_iter`). Defaults are the scene's."""

    name: ClassVar[str] = "implicit_euler"
    tol: float = field(default=_scene_default("implicit_tol"))
    max_iter: int = field(default=_scene_default("implicit_max_iter"))

    def __post_init__(self):
        meta = {f.name: f.metadata for f in dataclasses.fields(Scene)}
        for attr, key in (("tol", "implicit_tol"), ("max_iter", "implicit_max_iter")):
            try:
                value = check_value(f"ImplicitEuler.{attr}", meta[key]["kind"], getattr(self, attr), meta[key])
            except SceneError as e:  # an argument of a Python call, not a scene file's key
                raise ArgumentError(str(e)) from None
            object.__setattr__(self, attr, value)

    def model_for(self, model: Model) -> Model:
        self._check(model)
        return model.with_dt(model.dt_s, self.name, implicit_tol=self.tol, implicit_max_iter=self.max_iter)

    def new_work(self, model: Model, state: MembraneState) -> ImplicitWork | None:
        return implicit_work(
            model.arrays, state.lung_wall_pos, state.lung_wall_vel, model.slide_vert, model.slide_stiffness_n_per_m
        )


#: one solver class for each entry of the registry, by its name
SOLVERS: dict[str, type[Solver]] = {cls.name: cls for cls in (ExplicitEuler, SymplecticEuler, ImplicitEuler)}
assert tuple(SOLVERS) == NAMES  # the registry's order: a solver for each integrator


def solver_of(model: Model) -> Solver:
    """The solver `model` steps with: its scene's `integrator` with its settings."""
    cls = SOLVERS[INTEGRATORS[model.arrays.integrator].name]
    if cls is ImplicitEuler:
        return ImplicitEuler(tol=model.scene.implicit_tol, max_iter=model.scene.implicit_max_iter)
    return cls()
