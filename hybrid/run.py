"""Run a scene to the end and summarise it: `summary.json` and `breathing.png`.

The runner is an observer: it never changes the state. A frame is taken every
`frame_dt_s` of simulated time; up to `FRAMES_PER_CALL` of them are stepped and
captured in one compiled call (`Simulation.step_frames`: positions, volume,
pressure, kinetic energy, the bodies' poses), and the trace is computed from them
in whole arrays. With an observer that wants the simulation at each frame, or a
scene with Python schedules, it steps frame by frame instead; both ways give the
same trace to the bit. A run that fails or diverges still writes what it
recorded up to the failure, with the error in the summary.
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import HybridError
from .model import Model
from .schedule import Breathing, schedule_eval, stack_schedules
from .scene import Muscle
from .simulation import Simulation
from .step import F_KE, F_PRESSURE, F_TIME, F_VOLUME, capture_frame

__all__ = ["Trace", "run", "out_folder", "write_outputs"]


@dataclass
class Trace:
    """Time series recorded at each frame (SI units unless the name says mm)."""
    t_s: list = field(default_factory=list)
    volume_m3: list = field(default_factory=list)
    rib_lift_mm: list = field(default_factory=list)      # cranial (+z) displacement of the linked points' centroid
    apex_descent_mm: list = field(default_factory=list)  # caudal (-z) displacement of the apex
    volume_rel_error: list = field(default_factory=list)
    pressure_pa: list = field(default_factory=list)
    muscle_n_per_m: list = field(default_factory=list)
    kinetic_energy_j: list = field(default_factory=list)

    def arrays(self) -> dict:
        return {k: np.asarray(v, float) for k, v in self.__dict__.items()}


def _apex_vertex(model: Model) -> int:
    """The integrated point highest (most cranial) at rest: the diaphragm's apex."""
    z = model.mesh.vert_pos[:, 2].copy()
    z[model.arrays.vert_free == 0] = -np.inf
    return int(np.argmax(z))


def _mean_z(pos: np.ndarray, vert: np.ndarray) -> np.ndarray:
    """Mean z of the points vert in each frame of pos (nframe, nvert, 3), summed in
    vert's order: the same figure whatever the number of frames."""
    z = pos[:, vert[0], 2].copy()
    for i in vert[1:]:
        z += pos[:, i, 2]
    return z / len(vert)


def _breathing(model: Model):
    """The first muscle's schedule, and its breathing period if it has one."""
    for term in model.scene.forces:
        if isinstance(term, Muscle):
            return term.stiffness, (term.stiffness if isinstance(term.stiffness, Breathing) else None)
    return None, None


#: frames stepped in one compiled call by the runner (fewer for large meshes)
FRAMES_PER_CALL = 100


def run(sim: Simulation, duration_s: float, *, frame_dt_s: float = 0.01, progress: bool = False,
        observers=()) -> dict:
    """Run `sim` for `duration_s` and return the summary (see `summary keys`).

    `observers`: called at each frame after the trace has its values (e.g.
    `hybrid.record.Recorder`); they must not change the state. An observer with a
    `frames(sim, frames, trace)` method takes the frames a compiled call captured
    (`hybrid.step.Frames`, `frames.count` of them, the trace's last rows);
    otherwise it is called as `obs(sim, trace)` at each frame, the simulation then
    stepped frame by frame.

    Returns a dict with the summary and the trace under "trace". On a
    HybridError the summary holds "status": "failed" and "error", and the
    error is re-raised as `RunFailed` carrying the partial result.
    """
    model = sim.model
    h = model.dt_s
    nstep = int(round(duration_s / h))
    frame_steps = max(1, int(round(frame_dt_s / h)))
    apex = _apex_vertex(model)
    link = model.link_vert
    rest = model.mesh.vert_pos
    apex_z0 = rest[apex, 2]
    rib_z0 = rest[link, 2].mean() if link.size else 0.0
    v0 = model.arrays.vol0
    muscle_sched, breath = _breathing(model)
    # the muscle stiffness at each frame: its table stacked once, evaluated compiled
    muscle_table, muscle_fns = stack_schedules([muscle_sched]) if muscle_sched is not None else (None, [])
    muscle_val = np.zeros(3)

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
    stops = np.array(sorted(set(list(range(frame_steps, nstep + 1, frame_steps)) + [nstep]
                                + ([cycle_end_step] if cycle_end_step else []))), np.int64)
    trace = Trace()
    rest_return_mm = None
    error = None
    batch_observers = [o for o in observers if hasattr(o, "frames")]
    per_frame = [o for o in observers if not hasattr(o, "frames")]
    batched = sim.can_step_frames and not per_frame
    per_call = max(1, min(FRAMES_PER_CALL, int(2e6 // (24 * model.nvert))))  # frames of at most ~2 MB
    frames = sim.frames_buffer(per_call if batched else 1)
    sim.step(0)  # loads (or compiles, on a first run) the step, outside the timed run
    if batched:
        sim.step_frames(stops[:0], frames)

    def take(frames):
        """The trace's rows of the frames captured, then the observers."""
        k = frames.count
        pos, scal = frames.pos[:k], frames.scal[:k]
        trace.t_s.extend(scal[:, F_TIME].tolist())
        trace.apex_descent_mm.extend((-(pos[:, apex, 2] - apex_z0) * 1e3).tolist())
        trace.rib_lift_mm.extend(((_mean_z(pos, link) - rib_z0) * 1e3).tolist() if link.size else [0.0] * k)
        vol = scal[:, F_VOLUME]
        trace.volume_m3.extend(vol.tolist())
        trace.volume_rel_error.extend((np.abs(vol - v0) / v0 if v0 else np.zeros(k)).tolist())
        trace.pressure_pa.extend(scal[:, F_PRESSURE].tolist())
        trace.kinetic_energy_j.extend(scal[:, F_KE].tolist())
        trace.muscle_n_per_m.extend(muscle_at(t) for t in scal[:, F_TIME].tolist())
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

    capture_now()
    wall0 = time.perf_counter()
    bar = _Progress(nstep) if progress else None
    try:
        i = 0
        while i < len(stops):
            batch = stops[i:i + (per_call if batched else 1)]
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
            i += len(batch)
            if bar:
                bar.update(int(batch[-1]))
    except HybridError as exc:
        error = exc
    finally:
        if bar:
            bar.close()
    wall = time.perf_counter() - wall0
    arr = trace.arrays()
    summary = {
        "scene": model.scene.name,
        "status": "ok" if error is None else "failed",
        "steps": sim.steps_done,
        "dt": h,
        "duration_s": sim.time,
        "wall_s": wall,
        "us_per_step": wall / max(sim.steps_done, 1) * 1e6,
        "volume_rel_error_max": float(arr["volume_rel_error"].max()),
        "pressure_min_pa": float(arr["pressure_pa"].min()),
        "pressure_max_pa": float(arr["pressure_pa"].max()),
        "rib_lift_mm": float(arr["rib_lift_mm"].max()),
        "apex_descent_mm": float(arr["apex_descent_mm"].max()),
        "rest_return_mm": rest_return_mm,
    }
    if error is not None:
        summary["error"] = str(error)
    result = {"summary": summary, "trace": trace}
    if error is not None:
        raise RunFailed(error, result) from error
    return result


class RunFailed(HybridError):
    """A run stopped on an error; `.result` holds what was recorded before it."""

    def __init__(self, error: Exception, result: dict):
        super().__init__(str(error))
        self.error = error
        self.result = result


def out_folder(out: Path) -> Path:
    """The output folder `out`, created now: a folder that cannot be written fails
    before the run (a HybridError naming --out)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise HybridError(f"--out: expected a folder that can be created and written, received {str(out)!r} "
                          f"({exc.strerror or exc})") from None
    return out


def write_outputs(result: dict, out_dir: Path, *, plot: bool = True) -> None:
    """Write summary.json (and breathing.png) into out_dir."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(result["summary"], indent=2) + "\n")
    if plot:
        plot_trace(result["trace"], out_dir / "breathing.png", title=result["summary"]["scene"])


def plot_trace(trace: Trace, path: Path, *, title: str = "") -> None:
    """Five time series, one panel each: rib elevation, apex descent, volume
    error, pressure and muscle stiffness."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = trace.arrays()
    panels = [("rib_lift_mm", "rib elevation (mm)"), ("apex_descent_mm", "apex descent (mm)"),
              ("volume_rel_error", "|V - V0| / V0"), ("pressure_pa", "pressure (Pa)"),
              ("muscle_n_per_m", "muscle stiffness (N/m)")]
    # fixed margins: tight_layout took half a second of every run
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 9), sharex=True,
                             gridspec_kw=dict(left=0.13, right=0.97, top=0.95, bottom=0.06, hspace=0.12))
    for ax, (key, label) in zip(axes, panels):
        y = a[key]
        if key == "volume_rel_error":
            ax.semilogy(a["t_s"], np.maximum(y, 1e-17))
        else:
            ax.plot(a["t_s"], y)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    fig.savefig(path, dpi=100)
    plt.close(fig)


class _Progress:
    """A one-line progress bar on stderr, only on a terminal."""

    def __init__(self, total: int):
        self.total = max(total, 1)
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()

    def update(self, done: int) -> None:
        if not self.tty:
            return
        frac = done / self.total
        n = int(30 * frac)
        el = time.perf_counter() - self.t0
        sys.stderr.write(f"\r[{'#' * n}{'.' * (30 - n)}] {100 * frac:5.1f}%  {el:6.1f} s")
        sys.stderr.flush()

    def close(self) -> None:
        if self.tty:
            sys.stderr.write("\n")
