"""Volume and area of triangle surfaces, on plain arrays (vectorized numpy).

The volume of a closed, outward surface (paper section 4.3) is
V = 1/6 sum_f a . (b x c), and dV/dx_a = 1/6 sum_{f containing a} b x c with
(a, b, c) rotated so that a comes first. Both are evaluated relative to the
mean of the positions, which keeps the terms of the size of the body rather
than of its distance to the origin (a body 100 m away loses no digits).
`cross_rows` and `scatter_corners` are the row-wise building blocks that
`hybrid.mesh.surface` and the validation share.
"""

from __future__ import annotations

import numpy as np

__all__ = ["volume", "volume_gradient", "vertex_area", "region_faces", "cross_rows", "scatter_corners"]


def volume(vert_pos: np.ndarray, face_vert: np.ndarray) -> float:
    """Signed volume enclosed by a triangle surface (m^3).

    vert_pos (nvert, 3) m, face_vert (nface, 3) int (counter-clockwise seen
    from outside). Returns V = 1/6 sum_f a . (b x c), with the corners taken
    relative to o = mean(vert_pos). For a closed surface V does not depend on
    o and is positive when the faces point outward. For an open surface it is
    the signed volume of the cones from o to every face, so it depends on o:
    it is relative to the mean of the positions given.
    """
    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert)
    rel = pos - pos.mean(axis=0)
    a, b, c = rel[face[:, 0]], rel[face[:, 1]], rel[face[:, 2]]
    return float(np.sum(a * cross_rows(b, c)) / 6.0)


def volume_gradient(vert_pos: np.ndarray, face_vert: np.ndarray) -> np.ndarray:
    """Gradient of `volume` with respect to every vertex position, (nvert, 3) m^2.

    dV/dx_a = 1/6 sum_{faces (a, b, c) containing a} x_b x x_c, with the face
    rotated so that a comes first. Positions are taken relative to
    o = mean(vert_pos). For a closed surface the result does not depend on o
    (around a closed fan the terms o x (x_c - x_b) telescope to zero) and it
    sums to zero over the vertices. For an open surface it is the gradient of
    the cone volume with the apex o held fixed.
    """
    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert)
    rel = pos - pos.mean(axis=0)
    a, b, c = rel[face[:, 0]], rel[face[:, 1]], rel[face[:, 2]]
    return scatter_corners(face, cross_rows(b, c), cross_rows(c, a), cross_rows(a, b), len(pos)) / 6.0


def vertex_area(vert_pos: np.ndarray, face_vert: np.ndarray) -> np.ndarray:
    """Each vertex's share of the surface area, a third of its faces' areas, (nvert,) m^2."""
    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert)
    a = pos[face[:, 0]]
    third = np.linalg.norm(cross_rows(pos[face[:, 1]] - a, pos[face[:, 2]] - a), axis=1) / 6.0
    return np.bincount(face.T.ravel(), weights=np.tile(third, 3), minlength=len(pos))


def region_faces(face_vert: np.ndarray, verts, nvert: int) -> np.ndarray:
    """Indices of a region's faces: those with at least two of their corners among
    `verts` (so two regions that split the points split the faces)."""
    inside = np.zeros(nvert, bool)
    inside[verts] = True
    return np.nonzero(inside[face_vert].sum(axis=1) >= 2)[0]


def cross_rows(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise cross product of two (n, 3) arrays (cheaper than np.cross on small arrays)."""
    out = np.empty_like(u)
    out[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    out[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    out[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


def scatter_corners(face_vert, val_a, val_b, val_c, nvert) -> np.ndarray:
    """Sum per-corner values (nface, 3) into their vertices, (nvert, 3).

    val_a goes to face_vert[:, 0], val_b to [:, 1], val_c to [:, 2]. bincount
    is much faster than np.add.at and sums in a fixed order (deterministic).
    """
    index = np.asarray(face_vert).T.ravel()
    value = np.concatenate([val_a, val_b, val_c])
    out = np.empty((nvert, 3))
    for k in range(3):
        out[:, k] = np.bincount(index, weights=value[:, k], minlength=nvert)
    return out
