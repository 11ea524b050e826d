"""A non-convex closed mesh read from a file (a peanut: a waist 0.06 m across between two
lobes 0.14 m across, 162 points) refines to four levels on the smooth surface through its
points, and `hybrid study convergence` on a scene using it reports limits, orders and a
recommendation, as on the capsule (`test_convergence_capsule.py`)."""

from __future__ import annotations

import math

import numpy as np
import trimesh
from helpers import strict_load
from test_convergence_capsule import INFLATION, ORDER_SPACE

import hybrid
from hybrid.studies.cli import main_study
from hybrid.studies.convergence import TARGETS

#: the peanut: a sphere of radius 0.1 m whose radius is scaled by 1 + WAIST cos(2 theta),
#: theta from the x axis: concave at the waist where WAIST > 0.2
WAIST = 0.4


def write_peanut_scene(folder):
    ico = trimesh.creation.icosphere(subdivisions=2)
    pos = ico.vertices * (0.1 * (1 + WAIST * (2 * ico.vertices[:, 0] ** 2 - 1)))[:, None]
    hybrid.mesh.Mesh.from_arrays(pos, ico.faces, name="peanut").save(folder / "peanut.obj")
    path = folder / "peanut.toml"
    path.write_text(
        INFLATION.replace('name = "capsule_inflation"', 'name = "peanut_inflation"').replace(
            'path = "capsule.obj"', 'path = "peanut.obj"'
        )
    )
    return path


def test_a_non_convex_file_mesh_refines_to_four_levels_on_one_smooth_surface(tmp_path):
    """Levels 0-4 (162 to 40,962 points): closed, the file's points kept, still non-convex
    (7% short of its convex hull's volume), and the enclosed volume converging at second
    order, each level's change about a quarter of the last (the Loop limit surface is smooth
    and the faces' chords approach it as the spacing squared)."""
    scene = write_peanut_scene(tmp_path)
    volumes = []
    for level in range(5):
        mesh = hybrid.load(str(scene), overrides=[f"mesh.level={level}"]).model.mesh
        assert mesh.closed and mesh.nvert == 10 * 4 ** (2 + level) + 2
        tm = trimesh.Trimesh(mesh.vert_pos, mesh.face_vert)
        assert tm.volume < 0.95 * tm.convex_hull.volume  # the waist stays concave
        volumes.append(tm.volume)
    change = np.abs(np.diff(volumes))
    ratio = change[:-1] / change[1:]
    assert ((ratio > 3.0) & (ratio < 5.0)).all(), ratio  # 4 at second order


def test_the_small_convergence_study_of_a_non_convex_scene_converges(tmp_path, capsys):
    scene = write_peanut_scene(tmp_path)
    metrics = ("volume_m3", "volume_rel_change")
    out = tmp_path / "cv"
    args = ["convergence", str(scene), "--out", str(out), "--small", "--levels", "0-2", "--steps", "2"]
    args += ["--duration", "0.25", "--repeats", "1"]
    assert main_study(args + [a for k in metrics for a in ("--metric", k)]) == 0
    assert capsys.readouterr().out.startswith("convergence: 6 runs, 0 failed")
    data = strict_load(out / "convergence.json")
    for k in metrics:
        e = data["estimate"][k]
        x = e["value_by_level"]
        assert abs(x[1] - x[0]) > 2.0 * abs(x[2] - x[1]) > 0, (k, x)  # at least first order
        assert ORDER_SPACE[0] <= e["observed_order_space"] <= ORDER_SPACE[1], (k, e["observed_order_space"])
        assert math.isfinite(e["limit"]) and e["error_by_level"][-1] < 0.03
    rows = data["recommendation"]
    assert {(r["metric"], r["target_rel_error"]) for r in rows} == {(k, t) for k in metrics for t in TARGETS}
    assert all(r["basis"] != "beyond" for r in rows), [(r["metric"], r["basis"]) for r in rows]
