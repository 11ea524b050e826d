"""The membrane combined with a third-party MJCF model: an abdomen under the torso of
MuJoCo's humanoid (tests/data/humanoid.xml, the copy gymnasium ships, MIT), its top
ring riding on the torso.

    python scripts/third_party_mjcf.py [--mjcf humanoid.xml] [--duration 1] [--out DIR] [--quick]

The humanoid has no control, so it falls; the membrane goes with it, its volume kept.
The MJCF file is only read (our attachment sites and the linked points' masses are
added in memory). Writes third_party.csv / third_party.md (the torso's height, the
membrane's centroid height and its volume error at a few times) and third_party.png.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import parse, pyplot, write_table

import hybrid

CENTRE_M = (0.0, 0.0, 1.12)  # under the humanoid's torso at its initial pose


HUMANOID_XML = Path(__file__).resolve().parents[1] / "tests" / "data" / "humanoid.xml"


def scene(mjcf: Path) -> hybrid.Scene:
    z = CENTRE_M[2]
    ring = hybrid.Box((-1, -1, z + 0.07), (1, 1, z + 0.08))  # the border ring of the 80-point sphere
    return hybrid.Scene(
        name="humanoid_abdomen",
        formulation="paper",
        dt_s=1e-3,
        mesh=hybrid.MeshSpec("uv_sphere", radius_m=0.12, center_m=CENTRE_M),
        masses=hybrid.Masses(total_kg=4.0),
        regions={"top": hybrid.HalfSpace((0, 0, z + 0.07), (0, 0, 1))},
        forces=(
            hybrid.ShapeMemory(3000.0),
            hybrid.Damping(critical_fraction=0.3),
            hybrid.Muscle("top", hybrid.Breathing(4.0, 0.4, 60.0), toward_m=(0, 0, z + 0.12)),
        ),
        constraints=(hybrid.Volume(),),
        rigid=hybrid.Rigid(str(mjcf), links=(hybrid.RigidLink(ring, "torso", name="ribs"),), prefix="membrane_"),
    )


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "third_party_mjcf",
        lambda p: (
            p.add_argument("--mjcf", type=Path, default=None, help="the MJCF file (default: tests/data/humanoid.xml)"),
            p.add_argument("--duration", type=float, default=1.0, help="simulated time (s)"),
        ),
    )
    mjcf = args.mjcf or HUMANOID_XML
    duration = 0.2 if args.quick else args.duration
    sim = hybrid.load(scene(mjcf))
    torso = sim.mj_model.body("torso").id
    seen = {"t": [], "torso_z": [], "membrane_z": []}

    def observe(s, trace):  # each frame: the torso's height and the membrane's centroid height
        seen["t"].append(s.time)
        seen["torso_z"].append(float(s.mj_data.xpos[torso, 2]))
        seen["membrane_z"].append(float(s.vert_pos[:, 2].mean()))

    trace = hybrid.run(sim, duration, observers=[observe])["trace"].arrays()
    t = np.asarray(seen["t"])
    picks = sorted({int(np.searchsorted(t, x * duration - 1e-9)) for x in (0, 0.25, 0.5, 0.75, 1.0)})
    write_table(
        [
            {
                "t_s": t[k],
                "torso_z_m": seen["torso_z"][k],
                "membrane_centroid_z_m": seen["membrane_z"][k],
                "volume_rel_error": float(trace["volume_rel_error"][k]),
            }
            for k in picks
        ],
        args.out,
        "third_party",
    )

    plt = pyplot()
    fig, (a, b) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    a.plot(t, seen["torso_z"], label="humanoid torso")
    a.plot(t, seen["membrane_z"], label="membrane centroid")
    a.set_ylabel("height z (m)")
    a.legend()
    b.semilogy(trace["t_s"], np.maximum(trace["volume_rel_error"], 1e-17))
    b.set_ylabel("|V - V0| / V0")
    b.set_xlabel("time (s)")
    a.set_title(f"membrane on {Path(mjcf).name}'s torso")
    for ax in (a, b):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out / "third_party.png", dpi=100)
    plt.close(fig)
    print(f"-> {args.out}/third_party.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
