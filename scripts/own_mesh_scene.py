"""An own scene on a mesh file: an ellipsoidal abdomen written as an OBJ file, a scene
file that uses it, and a run.

    python scripts/own_mesh_scene.py [--duration 8] [--out DIR] [--quick]

The OBJ (out/ellipsoid.obj, 0.10 x 0.08 x 0.14 m half-axes, an icosphere of 162 points
stretched) and the scene file (out/ellipsoid.toml: its top cap a breathing muscle whose
fibres converge on the apex, its bottom nailed, the volume kept) are written first;
`hybrid.load(path)` reads them back, as `hybrid run out/ellipsoid.toml` would. On this
elongated body the contracting cap narrows and its apex rises (a negative apex
descent), unlike the sphere's dome. Writes own_scene.csv / own_scene.md (the apex's
range, the pressure, the volume error) and own_scene.png (apex descent, pressure and
the volume over time).
"""

from __future__ import annotations

import numpy as np
import trimesh
from _common import parse, pyplot, write_table

import hybrid

HALF_AXES_M = (0.10, 0.08, 0.14)

SCENE_TOML = """\
# An ellipsoidal abdomen: its top cap contracts along the meridians, its bottom is nailed.
name = "ellipsoid"
formulation = "paper"
dt_s = 5e-4
duration_s = {duration}

[mesh]
path = "ellipsoid.obj"

[masses]
total_kg = 3.0

[regions]
cap = {{ half_space = {{ point = [0.0, 0.0, 0.09], normal = [0.0, 0.0, 1.0] }} }}
base = {{ half_space = {{ point = [0.0, 0.0, -0.12], normal = [0.0, 0.0, -1.0] }} }}

[[forces]]
type = "shape_memory"
stiffness_n_per_m = 3000.0

[[forces]]
type = "muscle"
region = "cap"
toward_m = [0.0, 0.0, 0.14]
stiffness = {{ breathing = {{ period_s = 4.0, inspiration_fraction = 0.4, peak = 150.0 }} }}

[[forces]]
type = "damping"
critical_fraction = 0.3

[[constraints]]
type = "nailed"
region = "base"

[[constraints]]
type = "volume"
"""


def write_mesh(path) -> int:
    """An ellipsoid as an OBJ file (outward faces); returns its number of points."""
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    sphere.vertices = sphere.vertices * np.asarray(HALF_AXES_M)
    sphere.export(path)
    return len(sphere.vertices)


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "own_mesh_scene",
        lambda p: p.add_argument("--duration", type=float, default=8.0, help="simulated time (s), default two breaths"),
    )
    duration = 0.2 if args.quick else args.duration
    npoint = write_mesh(args.out / "ellipsoid.obj")
    (args.out / "ellipsoid.toml").write_text(SCENE_TOML.format(duration=duration))
    sim = hybrid.load(args.out / "ellipsoid.toml")
    result = hybrid.run(sim, duration)
    summary, trace = result["summary"], result["trace"].arrays()
    write_table(
        [
            {
                "points": npoint,
                "faces": len(sim.model.mesh.face_vert),
                "duration_s": summary["duration_s"],
                "apex_descent_min_mm": float(trace["apex_descent_mm"].min()),
                "apex_descent_max_mm": float(trace["apex_descent_mm"].max()),
                "pressure_max_pa": float(trace["pressure_pa"].max()),
                "volume_rel_error_max": float(trace["volume_rel_error"].max()),
                "us_per_step": summary["us_per_step"],
            }
        ],
        args.out,
        "own_scene",
    )

    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for ax, key, label in zip(
        axes,
        ("apex_descent_mm", "pressure_pa", "volume_m3"),
        ("apex descent (mm, caudal +)", "pressure (Pa)", "volume (m^3)"),
    ):
        ax.plot(trace["t_s"], trace[key])
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(f"ellipsoid.obj: {npoint} points, {duration:g} s")
    fig.tight_layout()
    fig.savefig(args.out / "own_scene.png", dpi=100)
    plt.close(fig)
    print(f"-> {args.out}/own_scene.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
