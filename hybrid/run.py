"""Run a scene to the end and summarise it: the summary, its metrics and the trace.

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
from .model import Model
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
from .provenance import run_provenance
from .readouts import pitch_deg, quat_rot, swept_volumes
from .respiratory import work_of_breathing
from .scene import Muscle, MuscleFibres, SoftVolume, Volume
from .schedule import Breathing, schedule_eval, stack_schedules
from .simulation import Simulation
from .step import F_ALVEOLAR, F_FLOW, F_KE, F_LUNG_VOLUME, F_PLEURAL, F_PRESSURE, F_TIME, F_VOLUME
from .terms import Lungs
from .terms.lungs import CMH2O_PA, CMH2O_PER_L, P_E, P_RECOIL, P_V0
from .terms.volume import face_volume

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


#: the trace's series, one column each (SI units unless the name says mm); a series
#: of a part the scene lacks is NaN throughout (docs/metrics.md)
TRACE_KEYS = (
    "t_s",
    "volume_m3",  # enclosed volume (closed surfaces)
    "rib_lift_mm",  # cranial (+z) displacement of the linked points' centroid (scenes with ribs)
    "apex_descent_mm",  # caudal (-z) displacement of the apex
    "volume_rel_error",  # |V - V0| / V0 under the exact volume constraint
    "pressure_pa",  # gauge pressure (scenes with a volume term)
    "muscle_n_per_m",  # the first muscle term's stiffness or fibre tension (scenes with a muscle)
    "kinetic_energy_j",
    "volume_rel_change",  # |V - V0| / V0 whatever keeps the volume (closed surfaces)
    "swept_volume_ml",  # volume the region named "diaphragm" swept inward from rest (scenes with one)
    "thorax_pitch_deg",  # the thoracic body's pitch change from its start (scenes with rigid.ribs)
    # scenes with lungs (hybrid.terms.lungs), in the respiratory physiologist's units:
    "lung_volume_change_l",  # the thoracic cavity's volume above rest
    "flow_l_per_s",  # into the lungs (inspiration positive): each step's volume change over h
    "pleural_pressure_cmh2o",  # absolute (the oesophageal pressure's model), at the last step's start
    "alveolar_pressure_cmh2o",
    "transdiaphragmatic_pressure_change_cmh2o",  # abdominal minus pleural, change from rest
)
#: the series a summary gives min, max and their times of (all but the time)
METRIC_KEYS = TRACE_KEYS[1:]
_COL = {key: i for i, key in enumerate(TRACE_KEYS)}

#: rows a streamed trace holds in memory before it writes them to its file
SPILL_ROWS = 8192


class Trace:
    """Time series recorded at each frame, one row a frame and one column per key
    of `TRACE_KEYS` (`trace.t_s`, `trace.arrays()`), in a preallocated array: no
    Python object per frame. `capacity`: the rows to expect (more still fit: the
    array then doubles). `spill`: a binary file (e.g. an unlinked temporary file)
    to stream the rows to, `SPILL_ROWS` at a time, so that memory does not grow
    with the run; `arrays()` then reads them back. The running minima and maxima
    of each series (`lowest`, `highest`) and their times (`t_lowest`, `t_highest`: the
    first frame reaching them) are kept as rows come."""

    def __init__(self, capacity: int = 1024, spill=None):
        self._spill = spill
        rows = SPILL_ROWS if spill is not None else max(int(capacity), 1)
        self._buf = np.empty((rows, len(TRACE_KEYS)))
        self._held = 0  # rows in _buf
        self._written = 0  # rows in the spill file
        self.lowest = np.full(len(TRACE_KEYS), np.inf)
        self.highest = np.full(len(TRACE_KEYS), -np.inf)
        self.t_lowest = np.full(len(TRACE_KEYS), np.nan)
        self.t_highest = np.full(len(TRACE_KEYS), np.nan)
        #: what the figure needs besides the series (`run` fills it): "muscle", the label
        #: of `muscle_n_per_m`; "lung_elastance_cmh2o_per_l" and "resting_recoil_cmh2o"
        #: (scenes with lungs), for the Campbell diagram's static recoil line
        self.about: dict = {}

    def __len__(self) -> int:
        return self._written + self._held

    def reserve(self, k: int) -> np.ndarray:
        """(k, len(TRACE_KEYS)) rows to fill; they count once `commit(k)` is called,
        so that an interrupt between the two leaves the trace as it was."""
        if self._held + k > len(self._buf):
            if self._spill is not None and self._held:
                self._spill.write(self._buf[: self._held].tobytes())
                self._written += self._held
                self._held = 0
            if self._held + k > len(self._buf):
                grown = np.empty((max(2 * len(self._buf), self._held + k), len(TRACE_KEYS)))
                grown[: self._held] = self._buf[: self._held]
                self._buf = grown
        return self._buf[self._held : self._held + k]

    def commit(self, k: int) -> None:
        rows = self._buf[self._held : self._held + k]
        if k:
            cols = np.arange(len(TRACE_KEYS))
            for pick, best, when, better in (
                (rows.argmin(axis=0), self.lowest, self.t_lowest, np.less),
                (rows.argmax(axis=0), self.highest, self.t_highest, np.greater),
            ):
                value = rows[pick, cols]
                # a series of NaN (a part the scene lacks) stays NaN
                new = better(value, best) | (np.isnan(value) & ~np.isnan(best))
                best[new] = value[new]
                when[new] = rows[pick[new], 0]
        self._held += k

    def last(self, k: int) -> np.ndarray:
        """The last k rows committed (k at most the rows of the last commit), a view."""
        return self._buf[self._held - k : self._held]

    def _table(self) -> np.ndarray:
        if self._spill is None or not self._written:
            return self._buf[: self._held]
        self._spill.seek(0)
        head = np.fromfile(self._spill, dtype=float, count=self._written * len(TRACE_KEYS))
        self._spill.seek(0, 2)
        return np.concatenate([head.reshape(-1, len(TRACE_KEYS)), self._buf[: self._held]])

    def arrays(self) -> dict:
        """Every series as a float array of len(self) values: copies."""
        table = self._table()
        return {key: table[:, i].copy() for i, key in enumerate(TRACE_KEYS)}

    def columns(self, keys, every: int = 1) -> dict:
        """The series `keys` (of `TRACE_KEYS`) as float arrays, every `every`-th row from
        the first: read from the spill file a run of rows at a time, so that only those
        columns are held (the work of breathing, the lab export, the figure's diagrams)."""
        cols = [_COL[k] for k in keys]
        every = max(int(every), 1)
        parts = []
        start = 0  # the run's row index of the next row read
        if self._spill is not None and self._written:
            self._spill.seek(0)
            left = self._written
            while left:
                count = min(left, SPILL_ROWS)
                rows = np.fromfile(self._spill, dtype=float, count=count * len(TRACE_KEYS))
                rows = rows.reshape(-1, len(TRACE_KEYS))
                parts.append(rows[(-start) % every :: every][:, cols])
                start += count
                left -= count
            self._spill.seek(0, 2)
        parts.append(self._buf[(-start) % every : self._held : every][:, cols])
        table = np.concatenate(parts) if parts else np.empty((0, len(cols)))
        return {key: table[:, i].copy() for i, key in enumerate(keys)}

    def __getattr__(self, key):
        if key in _COL:
            return self._table()[:, _COL[key]].copy()
        raise AttributeError(key)

    def envelope(self, bins: int) -> dict:
        """Each series with at most 2 `bins` points, for a plot: the lowest and the
        highest value of each of `bins` runs of rows (every row when there are
        fewer), read from the spill file a run at a time."""
        n = len(self)
        if n <= 2 * bins:
            return self.arrays()
        per = -(-n // bins)
        parts = []

        def reduce(rows):
            for lo in range(0, len(rows), per):
                run_ = rows[lo : lo + per]
                lo_i, hi_i = run_.argmin(axis=0), run_.argmax(axis=0)
                first, second = np.minimum(lo_i, hi_i), np.maximum(lo_i, hi_i)
                cols = np.arange(len(TRACE_KEYS))
                pair = np.stack([run_[first, cols], run_[second, cols]])
                pair[:, 0] = run_[[0, -1], 0]  # time: the run's first and last
                parts.append(pair)

        if self._spill is not None and self._written:
            self._spill.seek(0)
            left, carry = self._written, np.empty((0, len(TRACE_KEYS)))
            while left:
                count = min(left, 64 * per)
                rows = np.fromfile(self._spill, dtype=float, count=count * len(TRACE_KEYS))
                rows = np.concatenate([carry, rows.reshape(-1, len(TRACE_KEYS))])
                whole = len(rows) // per * per
                reduce(rows[:whole])
                carry = rows[whole:]
                left -= count
            self._spill.seek(0, 2)
            reduce(np.concatenate([carry, self._buf[: self._held]]))
        else:
            reduce(self._buf[: self._held])
        table = np.concatenate(parts)
        return {key: table[:, i] for i, key in enumerate(TRACE_KEYS)}


def scene_parts(model: Model) -> frozenset:
    """What the scene has that some metrics need: "ribs" (points linked to rigid
    bodies), "closed surface", "volume constraint" (the exact one), "pressure" (a
    volume term, exact or soft), "muscle", "diaphragm" (a region of that name) and "lungs"."""
    on = model.arrays.term_on
    parts = {
        "ribs": model.link_vert.size > 0,
        "closed surface": model.mesh.closed,
        "volume constraint": bool(on[Volume.id]),
        "pressure": bool(on[Volume.id] or on[SoftVolume.id]),
        "muscle": _breathing(model)[0] is not None,
        "diaphragm": SWEPT_REGION in model.regions,
        "lungs": bool(on[Lungs.id]),
    }
    return frozenset(name for name, has in parts.items() if has)


def metric_table(trace: Trace) -> dict:
    """{series: {"min", "max", "t_min_s", "t_max_s"}} for each series of `METRIC_KEYS`
    the scene has (a series of NaN, a part it lacks, is left out)."""
    table = {}
    for key in METRIC_KEYS:
        i = _COL[key]
        if np.isfinite(trace.highest[i]):
            table[key] = {
                "min": float(trace.lowest[i]),
                "max": float(trace.highest[i]),
                "t_min_s": float(trace.t_lowest[i]),
                "t_max_s": float(trace.t_highest[i]),
            }
    return table


def _headline(trace: Trace) -> dict:
    """The summary's top-level metrics (kept for earlier scripts; docs/metrics.md):
    only those of the parts the scene has, but `volume_rel_error_max`, null without
    the exact volume constraint."""
    table = metric_table(trace)
    head = {"volume_rel_error_max": table["volume_rel_error"]["max"] if "volume_rel_error" in table else None}
    if "volume_rel_change" in table:
        head["volume_rel_change_max"] = table["volume_rel_change"]["max"]
    if "pressure_pa" in table:
        head["pressure_min_pa"], head["pressure_max_pa"] = table["pressure_pa"]["min"], table["pressure_pa"]["max"]
    if "rib_lift_mm" in table:
        head["rib_lift_mm"] = table["rib_lift_mm"]["max"]
    head["apex_descent_mm"] = table["apex_descent_mm"]["max"]
    if "thorax_pitch_deg" in table:
        pitch = table["thorax_pitch_deg"]
        head["thorax_pitch_change_deg_max"] = max(abs(pitch["min"]), abs(pitch["max"]))
    if "lung_volume_change_l" in table:  # the swing over the run: a run of steady breaths' tidal volume
        vol = table["lung_volume_change_l"]
        head["tidal_volume_l"] = vol["max"] - vol["min"]
        pdi = table["transdiaphragmatic_pressure_change_cmh2o"]
        head["transdiaphragmatic_pressure_swing_cmh2o"] = pdi["max"] - pdi["min"]
    return head


def _work(trace: Trace, model: Model) -> dict:
    """The work of breathing's summary keys (`hybrid.respiratory.work_of_breathing`),
    from the trace's lung volume."""
    cols = trace.columns(("t_s", "lung_volume_change_l"))
    return work_of_breathing(cols["t_s"], cols["lung_volume_change_l"], model.arrays.lung_par)


def _thorax(model: Model):
    """(body index among the frames' bodies, anterior, cranial: unit vectors of the scene's
    frame) of the thoracic body the scene's ribs hang on (`rigid.ribs.body`), or None."""
    rigid = model.rigid
    ribs = getattr(rigid, "ribs", None) if rigid is not None else None
    if rigid is None or ribs is None:
        return None
    b = int(rigid.model.body(ribs.body).id)
    return b - 1, ribs.anterior, ribs.cranial


def _apex_vertex(model: Model) -> int:
    """The integrated point highest (most cranial) at rest: the diaphragm's apex."""
    z = model.mesh.vert_pos[:, 2].copy()
    z[model.arrays.vert_free == 0] = -np.inf
    return int(np.argmax(z))


def _mean_z(pos: np.ndarray, vert: np.ndarray) -> np.ndarray:
    """Mean z of the points vert in each frame of pos (nframe, nvert, 3), summed in
    vert's order (a cumulative sum adds one point after the other): the same figure
    whatever the number of frames."""
    return np.cumsum(pos[:, vert, 2], axis=1)[:, -1] / len(vert)


def muscle_label(model: Model) -> str | None:
    """What `muscle_n_per_m` is for this scene's first muscle term, with its unit (the
    figure's label), or None without a muscle."""
    for term in model.scene.forces:
        if isinstance(term, Muscle):
            return "muscle stiffness (N/m)"
        if isinstance(term, MuscleFibres):
            return "muscle fibre tension (N/m)"
    return None


def _breathing(model: Model):
    """The first muscle's schedule (a per-point muscle's stiffness, or a fibre
    tension), and its breathing waveform if it has one."""
    for term in model.scene.forces:
        if isinstance(term, (Muscle, MuscleFibres)):
            sched = term.stiffness if isinstance(term, Muscle) else term.tension_n_per_m
            return sched, (sched if isinstance(sched, Breathing) else None)
    return None, None


#: the region whose swept volume the trace gives (`swept_volume_ml`)
SWEPT_REGION = "diaphragm"


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
    apex = _apex_vertex(model)
    link = model.link_vert
    rest = model.mesh.vert_pos
    apex_z0 = rest[apex, 2]
    rib_z0 = rest[link, 2].mean() if link.size else 0.0
    parts = scene_parts(model)
    # the rest volume: the volume terms' own, else the closed surface's (nothing for an open one)
    v0 = model.arrays.vol0 or (float(face_volume(model.arrays.face_vert, rest)) if model.mesh.closed else 0.0)
    muscle_sched, breath = _breathing(model)
    # the muscle stiffness at each frame: its table stacked once, evaluated compiled
    muscle_table, muscle_fns = stack_schedules([muscle_sched]) if muscle_sched is not None else (None, [])
    muscle_val = np.zeros(3)
    swept_faces = model.mesh.face_vert[model.region_faces(SWEPT_REGION)] if "diaphragm" in parts else None
    thorax = _thorax(model)
    thorax_axis = None  # the thorax's anterior axis in its own frame, from its pose at the first frame

    def muscle_at(t):
        if muscle_table is None:
            return 0.0
        if muscle_fns:
            return float(np.atleast_1d(muscle_fns[0][1](t))[0])
        schedule_eval(muscle_table, 0, t, muscle_val)
        return float(muscle_val[0])

    # the end of the last complete expiration, where the body should be back at rest
    cycle_end_step = None
    if breath is not None:
        ncycle = math.floor((duration_s - breath.onset_s) / breath.period_s + 1e-9)
        if ncycle >= 1:
            cycle_end_step = int(round((breath.onset_s + ncycle * breath.period_s) / h))
    extra = [nstep] + ([cycle_end_step] if cycle_end_step else [])
    trace = Trace(1 + _count_stops(nstep, periods, extra), spill=trace_spill)
    trace.about["muscle"] = muscle_label(model)
    if "lungs" in parts:
        trace.about["lung_elastance_cmh2o_per_l"] = float(model.arrays.lung_par[P_E]) / CMH2O_PER_L
        trace.about["resting_recoil_cmh2o"] = float(model.arrays.lung_par[P_RECOIL]) / CMH2O_PA
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

    lung_par = model.arrays.lung_par

    def lung_rows(rows, scal):
        """The lungs' series of the frames scal, NaN without lungs."""
        keys = [k for k in TRACE_KEYS[_COL["lung_volume_change_l"] :]]
        if "lungs" not in parts:
            for key in keys:
                rows[:, _COL[key]] = np.nan
            return
        pleural = scal[:, F_PLEURAL]
        rows[:, _COL["lung_volume_change_l"]] = (scal[:, F_LUNG_VOLUME] - lung_par[P_V0]) * 1e3
        rows[:, _COL["flow_l_per_s"]] = scal[:, F_FLOW] * 1e3
        rows[:, _COL["pleural_pressure_cmh2o"]] = pleural / CMH2O_PA
        rows[:, _COL["alveolar_pressure_cmh2o"]] = scal[:, F_ALVEOLAR] / CMH2O_PA
        abdominal = scal[:, F_PRESSURE] if "pressure" in parts else 0.0
        rows[:, _COL["transdiaphragmatic_pressure_change_cmh2o"]] = (
            abdominal - (pleural + lung_par[P_RECOIL])
        ) / CMH2O_PA

    def take(frames):
        """The trace's rows of the frames captured, then the observers."""
        k = frames.count
        pos, scal = frames.pos[:k], frames.scal[:k]
        rows = trace.reserve(k)
        rows[:, _COL["t_s"]] = scal[:, F_TIME]
        rows[:, _COL["apex_descent_mm"]] = (apex_z0 - pos[:, apex, 2]) * 1e3
        rows[:, _COL["rib_lift_mm"]] = (_mean_z(pos, link) - rib_z0) * 1e3 if "ribs" in parts else np.nan
        vol = scal[:, F_VOLUME]
        closed = "closed surface" in parts
        rows[:, _COL["volume_m3"]] = vol if closed else np.nan
        rows[:, _COL["volume_rel_change"]] = np.abs(vol - v0) / v0 if closed else np.nan
        rows[:, _COL["volume_rel_error"]] = (
            rows[:, _COL["volume_rel_change"]] if "volume constraint" in parts else np.nan
        )
        rows[:, _COL["pressure_pa"]] = scal[:, F_PRESSURE] if "pressure" in parts else np.nan
        rows[:, _COL["kinetic_energy_j"]] = scal[:, F_KE]
        rows[:, _COL["swept_volume_ml"]] = (
            -swept_volumes(swept_faces, rest, pos) * 1e6 if swept_faces is not None else np.nan
        )
        if thorax is not None:
            nonlocal thorax_axis
            bq = frames.body_quat[:k, thorax[0]]
            if thorax_axis is None:
                thorax_axis = quat_rot(bq[:1])[0].T @ thorax[1]
            rows[:, _COL["thorax_pitch_deg"]] = pitch_deg(bq, thorax_axis, thorax[1], thorax[2])
        else:
            rows[:, _COL["thorax_pitch_deg"]] = np.nan
        lung_rows(rows, scal)
        if "muscle" in parts:
            for j, t in enumerate(scal[:, F_TIME].tolist()):
                rows[j, _COL["muscle_n_per_m"]] = muscle_at(t)
        else:
            rows[:, _COL["muscle_n_per_m"]] = np.nan
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
                rest_return_mm = float(np.linalg.norm(at - rest, axis=1).max() * 1e3)
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
    summary = {
        "scene": model.scene.name,
        "mesh_points": model.nvert,
        "status": "ok" if error is None and interrupted is None else "failed" if error else "interrupted",
        "steps": sim.steps_done,
        "dt": h,
        "duration_s": sim.time,
        "wall_s": wall,
        "us_per_step": wall / max(sim.steps_done, 1) * 1e6,
        **_headline(trace),
        **(_work(trace, model) if "lungs" in parts else {}),
        "rest_return_mm": rest_return_mm,
        "metrics": metric_table(trace),
    }
    if model.rigid is not None:  # what the rigid model runs with: the MJCF's own or the scene's
        summary["rigid"] = {
            **model.rigid.settings(),
            "timestep_s": h,
            "timestep_from": "mjcf" if model.scene.dt_s is None else "scene",
        }
    if loads is not None:
        summary["loads"] = loads.summary()
    if error is not None:
        summary["error"] = str(error)
    if interrupted is not None:
        summary["duration_requested_s"] = nstep * h
    summary["provenance"] = provenance if provenance is not None else run_provenance(sim)
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
