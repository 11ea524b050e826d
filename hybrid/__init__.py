"""hybrid: the breathing human trunk, MuJoCo ribs coupled to a volume-preserving membrane.

The public API for scripted experiments:

>>> import hybrid
>>> sim = hybrid.load()                 # the built-in breathing trunk (or a path, or a Scene)
>>> sim.step(1000); sim.time, sim.volume, sim.pressure, sim.vert_pos.shape
>>> sim.mj_model, sim.mj_data           # MuJoCo's model and data (None for a membrane-only scene)

A `Scene` is plain dataclasses: change a field with `dataclasses.replace` and
load it again to repeat the run with other parameters; `sim.model.with_dt(h)`
changes the step without compiling anything else.
"""

from __future__ import annotations

from pathlib import Path

from .errors import (ConstraintError, HybridError, MeshError, RigidError, SceneError,
                     SimulationDiverged)
from .model import Model, compile_scene
from .scene import Scene
from .simulation import Simulation

__all__ = ["load", "load_scene", "compile_scene", "Scene", "Model", "Simulation", "HybridError",
           "MeshError", "SceneError", "ConstraintError", "RigidError", "SimulationDiverged"]


def load_scene(path_or_name: str | Path = "breathing") -> Scene:
    """A scene from a TOML file, or a packaged scene by name ("breathing")."""
    from . import scenefile
    p = Path(path_or_name)
    if p.suffix != ".toml":
        p = scenefile.builtin_scene(str(path_or_name))
    return scenefile.load_scene(p)


def load(path_or_scene: str | Path | Scene = "breathing") -> Simulation:
    """A ready-to-step simulation of a scene file, a packaged scene name or a `Scene`."""
    scene = path_or_scene if isinstance(path_or_scene, Scene) else load_scene(path_or_scene)
    return Simulation(compile_scene(scene))
