"""A controller in your own code drives the diaphragm: the dome's fibre tension set each
step through `sim.control` to hold a target volume displacement.

    python scripts/closed_loop.py [--target-ml 100] [--duration 3] [--out DIR] [--quick]

A proportional-integral controller reads the volume the dome has swept since rest (the
diaphragm's share of the tidal volume, `sim.swept_volume_m3("diaphragm")`) and sets the
muscle fibres' tension (N/m) for the next step; the scene's breathing schedule is
replaced by the controller's output (`sim.control.set`). A ventilator model, a neural
drive or a learning agent plugs in the same way. Writes closed_loop.csv / .md (the
target, the displacement reached, the tension that holds it) and closed_loop.png.
"""

from __future__ import annotations

import numpy as np
from _common import parse, pyplot, write_table

import hybrid

KEY = "forces['muscle'].tension_n_per_m"  # the dome's fibre tension in the breathing scene
KP_N_PER_M_PER_ML = 0.02  # proportional gain
KI_N_PER_M_PER_ML_S = 0.6  # integral gain: within 1% of the target after about 1 s (level 1)


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "closed_loop",
        lambda p: (
            p.add_argument("--target-ml", type=float, default=100.0, help="dome displacement to hold (mL)"),
            p.add_argument("--duration", type=float, default=3.0, help="simulated time (s)"),
        ),
    )
    level, duration = (1, 1.5) if args.quick else (4, args.duration)
    sim = hybrid.load("breathing", overrides=[f"mesh.level={level}"])
    h = sim.model.dt_s
    nstep = int(round(duration / h))
    integral_ml_s = 0.0
    rows = np.empty((nstep, 3))
    for k in range(nstep):
        displaced_ml = -1e6 * sim.swept_volume_m3("diaphragm")  # positive as the dome descends
        error_ml = args.target_ml - displaced_ml
        integral_ml_s += error_ml * h
        tension = max(0.0, KP_N_PER_M_PER_ML * error_ml + KI_N_PER_M_PER_ML_S * integral_ml_s)
        sim.control.set(KEY, tension)
        sim.step(1)
        rows[k] = (sim.time, displaced_ml, tension)
    last = rows[rows[:, 0] >= rows[-1, 0] - 0.2]  # the last 0.2 s
    write_table(
        [
            {
                "target_ml": args.target_ml,
                "displaced_ml": float(last[:, 1].mean()),
                "error_percent": float(100 * abs(last[:, 1].mean() - args.target_ml) / args.target_ml),
                "tension_n_per_m": float(last[:, 2].mean()),
                "points": sim.model.nvert,
            }
        ],
        args.out,
        "closed_loop",
    )
    plt = pyplot()
    fig, (a, b) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    a.plot(rows[:, 0], rows[:, 1], label="dome displacement")
    a.axhline(args.target_ml, ls="--", c="k", label="target")
    a.set_ylabel("volume swept by the dome (mL)")
    a.legend(fontsize=8)
    b.plot(rows[:, 0], rows[:, 2])
    b.set_ylabel("fibre tension set (N/m)")
    b.set_xlabel("time (s)")
    fig.suptitle(f"the dome's tension from a PI controller (breathing scene, {sim.model.nvert} points)")
    fig.tight_layout()
    fig.savefig(args.out / "closed_loop.png", dpi=110)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
