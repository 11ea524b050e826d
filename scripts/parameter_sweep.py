"""A parameter sweep with hybrid.sweep: the diaphragm's peak muscle stiffness against
the apex descent and the rib lift of the breathing trunk.

    python scripts/parameter_sweep.py [--peaks 25,50,75,100,125] [--workers N] [--out DIR] [--quick]

Each case is `hybrid run breathing_paper --set forces.muscle.stiffness.breathing.peak=P`, run
in its own process (all local cores by default); a case that fails is a row with its
error, the others still come back. Writes sweep.csv / sweep.md and sweep.png.
"""

from __future__ import annotations

from _common import parse, pyplot, write_table

import hybrid

KEY = "forces.muscle.stiffness.breathing.peak"


def one_case(peak: float, duration_s: float, scene: str) -> dict:
    """One run of the sweep (top level: the workers import it by name)."""
    trace = hybrid.run(hybrid.load(scene, overrides=[f"{KEY}={peak}"]), duration_s)["trace"].arrays()
    return {
        "apex_descent_max_mm": float(trace["apex_descent_mm"].max()),
        "rib_lift_max_mm": float(trace["rib_lift_mm"].max()),
        "pressure_max_pa": float(trace["pressure_pa"].max()),
    }


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "parameter_sweep",
        lambda p: (
            p.add_argument("--scene", default="breathing_paper"),
            p.add_argument(
                "--peaks", default="25,50,75,100,125", help="peak muscle stiffnesses (N/m), comma-separated"
            ),
            p.add_argument("--duration", type=float, default=2.0, help="simulated time (s), past the peak inspiration"),
            p.add_argument("--workers", type=int, default=None, help="local processes (default: every core)"),
        ),
    )
    peaks = [40.0, 80.0] if args.quick else [float(x) for x in args.peaks.split(",")]
    duration = 0.3 if args.quick else args.duration
    workers = 1 if args.quick else args.workers  # --quick: in this process, no process start-up
    params = [{"peak": p, "duration_s": duration, "scene": args.scene} for p in peaks]
    results = hybrid.sweep(one_case, params, workers=workers, on_error="return")
    rows = []
    for p, r in zip(peaks, results):
        failed = isinstance(r, Exception)
        nan = float("nan")
        rows.append(
            {
                "peak_n_per_m": p,
                **({k: nan for k in ("apex_descent_max_mm", "rib_lift_max_mm", "pressure_max_pa")} if failed else r),
                "error": f"{type(r).__name__}: {r}" if failed else "",
            }
        )
    write_table(rows, args.out, "sweep")

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(peaks, [r["apex_descent_max_mm"] for r in rows], "o-", label="apex descent")
    ax.plot(peaks, [r["rib_lift_max_mm"] for r in rows], "s-", label="rib lift")
    ax.set_xlabel("peak muscle stiffness (N/m)")
    ax.set_ylabel(f"largest value over {duration:g} s (mm)")
    ax.set_title(f"{args.scene}: {KEY}")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out / "sweep.png", dpi=100)
    plt.close(fig)
    print(f"-> {args.out}/sweep.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
