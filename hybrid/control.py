"""The inputs a step reads, set by the scene's schedules or by the user's program.

A scene's muscles, pressures, applied forces, prescribed motions and driven MuJoCo
actuators each read one input per step. By default the step evaluates the scene's
schedule for it at the step's time. `Control.set` hands an input to the user's program
instead (a controller, a ventilator model, a neural drive, a learning agent): the step
then reads the value set, until `release` gives the input back to its schedule.

    sim = hybrid.load("breathing")
    key = "forces['muscle_fibres'].tension_n_per_m"
    for _ in range(1000):
        sim.control.set(key, my_controller(sim))   # N/m, read by the next steps
        sim.step(1)

A run driven through `Control` with the values its schedules would give is the same
run, bit for bit (`tests/test_control.py`). An input's unit is its scene key's.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import SceneError
from .step_work import ControlArrays

__all__ = ["Control"]


class Control:
    """The inputs of one `Simulation` (`Simulation.control`).

    keys: every input's scene key: the schedules' (e.g.
    "forces['muscle_fibres'].tension_n_per_m", N/m) then the driven actuators'
    ("rigid.ctrl['NAME']", in the actuator's own unit). `set(key, value)`,
    `release(key)`, `value(key)`, `is_set(key)`.
    """

    def __init__(self, schedule_keys, arrays: ControlArrays, actuator_names=(), ctrl_user=None, mj_ctrl=None):
        self._rows = {key: (row, ncomp) for row, (key, ncomp) in enumerate(schedule_keys)}
        self._acts = {f"rigid.ctrl[{name!r}]": j for j, name in enumerate(actuator_names)}
        self.arrays = arrays
        self._ctrl_user = ctrl_user
        self._act_ids = None
        self._mj_ctrl = mj_ctrl  # a callable giving (MjData.ctrl, actuator ids), with a rigid part

    @property
    def keys(self) -> tuple:
        """Every input's scene key, the schedules' first."""
        return (*self._rows, *self._acts)

    def _where(self, key):
        if key in self._rows:
            return self._rows[key]
        if key in self._acts:
            return self._acts[key]
        raise SceneError(f"control {key!r}: not an input of this scene; expected one of {list(self.keys)}")

    def set(self, key: str, value) -> None:
        """The step reads `value` for input `key` from now on, instead of its schedule: a
        number, or a 3-vector for a 3-component input (a force, a displacement)."""
        where = self._where(key)
        if key in self._acts:
            v = _finite(key, value, 1)
            ctrl, ids = self._mj_ctrl()
            ctrl[ids[where]] = v[0]
            self._ctrl_user[where] = 1
            return
        row, ncomp = where
        v = _finite(key, value, ncomp)
        a = self.arrays
        a.value[row, :ncomp] = v
        a.value_next[row, :ncomp] = v  # held over the step: a prescribed motion reads both ends
        a.user[row] = 1

    def release(self, key: str) -> None:
        """Input `key` back to its schedule from the next step on."""
        where = self._where(key)
        if key in self._acts:
            self._ctrl_user[where] = 0
        else:
            self.arrays.user[where[0]] = 0

    def is_set(self, key: str) -> bool:
        """Whether the user's program sets input `key` (else its schedule does)."""
        where = self._where(key)
        return bool(self._ctrl_user[where] if key in self._acts else self.arrays.user[where[0]])

    def value(self, key: str):
        """Input `key` as the last step read it (or as set since): a float, or a (3,) array."""
        where = self._where(key)
        if key in self._acts:
            ctrl, ids = self._mj_ctrl()
            return float(ctrl[ids[where]])
        row, ncomp = where
        v = self.arrays.value[row, :ncomp].copy()
        return float(v[0]) if ncomp == 1 else v

    def values(self) -> dict:
        """{key: value} of every input (`value`)."""
        return {k: self.value(k) for k in self.keys}


def _finite(key: str, value, ncomp: int) -> np.ndarray:
    """value as ncomp finite floats, or a one-line error naming the input."""
    want = "a finite number" if ncomp == 1 else "3 finite numbers"
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise SceneError(f"control {key!r}: expected {want}, received {value!r}") from None
    if isinstance(value, (str, bytes)) or v.size != ncomp or not all(math.isfinite(x) for x in v):
        raise SceneError(f"control {key!r}: expected {want}, received {value!r}")
    return v
