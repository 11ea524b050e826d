"""Functions of time: muscle contraction, applied forces, trajectories.

A schedule gives a value (a scalar or a 3-vector) at every time t. The
compiled step evaluates constants, tables and the breathing waveform itself;
a Python callable is evaluated in Python before each step (slower: the run
then steps one at a time), so prefer a table when speed matters.

All schedules of a model are stacked into one `ScheduleTable` so that the
compiled step receives a few arrays, whatever the number of schedules.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Union

import numpy as np

from .errors import SceneError
from .kernel import kernel

__all__ = [
    "Constant",
    "Table",
    "Breathing",
    "Function",
    "Schedule",
    "as_schedule",
    "ScheduleTable",
    "stack_schedules",
    "schedule_eval",
]

KIND_CONSTANT, KIND_TABLE, KIND_BREATHING, KIND_PYTHON = 0, 1, 2, 3


@dataclass(frozen=True)
class Constant:
    """The same value at all times."""

    value: float | tuple[float, float, float]


@dataclass(frozen=True)
class Table:
    """Piecewise-linear interpolation of (t_s, value) samples, held constant
    outside the sampled range; `periodic=True` repeats it with the table's span."""

    t_s: tuple[float, ...]
    value: tuple  # scalars or 3-vectors, one per time
    periodic: bool = False


@dataclass(frozen=True)
class Breathing:
    """A smooth breathing cycle between 0 and `peak`.

    Each cycle of `period_s` starts with an inspiration of
    `inspiration_fraction * period_s` where the value rises as a raised cosine
    from 0 to `peak`, followed by an expiration where it falls back to 0 the
    same way; `onset_s` delays the first cycle (value 0 before it).
    Quiet breathing: 15 breaths/min -> period 4 s, inspiration about 40%.
    """

    period_s: float = 4.0
    inspiration_fraction: float = 0.4
    peak: float = 1.0
    onset_s: float = 0.0


@dataclass(frozen=True)
class Function:
    """Any Python callable f(t_s) -> scalar or 3-vector (evaluated in Python)."""

    fn: Callable[[float], object]


Schedule = Union[Constant, Table, Breathing, Function]


def as_schedule(value, *, name: str, ncomp: int) -> Schedule:
    """Turn a number, a vector, a callable or a schedule into a validated schedule.

    `ncomp` is 1 for scalars (stiffness) and 3 for vectors (forces, displacements).
    """
    if isinstance(value, (Constant, Table, Breathing, Function)):
        sched = value
    elif callable(value):
        sched = Function(value)
    else:
        sched = Constant(value)
    _validate(sched, name=name, ncomp=ncomp)
    return sched


def _check_value(v, *, name: str, ncomp: int) -> np.ndarray:
    arr = np.asarray(v, dtype=float) if not isinstance(v, str) else None
    want = "a number" if ncomp == 1 else "a 3-vector"
    if arr is None or arr.size != ncomp or not np.all(np.isfinite(arr)):
        raise SceneError(f"{name}: expected {want} of finite floats, received {v!r}")
    return arr.reshape(ncomp)


def _validate(s: Schedule, *, name: str, ncomp: int) -> None:
    if isinstance(s, Constant):
        _check_value(s.value, name=name, ncomp=ncomp)
    elif isinstance(s, Table):
        t = np.asarray(s.t_s, dtype=float)
        if t.ndim != 1 or t.size < 1 or not np.all(np.isfinite(t)):
            raise SceneError(f"{name}.t_s: expected a non-empty list of finite times, received {s.t_s!r}")
        if np.any(np.diff(t) <= 0):
            raise SceneError(f"{name}.t_s: expected strictly increasing times, received {t.tolist()}")
        if len(s.value) != t.size:
            raise SceneError(f"{name}.value: expected {t.size} values (one per time), received {len(s.value)}")
        for v in s.value:
            _check_value(v, name=f"{name}.value", ncomp=ncomp)
        if s.periodic and t.size < 2:
            raise SceneError(f"{name}: a periodic table needs at least 2 samples, received {t.size}")
    elif isinstance(s, Breathing):
        if ncomp != 1:
            raise SceneError(
                f"{name}: a breathing waveform is scalar; expected a vector schedule (constant, table or function)"
            )
        if not (s.period_s > 0 and math.isfinite(s.period_s)):
            raise SceneError(f"{name}.period_s: expected > 0, received {s.period_s!r}")
        if not (0.0 < s.inspiration_fraction < 1.0):
            raise SceneError(f"{name}.inspiration_fraction: expected in (0, 1), received {s.inspiration_fraction!r}")
        if not math.isfinite(s.peak):
            raise SceneError(f"{name}.peak: expected a finite number, received {s.peak!r}")
        if not (s.onset_s >= 0 and math.isfinite(s.onset_s)):
            raise SceneError(f"{name}.onset_s: expected >= 0, received {s.onset_s!r}")
    elif isinstance(s, Function):
        _probe(s, name=name, ncomp=ncomp)  # and checked each time it is called
    else:  # pragma: no cover - guarded by as_schedule
        raise SceneError(f"{name}: expected a constant, table, breathing waveform or function, received {s!r}")


def _probe(s: Function, *, name: str, ncomp: int) -> None:
    """A function's value at t = 0 s, of `ncomp` components (a scalar schedule that
    returns a vector would be read as its first component): a function that fails
    there is left to fail when the run calls it."""
    if not callable(s.fn):
        raise SceneError(f"{name}: expected a callable f(t_s), received {s.fn!r}")
    try:
        value = np.asarray(s.fn(0.0), dtype=float)
    except Exception:  # noqa: BLE001 - the run reports it at its time
        return
    if value.size != ncomp:
        want = "a number" if ncomp == 1 else "a 3-vector"
        raise SceneError(
            f"{name}: expected a function returning {want}, received {getattr(s.fn, '__name__', s.fn)!r}, "
            f"which returns {value.size} values ({value.reshape(-1)[:4].tolist()}) at t = 0 s"
        )


class ScheduleTable(NamedTuple):
    """All schedules of a model, stacked for the compiled step.

    kind (ns,) int64; par (ns, 4) float64 (breathing: period, fraction, peak, onset;
    table: periodic flag); tab_len (ns,) int64; tab_t (ns, L) s; tab_v (ns, L, 3).
    Constants (and Python functions, refreshed each step) live in tab_v[:, 0].
    """

    kind: np.ndarray
    par: np.ndarray
    tab_len: np.ndarray
    tab_t: np.ndarray
    tab_v: np.ndarray


def stack_schedules(scheds: Sequence[Schedule]) -> tuple[ScheduleTable, list]:
    """Stack schedules; returns the table and the Python functions [(row, fn, ncomp)]."""
    ns = len(scheds)
    lmax = max([len(s.t_s) for s in scheds if isinstance(s, Table)] + [1])
    kind = np.zeros(ns, np.int64)
    par = np.zeros((ns, 4))
    tab_len = np.ones(ns, np.int64)
    tab_t = np.zeros((max(ns, 1), lmax))[:ns]
    tab_v = np.zeros((max(ns, 1), lmax, 3))[:ns]
    python_fns = []
    for row, s in enumerate(scheds):
        if isinstance(s, Constant):
            kind[row] = KIND_CONSTANT
            v = np.atleast_1d(np.asarray(s.value, float))
            tab_v[row, 0, : v.size] = v
        elif isinstance(s, Table):
            kind[row] = KIND_TABLE
            n = len(s.t_s)
            tab_len[row] = n
            tab_t[row, :n] = s.t_s
            for k, v in enumerate(s.value):
                v = np.atleast_1d(np.asarray(v, float))
                tab_v[row, k, : v.size] = v
            par[row, 0] = 1.0 if s.periodic else 0.0
        elif isinstance(s, Breathing):
            kind[row] = KIND_BREATHING
            par[row] = (s.period_s, s.inspiration_fraction, s.peak, s.onset_s)
        else:
            kind[row] = KIND_PYTHON
            python_fns.append((row, s.fn))
    return ScheduleTable(kind, par, tab_len, tab_t, tab_v), python_fns


@kernel
def breathing_value(par, t):
    """Raised-cosine breathing cycle (see `Breathing`); par = (period, fraction, peak, onset).
    # Model: par (period s, fraction, peak, onset s)   # Data in: t s   # Data out: returns the value
    """
    period, frac, peak, onset = par[0], par[1], par[2], par[3]
    if t < onset:
        return 0.0
    tau = (t - onset) % period
    t_insp = frac * period
    if tau < t_insp:
        return peak * 0.5 * (1.0 - math.cos(math.pi * tau / t_insp))
    return peak * 0.5 * (1.0 + math.cos(math.pi * (tau - t_insp) / (period - t_insp)))


@kernel
def schedule_eval(sched, row, t, out):
    """Write schedule `row` at time t (s) into out (3,); scalars land in out[0].

    # Model: sched
    # Data in: row, t s
    # Data out: out
    """
    kind = sched.kind[row]
    if kind == KIND_BREATHING:
        out[0] = breathing_value(sched.par[row], t)
        out[1] = 0.0
        out[2] = 0.0
        return
    if kind != KIND_TABLE:  # constant, or a Python function refreshed before the step
        for c in range(3):
            out[c] = sched.tab_v[row, 0, c]
        return
    n = sched.tab_len[row]
    tt = sched.tab_t[row]
    if sched.par[row, 0] > 0.0 and n > 1:  # periodic: wrap into the table's span
        span = tt[n - 1] - tt[0]
        t = tt[0] + (t - tt[0]) % span
    if t <= tt[0]:
        for c in range(3):
            out[c] = sched.tab_v[row, 0, c]
        return
    if t >= tt[n - 1]:
        for c in range(3):
            out[c] = sched.tab_v[row, n - 1, c]
        return
    # k: the last table time below t (np.searchsorted's answer, less one), by bisection
    # here: numba's generic searchsorted would add its own compiling to a first run
    k, hi = 0, n - 1  # tt[k] < t <= tt[hi]
    while hi - k > 1:
        mid = (k + hi) // 2
        if tt[mid] < t:
            k = mid
        else:
            hi = mid
    w = (t - tt[k]) / (tt[k + 1] - tt[k])
    for c in range(3):
        out[c] = (1.0 - w) * sched.tab_v[row, k, c] + w * sched.tab_v[row, k + 1, c]


def evaluate(s: Schedule, t: float) -> np.ndarray:
    """Value of one schedule at time t, in Python (for plots, tests and summaries)."""
    table, fns = stack_schedules([s])
    if fns:
        return np.atleast_1d(np.asarray(fns[0][1](t), float))  # s.fn
    out = np.zeros(3)
    schedule_eval(table, 0, float(t), out)
    return out
