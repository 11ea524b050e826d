"""The breathing trunk and its ablations: without the volume constraint, and without
each muscle or fibre term in turn (the paper's scene by default; `--scene breathing` for the continuum one).

    python scripts/breathing_ablations.py [--scene breathing_paper] [--duration 4] [--out DIR] [--quick]

Writes ablations.csv / ablations.md (per case: the rib lift's range, the largest apex descent,
the pressure range and the largest relative change of the volume, from the trace) and ablations.png
(rib lift and apex descent over time, one line per case). The paper's argument: the
ribs rise because the contracting diaphragm pushes on the incompressible abdomen:
without the volume constraint they go down instead.
"""

from __future__ import annotations

from _common import parse, pyplot, write_table

import hybrid


def cases(scene: hybrid.Scene) -> list[tuple[str, tuple]]:
    """(label, terms removed): the full scene, without volume, without each muscle or fibre term."""
    out = [("full scene", ())]
    if any(isinstance(c, hybrid.Volume) for c in scene.constraints):
        out.append(("without volume", ("volume",)))
    out += [
        (f"without {t.name}", (t.name,))
        for t in scene.forces
        if isinstance(t, (hybrid.Muscle, hybrid.MuscleFibres, hybrid.PassiveFibres))
    ]
    return out


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "breathing_ablations",
        lambda p: (
            p.add_argument(
                "--scene", default="breathing_paper", help="a scene name or TOML file (default breathing_paper)"
            ),
            p.add_argument("--duration", type=float, default=4.0, help="simulated time (s), default one breath"),
        ),
    )
    duration = 0.5 if args.quick else args.duration
    scene = hybrid.load_scene(args.scene)
    rows, traces = [], {}
    for label, drop in cases(scene):
        trace = hybrid.run(hybrid.load(scene, without=drop), duration)["trace"].arrays()
        traces[label] = trace
        rows.append(
            {
                "case": label,
                "removed": " ".join(drop) or "-",
                # min and max: without the volume constraint the ribs go down, not up
                "rib_lift_min_mm": float(trace["rib_lift_mm"].min()),
                "rib_lift_max_mm": float(trace["rib_lift_mm"].max()),
                "apex_descent_max_mm": float(trace["apex_descent_mm"].max()),
                "pressure_min_pa": float(trace["pressure_pa"].min()),
                "pressure_max_pa": float(trace["pressure_pa"].max()),
                # the volume's change from the first frame, measured: meaningful with and without the constraint
                "volume_rel_change_max": float(abs(trace["volume_m3"] / trace["volume_m3"][0] - 1).max()),
            }
        )
    write_table(rows, args.out, "ablations")

    plt = pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for label, trace in traces.items():
        axes[0].plot(trace["t_s"], trace["rib_lift_mm"], label=label)
        axes[1].plot(trace["t_s"], trace["apex_descent_mm"], label=label)
    axes[0].set_ylabel("rib lift (mm, cranial)")
    axes[1].set_ylabel("apex descent (mm, caudal)")
    axes[1].set_xlabel("time (s)")
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{scene.name}: ablations over {duration:g} s")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out / "ablations.png", dpi=100)
    plt.close(fig)
    print(f"-> {args.out}/ablations.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
