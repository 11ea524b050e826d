"""The convergence study's report (`hybrid.studies.convergence`): the change between the two
finest levels, the markdown table and the figure of error against run time."""

from __future__ import annotations

from pathlib import Path

from ..outputs import save_figure as _save_figure

__all__ = ["REPEAT_BELOW_S", "MAX_EXTRAPOLATED_LEVELS", "cost", "finest_change", "markdown", "plot"]


#: a run shorter than this in CPU time is repeated (the study's REPEATS runs, the least kept): a
#: scheduler's tick or a cache miss is a visible share of it
REPEAT_BELOW_S = 1.0
#: the recommendation extrapolates at most this many levels past the finest run
MAX_EXTRAPOLATED_LEVELS = 2


def cost(r: dict) -> float:
    """A run's cost per simulated second: its CPU time, or the wall time of a study
    written before CPU times were measured."""
    return r["cpu_s_per_sim_s"] if "cpu_s_per_sim_s" in r else r["wall_s_per_sim_s"]


def finest_change(runs, metrics, levels) -> dict:
    """Per metric, the relative change between the two finest levels at their smallest steps."""
    by = {}
    for lv in levels[-2:]:
        rows = [r for r in runs if r["level"] == lv and r["status"] == "ok"]
        if rows:
            by[lv] = min(rows, key=lambda r: r["dt"])
    if len(by) < 2:
        return {}
    a, b = (by[lv] for lv in levels[-2:])
    return {k: abs(b["values"][k] - a["values"][k]) / max(abs(b["values"][k]), 1e-300) for k in metrics}


def _fmt(x, spec=".4g"):
    return "-" if x is None else format(x, spec)


def markdown(res: dict) -> str:
    lines = [
        f"# Convergence of `{res['scene']}` in space and time",
        "",
        f"Mesh levels {res['levels']} x {res['steps_per_level']} time steps per level, "
        f"{res['duration_s']:g} s simulated per run; overrides {res['overrides'] or 'none'}. "
        "Errors are relative to the Richardson limit.",
        "",
        "| metric | limit | its error estimate | order in space | order in time | change between the two finest levels |",
        "|---|---|---|---|---|---|",
    ]
    for k in res["metrics"]:
        e = res["estimate"].get(k)
        if e is None:
            continue
        lines.append(
            f"| {k} | {_fmt(e['limit'])} | {_fmt(e['limit_error_estimate'], '.2g')} | "
            f"{_fmt(e['observed_order_space'], '.2f')} | {_fmt(e['observed_order_time'], '.2f')} | "
            f"{_fmt(res['finest_change'].get(k), '.2%')} |"
        )
    lines += [
        "",
        "## Runs",
        "",
        "CPU s per sim s: the run's CPU time per simulated second (the least of the repeats "
        f"of a run under {REPEAT_BELOW_S:g} s; spread (max - min) / least); wall s per sim s: the first "
        "run's stepping, which other programs on the machine slow.",
        "",
        "| level | points | dt (s) | " + " | ".join(res["metrics"]) + " | CPU s per sim s | repeats, spread "
        "| wall s per sim s |",
        "|---|---|---|" + "---|" * len(res["metrics"]) + "---|---|---|",
    ]
    for r in res["runs"]:
        spread = f"{r['repeats']}, {r['cpu_s_spread']:.0%}" if "repeats" in r else "-"
        lines.append(
            f"| {r['level']} | {r['nvert']} | {r['dt']:.3g} | "
            + " | ".join(_fmt(r["values"][k]) for k in res["metrics"])
            + f" | {_fmt(r.get('cpu_s_per_sim_s'), '.3g')} | {spread} | {_fmt(r.get('wall_s_per_sim_s'), '.3g')} |"
        )
    finest = max((r["level"] for r in res["runs"] if r["status"] == "ok"), default=None)
    lines += [
        "",
        "## Recommendation",
        "",
        f"Measured: a run of the grid. Predicted: the error models' step at a measured level. Extrapolated: "
        f"a level past the finest run (level {finest}), its cost scaled from that run as points x steps; "
        f"at most {MAX_EXTRAPOLATED_LEVELS} levels past it, beyond which the study does not guess.",
        "",
        "| metric | target | level | points | dt (s) | error | CPU s per sim s | |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in res["recommendation"]:
        if r.get("basis") == "beyond":
            lines.append(
                f"| {r['metric']} | {r['target_rel_error']:.0%} | > {finest + MAX_EXTRAPOLATED_LEVELS} | - | - | - | "
                f"- | beyond: the fitted model asks {r['levels_past_finest']} levels past the finest run; "
                "run the study to finer levels |"
            )
            continue
        basis = r.get("basis", "predicted" if r["predicted"] else "measured")
        if basis == "extrapolated":
            basis += f", {r['levels_past_finest']} level{'s' * (r['levels_past_finest'] > 1)} past the finest run"
        lines.append(
            f"| {r['metric']} | {r['target_rel_error']:.0%} | {r['level']} | {r['nvert']} | {r['dt']:.3g} | "
            f"{_fmt(r['rel_error'], '.2%')} | {cost(r):.3g} | {basis} |"
        )
    if res["failures"]:
        lines += ["", "## Failed runs", ""] + [
            f"- level {f['level']}, dt {f['dt']:.3g} s: {f['error']}" for f in res["failures"]
        ]
    return "\n".join(lines) + "\n"


def plot(path: Path, res: dict) -> None:
    """Error against CPU time per simulated second, a panel per metric: the runs of the
    grid (filled: measured), and the recommendation's rows that are not runs (hollow:
    predicted or extrapolated, at their target error and scaled cost)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ok = [r for r in res["runs"] if r["status"] == "ok" and "rel_error" in r]
    ms = [k for k in res["metrics"] if res["estimate"].get(k)] or [None]
    ncol = min(len(ms), 2)
    nrow = (len(ms) + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.6 * ncol, 4.2 * nrow), squeeze=False)
    for ax in axes.flat[len(ms) :]:
        ax.set_visible(False)
    for ax, k in zip(axes.flat, ms):
        if k is None:
            continue
        for lv in res["levels"]:  # one curve per level, across time steps
            rows = sorted((r for r in ok if r["level"] == lv), key=lambda r: -r["dt"])
            if rows:
                ax.loglog(
                    [cost(r) for r in rows], [max(r["rel_error"][k], 1e-16) for r in rows], "o-", label=f"level {lv}"
                )
        for j in range(res["steps_per_level"]):  # one per time step index, across levels
            rows = []
            for lv in res["levels"]:
                same = sorted((r for r in ok if r["level"] == lv), key=lambda r: -r["dt"])
                if len(same) > j:
                    rows.append(same[j])
            if len(rows) > 1:
                ax.loglog(
                    [cost(r) for r in rows],
                    [max(r["rel_error"][k], 1e-16) for r in rows],
                    "k--",
                    lw=0.8,
                    alpha=0.5,
                    label="dt0/2^j, across levels" if j == 0 else None,
                )
        guessed = [
            r for r in res["recommendation"] if r["metric"] == k and r["predicted"] and r.get("basis") != "beyond"
        ]
        if guessed:
            ax.loglog(
                [cost(r) for r in guessed],
                [r["target_rel_error"] for r in guessed],
                "o",
                mfc="none",
                mec="k",
                ms=8,
                label="extrapolated: a target's predicted run",
            )
            for r in guessed:
                ax.annotate(
                    f"level {r['level']}",
                    (cost(r), r["target_rel_error"]),
                    fontsize=7,
                    xytext=(-6, 6),
                    ha="right",
                    textcoords="offset points",
                )
        ax.set_title(k)
        ax.set_xlabel("CPU s per simulated s (filled: measured)")
        ax.set_ylabel("relative error")
        # 1, 2, 5 a decade in plain numbers, the minor ticks unlabelled: their labels overlapped
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    _save_figure(fig, path, dpi=110)
    plt.close(fig)
