"""Sphere generators: the paper's UV sphere, the icosahedron and icospheres.

The paper's test body is `uv_sphere()`: 80 points, 156 faces. `icosphere`
gives evenly spaced spheres for convergence studies. Every generator returns
a validated `Mesh` whose faces point outward.
"""

from __future__ import annotations

import numpy as np

from hybrid.checks import MAX_POINTS
from hybrid.errors import MeshError

from .surface import Mesh

__all__ = ["uv_sphere", "icosahedron", "icosphere", "irregular_sphere", "ICOSPHERE_MAX_SUBDIVISIONS"]


def _check_sphere_args(radius, center, who: str) -> np.ndarray:
    if not (np.isfinite(radius) and radius > 0):
        raise MeshError(f"{who}: radius must be a positive finite length (m); received {radius!r}")
    ctr = np.asarray(center, dtype=np.float64)
    if ctr.shape != (3,) or not np.isfinite(ctr).all():
        raise MeshError(f"{who}: center must be 3 finite coordinates (m); received {center!r}")
    return ctr


def uv_sphere(radius: float = 1.0, segments: int = 13, rings: int = 7,
              center=(0.0, 0.0, 0.0)) -> Mesh:
    """The paper's sphere: two poles and rings - 1 latitude circles of `segments` points.

    radius (m), center (3,) m. Vertex 0 is the north pole (+z), the last the
    south pole (-z); the circles run from north to south, each starting at
    +x and turning counter-clockwise seen from +z. The defaults give the
    paper's 80 vertices and 156 faces; in general 2 + segments (rings - 1)
    vertices and 2 segments (rings - 1) faces. Faces point outward.
    """
    if int(segments) != segments or segments < 3:
        raise MeshError(f"uv_sphere: segments must be an integer >= 3; received {segments!r}")
    if int(rings) != rings or rings < 2:
        raise MeshError(f"uv_sphere: rings must be an integer >= 2; received {rings!r}")
    ctr = _check_sphere_args(radius, center, "uv_sphere")
    segments, rings = int(segments), int(rings)
    if segments * (rings - 1) + 2 > MAX_POINTS:  # before any array is allocated
        raise MeshError(f"uv_sphere: segments = {segments} x rings = {rings} gives {segments * (rings - 1) + 2} "
                        f"points; expected at most {MAX_POINTS}")

    theta = np.pi * np.arange(1, rings) / rings  # polar angle of each circle
    phi = 2.0 * np.pi * np.arange(segments) / segments
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    circle = np.stack(
        [st * np.cos(phi), st * np.sin(phi), np.broadcast_to(ct, (rings - 1, segments))],
        axis=-1,
    ).reshape(-1, 3)
    unit = np.concatenate([[[0.0, 0.0, 1.0]], circle, [[0.0, 0.0, -1.0]]])

    south = 1 + segments * (rings - 1)
    j = np.arange(segments)
    jn = (j + 1) % segments
    faces = [np.stack([np.zeros_like(j), 1 + j, 1 + jn], axis=1)]  # north cap
    for i in range(rings - 2):  # band between circles i and i + 1: two triangles per quad
        top, bot = 1 + i * segments, 1 + (i + 1) * segments
        faces.append(np.stack([top + j, bot + j, bot + jn], axis=1))
        faces.append(np.stack([top + j, bot + jn, top + jn], axis=1))
    last = 1 + (rings - 2) * segments
    faces.append(np.stack([np.full_like(j, south), last + jn, last + j], axis=1))  # south cap
    return Mesh(ctr + radius * unit, np.concatenate(faces), name="uv_sphere")


_PHI = (1.0 + 5.0**0.5) / 2.0
_ICO_VERT = np.array([
    [-1, _PHI, 0], [1, _PHI, 0], [-1, -_PHI, 0], [1, -_PHI, 0],
    [0, -1, _PHI], [0, 1, _PHI], [0, -1, -_PHI], [0, 1, -_PHI],
    [_PHI, 0, -1], [_PHI, 0, 1], [-_PHI, 0, -1], [-_PHI, 0, 1],
]) / np.sqrt(1.0 + _PHI**2)
_ICO_FACE = np.array([
    [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
    [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
    [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
    [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
])


def icosahedron(radius: float = 1.0, center=(0.0, 0.0, 0.0)) -> Mesh:
    """Regular icosahedron inscribed in a sphere of `radius` (m): 12 vertices, 20 faces."""
    ctr = _check_sphere_args(radius, center, "icosahedron")
    return Mesh(ctr + radius * _ICO_VERT, _ICO_FACE, name="icosahedron")


#: largest subdivision level icosphere accepts (2,621,442 vertices)
ICOSPHERE_MAX_SUBDIVISIONS = 9


def icosphere(subdivisions: int, radius: float = 1.0, center=(0.0, 0.0, 0.0)) -> Mesh:
    """Sphere from an icosahedron whose faces are split into 4, `subdivisions` times.

    10 * 4**subdivisions + 2 vertices (12, 42, 162, 642, 2562, 10242, 40962 for
    0..6), all on the sphere of `radius` (m) around `center` (3,) m; faces
    point outward. Edge midpoints are pushed out to the sphere at each level.
    """
    if int(subdivisions) != subdivisions or not 0 <= subdivisions <= ICOSPHERE_MAX_SUBDIVISIONS:
        raise MeshError(
            f"icosphere: subdivisions must be an integer in [0, {ICOSPHERE_MAX_SUBDIVISIONS}]; "
            f"received {subdivisions!r}"
        )
    ctr = _check_sphere_args(radius, center, "icosphere")
    unit, face = _ICO_VERT.copy(), _ICO_FACE.copy()
    for _ in range(int(subdivisions)):
        # One new vertex per unique edge, numbered after the old ones.
        corner = face[:, [0, 1, 2]], face[:, [1, 2, 0]]
        lo, hi = np.minimum(*corner), np.maximum(*corner)  # (nface, 3): edges ab, bc, ca
        key, inverse = np.unique(lo * len(unit) + hi, return_inverse=True)
        mid_index = len(unit) + inverse.reshape(-1, 3)
        mid = unit[key // len(unit)] + unit[key % len(unit)]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        unit = np.concatenate([unit, mid])
        a, b, c = face.T
        ab, bc, ca = mid_index.T
        face = np.concatenate([
            np.stack([a, ab, ca], axis=1), np.stack([b, bc, ab], axis=1),
            np.stack([c, ca, bc], axis=1), np.stack([ab, bc, ca], axis=1),
        ])
    return Mesh(ctr + radius * unit, face, name=f"icosphere{int(subdivisions)}")


def irregular_sphere(npoint: int, radius: float = 1.0, seed: int = 0, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A sphere of `npoint` unevenly spaced points and their convex hull's triangles:
    the spiral (Fibonacci) points moved at random by up to a third of their spacing,
    so the valences and angles vary as on a remeshed anatomy surface, without
    slivers. radius (m), center (3,) m; the same seed gives the same mesh."""
    from scipy.spatial import ConvexHull
    ctr = _check_sphere_args(radius, center, "irregular_sphere")
    if int(npoint) != npoint or not 12 <= npoint <= MAX_POINTS:
        raise MeshError(f"irregular_sphere: npoint must be an integer in [12, {MAX_POINTS}]; received {npoint!r}")
    k = np.arange(npoint) + 0.5
    z = 1.0 - 2.0 * k / npoint
    phi = np.pi * (1.0 + 5.0 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    p = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    spacing = np.sqrt(4.0 * np.pi / npoint)
    jitter = np.random.default_rng(seed).uniform(-1.0, 1.0, p.shape) * spacing / 3.0
    p = p + jitter - np.einsum("ij,ij->i", jitter, p)[:, None] * p  # tangential moves only
    p /= np.linalg.norm(p, axis=1)[:, None]
    faces = ConvexHull(p).simplices.astype(np.int64)
    # outward: each face's normal along its centroid
    a, b, c = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) < 0
    faces[inward] = faces[inward][:, ::-1]
    return Mesh.from_arrays(radius * p + ctr, faces, name=f"irregular_sphere_{npoint}")
