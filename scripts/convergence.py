"""Convergence of a chosen metric in the time step and in the mesh, on a breathing dome
of the continuum formulation (whose parameters mean the same on every mesh).

    python scripts/convergence.py [--metric apex_descent_mm] [--at 1.6] [--out DIR] [--quick]

The scene (built here): an incompressible sphere of radius 0.12 m and 4 kg, an elastic
membrane (2D Young's modulus 1000 N/m), muscle fibres in its top cap converging on the
apex with a breathing tension (peak 100 N/m), a drag near critical, a nailed patch at
the bottom. Mesh: icospheres of 42 to 2562 points, each at half its stable step (or
1 ms). Time step: h halving from 1 ms on the 162-point mesh; the change of the metric
from h to h/2, d(h), and the observed order log2(d(h) / d(h/2)) (first order: 1). The metric is read at the
last frame of a run of --at seconds (a trace key, docs/metrics.md). Writes
convergence.csv / convergence.md and convergence.png.
"""

from __future__ import annotations

import dataclasses
import math

from _common import parse, pyplot, write_table

import hybrid

RADIUS_M, MASS_KG, YOUNGS_N_PER_M = 0.12, 4.0, 1000.0


def dome(subdivisions: int) -> hybrid.Scene:
    drag = 2.0 * math.sqrt(YOUNGS_N_PER_M * MASS_KG / (4 * math.pi * RADIUS_M**2)) / RADIUS_M  # about critical
    return hybrid.Scene(
        name="continuum_dome",
        formulation="continuum",
        mesh=hybrid.MeshSpec("icosphere", radius_m=RADIUS_M, subdivisions=subdivisions),
        masses=hybrid.Masses(total_kg=MASS_KG),
        regions={"cap": hybrid.HalfSpace((0, 0, 0.05), (0, 0, 1)), "base": hybrid.Patch((0, 0, -RADIUS_M), 0.05)},
        forces=(
            hybrid.Membrane(YOUNGS_N_PER_M, poisson_ratio=0.3),
            hybrid.MuscleFibres("cap", hybrid.Breathing(4.0, 0.4, 100.0), toward_m=(0, 0, RADIUS_M)),
            hybrid.Damping(drag_n_s_per_m3=drag),
        ),
        constraints=(hybrid.Nailed("base"), hybrid.Volume()),
    )


def metric_at(scene: hybrid.Scene, dt_s, metric: str, at_s: float) -> tuple[float, int, float]:
    """(the trace's `metric` at the last frame of a run of at_s, points, step used);
    dt_s None: half the stable step, at most 1 ms."""
    if dt_s is None:
        dt_s = min(1e-3, 0.5 * hybrid.compile_scene(scene).dt_stable_s)
    sim = hybrid.load(dataclasses.replace(scene, dt_s=dt_s))
    trace = hybrid.run(sim, at_s)["trace"].arrays()
    return float(trace[metric][-1]), sim.model.nvert, dt_s


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "convergence",
        lambda p: (
            p.add_argument("--metric", default="apex_descent_mm", help="a trace key (docs/metrics.md)"),
            p.add_argument("--at", type=float, default=1.6, help="when to read it (s); default the peak inspiration"),
        ),
    )
    at = 0.1 if args.quick else args.at
    steps = [1e-3, 5e-4, 2.5e-4] if args.quick else [1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5]
    levels = [1, 2] if args.quick else [1, 2, 3, 4]
    rows = []
    by_h = [metric_at(dome(2), h, args.metric, at)[0] for h in steps]
    change = [abs(a - b) for a, b in zip(by_h, by_h[1:])] + [float("nan")]  # d(h) = |m(h) - m(h/2)|
    for k, h in enumerate(steps):
        order = math.log2(change[k - 1] / change[k]) if k and change[k] > 0 else float("nan")
        rows.append(
            {
                "study": "time step",
                "nvert": 162,
                "dt_s": h,
                args.metric: by_h[k],
                "change_to_next": change[k],
                "observed_order": order,
            }
        )
    by_mesh = [metric_at(dome(level), None, args.metric, at) for level in levels]
    for k, (value, n, h) in enumerate(by_mesh):
        rows.append(
            {
                "study": "mesh",
                "nvert": n,
                "dt_s": h,
                args.metric: value,
                "change_to_next": abs(value - by_mesh[k + 1][0]) if k + 1 < len(by_mesh) else float("nan"),
                "observed_order": float("nan"),
            }
        )
    write_table(rows, args.out, "convergence")

    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    errs = list(zip(steps[:-1], change[:-1]))
    a.loglog([h for h, _ in errs], [e for _, e in errs], "o-", label="|m(h) - m(h/2)|")
    if errs and errs[0][1] > 0:
        a.loglog([h for h, _ in errs], [errs[0][1] * h / errs[0][0] for h, _ in errs], "k--", label="first order")
    a.xaxis.set_minor_formatter(plt.NullFormatter())
    a.set_xlabel("time step h (s), 162 points")
    a.set_ylabel(f"change of {args.metric}")
    a.legend()
    a.grid(alpha=0.3, which="both")
    b.semilogx([n for _, n, _ in by_mesh], [v for v, _, _ in by_mesh], "s-")
    b.set_xlabel("mesh points (icospheres)")
    b.set_ylabel(f"{args.metric} at t = {at:g} s")
    b.grid(alpha=0.3)
    fig.suptitle(f"continuum dome: {args.metric} at t = {at:g} s")
    fig.tight_layout()
    fig.savefig(args.out / "convergence.png", dpi=100)
    plt.close(fig)
    print(f"-> {args.out}/convergence.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
