"""Run a scene to the end: step it, take its frames and hand them to the observers (the
trace, its metrics and the summary: `hybrid.observers`).

The runner is an observer: it never changes the state. A frame is taken every
`frame_dt_s` of simulated time (and at least every `MAX_STEPS_PER_CALL` steps, and
at each multiple of an observer's `every_steps`); up to `FRAMES_PER_CALL` of them are stepped and
captured in one compiled call (`Simulation.step_frames`: positions, volume,
pressure, kinetic energy, the bodies' poses), and the trace is computed from them
in whole arrays. With an observer that wants the simulation at each frame, or a
scene with Python schedules, it steps frame by frame instead; both ways give the
same trace to the bit. The trace is kept in preallocated rows, or streamed to a
file (`trace_spill`): no Python object per frame. A run that fails, diverges or
is interrupted still returns what it recorded, with its status in the summary.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from .errors import ArgumentError, HybridError, reduce_exception
from .loads import Loads, LoadsObserver
from .loop import capture_frame
from .observers.metrics import TraceMetrics, scene_parts
from .observers.metrics import apex_vertex as _apex_vertex  # noqa: F401 (hybrid.studies.work_precision's import)
from .observers.summary import METRIC_KEYS, metric_table, run_summary
from .observers.trace import TRACE_KEYS, Trace
from .outputs import (
    FolderLock,
    claim_folder,
    default_out,
    holds_run,
    out_folder,
    plot_trace,
    write_outputs,
    write_summary,
)
from .simulation import Simulation

__all__ = [
    "TRACE_KEYS",
    "METRIC_KEYS",
    "Trace",
    "scene_parts",
    "metric_table",
    "run",
    "RunFailed",
    "RunInterrupted",
    "FolderLock",
    "default_out",
    "run_steps",
    "frame_interval_s",
    "out_folder",
    "claim_folder",
    "holds_run",
    "write_summary",
    "write_outputs",
    "plot_trace",
]


#: steps a command-line run starts only when confirmed (--yes)
CONFIRM_STEPS = 10**8
#: beyond this many steps the time t = n dt no longer grows by dt in double precision
MAX_STEPS = 2**53


def run_steps(duration_s, dt_s: float, *, confirmed: bool = True, name: str = "--duration") -> int:
    """The number of steps of a run of `duration_s` at `dt_s`, or a HybridError on
    one line: a duration that is not a finite time > 0 s, fewer than one step, more
    than `MAX_STEPS`, or more than `CONFIRM_STEPS` unless `confirmed` (the message
    then says how many and to add --yes). `name`: the duration's, for the messages."""
    ok = isinstance(duration_s, (int, float, np.integer, np.floating)) and not isinstance(duration_s, bool)
    if not (ok and math.isfinite(duration_s) and duration_s > 0):
        raise HybridError(f"{name}: expected a finite time > 0 s, received {duration_s!r}")
    steps = duration_s / dt_s
    if not steps < MAX_STEPS:
        raise HybridError(
            f"{name} {duration_s:g} s at dt_s = {dt_s:g} s: expected at most 2^53 = "
            f"{MAX_STEPS:.3g} steps (beyond, t + dt no longer advances t), received {steps:.3g}"
        )
    n = int(round(steps))
    if n < 1:
        raise HybridError(
            f"{name} {duration_s:g} s: expected at least one step of dt_s = {dt_s:g} s, received {steps:.3g} steps"
        )
    if n > CONFIRM_STEPS and not confirmed:
        raise HybridError(
            f"{name} {duration_s:g} s at dt_s = {dt_s:g} s is {n:.4g} steps, more than "
            f"{CONFIRM_STEPS:.0e}; add --yes to run them"
        )
    return n


#: frames stepped in one compiled call by the runner (fewer for large meshes)
FRAMES_PER_CALL = 100
#: steps of one compiled call at most, and so between two frames: a run stops within
#: about a second of a signal (compiled code cannot be interrupted) however far apart
#: its frames are
MAX_STEPS_PER_CALL = 100_000


#: the runner's frame interval (s) unless asked otherwise (`run`'s `frame_dt_s`)
FRAME_DT_S = 0.01


def _frame_steps(frame_dt_s: float, dt_s: float) -> int:
    """Steps between two of the runner's regular frames: the whole number nearest
    frame_dt_s / dt_s, at least 1."""
    return max(1, int(round(frame_dt_s / dt_s)))


def frame_interval_s(dt_s: float, frame_dt_s: float = FRAME_DT_S) -> float:
    """The interval (s) of a run's regular frames at the step dt_s: a whole number of
    steps nearest frame_dt_s, at most `MAX_STEPS_PER_CALL` (an observer's `every_steps`
    and the run's end add frames between them)."""
    return min(_frame_steps(frame_dt_s, dt_s), MAX_STEPS_PER_CALL) * dt_s


def _stop_batches(nstep: int, periods, extra, size: int):
    """The step indices where frames are taken, in increasing batches of at most
    `size`: every multiple of each of `periods` (steps) up to `nstep`, and `extra`
    (nstep among them), a batch spanning at most `MAX_STEPS_PER_CALL` steps. Made a
    batch at a time: memory independent of nstep."""
    extra = np.array(sorted({int(e) for e in extra if 0 < e <= nstep}), np.int64)
    step = min(periods)
    done = 0
    while done < nstep:
        hi = min(nstep, done + min(size * step, MAX_STEPS_PER_CALL))
        parts = [np.arange((done // p + 1) * p, hi + 1, p, dtype=np.int64) for p in periods]
        parts.append(extra[(extra > done) & (extra <= hi)])
        batch = np.unique(np.concatenate(parts))[:size]
        yield batch
        done = int(batch[-1])


def _count_stops(nstep: int, periods, extra) -> int:
    """How many stops `_stop_batches` makes (exactly for one period, at most otherwise)."""
    extra = {int(e) for e in extra if 0 < e <= nstep}
    return sum(nstep // p for p in periods) + sum(1 for e in extra if all(e % p for p in periods))


def run(
    sim: Simulation,
    duration_s: float,
    *,
    frame_dt_s: float = FRAME_DT_S,
    progress: bool = False,
    observers=(),
    trace_spill=None,
    stop=None,
    provenance: dict | None = None,
    loads=None,
) -> dict:
    """Run `sim` for `duration_s`; returns `{"summary": dict, "trace": Trace}`, the
    summary one level down: `run(sim, 4.0)["summary"]["apex_descent_mm"]`
    (docs/metrics.md defines every key of both).

    `observers`: called at each frame after the trace has its values (e.g.
    `hybrid.record.Recorder`); they must not change the state. An observer with a
    `frames(sim, frames, trace)` method takes the frames a compiled call captured
    (`hybrid.loop.Frames`, `frames.count` of them, the trace's last rows);
    otherwise it is called as `obs(sim, trace)` at each frame, the simulation then
    stepped frame by frame. An observer with an `every_steps` attribute gets a
    frame at every multiple of that many steps, besides those `frame_dt_s` apart.
    `trace_spill`: a binary file to stream the trace to (`Trace`), so that the
    run's memory does not grow with its length; by default the trace is held in
    memory (8 bytes a series a frame). `stop`: a function of no argument, asked after each
    compiled call; when it returns true the run stops there as on Ctrl-C (a signal
    handler can set it without breaking a call in the middle). `provenance`: the
    summary's "provenance" table (`hybrid.provenance.run_provenance`; by default
    made here, without the command line's overrides and removed terms). `loads`: True
    to give the membrane's loads on the skeleton (`hybrid.loads`; `hybrid run` does) in
    the summary's "loads" for a scene with linked bodies or nailed regions, the run then
    stepping frame by frame; None (the default) only when an observer has its own
    (a `Recorder(..., loads=True)`: the same figures fill both); False never; or a
    `hybrid.loads.LoadsObserver` to fill.

    The summary (docs/outputs.md): scene, status, steps, times; the
    top-level metrics of earlier versions; "metrics", {series: {"min", "max",
    "t_min_s", "t_max_s"}} for each series of the parts the scene has; and
    "provenance". On a HybridError the summary holds "status": "failed" and "error", and the
    error is re-raised as `RunFailed` carrying the partial result; on a
    KeyboardInterrupt, "status": "interrupted", re-raised as `RunInterrupted`.
    """
    observers = _check_run_args(sim, frame_dt_s, observers)
    model = sim.model
    h = model.dt_s
    nstep = run_steps(duration_s, h, name="duration_s")
    frame_steps = _frame_steps(frame_dt_s, h)
    periods = sorted(
        {min(frame_steps, MAX_STEPS_PER_CALL)}
        | {int(o.every_steps) for o in observers if getattr(o, "every_steps", None)}
    )
    metrics = TraceMetrics(model, sim.control.arrays)  # the inputs that ran, where the user's program set them
    breath = metrics.breath

    # the end of the last complete expiration, where the body should be back at rest
    cycle_end_step = None
    if breath is not None:
        ncycle = math.floor((duration_s - breath.onset_s) / breath.period_s + 1e-9)
        if ncycle >= 1:
            cycle_end_step = int(round((breath.onset_s + ncycle * breath.period_s) / h))
    extra = [nstep] + ([cycle_end_step] if cycle_end_step else [])
    trace = Trace(1 + _count_stops(nstep, periods, extra), spill=trace_spill)
    trace.about.update(metrics.about())
    rest_return_mm = None
    error = interrupted = None
    batch_observers = [o for o in observers if hasattr(o, "frames")]
    per_frame = [o for o in observers if not hasattr(o, "frames")]
    loads = _loads_observer(sim, loads, observers)
    if loads is not None:  # read from the state after each frame's step: frame by frame
        per_frame.insert(0, loads)
    batched = sim.can_step_frames and not per_frame
    per_call = max(1, min(FRAMES_PER_CALL, int(2e6 // (24 * model.nvert))))  # frames of at most ~2 MB
    frames = sim.frames_buffer(per_call if batched else 1)

    def take(frames):
        """The trace's rows of the frames captured, then the observers."""
        k = frames.count
        metrics.fill(trace.reserve(k), frames)
        trace.commit(k)
        for obs in batch_observers:
            obs.frames(sim, frames, trace)
        for obs in per_frame:
            obs(sim, trace)

    def capture_now():
        """The current state as one frame (the start, and frame-by-frame runs)."""
        frames.count = 1
        capture_frame(model.arrays, sim.state, frames.pos[0], frames.scal[0])
        if frames.body_pos.shape[1]:
            d = sim.mj_data
            frames.body_pos[0] = d.xpos[1:]
            frames.body_quat[0] = d.xquat[1:]
        take(frames)

    # the start, which also loads (or compiles, on a first run) the step outside the timed
    # run: batched, by the frames' own kernel (a stop at the current step steps nothing),
    # so that a first run compiles that one loop only
    if batched:
        sim.step_frames(np.array([sim.steps_done], np.int64), frames)
        take(frames)
    else:
        sim.step(0)
        capture_now()
    wall0 = time.perf_counter()
    bar = _Progress(nstep) if progress else None
    try:
        for batch in _stop_batches(nstep, periods, extra, per_call if batched else 1):
            try:
                if batched:
                    sim.step_frames(batch, frames)
                else:
                    sim.step(int(batch[0]) - sim.steps_done)
            finally:
                if batched and frames.count:
                    take(frames)
            if not batched:
                capture_now()
            if cycle_end_step is not None and batch[0] <= cycle_end_step <= batch[-1]:
                j = int(np.searchsorted(batch, cycle_end_step))
                at = frames.pos[j] if batched else sim.state.vert_pos
                rest_return_mm = metrics.rest_distance_mm(at)
            if bar:
                bar.update(int(batch[-1]))
            if stop is not None and stop() and int(batch[-1]) < nstep:  # after the last step: done
                raise KeyboardInterrupt
    except HybridError as exc:
        error = exc
    except KeyboardInterrupt as exc:  # Ctrl-C, or a signal the command line turns into one
        interrupted = exc
    finally:
        if bar:
            bar.close()
    wall = time.perf_counter() - wall0
    summary = run_summary(
        sim,
        trace,
        wall_s=wall,
        rest_return_mm=rest_return_mm,
        loads=loads,
        error=error,
        interrupted=interrupted,
        steps_requested=nstep,
        provenance=provenance,
    )
    result = {"summary": summary, "trace": trace}
    if error is not None:
        raise RunFailed(error, result) from error
    if interrupted is not None:
        raise RunInterrupted(result) from interrupted
    return result


def _check_run_args(sim, frame_dt_s, observers) -> tuple:
    """`run`'s arguments that its loop takes on trust: a Simulation, a frame interval
    that is a finite time > 0 s, observers as a list (not a string, not one observer)."""
    if not isinstance(sim, Simulation):
        hint = "; hybrid.load(name) makes one" if isinstance(sim, str) else ""
        raise ArgumentError(f"sim: expected a hybrid.Simulation{hint}, received {type(sim).__name__} {sim!r:.80}")
    ok = isinstance(frame_dt_s, (int, float, np.integer, np.floating)) and not isinstance(frame_dt_s, bool)
    if not (ok and math.isfinite(frame_dt_s) and frame_dt_s > 0):
        raise ArgumentError(f"frame_dt_s: expected a finite time > 0 s, received {frame_dt_s!r}")
    if isinstance(observers, (str, bytes)) or callable(observers) or hasattr(observers, "frames"):
        raise ArgumentError(f"observers: expected a list of observers, received {type(observers).__name__}")
    try:
        return tuple(observers)
    except TypeError:
        raise ArgumentError(f"observers: expected a list of observers, received {type(observers).__name__}") from None


def _loads_observer(sim: Simulation, loads, observers):
    """The run's loads observer (`run`'s `loads`; a recorder's own, so that both read
    the same figures), or None."""
    if isinstance(loads, LoadsObserver):
        return loads
    if loads is False:
        return None
    for obs in observers:
        if isinstance(getattr(obs, "loads", None), LoadsObserver):
            return obs.loads
    if loads is None:
        return None
    found = Loads(sim)
    return LoadsObserver(found) if found else None


class RunFailed(HybridError):
    """A run stopped on an error; `.result` holds what was recorded before it."""

    def __init__(self, error: Exception, result: dict):
        super().__init__(str(error))
        self.error = error
        self.result = result


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C (or a signal taken as one); `.result` holds what was
    recorded before it, its summary's "status" "interrupted"."""

    __reduce__ = reduce_exception

    def __init__(self, result: dict):
        super().__init__(f"interrupted at t = {result['summary']['duration_s']:.6g} s")
        self.result = result


class _Progress:
    """The run's progress on stderr: a one-line bar redrawn on a terminal; in a Jupyter
    kernel (its stderr is no terminal, yet shown under the cell) a display updated in
    place at most twice a second with IPython, else a plain line each tenth of the run;
    elsewhere (a pipe, a log file) nothing."""

    def __init__(self, total: int):
        self.total = max(total, 1)
        self.t0 = self.shown_t = time.perf_counter()
        self.tty = sys.stderr.isatty()
        self.notebook = not self.tty and "ipykernel" in sys.modules
        self.handle = None
        self.tenths = -1  # the last tenth written as a plain line
        if self.notebook:
            try:
                from IPython.display import Pretty, display

                self.pretty, self.handle = Pretty, display(Pretty(self._text(0)), display_id=True)
            except ImportError:  # a kernel without IPython's display: plain lines
                pass

    def _text(self, done: int) -> str:
        frac = done / self.total
        n = int(30 * min(frac, 1.0))
        return f"[{'#' * n}{'.' * (30 - n)}] {100 * frac:5.1f}%  {time.perf_counter() - self.t0:6.1f} s"

    def update(self, done: int) -> None:
        if self.tty:
            sys.stderr.write(f"\r{self._text(done)}")
            sys.stderr.flush()
        elif self.handle is not None:
            now = time.perf_counter()
            if now - self.shown_t >= 0.5 or done >= self.total:  # a modest rate: the kernel sends each update
                self.handle.update(self.pretty(self._text(done)))
                self.shown_t = now
        elif self.notebook and 10 * done // self.total > self.tenths:
            self.tenths = 10 * done // self.total
            sys.stderr.write(self._text(done) + "\n")
            sys.stderr.flush()

    def close(self) -> None:
        if self.tty:
            sys.stderr.write("\n")
