"""The exceptions of `hybrid`.

Every message names the argument or element at fault, what was expected and
what was received, so that a user can fix the input without reading code.
The command line prints the message on one line and exits with status 2.

Every exception of the package pickles to an equal one (class, arguments,
attributes, notes), whatever its constructor takes: a failure in a worker of
`hybrid.sweep` comes back whole instead of breaking the pool. A class with its
own `__init__` outside this hierarchy takes `__reduce__ = reduce_exception`.
"""

from __future__ import annotations

__all__ = [
    "HybridError",
    "MeshError",
    "SceneError",
    "ArgumentError",
    "ConstraintError",
    "RigidError",
    "SimulationDiverged",
    "reduce_exception",
]


def _rebuild(cls, args: tuple, state: dict) -> BaseException:
    """An exception of class cls with these args and attributes, its __init__ not called."""
    exc = cls.__new__(cls, *args)
    exc.args = args
    exc.__dict__.update(state)
    return exc


def reduce_exception(exc: BaseException) -> tuple:
    """`__reduce__` for exceptions whose __init__ takes other arguments than
    `args` (keyword-only ones, say), which pickle's default cannot call again:
    rebuilt from class, args and attributes."""
    return (_rebuild, (type(exc), exc.args, dict(vars(exc))))


class HybridError(Exception):
    """Base class of every error `hybrid` raises on purpose."""

    __reduce__ = reduce_exception


class MeshError(HybridError, ValueError):
    """A triangle surface is unusable: topology, orientation or coordinates."""


class SceneError(HybridError, ValueError):
    """A scene (TOML file or dataclasses) has a wrong key, type or value."""


class ArgumentError(HybridError, ValueError):
    """A call of the Python API received an argument of the wrong kind or value
    (a Scene where a Simulation goes, a string where a list goes, a step count
    that is not an integer)."""


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

    def __init__(self, message: str, *, time_s: float, step: int, vert: int, dt_suggested_s: float):
        super().__init__(message)
        self.time_s = float(time_s)
        self.step = int(step)
        self.vert = int(vert)
        self.dt_suggested_s = float(dt_suggested_s)
