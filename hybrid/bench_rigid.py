"""`hybrid bench` sections that need MuJoCo: the coupled breathing step against a
bare `mj_step` of the trunk model, and MuJoCo's own 2D flex sphere beside our
membrane. Imported by `hybrid.bench` only when MuJoCo is installed."""

from __future__ import annotations

import statistics
import time

from . import rigid
from .coupling import resolve_mjcf
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
        return {"coupled": coupled_row(nstep=500, repeats=3)}
    return {"coupled": coupled_row(), "flex": flex_rows()}
