"""A sweep on a Dask cluster: `hybrid.sweep(..., scheduler=ADDRESS)` over the time step of
the membrane-only demo, reading the apex descent and the step's cost.

    python scripts/dask_sweep.py [--scheduler tcp://HOST:PORT] [--out DIR] [--quick]

With --scheduler the runs go to that cluster (its workers must import hybrid); without
it a local cluster is started for the sweep (worker processes; --quick: threads in this
process). Needs the extra: pip install -e ".[dask]"; without it the script says so and
exits with status 2. Writes dask_sweep.csv / dask_sweep.md and dask_sweep.png.
"""

from __future__ import annotations

import importlib.util
import sys

from _common import parse, pyplot, write_table

import hybrid


def one_case(dt_s: float, duration_s: float) -> dict:
    """One run of the sweep, on a worker."""
    result = hybrid.run(hybrid.load("membrane_demo", overrides=[f"dt_s={dt_s}"]), duration_s)
    trace = result["trace"].arrays()
    return {"apex_descent_mm": float(trace["apex_descent_mm"][-1]), "us_per_step": result["summary"]["us_per_step"]}


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "dask_sweep",
        lambda p: (
            p.add_argument("--scheduler", default=None, help="an existing cluster's address (default: a local one)"),
            p.add_argument("--duration", type=float, default=1.6, help="simulated time (s)"),
        ),
    )
    if importlib.util.find_spec("distributed") is None:
        sys.stderr.write('dask_sweep: needs dask.distributed: pip install -e ".[dask]"\n')
        return 2
    from dask.distributed import LocalCluster

    steps = [2e-3, 1e-3] if args.quick else [4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4]
    duration = 0.1 if args.quick else args.duration
    params = [{"dt_s": h, "duration_s": duration} for h in steps]
    cluster = None
    address = args.scheduler
    if address is None:
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=not args.quick, dashboard_address=None)
        address = cluster.scheduler_address
    try:
        results = hybrid.sweep(one_case, params, scheduler=address, on_error="return")
    finally:
        if cluster is not None:
            cluster.close()
    nan = float("nan")
    rows = [
        {
            "dt_s": h,
            **({"apex_descent_mm": nan, "us_per_step": nan} if isinstance(r, Exception) else r),
            "error": f"{type(r).__name__}: {r}" if isinstance(r, Exception) else "",
        }
        for h, r in zip(steps, results)
    ]
    write_table(rows, args.out, "dask_sweep")

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.semilogx(steps, [r["apex_descent_mm"] for r in rows], "o-")
    ax.set_xlabel("time step (s)")
    ax.set_ylabel(f"apex descent at t = {duration:g} s (mm)")
    ax.set_title(f"membrane_demo on a Dask cluster ({address})", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out / "dask_sweep.png", dpi=100)
    plt.close(fig)
    print(f"-> {args.out}/dask_sweep.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
