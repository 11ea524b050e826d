"""Refinement of a triangle surface by splitting every face into four.

Each level puts a new point at the midpoint of every edge (numbered after the
old points, which keep their indices and positions) and replaces each face
(a, b, c) by (a, ab, ca), (b, bc, ab), (c, ca, bc) and (ab, bc, ca): the
orientation is kept, the points are multiplied by about 4 and the spacing
halved. Where the surface is a sphere, the new points are projected back onto
it (`center`, `radius_m`); otherwise they stay on the old faces, which keeps
the polyhedron's surface exactly.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import MeshError

__all__ = ["split_faces", "fit_sphere"]


def split_faces(
    vert_pos: np.ndarray, face_vert: np.ndarray, times: int = 1, *, center=None, radius_m: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(vert_pos, face_vert) after `times` levels of splitting each face into four.

    With `center` (3,) m and `radius_m`, each new point is moved along the ray
    from the centre onto that sphere."""
    from ..checks import mesh_points
    from ..errors import MeshError

    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert, dtype=np.int64)
    # a closed surface has 3F/2 edges, each a new point a level, the faces times 4: before any array
    mesh_points(
        "split_faces",
        len(pos) + (4 ** int(times) - 1) * len(face) // 2,
        f"{int(times)} levels of splitting {len(face)} faces give about ",
        error=MeshError,
    )
    ctr = None if center is None else np.asarray(center, dtype=np.float64)
    for _ in range(int(times)):
        n = len(pos)
        corner = face[:, [0, 1, 2]], face[:, [1, 2, 0]]
        lo, hi = np.minimum(*corner), np.maximum(*corner)  # (nface, 3): edges ab, bc, ca
        key, inverse = np.unique(lo * n + hi, return_inverse=True)
        mid_index = n + inverse.reshape(-1, 3)
        mid = 0.5 * (pos[key // n] + pos[key % n])
        if ctr is not None:
            rel = mid - ctr
            mid = ctr + rel / (np.linalg.norm(rel, axis=1, keepdims=True) / radius_m)
        pos = np.concatenate([pos, mid])
        a, b, c = face.T
        ab, bc, ca = mid_index.T
        face = np.concatenate(
            [
                np.stack([a, ab, ca], axis=1),
                np.stack([b, bc, ab], axis=1),
                np.stack([c, ca, bc], axis=1),
                np.stack([ab, bc, ca], axis=1),
            ]
        )
    return pos, face


def fit_sphere(vert_pos: np.ndarray, rel_tol: float, who: str) -> tuple[np.ndarray, float]:
    """(center (3,) m, radius m) of the sphere through the points (least squares on
    |p|^2 = 2 c.p + r^2 - |c|^2). Raises MeshError naming `who` when a point is off it by
    more than rel_tol of the radius."""
    pos = np.asarray(vert_pos, dtype=np.float64)
    o = pos.mean(axis=0)
    rel = pos - o  # relative to the mean: no digits lost far from the origin
    a = np.hstack([2.0 * rel, np.ones((len(rel), 1))])
    sol = np.linalg.lstsq(a, np.einsum("ij,ij->i", rel, rel), rcond=None)[0]
    c = sol[:3]
    radius = float(np.sqrt(sol[3] + c @ c))
    off = float(np.max(np.abs(np.linalg.norm(rel - c, axis=1) - radius)) / radius)
    if not off <= rel_tol:
        raise MeshError(
            f"{who}: expected points on a sphere (within {rel_tol:g} of its radius), received points "
            f"off the best-fitting sphere (radius {radius:.6g} m) by up to {off:.3g} of it"
        )
    return o + c, radius
