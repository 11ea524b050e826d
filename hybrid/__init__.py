"""hybrid: the breathing human trunk, MuJoCo ribs coupled to a volume-preserving membrane.

The public API for scripted experiments:

>>> import hybrid
>>> sim = hybrid.load()                 # the packaged breathing trunk (or a name, a path, a Scene)
>>> sim.step(1000); sim.time, sim.volume, sim.pressure, sim.vert_pos.shape
>>> sim.mj_model, sim.mj_data           # MuJoCo's model and data (None for a membrane-only scene)
>>> result = hybrid.run(hybrid.load("membrane_demo"), 4.0)   # {"summary": {...}, "trace": Trace}
>>> result["summary"]["apex_descent_mm"], result["trace"].arrays()["t_s"].shape

A `Scene` is plain dataclasses (its terms, region selectors and schedules are
all here): change a field with `dataclasses.replace` and load it again to
repeat the run with other parameters; `sim.model.with_dt(h)` changes the step
without compiling anything else; `sim.set_state(...)` starts from another state; `hybrid.load(..., solver=hybrid.ImplicitEuler())`
steps with another solver (`sim.solver` says which).
`hybrid.read` (an MCAP recording) and `hybrid.sweep` (runs in parallel) are the
observers' side. Everything else lives in the submodules, which may change.
"""

from __future__ import annotations

#: the package's version, its one place: pyproject.toml reads it (setuptools' dynamic
#: version), `hybrid --version` prints it, every run's provenance records it
#: (the policy: CHANGELOG.md, "Versions")
__version__ = "0.28.1"

from collections.abc import Sequence
from pathlib import Path

from .control import Control
from .errors import ConstraintError, HybridError, MeshError, RigidError, SceneError, SimulationDiverged
from .model import Model, compile_scene
from .regions import All, Ball, Border, Box, Difference, HalfSpace, Indices, Intersection, Nearest, Patch, Union_, Wedge
from .resolve import resolve_scene, scene_names

# `run` and `sweep` are both a module and its function: importing the function here
# makes `hybrid.run` / `hybrid.sweep` the function (`from hybrid.run import ...` still
# reaches the module). Both modules are light (matplotlib and dask load when used).
from .run import RunFailed, run
from .scene import (
    AppliedForce,
    Attraction,
    Damping,
    Gravity,
    KeepIn,
    Lungs,
    Masses,
    MassSpring,
    Membrane,
    MeshSpec,
    Muscle,
    MuscleFibres,
    Nailed,
    PassiveFibres,
    Prescribed,
    Pressure,
    RestingTension,
    RibPair,
    Ribs,
    Rigid,
    RigidLink,
    Scene,
    ShapeMemory,
    SoftVolume,
    Volume,
)
from .schedule import Breathing, Constant, Function, Table
from .simulation import Simulation
from .solvers import ExplicitEuler, ImplicitEuler, Solver, SymplecticEuler
from .state import State
from .sweep import sweep

__all__ = [
    # loading and running
    "load",
    "load_scene",
    "scene_names",
    "compile_scene",
    "Model",
    "Simulation",
    "State",
    "Control",
    # the membrane's solvers (Simulation(model, solver=...))
    "Solver",
    "SymplecticEuler",
    "ExplicitEuler",
    "ImplicitEuler",
    "run",
    "read",
    "sweep",
    # the scene and its terms
    "Scene",
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
    "Rigid",
    "RigidLink",
    "Ribs",
    "RibPair",
    "Pressure",
    "MuscleFibres",
    "PassiveFibres",
    "Lungs",
    "RestingTension",
    # region selectors
    "All",
    "Border",
    "Indices",
    "HalfSpace",
    "Ball",
    "Box",
    "Wedge",
    "Nearest",
    "Patch",
    "Union_",
    "Intersection",
    "Difference",
    # schedules
    "Constant",
    "Table",
    "Breathing",
    "Function",
    # errors
    "HybridError",
    "MeshError",
    "SceneError",
    "ConstraintError",
    "RigidError",
    "SimulationDiverged",
    "RunFailed",
]


def load_scene(
    source: str | Path | Scene = "breathing", *, overrides: Sequence[str] = (), without: Sequence[str] = ()
) -> Scene:
    """The `Scene` a source names: a packaged scene ("breathing", "myotorso_breathing"),
    a scene written in Python ("membrane_demo"), a path to a TOML file, or a `Scene`;
    with "KEY=VALUE" `overrides` applied and the terms named in `without` removed
    (`hybrid run SCENE --set KEY=VALUE --without NAME`). An unknown name raises
    SceneError listing the valid ones (`scene_names()`)."""
    return resolve_scene(source, overrides=overrides, without=without)


def load(
    source: str | Path | Scene = "breathing",
    *,
    overrides: Sequence[str] = (),
    without: Sequence[str] = (),
    solver: Solver | None = None,
) -> Simulation:
    """A ready-to-step simulation of a source, as `load_scene` takes it, stepping with
    `solver` (`hybrid.ImplicitEuler(tol=1e-8)`, ...; None: the scene's `integrator`)."""
    return Simulation(compile_scene(load_scene(source, overrides=overrides, without=without)), solver=solver)


def _read(path, *, t_s=None, topics=None, strict: bool = True) -> dict:
    """The recorded channels of `path` as numpy arrays, by topic (`hybrid.record.read`),
    the path checked first (`hybrid.outputs.recording_path`): a HybridError on one line
    for what is no recording, a RecordingWarning for the recording of a run that died."""
    from .outputs import recording_path
    from .record import read

    return read(recording_path(path, strict=strict), t_s=t_s, topics=topics, strict=strict)


def __getattr__(name: str):
    # the recording's reader, with its MCAP decoding, only when asked for
    if name == "read":
        globals()["read"] = _read
        return _read
    raise AttributeError(f"module 'hybrid' has no attribute {name!r}")
