"""The convex hull's triangles of points on a sphere (`hull_faces`), cached on disk.

The spiral and ring spheres (`hybrid.mesh.spheres`) take their triangles from
scipy's Qhull. Importing scipy.spatial costs a run 0.3 s of CPU, more than
building the mesh, so the faces are kept in a cache folder the package owns
(`hybrid.kernel.cache_base`, beside the compiled kernels), one file per hull,
named after a hash of the points' exact bits: the same points read the same
faces back, bit for bit, and any other points (another level, radius of the
unit sphere's points, conforming circle) are a file of their own. The folder's
name holds a hash of this module's source and of scipy's and numpy's versions,
so that a change to either builds afresh; `hybrid.kernel.prune_old_caches`
removes the folders of other versions once unused for a month. A cache that
cannot be read or written is passed by: the hull is computed instead.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["hull_faces", "hull_cache_dir"]


@functools.cache
def hull_cache_dir() -> Path:
    """This version's folder of cached hulls: hulls-<16 hex digits> in the package's cache folder."""
    import scipy

    from ..kernel import cache_base

    digest = hashlib.sha256(Path(__file__).read_bytes())
    digest.update(f"scipy {scipy.__version__} numpy {np.__version__}".encode())
    return Path(cache_base()) / f"hulls-{digest.hexdigest()[:16]}"


def _compute(p: np.ndarray) -> np.ndarray:
    """Qhull's triangles of the unit vectors p, each turned to face outward."""
    from scipy.spatial import ConvexHull

    faces = ConvexHull(p).simplices.astype(np.int64)
    # outward: each face's normal along its centroid
    a, b, c = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) < 0
    faces[inward] = faces[inward][:, ::-1]
    return faces


def _read(path: Path, npoint: int) -> np.ndarray | None:
    """The faces stored at path, or None when it is missing or not triangles of npoint points."""
    try:
        faces = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None
    if faces.dtype != np.int64 or faces.ndim != 2 or faces.shape[1] != 3 or not faces.size:
        return None
    if faces.min() < 0 or faces.max() >= npoint:
        return None
    return faces


def _write(folder: Path, path: Path, faces: np.ndarray) -> None:
    """faces saved at path whole: written aside in the folder, then renamed over it (two
    processes building one mesh at once each leave a whole file)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".npy")
        try:
            with os.fdopen(fd, "wb") as f:
                np.save(f, faces, allow_pickle=False)
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise
    except OSError:  # a read-only or full cache folder: the next run computes it again
        pass


def hull_faces(p: np.ndarray, folder: Path | None = None) -> np.ndarray:
    """The convex hull's triangles of the unit vectors p (npoint, 3), faces outward,
    (nface, 3) int64: read from the cache folder (default `hull_cache_dir`) when these
    exact points were seen before, else computed by Qhull and stored there."""
    p = np.ascontiguousarray(p, dtype=np.float64)
    folder = hull_cache_dir() if folder is None else Path(folder)
    key = hashlib.sha256(repr(p.shape).encode() + p.tobytes()).hexdigest()[:32]
    path = folder / f"{key}.npy"
    faces = _read(path, len(p))
    if faces is None:
        faces = _compute(p)
        _write(folder, path, faces)
    try:  # used now: kept by `prune_old_caches`
        (folder / ".last_used").touch()
    except OSError:
        pass
    return faces
