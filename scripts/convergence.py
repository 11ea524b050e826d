"""Convergence of a chosen metric in the time step and in the mesh: the apex descent of
the membrane-only breathing demo at a fixed time.

    python scripts/convergence.py [--scene membrane_demo] [--metric apex_descent_mm] [--at 1.6] [--out DIR] [--quick]

Time step: h halving from 2 ms; the error of each against the smallest h and the
observed order, log2(e(h) / e(h/2)). Mesh: the UV sphere refined (segments x rings),
each at h = 0.5 ms. Under formulation = "paper" the stiffnesses act on points, so the
metric is not expected to converge with the mesh: the table shows how far it moves.
Writes convergence.csv / convergence.md and convergence.png.
"""

from __future__ import annotations

import math

import hybrid

from _common import parse, pyplot, write_table


def metric_at(scene, overrides, metric: str, at_s: float) -> tuple[float, int]:
    """The trace's `metric` at the last frame of a run of `at_s`, and the points."""
    sim = hybrid.load(scene, overrides=overrides)
    trace = hybrid.run(sim, at_s)["trace"].arrays()
    return float(trace[metric][-1]), sim.model.nvert


def main(argv=None) -> int:
    args = parse(__doc__, argv, "convergence", lambda p: (
        p.add_argument("--scene", default="membrane_demo"),
        p.add_argument("--metric", default="apex_descent_mm", help="a trace key (docs/metrics.md)"),
        p.add_argument("--at", type=float, default=1.6, help="when to read it (s); default the peak inspiration")))
    at = 0.1 if args.quick else args.at
    steps = [2e-3, 1e-3, 5e-4] if args.quick else [2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4]
    meshes = [(13, 7), (19, 10)] if args.quick else [(13, 7), (19, 10), (25, 13), (37, 19)]
    rows = []
    by_h = [metric_at(args.scene, [f"dt_s={h}"], args.metric, at)[0] for h in steps]
    for k, h in enumerate(steps):
        err = abs(by_h[k] - by_h[-1])
        prev = abs(by_h[k - 1] - by_h[-1]) if k else float("nan")
        rows.append({"study": "time step", "dt_s": h, "nvert": "", args.metric: by_h[k], "error_vs_finest": err,
                     "observed_order": math.log2(prev / err) if k and err > 0 and k < len(steps) - 1 else float("nan")})
    by_mesh = []
    for seg, ring in meshes:
        value, n = metric_at(args.scene, ["dt_s=5e-4", f"mesh.segments={seg}", f"mesh.rings={ring}"], args.metric, at)
        by_mesh.append((n, value))
        rows.append({"study": "mesh", "dt_s": 5e-4, "nvert": n, args.metric: value,
                     "error_vs_finest": float("nan"), "observed_order": float("nan")})
    write_table(rows, args.out, "convergence")

    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    errs = [(h, abs(v - by_h[-1])) for h, v in zip(steps[:-1], by_h[:-1])]
    a.loglog([h for h, _ in errs], [e for _, e in errs], "o-", label="|m(h) - m(h_min)|")
    if errs and errs[0][1] > 0:
        a.loglog([h for h, _ in errs], [errs[0][1] * h / errs[0][0] for h, _ in errs], "k--", label="first order")
    a.xaxis.set_minor_formatter(plt.NullFormatter())
    a.set_xlabel("time step h (s)")
    a.set_ylabel(f"error of {args.metric}")
    a.legend()
    a.grid(alpha=0.3, which="both")
    b.plot([n for n, _ in by_mesh], [v for _, v in by_mesh], "s-")
    b.set_xlabel("mesh points")
    b.set_ylabel(f"{args.metric} at t = {at:g} s")
    b.grid(alpha=0.3)
    fig.suptitle(f"{args.scene}: {args.metric} at t = {at:g} s")
    fig.tight_layout()
    fig.savefig(args.out / "convergence.png", dpi=100)
    plt.close(fig)
    print(f"-> {args.out}/convergence.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
