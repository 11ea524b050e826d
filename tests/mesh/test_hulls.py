"""The convex hulls' cache (`hybrid.mesh.hulls`): what it reads back is what Qhull
builds, bit for bit; it writes in its own folder and nowhere else; a damaged file is
rebuilt; and a warm run's mesh no longer imports scipy.spatial. The pieces of a
surface (`Mesh.components`) are found without scipy, as scipy's graph routines found them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hybrid.mesh import Mesh, icosphere, ring_sphere
from hybrid.mesh.hulls import _compute, hull_cache_dir, hull_faces
from hybrid.mesh.spheres import _spiral_points

ROOT = Path(__file__).resolve().parents[2]


def _files(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_a_cached_hull_is_the_one_qhull_builds_bit_for_bit(tmp_path):
    p = _spiral_points(500)
    fresh = _compute(p)
    first = hull_faces(p, tmp_path)  # computed, stored
    stored = [f for f in _files(tmp_path) if f.endswith(".npy")]
    assert len(stored) == 1
    again = hull_faces(p, tmp_path)  # read back
    for faces in (first, again):
        assert faces.dtype == fresh.dtype and faces.shape == fresh.shape
        assert np.array_equal(faces, fresh)
    # other points (one bit of one coordinate apart) are another file, their own hull
    q = p.copy()
    q[7, 2] = np.nextafter(q[7, 2], 2.0)
    assert np.array_equal(hull_faces(q, tmp_path), _compute(q))
    assert len([f for f in _files(tmp_path) if f.endswith(".npy")]) == 2


def test_a_mesh_built_from_the_cache_equals_one_built_afresh(tmp_path, monkeypatch):
    from hybrid.mesh import hulls

    args = dict(npoint=1229, radius=0.12, center=(0.0, 0.01, 0.0), conform_z=(0.11, 0.08, 0.045, -0.05))
    monkeypatch.setattr(hulls, "hull_cache_dir", lambda: tmp_path)
    built = ring_sphere(**args)  # computed into the empty folder
    monkeypatch.setattr(hulls, "_compute", lambda p: pytest.fail("computed again, not read"))
    cached = ring_sphere(**args)
    for name in Mesh.__slots__:
        a, b = getattr(built, name), getattr(cached, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and np.array_equal(a, b), name
        else:
            assert a == b, name


def test_the_cache_writes_in_its_folder_only_and_rebuilds_a_damaged_file(tmp_path, monkeypatch):
    folder, work = tmp_path / "cache" / "hulls-0123456789abcdef", tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    p = _spiral_points(200)
    hull_faces(p, folder)
    written = _files(tmp_path)
    assert written and all(name.startswith("cache/hulls-0123456789abcdef/") for name in written)
    (npy,) = [folder / n.rsplit("/", 1)[1] for n in written if n.endswith(".npy")]
    for damage in (b"not a numpy file", npy.read_bytes()[:-40]):
        npy.write_bytes(damage)
        assert np.array_equal(hull_faces(p, folder), _compute(p))
        assert np.array_equal(np.load(npy), _compute(p))  # stored whole again
    # a folder that cannot be written: the hull all the same, nothing written
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the folder would be")
    assert np.array_equal(hull_faces(p, blocked / "hulls"), _compute(p))
    assert set(_files(tmp_path)) == set(written) | {"blocked"}


def test_the_folder_is_the_package_caches_and_names_its_version(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run(
        [sys.executable, "-c", "from hybrid.mesh.hulls import hull_cache_dir; print(hull_cache_dir())"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    ).stdout.strip()
    assert Path(out).parent == tmp_path and Path(out).name.startswith("hulls-") and len(Path(out).name) == 22
    assert hull_cache_dir().name.startswith("hulls-")


def test_a_warm_scene_build_imports_neither_scipy_spatial_nor_scipy_sparse(tmp_path):
    """The breathing scene's model, twice, in processes of their own sharing a cache
    folder: the second reads its hull, and finds its mesh in one piece, without scipy's
    spatial or sparse modules (0.3 s and 0.2 s of CPU to import)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "PYTHONPATH": str(ROOT)}
    code = (
        "import sys; from hybrid.body import build_mesh; from hybrid.resolve import resolve_scene\n"
        "m = build_mesh(resolve_scene('breathing')); m.require_one_piece('one piece')\n"
        "print(sorted(k for k in ('scipy.spatial', 'scipy.sparse') if k in sys.modules))"
    )
    runs = [
        subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
        for _ in range(2)
    ]
    assert "scipy.spatial" in runs[0]  # the cold build: Qhull
    assert runs[1].strip() == "[]"


def _scipy_components(mesh):
    """The pieces as scipy's connected_components found them (the former `Mesh.components`)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = mesh.edge_vert
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(mesh.nvert, mesh.nvert))
    count, label = connected_components(graph, directed=False)
    order = np.argsort(label, kind="stable")
    return sorted(np.split(order, np.cumsum(np.bincount(label))[:-1]), key=lambda part: part[0])


@pytest.mark.parametrize("pieces", [1, 2, 4])
def test_the_pieces_of_a_surface_are_scipys_without_scipy(pieces):
    parts = [ring_sphere(150 + 30 * k, 0.1, center=(0.5 * k, 0.0, 0.0)) for k in range(pieces - 1)]
    parts.append(icosphere(2, 0.1, center=(0.0, 1.0, 0.0)))
    pos = np.concatenate([m.vert_pos for m in parts])
    offset = np.cumsum([0] + [m.nvert for m in parts])[:-1]
    face = np.concatenate([m.face_vert + o for m, o in zip(parts, offset)])
    perm = np.random.default_rng(pieces).permutation(len(pos))  # the pieces' points interleaved
    mesh = Mesh(pos[perm], np.argsort(perm)[face])
    got, want = mesh.components(), _scipy_components(mesh)
    assert len(got) == len(want) == pieces
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and np.array_equal(g, w)
