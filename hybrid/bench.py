"""`hybrid bench`: the speed of the full step, medians of repeated runs.

Its sections: the membrane step per mesh size (`bench_membrane`, the scene it
times); the coupled breathing step against a bare `mj_step` of the trunk model;
the cost of recording the breathing run; MuJoCo's own 2D flex sphere beside our
membrane. The MuJoCo calls (`rigid.BareStepper`, `rigid.FlexSphere`)
live in `hybrid.rigid`; this module only times them.

The machine this runs on may be shared and noisy: every figure is the median
of several repeats, and comparisons are ratios taken in the same run.
"""

from __future__ import annotations

import dataclasses
import json
import math
import statistics
import tempfile
import time
from pathlib import Path

from . import rigid
from .demo import RADIUS_M
from .implicit import Info
from .mesh import icosphere, uv_sphere
from .model import compile_scene
from .record import Recorder
from .regions import HalfSpace
from .resolve import resolve_scene
from .run import run as run_scene
from .scene import Damping, Gravity, Masses, Membrane, MeshSpec, Nailed, Scene, ShapeMemory, Volume
from .scenefile import apply_overrides, builtin_scene, load_scene
from .simulation import Simulation

__all__ = [
    "bench_membrane",
    "bench_membrane_rows",
    "bench_continuum",
    "formulation_rows",
    "implicit_rows",
    "realtime_row",
    "coupled_row",
    "recording_row",
    "flex_rows",
    "run_bench",
    "format_table",
]

# mesh (None = the paper's 80-point sphere, else icosphere subdivisions)
MEMBRANE_MESHES = (None, 3, 4, 5, 6)


def bench_membrane(subdivisions: int | None, dt_s: float = 1e-4) -> Scene:
    """The benchmark's full membrane step: shape memory, damping, gravity and
    the exact volume, on the paper's sphere (subdivisions=None) or an
    icosphere; a nailed cap keeps it from falling."""
    mesh = (
        MeshSpec(generator="uv_sphere", radius_m=RADIUS_M)
        if subdivisions is None
        else MeshSpec(generator="icosphere", subdivisions=subdivisions, radius_m=RADIUS_M)
    )
    return Scene(
        formulation="paper",
        name="bench_membrane",
        mesh=mesh,
        masses=Masses(total_kg=4.0),
        regions={"pelvis": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0))},
        forces=(Gravity(), ShapeMemory(300.0), Damping(critical_fraction=0.3)),
        constraints=(Nailed("pelvis"), Volume()),
        dt_s=dt_s,
    )


def bench_continuum(subdivisions: int | None, dt_s: float = 1e-4) -> Scene:
    """`bench_membrane` in the continuum formulation: the membrane (2D Young's
    modulus 300 N/m, Poisson 0.3), a drag per area, gravity and the exact volume."""
    return Scene(
        name="bench_continuum",
        mesh=bench_membrane(subdivisions).mesh,
        masses=Masses(total_kg=4.0),
        regions={"pelvis": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0))},
        forces=(Gravity(), Membrane(300.0), Damping(drag_n_s_per_m3=500.0)),
        constraints=(Nailed("pelvis"), Volume()),
        dt_s=dt_s,
    )


def formulation_rows(meshes=(None, 5), *, repeats: int = 7, work: float = 4e6) -> list[dict]:
    """The full step of both formulations on one mesh (the paper's 80 points, the
    10242-point icosphere), timed alternately repeat by repeat at one step (a quarter
    of the paper model's bound); medians of the times and of the per-repeat ratios."""
    rows = []
    for sub in meshes:
        paper = compile_scene(bench_membrane(sub))
        h = 0.25 * paper.dt_stable_s
        sims = {"paper": Simulation(paper.with_dt(h)), "continuum": Simulation(compile_scene(bench_continuum(sub, h)))}
        nstep = max(20, int(work / paper.nvert))
        for sim in sims.values():
            sim.step(max(1, nstep // 10))  # warm-up
        times = {k: [] for k in sims}
        for _ in range(repeats):
            for k, sim in sims.items():
                t0 = time.perf_counter()
                sim.step(nstep)
                times[k].append((time.perf_counter() - t0) / nstep * 1e6)
        rows.append(
            {
                "nvert": paper.nvert,
                **{f"{k}_us_per_step": statistics.median(v) for k, v in times.items()},
                "continuum_over_paper": statistics.median([c / p for c, p in zip(times["continuum"], times["paper"])]),
            }
        )
    return rows


def implicit_rows(meshes=(None, 5), *, repeats: int = 7, work: float = 4e6) -> list[dict]:
    """The continuum membrane step (`bench_continuum`) with symplectic and implicit
    Euler on one mesh at one step (a quarter of the paper model's bound, as
    `formulation_rows`), timed alternately repeat by repeat; medians of the times per
    step and per vertex-step, of the per-repeat ratio, and implicit Euler's Newton and
    conjugate-gradient iterations per step."""
    rows = []
    for sub in meshes:
        paper = compile_scene(bench_membrane(sub))
        h = 0.25 * paper.dt_stable_s
        scene = bench_continuum(sub, h)
        sims = {
            integ: Simulation(compile_scene(dataclasses.replace(scene, integrator=integ)))
            for integ in ("symplectic_euler", "implicit_euler")
        }
        n = paper.nvert
        nstep = max(20, int(work / n))
        for sim in sims.values():
            sim.step(max(1, nstep // 10))  # warm-up
        info = sims["implicit_euler"].solver_work.info
        newton0, cg0, steps0 = info[Info.NEWTON_TOTAL], info[Info.CG_TOTAL], sims["implicit_euler"].steps_done
        times: dict[str, list] = {k: [] for k in sims}
        for _ in range(repeats):
            for k, sim in sims.items():
                t0 = time.perf_counter()
                sim.step(nstep)
                times[k].append((time.perf_counter() - t0) / nstep * 1e6)
        done = sims["implicit_euler"].steps_done - steps0
        ex, im = statistics.median(times["symplectic_euler"]), statistics.median(times["implicit_euler"])
        rows.append(
            {
                "nvert": n,
                "dt_s": h,
                "explicit_us_per_step": ex,
                "implicit_us_per_step": im,
                "explicit_ns_per_vertex_step": ex * 1e3 / n,
                "implicit_ns_per_vertex_step": im * 1e3 / n,
                "implicit_over_explicit": statistics.median(
                    [i / e for i, e in zip(times["implicit_euler"], times["symplectic_euler"])]
                ),
                "newton_per_step": (info[Info.NEWTON_TOTAL] - newton0) / done,
                "cg_per_step": (info[Info.CG_TOTAL] - cg0) / done,
            }
        )
    return rows


#: the realtime rows' runs (integrator, step s, overrides), chosen by measurement (CHANGELOG.md,
#: "Performance"): at mesh level 4 symplectic Euler at 1 ms (0.77 of its bound) gives the breath's
#: metrics within 0.14% of a 0.1 ms run and is faster than implicit Euler; at levels 6-7 implicit
#: Euler at 10 ms solved to 1e-3 of the forces: at level 7 the 12 s run's metrics within 0.09% of
#: symplectic Euler at 0.2 ms in 0.6 of the time symplectic Euler takes at 1/3 ms, at level 6 the
#: 4 s run's within 0.08%; at level 8 implicit Euler at 30 ms solved to 1e-2 of the forces: the
#: 12 s run's metrics within 0.4% of those at 10 ms and within 0.04% of 30 ms solved to 1e-4 (at
#: 40 ms they move by up to 0.7%); the paper's scene at its own step. Other levels: `realtime_step`
REALTIME_RUNS = {
    ("breathing", 4): ("symplectic_euler", 1e-3, ()),
    ("breathing", 6): ("implicit_euler", 1e-2, ("implicit_tol=1e-3",)),
    ("breathing", 7): ("implicit_euler", 1e-2, ("implicit_tol=1e-3",)),
    ("breathing", 8): ("implicit_euler", 3e-2, ("implicit_tol=1e-2",)),
    ("breathing_paper", None): ("symplectic_euler", 1e-3, ()),
    # with lungs: the same runs as the trunk without. Level 8 at 30 ms, tol 1e-2, one breath against the
    # lungs' convergence study's limits (0.15): rib lift +0.09%, pressure -0.9%, apex -1.6%, lung volume
    # change -1.7%, Pdi -2.2%, swept volume -3.4%: a 2-3% run, not yet a 1% one (level 7 at 10 ms: -0.9%,
    # -1.0%, -0.6%, -2.8% for lung volume, apex, Pdi, swept volume, at 1.4 CPU s per simulated s)
    ("breathing_lungs", 4): ("symplectic_euler", 1e-3, ()),
    ("breathing_lungs", 8): ("implicit_euler", 3e-2, ("implicit_tol=1e-2",)),
}
#: the fraction of the stable-step estimate `realtime_step` takes (CHANGELOG.md: keep h below 0.8 of it)
REALTIME_BOUND_FRACTION = 0.7


def realtime_step(model) -> float:
    """Symplectic Euler's step for a realtime row at a level `REALTIME_RUNS` lacks: the largest
    step that divides the 10 ms frame and is at most REALTIME_BOUND_FRACTION of the stable-step
    estimate (at level 7, 1/3 ms, 0.70 of its 0.478 ms bound: the 12 s run's metrics the same as at
    0.2 ms to 1e-5)."""
    return 0.01 / math.ceil(0.01 / (REALTIME_BOUND_FRACTION * model.dt_stable_s))


def realtime_row(
    scene: str = "breathing",
    level: int | None = 4,
    *,
    integrator: str | None = None,
    dt_s: float | None = None,
    overrides: tuple | None = None,
    duration_s: float = 12.0,
    repeats: int = 3,
) -> dict:
    """`duration_s` of a packaged scene (`hybrid.run.run`, frames every 10 ms, no
    recording) at mesh `level` (None: the scene's own mesh) with `integrator` at `dt_s`
    with `overrides` ("KEY=VALUE"); each not given is `REALTIME_RUNS`'s (the overrides only
    with its integrator), else symplectic Euler at `realtime_step`. The median wall time of
    `repeats` runs, each from a new simulation whose compiled step is loaded.
    realtime_factor = sim_s / wall_s."""
    sc = resolve_scene(scene)  # a packaged scene file, or one written in Python (breathing_lungs)
    if level is not None:
        sc = apply_overrides(sc, [f"mesh.level={level}"])
    default = REALTIME_RUNS.get((scene, level))
    if default is None:
        default = ("symplectic_euler", realtime_step(compile_scene(dataclasses.replace(sc, dt_s=1e-3))), ())
    if overrides is None:
        overrides = default[2] if integrator in (None, default[0]) else ()
    integrator = default[0] if integrator is None else integrator
    dt_s = default[1] if dt_s is None else dt_s
    overrides = tuple(overrides)
    if overrides:
        sc = apply_overrides(sc, list(overrides))
    model = compile_scene(dataclasses.replace(sc, integrator=integrator, dt_s=dt_s))
    walls = []
    for _ in range(repeats):
        sim = Simulation(model)
        sim.step(0)
        t0 = time.perf_counter()
        run_scene(sim, duration_s)
        walls.append(time.perf_counter() - t0)
    wall = statistics.median(walls)
    return {
        "scene": scene,
        "level": level,
        "nvert": model.nvert,
        "integrator": integrator,
        "dt": dt_s,
        "overrides": list(overrides),
        "wall_s": wall,
        "sim_s": duration_s,
        "realtime_factor": duration_s / wall,
    }


def bench_membrane_rows(meshes=MEMBRANE_MESHES, *, repeats: int = 7, work: float = 4e6) -> list[dict]:
    """Full membrane step (shape memory, damping, gravity, exact volume) per mesh
    size, with the serial build, the parallel build and the default (`build="auto"`:
    the simulation times both as it runs and runs the faster, `hybrid.builds`).

    The three are timed in turn, repeat by repeat (the order rotating), each repeat
    about `work` vertex-steps; the step is a quarter of the model's stability bound
    so the run stays smooth. Medians of the times, and of the per-repeat ratio of
    the default to the faster of the two builds.
    """
    rows = []
    for sub in meshes:
        model = compile_scene(bench_membrane(sub))
        model = model.with_dt(0.25 * model.dt_stable_s)
        sims = {build: Simulation(model, build=build) for build in ("serial", "parallel", "auto")}
        nstep = max(20, int(work / model.nvert))
        for sim in sims.values():  # warm-up: compiled code loaded, caches filled, the default's first probe
            sim.step(max(1, nstep // 10))
        times: dict[str, list] = {build: [] for build in sims}
        for rep in range(repeats):
            order = list(sims)[rep % 3 :] + list(sims)[: rep % 3]
            for build in order:
                t0 = time.perf_counter()
                sims[build].step(nstep)
                times[build].append((time.perf_counter() - t0) / nstep * 1e6)
        med = {build: statistics.median(t) for build, t in times.items()}
        chosen = sims["auto"].builds.summary()
        rows.append(
            {
                "nvert": model.nvert,
                "us_per_step": med["auto"],
                "ns_per_vertex_step": med["auto"] * 1e3 / model.nvert,
                "serial_us_per_step": med["serial"],
                "parallel_us_per_step": med["parallel"],
                "parallel_to_serial": statistics.median([p / s for p, s in zip(times["parallel"], times["serial"])]),
                "default_to_faster": statistics.median(
                    [a / min(s, p) for a, s, p in zip(times["auto"], times["serial"], times["parallel"])]
                ),
                "default_build": "parallel" if chosen["parallel_now"] else "serial",
                "default_parallel_steps": chosen["parallel_steps"],
                "default_serial_steps": chosen["serial_steps"],
                "threads": chosen["threads"],
            }
        )
    return rows


def coupled_row(*, nstep: int = 4000, repeats: int = 9) -> dict:
    """The breathing scene's full coupled step against a bare mj_step of its
    MJCF. The two are timed alternately, repeat by repeat, so that the ratio
    of each repeat sees the same machine; medians of the times and of the ratios."""
    scene = load_scene(builtin_scene("breathing_paper"))
    sim = Simulation(compile_scene(scene))
    stepper = rigid.BareStepper(rigid.resolve_mjcf(scene))

    def bare(n):  # s per bare mj_step from the reset state
        stepper.reset()
        t0 = time.perf_counter()
        stepper.step(n)
        return (time.perf_counter() - t0) / n

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
    return {
        "us_per_step": statistics.median(coupled),
        "mj_step_us": statistics.median(mj),
        "ratio": statistics.median(ratio),
    }


def lungs_row(level: int = 4, *, duration_s: float = 4.0, repeats: int = 5) -> dict:
    """The breathing trunk with lungs (`breathing_lungs`) against the same trunk without
    (`breathing`), mesh `level`, symplectic Euler at 1 ms, `duration_s` each (`hybrid.run.run`),
    timed in turn repeat by repeat after a warm-up; medians of the times and of the ratios.
    Both on the serial build: the default's probe (`hybrid.builds.BuildChoice`) may choose the
    parallel build for one and not the other, and the ratio then measures the choice (it moved
    between 1.28 and 1.36 from run to run), not the lungs' cost."""
    models = {
        name: compile_scene(apply_overrides(resolve_scene(name), [f"mesh.level={level}", "dt_s=0.001"]))
        for name in ("breathing", "breathing_lungs")
    }
    times: dict[str, list] = {name: [] for name in models}
    for rep in range(repeats + 1):
        for name, model in models.items():
            sim = Simulation(model, build="serial")
            sim.step(0)
            t0 = time.perf_counter()
            run_scene(sim, duration_s)
            if rep:  # the first round loads the compiled loops
                times[name].append(time.perf_counter() - t0)
    base, lungs = times["breathing"], times["breathing_lungs"]
    return {
        "level": level,
        "nvert": models["breathing"].nvert,
        "duration_s": duration_s,
        "without_s": statistics.median(base),
        "with_s": statistics.median(lungs),
        "ratio": statistics.median([a / b for a, b in zip(lungs, base)]),
    }


def recording_row(*, duration_s: float = 12.0, repeats: int = 9) -> dict:
    """The breathing run (`hybrid.run.run`, frames every 10 ms) without a recording,
    with the default one (`Recorder`, encoding on its own thread), and with the
    encoding done between steps (`background=False`), timed in turn repeat by repeat,
    each from `Recorder(...)` to `close()`; medians of the times and of the ratios."""
    scene = load_scene(builtin_scene("breathing_paper"))
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
    return {
        "duration_s": duration_s,
        "run_s": statistics.median(off),
        "recorded_s": statistics.median(times["on"]),
        "inline_s": statistics.median(times["inline"]),
        "ratio": statistics.median([a / b for a, b in zip(times["on"], off)]),
        "inline_ratio": statistics.median([a / b for a, b in zip(times["inline"], off)]),
    }


def flex_rows(*, duration_s: float = 1.0) -> list[dict]:
    """MuJoCo's closed 2D flex sphere of 80 and 642 points (4 kg, soft-tissue
    elasticity) dropped on a plane for 1 s, beside our membrane's volume change."""
    rows = []
    for mesh in (uv_sphere(RADIUS_M), icosphere(3, RADIUS_M)):
        row = flex_sphere_row(mesh, duration_s)
        row["ours_volume_change"] = _our_volume_change(mesh.nvert, duration_s)
        rows.append(row)
    return rows


def flex_sphere_row(mesh, duration_s: float) -> dict:
    """MuJoCo's flex sphere on `mesh` for duration_s: {"nvert", "us_per_step", "volume_change"}."""
    flex = rigid.FlexSphere(mesh.vert_pos, mesh.face_vert)
    nstep = int(round(duration_s / flex.timestep_s))
    t0 = time.perf_counter()
    flex.step(nstep)
    wall = time.perf_counter() - t0
    return {"nvert": flex.nvert, "us_per_step": wall / nstep * 1e6, "volume_change": flex.volume_change()}


def _our_volume_change(nvert: int, duration_s: float) -> float:
    """Our incompressible membrane under the same load: relative volume change after duration_s."""
    model = compile_scene(bench_membrane(None if nvert == 80 else 3))
    model = model.with_dt(0.25 * model.dt_stable_s)
    sim = Simulation(model)
    sim.step(int(round(duration_s / model.dt_s)))
    return (sim.volume - model.arrays.vol0) / model.arrays.vol0


#: the benchmark's sections, in the order they run (`run_bench(only=...)`)
SECTIONS = ("membrane", "formulations", "implicit", "realtime", "coupled", "lungs", "recording", "flex")


#: the mesh level `hybrid study convergence` recommends for 1% on all four of the breathing
#: scene's metrics (levels 3-9 with implicit Euler: the rib lift's 1% at level 4, the peak
#: pressure's at 3, the apex descent's at 7 and the swept volume's at 8, 0.96% from its
#: limit; CHANGELOG.md, "Error against run time"); the realtime row's by default
RECOMMENDED_LEVEL = 8


def run_bench(
    json_path: Path | None = None,
    *,
    quick: bool = False,
    realtime_level: int = RECOMMENDED_LEVEL,
    only: tuple | None = None,
) -> dict:
    """The benchmark's sections (`only` a subset of SECTIONS; all by default), the
    breathing scene's realtime rows at mesh `realtime_level` and at its default level 4;
    writes them to json_path if given."""
    bad = sorted(set(only or ()) - set(SECTIONS))
    if bad:
        raise ValueError(f"only: expected sections among {list(SECTIONS)}, received {bad}")
    want = set(only or SECTIONS)
    result: dict = {}
    meshes = (None, 3) if quick else MEMBRANE_MESHES
    if "membrane" in want:
        result["membrane"] = bench_membrane_rows(meshes, repeats=3 if quick else 7, work=2e5 if quick else 4e6)
    if "formulations" in want:
        result["formulations"] = formulation_rows(
            (None, 3) if quick else (None, 5), repeats=3 if quick else 7, work=2e5 if quick else 4e6
        )
    if "implicit" in want:  # quick: a smoke test, the 80-point step
        result["implicit"] = implicit_rows((None,), repeats=1, work=2e4) if quick else implicit_rows((None, 5))
    if "realtime" in want:  # quick: half a second of the breathing scene at level 2
        levels = sorted({realtime_level, 4}, reverse=True)
        result["realtime"] = (
            [
                realtime_row("breathing", 2, duration_s=0.5, repeats=1),
                realtime_row("breathing_paper", None, duration_s=0.5, repeats=1),
            ]
            if quick
            else [realtime_row("breathing", k, repeats=5 if k <= 5 else 3) for k in levels]
            + [realtime_row("breathing_lungs", k, repeats=5 if k <= 5 else 3) for k in levels]
            + [realtime_row("breathing_paper", None, repeats=5)]
        )
    if "coupled" in want:
        result["coupled"] = coupled_row(nstep=500, repeats=3) if quick else coupled_row()
    if "lungs" in want:
        result["lungs"] = lungs_row(0, duration_s=0.5, repeats=2) if quick else lungs_row()
    if "recording" in want:
        result["recording"] = recording_row(duration_s=1.0, repeats=2) if quick else recording_row()
    if "flex" in want and not quick:
        result["flex"] = flex_rows()
    if json_path is not None:
        from .outputs import write_text

        write_text(json_path, json.dumps(result, indent=2) + "\n")
    return result


def format_table(result: dict) -> str:
    lines = [
        "membrane step (shape memory, damping, gravity, exact volume); medians, us per step",
        f"{'nvert':>8} {'serial':>10} {'parallel':>10} {'default':>10} {'ns/vertex-step':>15} "
        f"{'par/ser':>8} {'default/faster':>15}  default runs",
    ]
    for row in result.get("membrane", []):
        lines.append(
            f"{row['nvert']:>8} {row['serial_us_per_step']:>10.2f} {row['parallel_us_per_step']:>10.2f} "
            f"{row['us_per_step']:>10.2f} {row['ns_per_vertex_step']:>15.1f} "
            f"{row['parallel_to_serial']:>8.2f} {row['default_to_faster']:>15.2f}  "
            f"{row['default_build']} ({row['threads']} threads)"
        )
    if "formulations" in result:
        lines += [
            "",
            "full step of each formulation, same mesh and step; medians, ratio of per-repeat times",
            f"{'nvert':>8} {'paper us':>10} {'continuum us':>13} {'ratio':>7}",
        ]
        for row in result["formulations"]:
            lines.append(
                f"{row['nvert']:>8} {row['paper_us_per_step']:>10.2f} "
                f"{row['continuum_us_per_step']:>13.2f} {row['continuum_over_paper']:>7.2f}"
            )
    if "implicit" in result:
        lines += [
            "",
            "continuum membrane step, symplectic vs implicit Euler at the same step; medians",
            f"{'nvert':>8} {'dt (ms)':>8} {'explicit us':>12} {'implicit us':>12} {'ns/vstep ex':>12} "
            f"{'ns/vstep im':>12} {'ratio':>7} {'newton':>7} {'cg':>6}",
        ]
        for row in result["implicit"]:
            lines.append(
                f"{row['nvert']:>8} {row['dt_s'] * 1e3:>8.3f} {row['explicit_us_per_step']:>12.2f} "
                f"{row['implicit_us_per_step']:>12.2f} {row['explicit_ns_per_vertex_step']:>12.1f} "
                f"{row['implicit_ns_per_vertex_step']:>12.1f} {row['implicit_over_explicit']:>7.2f} "
                f"{row['newton_per_step']:>7.2f} {row['cg_per_step']:>6.2f}"
            )
    if "realtime" in result:
        lines += ["", "realtime: a packaged scene's run (frames every 10 ms); median wall time"]
        for r in result["realtime"]:
            extra = f" ({', '.join(r['overrides'])})" if r.get("overrides") else ""
            lines.append(
                f"  {r['scene']} level {r['level']} ({r['nvert']} points), {r['integrator']} at "
                f"{r['dt'] * 1e3:g} ms{extra}: {r['sim_s']:g} s in {r['wall_s']:.2f} s, "
                f"realtime factor {r['realtime_factor']:.2f}"
            )
    if "coupled" in result:
        c = result["coupled"]
        lines += [
            "",
            "coupled breathing step vs bare mj_step of the trunk model; medians",
            f"  coupled {c['us_per_step']:.2f} us   mj_step {c['mj_step_us']:.2f} us   ratio {c['ratio']:.2f}",
        ]
    if "lungs" in result:
        g = result["lungs"]
        lines += [
            "",
            f"breathing trunk with and without lungs, level {g['level']} ({g['nvert']} points), "
            f"{g['duration_s']:g} s at 1 ms; medians",
            f"  without {g['without_s']:.3f} s   with {g['with_s']:.3f} s   ratio {g['ratio']:.3f}",
        ]
    if "recording" in result:
        r = result["recording"]
        lines += [
            "",
            f"breathing run of {r['duration_s']:g} s, frames every 10 ms: without and with the MCAP recording; medians",
            f"  run {r['run_s']:.3f} s   recorded {r['recorded_s']:.3f} s (ratio {r['ratio']:.3f})   "
            f"encoded between steps {r['inline_s']:.3f} s (ratio {r['inline_ratio']:.3f})",
        ]
    if "flex" in result:
        lines += [
            "",
            "MuJoCo's 2D flex sphere on a plane under gravity, 1 s, beside our membrane",
            f"{'nvert':>8} {'flex us/step':>13} {'flex dV/V0':>11} {'ours dV/V0':>11}",
        ]
        for row in result["flex"]:
            lines.append(
                f"{row['nvert']:>8} {row['us_per_step']:>13.1f} {row['volume_change']:>11.3g} "
                f"{row['ours_volume_change']:>11.2g}"
            )
    return "\n".join(lines)
