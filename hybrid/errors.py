"""The exceptions of `hybrid`.

Every message names the argument or element at fault, what was expected and
what was received, so that a user can fix the input without reading code.
The command line prints the message on one line and exits with status 2.
"""

from __future__ import annotations

__all__ = [
    "HybridError",
    "MeshError",
    "SceneError",
    "ConstraintError",
    "RigidError",
    "SimulationDiverged",
]


class HybridError(Exception):
    """Base class of every error `hybrid` raises on purpose."""


class MeshError(HybridError, ValueError):
    """A triangle surface is unusable: topology, orientation or coordinates."""


class SceneError(HybridError, ValueError):
    """A scene (TOML file or dataclasses) has a wrong key, type or value."""


class ConstraintError(HybridError, RuntimeError):
    """A constraint cannot be satisfied (e.g. the volume projection has no root)."""


class RigidError(HybridError, ValueError):
    """The rigid (MuJoCo) part is inconsistent: unknown body or site, bad MJCF."""


class SimulationDiverged(HybridError, RuntimeError):
    """The state became non-finite or ran away.

    Attributes
    ----------
    time_s : float      simulated time of the failing step (s)
    step : int          index of the failing step
    vert : int          the worst vertex (largest speed or first non-finite)
    dt_suggested_s : float   a time step that the stability estimate deems safe (s)
    """

    def __init__(self, message: str, *, time_s: float, step: int, vert: int,
                 dt_suggested_s: float):
        super().__init__(message)
        self.time_s = float(time_s)
        self.step = int(step)
        self.vert = int(vert)
        self.dt_suggested_s = float(dt_suggested_s)
