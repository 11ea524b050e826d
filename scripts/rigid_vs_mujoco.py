"""Validating the rigid part against MuJoCo alone: the breathing trunk's ribs, stepped by
the coupled loop, against `mujoco.mj_step` driven by the same wrenches.

    python scripts/rigid_vs_mujoco.py [--scene breathing_paper] [--steps 4000] [--out DIR] [--quick]

Each step of the coupled run applies the membrane's forces on the ribs as wrenches
(`mj_data.xfrc_applied`); recorded step by step and replayed through a fresh `MjData`
of the same model with `mujoco.mj_step`, they must give the ribs' joint angles of the
coupled run (the coupled loop calls MuJoCo's own step). Writes rigid_vs_mujoco.csv /
.md (per joint: its range and the largest difference) and rigid_vs_mujoco.png.
"""

from __future__ import annotations

import mujoco
import numpy as np
from _common import parse, pyplot, write_table

import hybrid


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "rigid_vs_mujoco",
        lambda p: (
            p.add_argument("--scene", default="breathing_paper"),
            p.add_argument("--steps", type=int, default=4000, help="steps (default one breath at 1 ms)"),
        ),
    )
    nstep = 300 if args.quick else args.steps
    sim = hybrid.load(args.scene)
    m, d = sim.mj_model, sim.mj_data
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    start = np.empty(mujoco.mj_stateSize(m, full))
    mujoco.mj_getState(m, d, start, full)
    xfrc = np.empty((nstep, m.nbody, 6))
    qpos = np.empty((nstep, m.nq))
    for k in range(nstep):  # one step at a time, to read each step's wrenches
        sim.step(1)
        xfrc[k] = d.xfrc_applied
        qpos[k] = d.qpos
    alone = mujoco.MjData(m)
    mujoco.mj_setState(m, alone, start, full)
    replay = np.empty_like(qpos)
    for k in range(nstep):
        alone.xfrc_applied[:] = xfrc[k]
        mujoco.mj_step(m, alone)
        replay[k] = alone.qpos
    diff = np.abs(qpos - replay)
    t = sim.model.dt_s * np.arange(1, nstep + 1)
    joints = [(m.joint(j).name or f"joint{j}", int(m.jnt_qposadr[j])) for j in range(m.njnt)]
    write_table(
        [
            {
                "joint": name,
                "qpos_min": float(qpos[:, a].min()),
                "qpos_max": float(qpos[:, a].max()),
                "max_abs_difference": float(diff[:, a].max()),
            }
            for name, a in joints
        ],
        args.out,
        "rigid_vs_mujoco",
    )

    plt = pyplot()
    fig, (a, b) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for name, adr in joints:
        a.plot(t, qpos[:, adr], label=f"{name}: coupled run")
        a.plot(t, replay[:, adr], "--", label=f"{name}: MuJoCo alone")
        b.semilogy(t, np.maximum(diff[:, adr], 1e-18), label=name)
    a.set_ylabel("joint position (rad)")
    a.legend(fontsize=7)
    b.set_ylabel("|difference| (floor 1e-18)")
    if diff.max() == 0:
        b.text(0.5, 0.5, "identical at every step", transform=b.transAxes, ha="center", va="bottom")
    b.set_xlabel("time (s)")
    b.legend(fontsize=7)
    a.set_title(f"{args.scene}: the rigid part against mj_step, {nstep} steps")
    for ax in (a, b):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out / "rigid_vs_mujoco.png", dpi=100)
    plt.close(fig)
    print(f"largest difference {diff.max():.3g} rad -> {args.out}/rigid_vs_mujoco.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
