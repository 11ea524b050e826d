"""Error against run time in space and time: a scene's metrics on a grid of mesh
levels x time steps, their limits, and the cheapest run for a target accuracy.

`run(out_dir, scene=...)` writes `convergence.json`, `convergence.md` and
`convergence.png`.

Grid       mesh levels K (`mesh.level`: about 80 x 2^K points of a generator, the
           spacing divided by sqrt(2) a level; on a mesh read from a file, its faces
           split into four K times, the spacing halved a level, the new points on the
           sphere or the smooth closed surface the file's points sample,
           `hybrid.mesh.refine`) x time steps dt0(K) / 2^j, j = 0..NSTEP-1, where
           dt0(K) is the scene's own step at that level (`dt_s = "auto"`: half
           the stable-step estimate, rounded down; a numeric dt_s is kept where
           it is below that; with `--integrator implicit_euler`, its own step:
           "auto" is 4 times symplectic Euler's, at most 10 ms). Each run is
           independent (`hybrid.sweep`: the local cores or a Dask cluster) and
           simulates `duration_s` (default 4 s, one breath of the packaged scenes).
Metrics    each the largest value of a trace series over the run (`hybrid.run`,
           docs/metrics.md), or its smallest as `NAME:min` (a pressure that falls:
           `pleural_pressure_cmh2o:min`, the end-inspiratory pleural pressure of a
           breath): by default those of the rib lift, apex descent, peak
           pressure and the diaphragm's swept volume that the scene has (all four on
           the breathing trunk, on any mesh).
Time       at each level, Richardson extrapolation of the three steps (two when
           NSTEP = 2: first order, the order of both integrators) gives the
           level's value at dt -> 0 and the observed order in time.
Space      the levels' dt -> 0 values fitted by limit + C h^p over the five
           finest levels (h = r^-K, r the spacing ratio, `fit_space`): the limit, the observed
           order in space p, and the limit's own error estimate (the larger of the
           fit's rms residual and how far the limit moves when the coarsest level is
           left out, `_limit_error`; none, "-", from exactly three levels whose order
           they fit: two levels cannot fit an order too). Errors are relative to the
           limit.
Work       each run's cost: the process's CPU time of the run (after a warm-up
           that compiles) per simulated second, which other programs on the machine
           do not inflate as they do its wall time; a run under REPEAT_BELOW_S of CPU
           is run REPEATS times, the least kept (what others add to a run's CPU time,
           cache misses and migrations, only adds) and the spread (max - min) / least
           reported. The wall time of the first run is kept beside it.
Recommend  for target relative errors 10%, 3% and 1%, per metric, the run of the
           grid of least CPU time per simulated second whose error meets the
           target ("measured"); where none does, the level and step the fitted error
           models (C h^p in space, C dt^q in time, each given half the target)
           predict, with the cost scaled from the finest run as nvert x steps:
           "predicted" at a measured level (a smaller step), "extrapolated" at a
           level past the finest run, and refused ("beyond") more than
           MAX_EXTRAPOLATED_LEVELS levels past it, where the fitted model is no
           longer evidence.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..errors import HybridError
from ..integrators import is_implicit
from ..outputs import write_text as _write_text
from ..sweep import sweep
from .convergence_report import MAX_EXTRAPOLATED_LEVELS, REPEAT_BELOW_S, cost, finest_change, markdown, plot
from .stability.report import write_json

__all__ = [
    "run",
    "write",
    "simulate",
    "richardson",
    "fit_space",
    "estimate",
    "recommend",
    "DEFAULT_METRICS",
    "LUNG_METRICS",
    "SUMMARY_METRICS",
    "TARGETS",
]

#: with lungs (`hybrid.terms.lungs`): the largest lung volume above rest (the tidal volume of a run
#: from rest), the largest transdiaphragmatic pressure change (its swing), the lowest pleural
#: pressure (end inspiration's), and the largest volume each wall sweeps (the pulmonary and abdominal
#: rib cage's, with a lungs' wall on the upper ribs, and the abdomen's), whose ratios to the lung
#: volume's are the Konno-Mead shares
LUNG_METRICS = (
    "lung_volume_change_l",
    "transdiaphragmatic_pressure_change_cmh2o",
    "pleural_pressure_cmh2o:min",
    "rib_cage_pulmonary_volume_change_l",
    "rib_cage_abdominal_volume_change_l",
    "abdomen_volume_change_l",
)
#: the run summary's numbers a study takes besides the trace's series (`--metric NAME`, never by
#: default): per breath, so that each run must hold a complete inspiration
#: (`hybrid.respiratory.work_of_breathing`: the work of breathing over the litres inspired)
SUMMARY_METRICS = ("work_of_breathing_j_per_l",)
#: the metrics a study takes by default, those the scene has
DEFAULT_METRICS = ("rib_lift_mm", "apex_descent_mm", "pressure_pa", "swept_volume_ml", *LUNG_METRICS)
TARGETS = (0.10, 0.03, 0.01)
RATIO_SPACE = math.sqrt(2.0)  # the spacing ratio between a generator's mesh levels
RATIO_SPACE_FILE = 2.0  # between a file mesh's levels: each face split into four
RATIO_TIME = 2.0
#: (levels, steps per level, duration s or None for the scene's) by size
#: (the full size: levels 0-7, whose two finest change by under 2% on the breathing scene, over
#: one breath of the packaged scenes, 4 s)
SIZES = {
    False: dict(levels=(0, 1, 2, 3, 4, 5, 6, 7), nstep=3, duration_s=4.0),
    True: dict(levels=(0, 1, 2), nstep=2, duration_s=0.5),
}
#: the default levels of a mesh read from a file (full, small)
FILE_LEVELS = {False: (0, 1, 2), True: (0, 1)}
#: an observed order outside this range is not trusted for extrapolation: the
#: methods' formal order (1 in time; 1 in space for the regions' point membership) is used
ORDER_RANGE = (0.5, 4.0)
REPEATS = 5
#: the frames of the run (`hybrid.run`'s default) that the warm-up run before the timing takes two of
WARM_UP_FRAME_S = 0.01


def _model(scene, overrides, level, dt):
    from ..model import compile_scene
    from ..resolve import resolve_scene

    sets = [*overrides, f"mesh.level={level}"]
    if dt is not None:
        sets.append(f"dt_s={dt!r}")
    return compile_scene(resolve_scene(scene, overrides=sets))


def base_step(scene, overrides, level) -> tuple[float, int]:
    """(dt0, nvert) at a level: the scene's step there (see the module docstring)."""
    from ..model import auto_dt

    m = _model(scene, overrides, level, None)
    if is_implicit(m.scene.integrator):  # not bounded by stability: its own step ("auto": 4x symplectic's)
        return m.dt_s, m.nvert
    return min(m.dt_s, auto_dt(m.dt_stable_s)), m.nvert


#: a metric's statistic of its series: NAME (its largest value) or NAME:STAT
STATS = ("max", "min")


def series_of(metric: str) -> tuple[str, str]:
    """(series, statistic) of a metric: "NAME" -> (NAME, "max"), "NAME:min" -> (NAME, "min")."""
    name, _, stat = metric.partition(":")
    return name, stat or "max"


def _check_metrics(scene, overrides, level, metrics) -> tuple:
    """The metrics are series the scene reports (`hybrid.run.scene_parts`), checked on
    one step of the coarsest level, so that a wrong --metric is refused at once;
    `metrics` None: those of DEFAULT_METRICS the scene has. Returns the metrics."""
    from ..run import METRIC_KEYS
    from ..run import run as run_scene
    from ..simulation import Simulation

    unknown = [k for k in metrics or () if k not in SUMMARY_METRICS and series_of(k)[0] not in METRIC_KEYS]
    if unknown:
        raise HybridError(
            f"--metric: expected series among {list(METRIC_KEYS)} or a summary number among "
            f"{list(SUMMARY_METRICS)}, received {unknown}"
        )
    bad = [k for k in metrics or () if k not in SUMMARY_METRICS and series_of(k)[1] not in STATS]
    if bad:
        raise HybridError(f"--metric: expected NAME or NAME:min (its smallest value), received {bad}")
    model = _model(scene, overrides, level, None)
    table = run_scene(Simulation(model), model.dt_s)["summary"]["metrics"]
    if metrics is None:  # apex_descent_mm: every membrane has a highest point
        return tuple(k for k in DEFAULT_METRICS if series_of(k)[0] in table)
    missing = [k for k in metrics if _series(k) not in table]
    if missing:
        raise HybridError(
            f"--metric: scene {model.scene.name!r} has no series {missing}; expected some of {sorted(table)}"
        )
    return tuple(metrics)


def _series(metric: str) -> str:
    """The trace series a metric needs: its own, or the lung volume for a summary number."""
    return "lung_volume_change_l" if metric in SUMMARY_METRICS else series_of(metric)[0]


def simulate(scene, overrides, level, dt, duration_s, metrics, repeats=REPEATS) -> dict:
    """One run of the grid (a sweep task): {"values": {metric: its max or min}, "wall_s",
    "cpu_s" (the least over "repeats" runs), "cpu_s_spread", "nvert", "status"}."""
    from ..run import RunFailed
    from ..run import run as run_scene
    from ..simulation import Simulation

    model = _model(scene, overrides, level, dt)

    def one(duration):
        sim = Simulation(model)
        c0 = time.process_time()
        try:
            summary = run_scene(sim, duration)["summary"]
        except RunFailed as exc:
            summary = exc.result["summary"]
        return summary, time.process_time() - c0

    # a short run first compiles (or loads from the cache) every kernel a run calls, outside
    # the timing: loaded in the first timed run, they made it up to 3 times the next ones
    one(min(duration_s, 2 * WARM_UP_FRAME_S))
    summary, cpu = one(duration_s)  # the values: the same in every repeat
    cpus = [cpu]
    while summary["status"] == "ok" and cpus[0] < REPEAT_BELOW_S and len(cpus) < repeats:
        cpus.append(one(duration_s)[1])
    table = summary["metrics"]
    missing = [k for k in metrics if _series(k) not in table]
    if missing:
        raise HybridError(
            f"--metric: scene {model.scene.name!r} has no series {missing}; expected some of {sorted(table)}"
        )
    values = {k: summary.get(k) if k in SUMMARY_METRICS else table[series_of(k)[0]][series_of(k)[1]] for k in metrics}
    absent = [k for k, v in values.items() if v is None]
    if absent and summary["status"] == "ok":
        raise HybridError(
            f"--metric {absent[0]}: expected a run holding a complete inspiration, received none in "
            f"{duration_s:g} s at level {level}; give --duration of at least one breath"
        )
    return {
        "values": values,
        "wall_s": summary["wall_s"],
        "cpu_s": min(cpus),
        "cpu_s_spread": (max(cpus) - min(cpus)) / max(min(cpus), 1e-300),
        "repeats": len(cpus),
        "nvert": model.nvert,
        "status": summary["status"],
        "error": summary.get("error"),
    }


def richardson(values, ratio: float, order: float | None = None):
    """Extrapolate the sequence `values` (coarse to fine, refined by `ratio`) to the
    limit: (limit, observed order or None, order used). Three values or more: the
    order observed on the last three (used when in ORDER_RANGE, else 1); two: order 1."""
    v = np.asarray(values, float)
    observed = None
    if len(v) >= 3:
        d1, d2 = v[-2] - v[-3], v[-1] - v[-2]
        if d1 != 0 and d2 != 0 and d1 * d2 > 0:
            observed = math.log(abs(d1 / d2)) / math.log(ratio)
    p = (
        order
        if order is not None
        else (observed if observed is not None and ORDER_RANGE[0] <= observed <= ORDER_RANGE[1] else 1.0)
    )
    if len(v) < 2:
        return float(v[-1]), observed, p
    return float(v[-1] + (v[-1] - v[-2]) / (ratio**p - 1.0)), observed, p


#: the finest levels the spatial fit uses (the coarse ones are not yet asymptotic)
FIT_LEVELS = 5
#: the orders the fit tries
FIT_ORDERS = np.linspace(0.5, 4.0, 351)


def fit_space(levels, values, nfit: int = FIT_LEVELS, ratio: float = RATIO_SPACE):
    """x_K = limit + C h_K^p over the `nfit` finest levels, h_K = ratio^-K: for each p of
    FIT_ORDERS the least-squares (limit, C), the p of least residual kept. Returns (limit,
    p or None, rms residual): p is None when the best order is an end of FIT_ORDERS (no
    order fits; the limit is then that of p = 1, the formal order of borders that do not
    follow the mesh). A fit over several levels rather than Richardson's three, as the
    regions' borders that do not follow the mesh add an error that is not smooth in h."""
    lv = np.asarray(levels[-nfit:], float)
    x = np.asarray(values[-nfit:], float)
    h = ratio ** (-lv)
    fits = [(_solve_space(p, h, x), p) for p in FIT_ORDERS]
    (coef, rms), p = min(fits, key=lambda f: f[0][1])
    observed = float(p)
    if p in (FIT_ORDERS[0], FIT_ORDERS[-1]):  # no order fits: the values are not yet asymptotic
        observed, p = None, 1.0  # the formal order of the regions' borders
        coef, rms = _solve_space(p, h, x)
    return float(coef[0]), observed, rms


def _solve_space(p: float, h: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-squares (limit, C) of x = limit + C h^p, and its rms residual."""
    a = np.stack([np.ones_like(h), h**p], axis=1)
    coef, *_ = np.linalg.lstsq(a, x, rcond=None)
    return coef, float(np.sqrt(np.mean((a @ coef - x) ** 2)))


def _limit_error(levels, values, limit: float, observed, rms: float, ratio: float, nfit: int = FIT_LEVELS):
    """The error estimate of `fit_space`'s limit over the same levels: the larger of its rms
    residual and how far the limit moves when the coarsest of the fit's levels is left out
    (the least asymptotic: its limit refitted on the finer ones, the order fitted again
    where `fit_space` fitted it, else at the formal order 1). None where too few levels are
    left for that fit: exactly three levels whose order they fit (the remaining two fit a
    limit at a given order, not an order too; the three are fitted to the order grid's spacing, so the rms
    residual is no estimate either, and leaving out the finest at the fitted order moves
    nothing: it gave 0, or the FIT_ORDERS grid's spacing, for any three values)."""
    lv, x = list(levels[-nfit:]), list(values[-nfit:])
    if observed is None:  # the formal order: two levels fit its limit
        if len(lv) < 3:
            return None
        h = ratio ** (-np.asarray(lv[1:], float))
        finer = float(_solve_space(1.0, h, np.asarray(x[1:], float))[0][0])
    else:
        if len(lv) < 4:
            return None
        finer = fit_space(lv[1:], x[1:], nfit=len(lv) - 1, ratio=ratio)[0]
    return max(rms, abs(limit - finer))


def estimate(runs: list, metrics, levels, ratio: float = RATIO_SPACE) -> dict:
    """Per metric: each level's dt -> 0 value, the limit in space, the orders, the
    limit's error estimate, each level's relative error; and each run's error."""
    out = {}
    for k in metrics:
        per_level, orders_t = [], []
        for level in levels:
            rows = sorted((r for r in runs if r["level"] == level and r["status"] == "ok"), key=lambda r: -r["dt"])
            if not rows:
                continue
            x0, q_obs, _ = richardson([r["values"][k] for r in rows], RATIO_TIME)
            per_level.append((level, x0))
            if q_obs is not None:
                orders_t.append(q_obs)
        if not per_level:
            out[k] = None
            continue
        xs = [x for _, x in per_level]
        lv = [level for level, _ in per_level]
        if len(xs) >= 3:
            limit, p_obs, rms = fit_space(lv, xs, ratio=ratio)
            p = 1.0 if p_obs is None else p_obs
            err_est = _limit_error(lv, xs, limit, p_obs, rms, ratio)
        else:
            limit, p_obs, p = richardson(xs, ratio)
            err_est = None
        scale = abs(limit) if limit != 0 else 1.0
        out[k] = {
            "metric": k,
            "limit": limit,
            "limit_error_estimate": err_est,
            "observed_order_space": p_obs,
            "order_used_space": p,
            "observed_order_time": float(np.median(orders_t)) if orders_t else None,
            "levels": [lv for lv, _ in per_level],
            "value_by_level": xs,  # at dt -> 0
            "error_by_level": [abs(x - limit) / scale for x in xs],
        }
        for r in runs:
            if r["status"] == "ok":
                r.setdefault("rel_error", {})[k] = abs(r["values"][k] - limit) / scale
    return out


def recommend(runs: list, est: dict, metrics, targets=TARGETS, ratio: float = RATIO_SPACE) -> list:
    """The cheapest (level, dt) per metric and target (module docstring)."""
    rows = []
    ok = [r for r in runs if r["status"] == "ok"]
    finest = max(ok, key=lambda r: (r["nvert"], -r["dt"])) if ok else None
    for k in metrics:
        e = est.get(k)
        if e is None:
            continue
        for target in targets:
            meet = [r for r in ok if r["rel_error"][k] <= target]
            if meet:
                best = min(meet, key=cost)
                rows.append(
                    {
                        "metric": k,
                        "target_rel_error": target,
                        "level": best["level"],
                        "nvert": best["nvert"],
                        "dt": best["dt"],
                        "rel_error": best["rel_error"][k],
                        "cpu_s_per_sim_s": cost(best),
                        "predicted": False,
                        "basis": "measured",
                        "levels_past_finest": 0,
                    }
                )
            elif finest is not None:
                guess = _predict(e, runs, finest, target, ratio)
                past = guess["level"] - finest["level"]
                row = {"metric": k, "target_rel_error": target, "predicted": True, "levels_past_finest": past}
                if past > MAX_EXTRAPOLATED_LEVELS:  # refused: that far out the fitted model is no evidence
                    row.update(basis="beyond", level=None, nvert=None, dt=None, rel_error=None, cpu_s_per_sim_s=None)
                else:
                    row.update(basis="extrapolated" if past > 0 else "predicted", **guess)
                rows.append(row)
    return rows


def _predict(e: dict, runs: list, finest: dict, target: float, ratio: float = RATIO_SPACE) -> dict:
    """The level and step the error models predict for `target`, half of it to each:
    space error err_K r^(-p (K - K_last)) from the finest level's; the step the finest
    level's smallest, times the fall of the scene's own step per level between the
    two finest levels for each level added (the stable step falls with the spacing:
    by sqrt(2) on even meshes, by up to 2 on UV spheres), and smaller still where
    its time error (first order) would exceed the half."""
    levels, err = e["levels"], e["error_by_level"]
    p = e["order_used_space"]
    need = target / 2
    k_last = levels[-1]
    level = k_last if err[-1] <= need else k_last + math.ceil(math.log(err[-1] / need) / (p * math.log(ratio)))
    same = sorted((r for r in runs if r["level"] == k_last and r["status"] == "ok"), key=lambda r: r["dt"])
    scale = abs(e["limit"]) or 1.0
    # the stable step's fall per level, as the two finest levels' own steps show (at most halving)
    dt0 = {lv: max(r["dt"] for r in runs if r["level"] == lv and r["status"] == "ok") for lv in levels[-2:]}
    fall = min(max(dt0[levels[-1]] / dt0[levels[-2]], 0.5), 1.0) if len(dt0) == 2 else 0.5
    dt = same[0]["dt"] * fall ** (level - k_last)
    e_time = abs(same[0]["values"][e["metric"]] - e["value_by_level"][-1]) / scale
    if e_time > need:
        dt *= need / e_time
    nvert = round(finest["nvert"] * ratio ** (2 * (level - finest["level"])))  # points as spacing^-2
    scaled = cost(finest) * (nvert / finest["nvert"]) * (finest["dt"] / dt)
    return {"level": level, "nvert": nvert, "dt": dt, "rel_error": None, "cpu_s_per_sim_s": scaled}


def run(
    out_dir,
    *,
    scene: str = "breathing",
    metrics=None,
    small: bool = False,
    levels=None,
    nstep: int | None = None,
    duration_s: float | None = None,
    overrides=(),
    scheduler: str | None = None,
    repeats: int = REPEATS,
) -> dict:
    """The study (module docstring); returns what convergence.json holds. `metrics`: trace
    series (None: those of DEFAULT_METRICS the scene has). `repeats`: the most runs of a
    short run whose least CPU time is kept (1: its cost timed once)."""
    from ..resolve import resolve_scene

    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    size = SIZES[bool(small)]
    sc = resolve_scene(scene, overrides=list(overrides))
    from_file = bool(getattr(sc.mesh, "path", None))
    if levels is None:  # a file mesh's points grow 4 times a level
        levels = FILE_LEVELS[bool(small)] if from_file else size["levels"]
    levels = tuple(levels)
    nstep = size["nstep"] if nstep is None else int(nstep)
    if not (isinstance(repeats, int) and repeats >= 1):
        raise HybridError(f"--repeats: expected an integer >= 1, received {repeats!r}")
    if nstep < 1 or len(levels) < 2:
        raise HybridError(
            f"convergence: expected at least two mesh levels and one step per level, "
            f"received levels {list(levels)} and {nstep} step(s)"
        )
    duration = float(size["duration_s"] or sc.duration_s) if duration_s is None else float(duration_s)
    # before any run of the study
    metrics = _check_metrics(scene, overrides, levels[0], None if metrics is None else tuple(metrics))
    grid = []
    for level in levels:
        dt0, _ = base_step(scene, overrides, level)
        grid += [
            dict(
                scene=scene,
                overrides=tuple(overrides),
                level=level,
                dt=dt0 / 2**j,
                duration_s=duration,
                metrics=metrics,
                repeats=int(repeats),
            )
            for j in range(nstep)
        ]
    results = sweep(simulate, grid, scheduler=scheduler, on_error="return", out=out / "runs")
    runs, failures = [], []
    for g, r in zip(grid, results):
        if isinstance(r, Exception):
            if isinstance(r, HybridError) and "--metric" in str(r):
                raise r
            failures.append({"level": g["level"], "dt": g["dt"], "error": str(r)})
            continue
        row = {
            "level": g["level"],
            "nvert": r["nvert"],
            "dt": g["dt"],
            "values": r["values"],
            "wall_s": r["wall_s"],
            "wall_s_per_sim_s": r["wall_s"] / duration,
            "cpu_s": r["cpu_s"],
            "cpu_s_per_sim_s": r["cpu_s"] / duration,
            "cpu_s_spread": r["cpu_s_spread"],
            "repeats": r["repeats"],
            "status": r["status"],
        }
        if r["status"] != "ok":
            failures.append({"level": g["level"], "dt": g["dt"], "error": r["error"]})
        runs.append(row)
    ratio = RATIO_SPACE_FILE if from_file else RATIO_SPACE
    res = {
        "scene": sc.name,
        "overrides": list(overrides),
        "metrics": list(metrics),
        "duration_s": duration,
        "spacing_ratio": ratio,
        "levels": list(levels),
        "steps_per_level": nstep,
        "runs": runs,
        "failures": failures,
        "runtime_s": time.perf_counter() - t0,
    }
    return write(out, res)


def write(out, res: dict) -> dict:
    """The estimates, recommendation and outputs of a study's runs `res` (what
    convergence.json holds, its estimates recomputed): DIR/convergence.json, .md, .png."""
    out = Path(out)
    metrics, levels, runs = tuple(res["metrics"]), tuple(res["levels"]), res["runs"]
    for r in runs:
        r.pop("rel_error", None)
    ratio = res.get("spacing_ratio", RATIO_SPACE)
    est = estimate(runs, metrics, levels, ratio)
    res = {
        **res,
        "estimate": est,
        "recommendation": recommend(runs, est, metrics, ratio=ratio),
        "finest_change": finest_change(runs, metrics, levels),
    }
    write_json(out / "convergence.json", res)
    _write_text(out / "convergence.md", markdown(res))
    plot(out / "convergence.png", res)
    return res
