"""`hybrid bench` sections that need MuJoCo: the coupled breathing step against a
bare `mj_step` of the trunk model, the cost of recording the breathing run, and
MuJoCo's own 2D flex sphere beside our membrane. Imported by `hybrid.bench` only when MuJoCo is installed."""

from __future__ import annotations

import statistics
import time

from . import rigid
from .rigid import resolve_mjcf
from .mesh import icosphere, uv_sphere
from .model import compile_scene
from .scenefile import builtin_scene, load_scene
from .simulation import Simulation

__all__ = ["run"]


def coupled_row(*, nstep: int = 4000, repeats: int = 9) -> dict:
    """The breathing scene's full coupled step against a bare mj_step of its
    MJCF. The two are timed alternately, repeat by repeat, so that the ratio
    of each repeat sees the same machine; medians of the times and of the ratios."""
    scene = load_scene(builtin_scene("breathing"))
    sim = Simulation(compile_scene(scene))
    bare = rigid.bare_stepper(resolve_mjcf(scene))
    sim.step(nstep // 4)  # warm-up: compiled code loaded
    bare(nstep // 4)
    coupled, mj, ratio = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sim.step(nstep)
        c = (time.perf_counter() - t0) / nstep * 1e6
        b = bare(nstep) * 1e6
        coupled.append(c)
        mj.append(b)
        ratio.append(c / b)
    return {"us_per_step": statistics.median(coupled), "mj_step_us": statistics.median(mj),
            "ratio": statistics.median(ratio)}


def recording_row(*, duration_s: float = 12.0, repeats: int = 9) -> dict:
    """The breathing run (`hybrid.run.run`, frames every 10 ms) without a recording,
    with the default one (`Recorder`, encoding on its own thread), and with the
    encoding done between steps (`background=False`), timed in turn repeat by repeat,
    each from `Recorder(...)` to `close()`; medians of the times and of the ratios."""
    import tempfile

    from .record import Recorder
    from .run import run as run_scene

    scene = load_scene(builtin_scene("breathing"))
    model = compile_scene(scene)
    times: dict[str, list] = {"off": [], "on": [], "inline": []}
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(repeats + 1):
            for mode in times:
                sim = Simulation(model)
                sim.step(0)  # compiled step loaded, as `run` does before its clock starts
                t0 = time.perf_counter()
                if mode == "off":
                    run_scene(sim, duration_s)
                else:
                    # a new file each time (truncating one just written costs ~1 ms here)
                    with Recorder(f"{tmp}/run_{rep}_{mode}.mcap", sim, background=mode == "on") as rec:
                        run_scene(sim, duration_s, observers=[rec])
                if rep:  # the first round warms up (compiled encoder, file cache)
                    times[mode].append(time.perf_counter() - t0)
    off = times["off"]
    return {"duration_s": duration_s, "run_s": statistics.median(off),
            "recorded_s": statistics.median(times["on"]), "inline_s": statistics.median(times["inline"]),
            "ratio": statistics.median([a / b for a, b in zip(times["on"], off)]),
            "inline_ratio": statistics.median([a / b for a, b in zip(times["inline"], off)])}


def flex_rows(*, duration_s: float = 1.0) -> list[dict]:
    """MuJoCo's closed 2D flex sphere of 80 and 642 points (4 kg, soft-tissue
    elasticity) dropped on a plane for 1 s, beside our membrane's volume change."""
    rows = []
    for mesh in (uv_sphere(0.12), icosphere(3, 0.12)):
        row = rigid.flex_sphere_run(mesh.vert_pos, mesh.face_vert, duration_s=duration_s)
        row["ours_volume_change"] = _our_volume_change(mesh.nvert, duration_s)
        rows.append(row)
    return rows


def _our_volume_change(nvert: int, duration_s: float) -> float:
    """Our incompressible membrane under the same load: relative volume change after duration_s."""
    from .demo import bench_membrane
    model = compile_scene(bench_membrane(None if nvert == 80 else 3))
    model = model.with_dt(0.25 * model.dt_stable_s)
    sim = Simulation(model)
    sim.step(int(round(duration_s / model.dt_s)))
    return (sim.volume - model.arrays.vol0) / model.arrays.vol0


def run(*, quick: bool = False) -> dict:
    if quick:
        return {"coupled": coupled_row(nstep=500, repeats=3), "recording": recording_row(duration_s=1.0, repeats=2)}
    return {"coupled": coupled_row(), "recording": recording_row(), "flex": flex_rows()}
