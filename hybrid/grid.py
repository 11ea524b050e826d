"""`hybrid sweep`: one scene run over a grid of `--set` values, in parallel.

`grid_cases(["forces.shape_memory.stiffness=1000,3000", "dt_s=1e-3,5e-4"])` is
the cartesian product of the comma lists, the first key slowest:
[{"forces.shape_memory.stiffness": "1000", "dt_s": "1e-3"}, ...]. `run_grid`
checks every case (scene, overrides, duration) before it runs any, then runs
them through `hybrid.sweep` (a failure is a row, not the end of the sweep) and
writes into the sweep's folder:

- `sweep.jsonl`: a row per finished run as it comes in (`hybrid.sweep`'s table):
  a sweep that is interrupted keeps its rows, and a rerun skips those "ok";
- `sweep.csv`: a row per run in grid order: the swept values, status, error,
  and the summary's metrics;
- `sweep.png`: a metric against the first swept key, a line for each
  combination of the other keys;
- `sweep.json`: the scene, the removed terms and the duration, so that a rerun
  into the folder with other ones is refused rather than mixed.
"""

from __future__ import annotations

import csv
import functools
import itertools
import json
import math
from collections.abc import Sequence
from pathlib import Path

from .errors import HybridError
from .model import compile_scene
from .outputs import FolderLock, read_own, replaced, write_text
from .resolve import resolve_scene
from .run import out_folder, run, run_steps
from .simulation import Simulation
from .sweep import local_workers, sweep

__all__ = ["split_values", "grid_cases", "run_case", "run_grid", "PLOT_METRICS"]

#: the metric plotted by default: the first of these a run reports
PLOT_METRICS = ("apex_descent_mm", "rib_lift_mm", "pressure_max_pa", "volume_rel_error_max")


def split_values(item: str) -> tuple[str, list[str]]:
    """ "KEY=V1,V2,..." as (KEY, [V1, V2, ...]); commas inside brackets or quotes
    belong to their value (a vector such as [0, 0, -9.81])."""
    if not isinstance(item, str) or "=" not in item:
        raise HybridError(f"--set {item!r}: expected KEY=V1,V2,..., e.g. dt_s=1e-3,5e-4")
    key, text = item.split("=", 1)
    key = key.strip()
    values, depth, quote, start = [], 0, "", 0
    for k, ch in enumerate(text + ","):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth <= 0:
            values.append(text[start:k].strip())
            start = k + 1
    if quote or depth:  # a value cut short: refused rather than split elsewhere or dropped
        what = (
            f"a closing {quote}"
            if quote
            else "a closing ] or }"
            if depth > 0
            else "an opening [ or { before a closing one"
        )
        raise HybridError(f"--set {item!r}: expected brackets and quotes that close; the values lack {what}")
    if not key or not all(values):
        raise HybridError(f"--set {item!r}: expected KEY=V1,V2,... with a key and no empty value")
    return key, values


def grid_cases(sets: Sequence[str]) -> list[dict]:
    """The cartesian product of the `--set` lists, one {key: value text} per run."""
    if not sets:
        raise HybridError("--set: expected at least one KEY=V1,V2,... to sweep, received none")
    keys, lists = [], []
    for item in sets:
        key, values = split_values(item)
        if key in keys:
            raise HybridError(f"--set {item!r}: key {key!r} is swept twice; give its values in one --set")
        keys.append(key)
        lists.append(values)
    return [dict(zip(keys, combo)) for combo in itertools.product(*lists)]


def run_case(source: str | None, without: tuple, duration_s: float | None, /, **values) -> dict:
    """A sweep task: the scene with `values` set, run for duration_s (None: the
    scene's); its summary. A run that fails raises `hybrid.RunFailed`."""
    scene = resolve_scene(source, overrides=[f"{k}={v}" for k, v in values.items()], without=without)
    sim = Simulation(compile_scene(scene))
    return run(sim, scene.duration_s if duration_s is None else duration_s)["summary"]


def _checked(source, cases, without, duration_s):
    """Every case's model, compiled now: bad input stops the sweep before any run."""
    models = []
    for case in cases:
        try:
            scene = resolve_scene(source, overrides=[f"{k}={v}" for k, v in case.items()], without=without)
            model = compile_scene(scene)
            run_steps(scene.duration_s if duration_s is None else duration_s, model.dt_s)
        except HybridError as exc:
            sets = " ".join(f"{k}={v}" for k, v in case.items())
            raise HybridError(f"case {sets}: {exc}") from exc
        models.append(model)
    return models


def run_grid(
    source: str | None,
    sets: Sequence[str],
    *,
    without: Sequence[str] = (),
    duration_s: float | None = None,
    out: Path,
    metric: str | None = None,
    workers: int | None = None,
) -> dict:
    """Run the grid into the folder `out`; {"rows", "failed", "csv", "plot", "metric"}."""
    if workers is not None and not (isinstance(workers, int) and workers >= 1):
        raise HybridError(f"--workers: expected an integer >= 1, received {workers!r}")
    cases = grid_cases(sets)
    without = tuple(without)
    models = _checked(source, cases, without, duration_s)
    # compiled code loaded (or compiled, once) here, before the workers start; its one step
    # tells the metrics a run reports, so that a wrong --metric is refused before the sweep
    try:
        first = run(Simulation(models[0]), models[0].dt_s)["summary"]
    except HybridError:  # a case that fails at once is a row of the table, not a refusal
        first = None
    if metric is not None and first is not None and not _number(first.get(metric)):
        names = sorted(k for k, v in first.items() if _number(v))
        raise HybridError(f"--metric {metric!r}: expected a metric the runs report, one of {names}")
    out = out_folder(Path(out))
    # as a run's: a second sweep into the folder is refused while this one writes there
    lock = FolderLock(out, what="sweep")
    try:
        return _run_locked(source, cases, models, without, duration_s, out, metric, workers)
    finally:
        lock.release()


def _run_locked(source, cases, models, without, duration_s, out: Path, metric, workers) -> dict:
    meta = {"scene": source, "without": list(without), "duration_s": duration_s, "keys": list(cases[0])}
    meta_path = out / "sweep.json"
    text = read_own(meta_path)
    if text is not None:
        try:
            before = json.loads(text)
        except ValueError:
            before = None
        if before != meta:
            raise HybridError(
                f"--out {str(out)!r}: holds a sweep of {before}, expected {meta}; "
                f"choose another folder to sweep other settings"
            )
    write_text(meta_path, json.dumps(meta, indent=2) + "\n")
    task = functools.partial(run_case, source, without, duration_s)
    results = sweep(task, cases, workers=workers or min(local_workers(), len(cases)), on_error="return", out=out)
    rows = [_row(case, r) for case, r in zip(cases, results)]
    csv_path = out / "sweep.csv"
    _write_csv(rows, list(cases[0]), csv_path)
    metric = metric or next((m for m in PLOT_METRICS if any(_number(r.get(m)) for r in rows)), None)
    if metric is None or not any(_number(r.get(metric)) for r in rows):
        names = sorted({k for r in rows for k, v in r.items() if _number(v)} - set(cases[0]))
        raise HybridError(
            f"--metric {metric!r}: expected a metric the runs report, one of {names}; the runs are in {csv_path}"
        )
    plot_path = out / "sweep.png"
    _plot(rows, list(cases[0]), metric, plot_path, title=f"{models[0].scene.name}: {metric}")
    return {
        "rows": rows,
        "failed": sum(r["status"] != "ok" for r in rows),
        "csv": csv_path,
        "plot": plot_path,
        "metric": metric,
    }


def _row(case: dict, result) -> dict:
    if isinstance(result, BaseException):
        return {**case, "status": "failed", "error": " ".join(str(result).split())}
    return {
        **case,
        "status": "ok",
        "error": "",
        **{k: v for k, v in result.items() if v is None or isinstance(v, (int, float, str))},
    }


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _write_csv(rows: list[dict], keys: list, path: Path) -> None:
    columns = list(dict.fromkeys([*keys, "status", "error", *(k for r in rows for k in r)]))
    with replaced(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, columns, restval="")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: "" if v is None else v for k, v in r.items()})


def _plot(rows: list[dict], keys: list, metric: str, path: Path, *, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first, others = keys[0], keys[1:]
    xs = list(dict.fromkeys(r[first] for r in rows))
    try:
        where = {x: float(x) for x in xs}
        numeric = True
    except ValueError:
        where, numeric = {x: i for i, x in enumerate(xs)}, False
    fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
    for combo in dict.fromkeys(tuple(r[k] for k in others) for r in rows):
        mine = [r for r in rows if tuple(r[k] for k in others) == combo]
        pts = [(where[r[first]], r.get(metric) if _number(r.get(metric)) else math.nan) for r in mine]
        label = ", ".join(f"{k}={v}" for k, v in zip(others, combo)) or None
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=label)
    if not numeric:
        ax.set_xticks(range(len(xs)), xs)
    ax.set_xlabel(first)
    ax.set_ylabel(metric)
    ax.set_title(title)
    if others:
        ax.legend(fontsize="small")
    try:
        with replaced(path, "wb") as f:
            fig.savefig(f, dpi=120, format="png")
    finally:
        plt.close(fig)
