"""`hybrid bench`: the speed of the full step, medians of repeated runs.

The machine this runs on may be shared and noisy: every figure is the median
of several repeats, and comparisons are ratios taken in the same run.
"""

from __future__ import annotations

import json
import statistics
import time
from pathlib import Path

from .demo import bench_membrane
from .model import compile_scene
from .simulation import Simulation

__all__ = ["bench_membrane_rows", "run_bench", "format_table"]

# mesh (None = the paper's 80-point sphere, else icosphere subdivisions)
MEMBRANE_MESHES = (None, 3, 4, 5, 6)


def _median_us_per_step(sim: Simulation, nstep: int, repeats: int) -> float:
    sim.step(max(1, nstep // 10))  # warm-up: compiled code loaded, caches filled
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sim.step(nstep)
        times.append((time.perf_counter() - t0) / nstep)
    return statistics.median(times) * 1e6


def bench_membrane_rows(meshes=MEMBRANE_MESHES, *, repeats: int = 7, work: float = 4e6) -> list[dict]:
    """Full membrane step (shape memory, damping, gravity, exact volume) per mesh size.

    Each repeat runs about `work` vertex-steps; the step is a quarter of
    the model's stability bound so the run stays smooth.
    """
    rows = []
    for sub in meshes:
        model = compile_scene(bench_membrane(sub))
        model = model.with_dt(0.25 * model.dt_stable_s)
        sim = Simulation(model)
        nstep = max(20, int(work / model.nvert))
        us = _median_us_per_step(sim, nstep, repeats)
        rows.append({"nvert": model.nvert, "us_per_step": us, "ns_per_vertex_step": us * 1e3 / model.nvert})
    return rows


def run_bench(json_path: Path | None = None, *, quick: bool = False) -> dict:
    """All benchmark sections; writes them to json_path if given."""
    result: dict = {}
    meshes = (None, 3) if quick else MEMBRANE_MESHES
    result["membrane"] = bench_membrane_rows(meshes, repeats=3 if quick else 7,
                                             work=2e5 if quick else 4e6)
    from . import bench_rigid  # imports mujoco: the coupled and flex sections
    result.update(bench_rigid.run(quick=quick))
    if json_path is not None:
        Path(json_path).write_text(json.dumps(result, indent=2) + "\n")
    return result


def format_table(result: dict) -> str:
    lines = ["membrane step (shape memory, damping, gravity, exact volume); medians",
             f"{'nvert':>8} {'us/step':>10} {'ns/vertex-step':>15}"]
    for row in result.get("membrane", []):
        lines.append(f"{row['nvert']:>8} {row['us_per_step']:>10.2f} {row['ns_per_vertex_step']:>15.1f}")
    if "coupled" in result:
        c = result["coupled"]
        lines += ["", "coupled breathing step vs bare mj_step of the trunk model; medians",
                  f"  coupled {c['us_per_step']:.2f} us   mj_step {c['mj_step_us']:.2f} us   ratio {c['ratio']:.2f}"]
    if "recording" in result:
        r = result["recording"]
        lines += ["", f"breathing run of {r['duration_s']:g} s, frames every 10 ms: without and with the MCAP recording; medians",
                  f"  run {r['run_s']:.3f} s   recorded {r['recorded_s']:.3f} s (ratio {r['ratio']:.3f})   "
                  f"encoded between steps {r['inline_s']:.3f} s (ratio {r['inline_ratio']:.3f})"]
    if "flex" in result:
        lines += ["", "MuJoCo's 2D flex sphere on a plane under gravity, 1 s, beside our membrane",
                  f"{'nvert':>8} {'flex us/step':>13} {'flex dV/V0':>11} {'ours dV/V0':>11}"]
        for row in result["flex"]:
            lines.append(f"{row['nvert']:>8} {row['us_per_step']:>13.1f} {row['volume_change']:>11.3g} "
                         f"{row['ours_volume_change']:>11.2g}")
    return "\n".join(lines)
