"""Error against run time: the integrators of the breathing scene and of a
membrane-only scene at time steps from the stability bound down by halves.

`run(out_dir)` writes `work_precision.json`, `work_precision.md` and
`work_precision.png` (log-log error against wall time, and error against h).

Scenes     "breathing": a coupled scene (`--scene`; by default the paper's trunk,
           `hybrid.load_scene("breathing_paper")`,
           membrane coupled to MuJoCo ribs); "membrane": `hybrid.demo.membrane_demo()`.
           Both damp at 0.3 of critical, which explicit Euler needs.
Steps      h = 1e-3 s / 2^k, k = 0..LEVELS-1: 1e-3 s is the scenes' own step,
           about half the explicit Euler bound `compile_scene(scene).dt_stable_s`
           (1.87e-3 s; symplectic Euler's is 4.6e-3 s); every h divides the
           10 ms between recorded frames exactly (`Simulation.step(10 ms / h)`).
           Implicit Euler, on a scene of the continuum formulation (`--scene
           breathing`), at h = 10 ms / 2^k: its steps are not bounded by stability.
Reference  per scene, symplectic Euler at h_ref = 1e-3 s / 2^REF_K and at h_ref/2.
           Both integrators are first order (see `observed_order`), so by
           Richardson extrapolation the finer one's error is about
           |x(h_ref) - x(h_ref/2)|: reported as `reference_error` and checked
           to be far below the smallest error of the runs (`reference_ok`).
Errors     over one breath (4 s; 0.25 s in small mode), from frames every 10 ms:
           vertex: max over frames of max over vertices of |x - x_ref| (m),
           the runs' `error`; rib angle: max over frames and joints of
           |qpos - qpos_ref| (rad: the trunk's joints are its rib hinges; breathing
           scene only); rib lift: max over frames of the difference of the linked
           points' mean height from rest (mm, the summary's rib lift; breathing
           only); apex descent: the same for the apex's descent (mm; breathing only);
           pressure: max over frames of |p - p_ref| (Pa). The errors of the
           metrics' time series, smooth in t, show the integrators' order where
           the maxima over frames (the summary's) need not. These are the
           time step's errors on one mesh: `hybrid study convergence` adds the mesh's.
Work       wall time of the stepping (after a warm-up that compiles; the least
           of 3 repeats), and per simulated second. The runs are independent: `hybrid.sweep.sweep`
           runs them on all local cores, or on a Dask cluster (`scheduler`).
Order      the least-squares slope of log(error) against log(h) over the
           three finest levels, per SCENE/INTEGRATOR, of each error.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..errors import HybridError
from ..outputs import save_figure as _save_figure
from ..outputs import write_text as _write_text
from ..sweep import sweep
from .stability.report import write_json

__all__ = ["run", "simulate", "observed_order", "SCENES", "INTEGRATORS"]

SCENES = ("breathing", "membrane")
INTEGRATORS = ("explicit_euler", "symplectic_euler")
IMPLICIT = "implicit_euler"  # run on scenes of the continuum formulation
H0 = 1e-3  # the coarsest step (s); the levels are H0 / 2^k
H0_IMPLICIT = 1e-2  # implicit Euler's coarsest step (s): one frame
FRAME_S = 0.01  # recorded frames every 10 ms of simulated time
# (levels, reference level REF_K, window s) by size
SIZES = {False: dict(levels=5, ref_k=9, window_s=4.0), True: dict(levels=4, ref_k=8, window_s=0.25)}
ORDER_LEVELS = 3  # the observed order from the finest levels


#: the coupled scene the study runs by default (`--scene`): the paper's, at its 1 ms step
DEFAULT_SCENE = "breathing_paper"


def _scene(name: str, coupled: str = DEFAULT_SCENE):
    from ..resolve import resolve_scene

    if name not in SCENES:
        raise ValueError(f"scene: expected one of {list(SCENES)}, received {name!r}")
    return resolve_scene({"breathing": coupled, "membrane": "membrane_demo"}[name])


def simulate(
    scene: str, integrator: str, k: int, window_s: float, repeats: int = 1, coupled: str = DEFAULT_SCENE, h0: float = H0
) -> dict:
    """One run at h = h0 / 2^k over `window_s`: the frames every 10 ms
    (vertex positions, rib hinge angles, rib lift, apex descent, pressure) and the wall time.
    The wall time is the least of `repeats` runs (the machine is shared: the
    least is the least disturbed). A sweep task: top level and picklable arguments."""
    from ..model import compile_scene
    from ..run import _apex_vertex
    from ..simulation import Simulation

    dt = h0 / 2**k
    model = compile_scene(_scene(scene, coupled)).with_dt(dt, integrator)
    Simulation(model).step(1)  # warm-up: compiles (or loads numba's cache) outside the timing
    sim = Simulation(model)
    nq = sim.mj_model.nq if sim.mj_model is not None else 0  # the trunk's joints: its two rib hinges
    per_frame = int(round(FRAME_S / dt))  # exactly: h0 divides FRAME_S
    nframe = int(round(window_s / FRAME_S))
    pos = np.empty((nframe, model.nvert, 3))
    ang = np.empty((nframe, nq))
    prs = np.empty(nframe)
    lift = np.full(nframe, np.nan)  # mm: the linked points' mean z from rest (the summary's rib lift)
    apex_mm = np.full(nframe, np.nan)  # mm: the apex's descent (the summary's)
    link = model.link_vert
    z0 = model.mesh.vert_pos[link, 2].mean() if link.size else 0.0
    apex = _apex_vertex(model) if scene == "breathing" else -1
    za = model.mesh.vert_pos[apex, 2] if apex >= 0 else 0.0
    walls = []
    for rep in range(max(1, int(repeats))):
        if rep:
            sim = Simulation(model)
        wall = 0.0
        for f in range(nframe):
            t0 = time.perf_counter()
            sim.step(per_frame)
            wall += time.perf_counter() - t0
            if rep == 0:  # deterministic: the frames of the first run
                pos[f] = sim.vert_pos
                prs[f] = sim.pressure
                if link.size:
                    lift[f] = (sim.vert_pos[link, 2].mean() - z0) * 1e3
                if apex >= 0:
                    apex_mm[f] = (za - sim.vert_pos[apex, 2]) * 1e3
                if nq:
                    ang[f] = sim.mj_data.qpos
        walls.append(wall)
    wall = min(walls)
    return {
        "scene": scene,
        "integrator": integrator,
        "k": k,
        "dt": dt,
        "pos": pos,
        "angle": ang,
        "lift": lift,
        "apex": apex_mm,
        "pressure": prs,
        "wall_s": wall,
        "sim_s": nframe * FRAME_S,
    }


def _errors(r: dict, ref: dict) -> dict:
    e = {
        "error": float(np.max(np.linalg.norm(r["pos"] - ref["pos"], axis=2))),
        "pressure_error": float(np.max(np.abs(r["pressure"] - ref["pressure"]))),
    }
    e["angle_error"] = float(np.max(np.abs(r["angle"] - ref["angle"]))) if r["angle"].size else None
    e["rib_lift_error_mm"] = float(np.max(np.abs(r["lift"] - ref["lift"]))) if np.isfinite(r["lift"]).all() else None
    e["apex_descent_error_mm"] = (
        float(np.max(np.abs(r["apex"] - ref["apex"]))) if np.isfinite(r["apex"]).all() else None
    )
    return e


def observed_order(dts, errors, n: int = ORDER_LEVELS) -> float:
    """Slope of log(error) against log(h), least squares over the n smallest h."""
    pairs = sorted((d, e) for d, e in zip(dts, errors) if e is not None and e > 0 and math.isfinite(e))[:n]
    if len(pairs) < 2:
        return math.nan
    x, y = np.log([p[0] for p in pairs]), np.log([p[1] for p in pairs])
    return float(np.polyfit(x, y, 1)[0])


def run(
    out_dir,
    *,
    small: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    scene: str = DEFAULT_SCENE,
) -> dict:
    """The study, its coupled runs on `scene` (a scene name or file); writes
    DIR/work_precision.json, .md and .png; returns the JSON's dict. The time step
    only: `hybrid.studies.convergence` has the mesh's half."""
    t_start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    size = SIZES[bool(small)]
    window = size["window_s"]
    ref_k = size["ref_k"]
    from ..model import compile_scene

    bounds, integrators = {}, {}
    for s in SCENES:
        model = compile_scene(_scene(s, scene))
        bounds[s] = {i: model.with_dt(H0, i).dt_stable_s for i in INTEGRATORS}
        integrators[s] = INTEGRATORS
        if model.scene.formulation == "continuum":  # implicit Euler; its h / bound is against symplectic Euler's
            integrators[s] = INTEGRATORS + (IMPLICIT,)
            bounds[s][IMPLICIT] = bounds[s]["symplectic_euler"]
    # the references first: the longest tasks start first
    tasks = [
        dict(scene=s, integrator="symplectic_euler", k=k, window_s=window, coupled=scene)
        for s in SCENES
        for k in (ref_k + 1, ref_k)
    ]
    tasks += [
        dict(
            scene=s,
            integrator=i,
            k=k,
            window_s=window,
            repeats=3,
            coupled=scene,
            h0=H0_IMPLICIT if i == IMPLICIT else H0,
        )
        for s in SCENES
        for i in integrators[s]
        for k in range(size["levels"])
    ]
    results = sweep(simulate, tasks, scheduler=scheduler, workers=workers, on_error="return")

    nref = 2 * len(SCENES)
    refs, reference, runs, failures = {}, {}, [], []
    for j, (task, r) in enumerate(zip(tasks, results)):
        if isinstance(r, Exception):
            failures.append({**task, "dt": task.get("h0", H0) / 2 ** task["k"], "message": " ".join(str(r).split())})
        elif j < nref:
            refs[(task["scene"], task["k"])] = r
        else:
            runs.append(r)
    for s in SCENES:
        fine, coarse = refs.get((s, ref_k + 1)), refs.get((s, ref_k))
        if fine is None or coarse is None:
            raise HybridError(
                f"work-precision: the reference runs of {s!r} failed: "
                + "; ".join(f["message"] for f in failures if f["scene"] == s)
            )
        est = _errors(coarse, fine)  # p = 1: the finer reference's error ~ |x(h) - x(h/2)|
        reference[s] = {
            "dt": fine["dt"],
            "dt_check": coarse["dt"],
            "wall_s": fine["wall_s"],
            "error_estimate": est["error"],
            "angle_error_estimate": est["angle_error"],
            "pressure_error_estimate": est["pressure_error"],
        }

    rows = []
    for r in runs:
        ref = refs[(r["scene"], ref_k + 1)]
        rows.append(
            {
                "scene": r["scene"],
                "integrator": r["integrator"],
                "dt": r["dt"],
                **_errors(r, ref),
                "wall_s": r["wall_s"],
                "wall_per_sim_s": r["wall_s"] / r["sim_s"],
                "dt_over_bound": r["dt"] / bounds[r["scene"]][r["integrator"]],
            }
        )
    order, order_angle, order_pressure, order_lift, order_apex = {}, {}, {}, {}, {}
    for s in SCENES:
        for i in integrators[s]:
            sel = [x for x in rows if x["scene"] == s and x["integrator"] == i]
            key = f"{s}/{i}"
            dts = [x["dt"] for x in sel]
            order[key] = observed_order(dts, [x["error"] for x in sel])
            order_pressure[key] = observed_order(dts, [x["pressure_error"] for x in sel])
            if s == "breathing":
                order_angle[key] = observed_order(dts, [x["angle_error"] for x in sel])
                order_lift[key] = observed_order(dts, [x["rib_lift_error_mm"] for x in sel])
                order_apex[key] = observed_order(dts, [x["apex_descent_error_mm"] for x in sel])
    for s in SCENES:
        smallest = min((x["error"] for x in rows if x["scene"] == s), default=math.nan)
        reference[s]["smallest_run_error"] = smallest
        # converged: the reference's own error is at most a tenth of the smallest run error
        reference[s]["converged"] = bool(reference[s]["error_estimate"] <= 0.1 * smallest)

    data = {
        "coupled_scene": scene,
        "runs": rows,
        "order": order,
        "order_angle": order_angle,
        "order_pressure": order_pressure,
        "order_rib_lift": order_lift,
        "order_apex_descent": order_apex,
        "reference": reference,
        "failures": failures,
        "stability_bound_s": bounds,
        "window_s": window,
        "frame_s": FRAME_S,
        "small": bool(small),
        "scheduler": scheduler,
        "runtime_s": time.perf_counter() - t_start,
    }
    write_json(out / "work_precision.json", data)
    _plot(out / "work_precision.png", rows)
    _write_text(out / "work_precision.md", _markdown(data))
    data["runtime_s"] = time.perf_counter() - t_start
    write_json(out / "work_precision.json", data)
    return data


def _markdown(d: dict) -> str:
    lines = [
        f"Work-precision over {d['window_s']:g} s (frames every {1e3 * d['frame_s']:g} ms): the error of "
        f'the time step on one mesh; "breathing" is the scene `{d["coupled_scene"]}`. The mesh\'s share of '
        "the error, and both together, are `hybrid study convergence`'s.",
        "",
        "| scene | integrator | h (s) | h / bound | vertex error (m) | rib lift error (mm) "
        "| apex descent error (mm) | rib angle error (rad) | pressure error (Pa) | wall (s) | wall per simulated s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]

    def opt(v, fmt=".2e"):
        return "-" if v is None else format(v, fmt)

    for r in d["runs"]:
        lines.append(
            f"| {r['scene']} | {r['integrator']} | {r['dt']:.3g} | {r['dt_over_bound']:.2f} "
            f"| {r['error']:.2e} | {opt(r['rib_lift_error_mm'])} | {opt(r['apex_descent_error_mm'])} "
            f"| {opt(r['angle_error'])} | {r['pressure_error']:.2e} | {r['wall_s']:.3f} "
            f"| {r['wall_per_sim_s']:.3f} |"
        )
    lines += [
        "",
        "Observed orders (the errors of the time series, over the three finest steps):",
        "",
        "| scene/integrator | vertex | rib angle | rib lift | apex descent | pressure |",
        "|---|---|---|---|---|---|",
    ]
    for k, p in d["order"].items():
        lines.append(
            f"| {k} | {p:.2f} | {opt(d['order_angle'].get(k), '.2f')} | {opt(d['order_rib_lift'].get(k), '.2f')} "
            f"| {opt(d['order_apex_descent'].get(k), '.2f')} | {d['order_pressure'][k]:.2f} |"
        )
    lines += [
        "",
        "| scene | reference h (s) | its estimated vertex error (m) | smallest run error (m) | converged |",
        "|---|---|---|---|---|",
    ]
    for s, r in d["reference"].items():
        lines.append(
            f"| {s} | {r['dt']:.3g} | {r['error_estimate']:.2e} | {r['smallest_run_error']:.2e} | {r['converged']} |"
        )
    if d["failures"]:
        lines += ["", "Failed runs:"] + [
            f"- {f['scene']} {f['integrator']} h={f['dt']:.3g}: {f['message']}" for f in d["failures"]
        ]
    return "\n".join(lines) + "\n"


def _plot(path: Path, rows: list) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    styles = {"breathing": "-", "membrane": "--"}
    marks = {"explicit_euler": "o", "symplectic_euler": "s", IMPLICIT: "^"}
    for s in SCENES:
        for i in INTEGRATORS + (IMPLICIT,):
            sel = sorted((x for x in rows if x["scene"] == s and x["integrator"] == i), key=lambda x: -x["dt"])
            if not sel:
                continue
            lab = f"{s} / {i.replace('_', ' ')}"
            axes[0].loglog(
                [x["wall_per_sim_s"] for x in sel], [x["error"] for x in sel], styles[s], marker=marks[i], label=lab
            )
            axes[1].loglog([x["dt"] for x in sel], [x["error"] for x in sel], styles[s], marker=marks[i], label=lab)
    dts = sorted({x["dt"] for x in rows})
    if dts:
        e0 = max(x["error"] for x in rows)
        axes[1].loglog(dts, [e0 * d / dts[-1] for d in dts], ":", color="gray", label="slope 1")
    axes[0].set_xlabel("wall time per simulated second (s)")
    axes[1].set_xlabel("time step h (s)")
    for ax in axes:
        ax.set_ylabel("largest vertex error over the window (m)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title("error against run time")
    axes[1].set_title("error against time step")
    fig.tight_layout()
    _save_figure(fig, path, dpi=110)
    plt.close(fig)
