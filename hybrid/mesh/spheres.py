"""Sphere generators: the paper's UV sphere, the icosahedron, icospheres and spiral spheres.

The paper's test body is `uv_sphere()`: 80 points, 156 faces. `icosphere`
gives evenly spaced spheres for convergence studies. Every generator returns
a validated `Mesh` whose faces point outward.
"""

from __future__ import annotations

import numpy as np

from hybrid.checks import MAX_POINTS, mesh_points
from hybrid.errors import MeshError

from .hulls import hull_faces
from .refine import split_faces
from .surface import Mesh

__all__ = [
    "uv_sphere",
    "icosahedron",
    "icosphere",
    "irregular_sphere",
    "fibonacci_sphere",
    "ring_sphere",
    "level_counts",
    "ICOSPHERE_MAX_SUBDIVISIONS",
    "MAX_LEVEL",
]


def _check_sphere_args(radius, center, who: str) -> np.ndarray:
    if not (np.isfinite(radius) and radius > 0):
        raise MeshError(f"{who}: radius must be a positive finite length (m); received {radius!r}")
    ctr = np.asarray(center, dtype=np.float64)
    if ctr.shape != (3,) or not np.isfinite(ctr).all():
        raise MeshError(f"{who}: center must be 3 finite coordinates (m); received {center!r}")
    return ctr


def _conform_angles(conform_z, who: str) -> np.ndarray:
    """The polar angles (rad, increasing) of the latitudes conform_z (unit sphere, z in (-1, 1))."""
    z = np.asarray(conform_z, float).reshape(-1)
    if z.size and not (np.all(np.isfinite(z)) and np.all(np.abs(z) < 1.0)):
        raise MeshError(
            f"{who}: conform_z must be heights strictly inside the sphere (|z| < radius); "
            f"received {list(conform_z)!r} (in radii)"
        )
    return np.unique(np.arccos(z))


def _share(count: int, span: np.ndarray) -> np.ndarray:
    """`count` intervals shared among spans by their lengths, at least one each (count >=
    len(span)): rounded, then one fewer where the spacing is finest or one more where it
    is coarsest until they add up."""
    n = np.maximum(1, np.round(span / span.sum() * count).astype(int))
    while n.sum() > count:
        n[int(np.argmax(np.where(n > 1, n / span, -1.0)))] -= 1
    while n.sum() < count:
        n[int(np.argmax(span / n))] += 1
    return n


def _polar_angles(rings: int, conform_z, who: str) -> np.ndarray:
    """rings - 1 polar angles in (0, pi): evenly spaced, or, with latitudes conform_z
    (in radii), evenly spaced in each span between them with every latitude a circle
    (each span gets its share of the rings gaps by its angle, at least one)."""
    if not len(conform_z):
        return np.pi * np.arange(1, rings) / rings
    brk = np.concatenate([[0.0], _conform_angles(conform_z, who), [np.pi]])
    span = np.diff(brk)
    if rings < span.size:
        raise MeshError(f"{who}: {span.size - 1} latitudes to conform to need rings >= {span.size}; received {rings}")
    gaps = _share(rings, span)
    return np.concatenate([brk[i] + span[i] * np.arange(1, gaps[i] + 1) / gaps[i] for i in range(span.size)])[:-1]


def _place_conforming(pos: np.ndarray, ctr: np.ndarray, radius: float, conform_z_m) -> np.ndarray:
    """The points of each conforming circle at exactly the given height (m from the
    centre), so that a region bounded there selects them whatever the rounding."""
    for zc in conform_z_m:
        on = np.abs(pos[:, 2] - ctr[2] - zc) < 1e-9 * radius
        pos[on, 2] = ctr[2] + zc
    return pos


def _segment_azimuths(segments: int, azim: np.ndarray, who: str) -> np.ndarray:
    """`segments` azimuths (rad) around a circle: evenly spaced from +x, or, with
    conforming azimuths, one at each and the others evenly spaced in each arc between
    them (each arc gets its share of the segments by its angle, at least one)."""
    if not azim.size:
        return 2.0 * np.pi * np.arange(segments) / segments
    if segments < azim.size:
        raise MeshError(f"{who}: {azim.size} azimuths to conform to need segments >= {azim.size}; received {segments}")
    arc = np.diff(np.concatenate([azim, [azim[0] + 2.0 * np.pi]]))
    n = _share(segments, arc)
    return np.concatenate([azim[i] + arc[i] * np.arange(n[i]) / n[i] for i in range(azim.size)])


def uv_sphere(
    radius: float = 1.0,
    segments: int = 13,
    rings: int = 7,
    center=(0.0, 0.0, 0.0),
    conform_z=(),
    conform_azimuth_deg=(),
) -> Mesh:
    """The paper's sphere: two poles and rings - 1 latitude circles of `segments` points.

    radius (m), center (3,) m. Vertex 0 is the north pole (+z), the last the
    south pole (-z); the circles run from north to south, each starting at
    +x and turning counter-clockwise seen from +z. The defaults give the
    paper's 80 vertices and 156 faces; in general 2 + segments (rings - 1)
    vertices and 2 segments (rings - 1) faces. Faces point outward.
    `conform_z` (m from the centre): latitudes that are circles of the mesh (a
    region bounded there is then bounded by edges), the circles evenly spaced
    between them (`_polar_angles`). `conform_azimuth_deg` (degrees from +x toward +y):
    azimuths that are meridians of the mesh, the segments evenly spaced between them.
    """
    if int(segments) != segments or segments < 3:
        raise MeshError(f"uv_sphere: segments must be an integer >= 3; received {segments!r}")
    if int(rings) != rings or rings < 2:
        raise MeshError(f"uv_sphere: rings must be an integer >= 2; received {rings!r}")
    ctr = _check_sphere_args(radius, center, "uv_sphere")
    segments, rings = int(segments), int(rings)
    conform_m = np.asarray(conform_z, float).reshape(-1)
    conform_z = tuple(conform_m / radius)
    # before any array is allocated
    mesh_points(
        "uv_sphere", segments * (rings - 1) + 2, f"segments = {segments} x rings = {rings} gives ", error=MeshError
    )
    theta = _polar_angles(rings, conform_z, "uv_sphere")  # polar angle of each circle
    phi = _segment_azimuths(segments, _conform_azimuths(conform_azimuth_deg, "uv_sphere"), "uv_sphere")
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
    pos = _place_conforming(ctr + radius * unit, ctr, radius, conform_m)
    return Mesh(pos, np.concatenate(faces), name="uv_sphere")


_PHI = (1.0 + 5.0**0.5) / 2.0
_ICO_VERT = np.array(
    [
        [-1, _PHI, 0],
        [1, _PHI, 0],
        [-1, -_PHI, 0],
        [1, -_PHI, 0],
        [0, -1, _PHI],
        [0, 1, _PHI],
        [0, -1, -_PHI],
        [0, 1, -_PHI],
        [_PHI, 0, -1],
        [_PHI, 0, 1],
        [-_PHI, 0, -1],
        [-_PHI, 0, 1],
    ]
) / np.sqrt(1.0 + _PHI**2)
_ICO_FACE = np.array(
    [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ]
)


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
    mesh_points("icosphere", 10 * 4 ** int(subdivisions) + 2, f"subdivisions = {subdivisions} gives ", error=MeshError)
    # edge midpoints pushed out to the unit sphere at each level
    unit, face = split_faces(_ICO_VERT, _ICO_FACE, int(subdivisions), center=np.zeros(3), radius_m=1.0)
    return Mesh(ctr + radius * unit, face, name=f"icosphere{int(subdivisions)}")


def _spiral_points(npoint: int) -> np.ndarray:
    """npoint unit vectors on the golden-angle spiral (the spherical Fibonacci lattice):
    equal-area bands in z, no poles, every point's neighbourhood alike."""
    k = np.arange(npoint) + 0.5
    z = 1.0 - 2.0 * k / npoint
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _hull_mesh(p: np.ndarray, radius: float, ctr: np.ndarray, name: str) -> Mesh:
    """The convex hull's triangles of the unit vectors p, faces outward (`hull_faces`,
    cached), scaled and moved."""
    return Mesh.from_arrays(radius * p + ctr, hull_faces(p), name=name)


def _check_npoint(npoint, who: str) -> int:
    if isinstance(npoint, bool) or int(npoint) != npoint or not 12 <= npoint <= MAX_POINTS:
        raise MeshError(f"{who}: npoint must be an integer in [12, {MAX_POINTS}]; received {npoint!r}")
    return mesh_points(who, int(npoint), "npoint = ", error=MeshError)


def fibonacci_sphere(npoint: int, radius: float = 1.0, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A pole-free sphere of any number of points: the spherical Fibonacci lattice and
    its convex hull's (Delaunay) triangles. Every point has about the same area and
    the triangles are near-equilateral everywhere, unlike a UV sphere's thin pole
    fans. radius (m), center (3,) m."""
    ctr = _check_sphere_args(radius, center, "fibonacci_sphere")
    npoint = _check_npoint(npoint, "fibonacci_sphere")
    return _hull_mesh(_spiral_points(npoint), radius, ctr, f"fibonacci_sphere_{npoint}")


def irregular_sphere(npoint: int, radius: float = 1.0, seed: int = 0, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A sphere of `npoint` unevenly spaced points and their convex hull's triangles:
    the spiral (Fibonacci) points moved at random by up to a third of their spacing,
    so the valences and angles vary as on a remeshed anatomy surface, without
    slivers. radius (m), center (3,) m; the same seed gives the same mesh."""
    ctr = _check_sphere_args(radius, center, "irregular_sphere")
    npoint = _check_npoint(npoint, "irregular_sphere")
    p = _spiral_points(npoint)
    spacing = np.sqrt(4.0 * np.pi / npoint)
    jitter = np.random.default_rng(seed).uniform(-1.0, 1.0, p.shape) * spacing / 3.0
    p = p + jitter - np.einsum("ij,ij->i", jitter, p)[:, None] * p  # tangential moves only
    p /= np.linalg.norm(p, axis=1)[:, None]
    return _hull_mesh(p, radius, ctr, f"irregular_sphere_{npoint}")


def _conform_azimuths(conform_azimuth_deg, who: str) -> np.ndarray:
    """The azimuths (rad in [0, 2 pi), increasing, distinct) of conform_azimuth_deg."""
    a = np.asarray(conform_azimuth_deg, float).reshape(-1)
    if a.size and not (np.all(np.isfinite(a)) and np.all(np.abs(a) <= 360.0)):
        raise MeshError(
            f"{who}: conform_azimuth_deg must be angles in [-360, 360] degrees; received {list(conform_azimuth_deg)!r}"
        )
    a = np.unique(np.round(np.mod(np.deg2rad(a), 2.0 * np.pi), 12) % (2.0 * np.pi))
    if a.size == 1:
        raise MeshError(
            f"{who}: conform_azimuth_deg needs at least two distinct azimuths (the borders of a "
            f"wedge); received {list(conform_azimuth_deg)!r}"
        )
    return a


def _circle_azimuths(m: int, azim: np.ndarray, per_rad: float):
    """The azimuths (rad) of a circle of about m points with a point at each of `azim`
    and the others evenly spaced in each arc between them (per_rad points a radian of
    azimuth, the arc's share); None where there are no azimuths or an arc is shorter
    than half a spacing (a circle too small to hold them: it keeps its own points)."""
    if not azim.size:
        return None
    arc = np.diff(np.concatenate([azim, [azim[0] + 2.0 * np.pi]]))
    if arc.min() * per_rad < 0.5:
        return None
    n = np.maximum(1, np.round(arc * per_rad).astype(int))
    return np.concatenate([azim[i] + arc[i] * np.arange(n[i]) / n[i] for i in range(azim.size)])


def ring_sphere(npoint: int, radius: float = 1.0, center=(0.0, 0.0, 0.0), conform_z=(), conform_azimuth_deg=()) -> Mesh:
    """A pole-free sphere of about `npoint` evenly spaced points on circles of latitude:
    each circle has as many points as its length holds at the spacing h of an even
    triangle lattice of npoint points (h^2 sqrt(3) / 2 per point), none at the poles
    (the first circle is h/2 from each), and the convex hull's triangles. `conform_z`
    (m from the centre): latitudes that are circles (their points at exactly those
    heights), so that regions bounded there are bounded by edges; the circles are
    evenly spaced between them. `conform_azimuth_deg` (degrees from +x toward +y about
    the z axis through the centre): azimuths that are columns of points on every circle
    large enough to hold them (an arc between two at least half a spacing), so that
    wedges bounded there are bounded by edges; a symmetric set about 0 degrees makes
    those circles mirror-symmetric about the x-z plane. radius (m), center (3,) m."""
    ctr = _check_sphere_args(radius, center, "ring_sphere")
    npoint = _check_npoint(npoint, "ring_sphere")
    conform_m = np.asarray(conform_z, float).reshape(-1)
    brk = _conform_angles(conform_m / radius, "ring_sphere")
    # the lattice spacing (rad), 7% under the even lattice's: circles of points lie a little
    # farther apart than that lattice's rows, and the counts then come out near npoint
    h = 0.93 * np.sqrt(8.0 * np.pi / (np.sqrt(3.0) * npoint))
    edges = np.concatenate([[0.0], brk, [np.pi]])
    theta = list(brk)
    for i in range(edges.size - 1):
        a, b = edges[i], edges[i + 1]
        cap_n, cap_s = a == 0.0, b == np.pi
        if cap_n and cap_s:  # no latitude to conform to: circles at (k + 1/2) d
            n = max(2, int(round(np.pi / h)))
            theta += list((np.arange(n) + 0.5) * np.pi / n)
        elif cap_n or cap_s:  # a cap: circles d apart from its latitude, the last d/2 from the pole
            n = max(1, int(round((b - a) / h + 0.5)))
            d = (b - a) / (n - 0.5)
            k = np.arange(1, n)
            theta += list(b - k * d if cap_n else a + k * d)
        else:
            n = max(1, int(round((b - a) / h)))
            theta += list(a + (b - a) * np.arange(1, n) / n)
    theta = np.sort(np.asarray(theta))
    azim = _conform_azimuths(conform_azimuth_deg, "ring_sphere")
    pts = []
    for j, t in enumerate(theta):
        m = max(3, int(round(2.0 * np.pi * np.sin(t) / h)))
        phi = _circle_azimuths(m, azim, np.sin(t) / h)
        if phi is None:
            phi = 2.0 * np.pi * (np.arange(m) + (j * 0.6180339887498949) % 1.0) / m  # circles turned apart
        pts.append(np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.full(phi.size, np.cos(t))], axis=1))
    p = np.concatenate(pts)
    mesh = _hull_mesh(p, radius, ctr, f"ring_sphere_{p.shape[0]}")
    if not conform_m.size:
        return mesh
    return Mesh.from_arrays(
        _place_conforming(mesh.vert_pos.copy(), ctr, radius, conform_m), mesh.face_vert, name=mesh.name
    )


#: the paper's sphere: 13 segments x 7 rings, 80 points (mesh level 0 of both families)
LEVEL0_SEGMENTS, LEVEL0_RINGS = 13, 7
#: the largest mesh level (about 80 x 2^K points: 5.2 million at K = 16)
MAX_LEVEL = 16


def level_counts(level: int) -> tuple[int, int, int]:
    """(segments, rings, npoint) of mesh level K: the paper's 13 x 7 UV sphere (80
    points) with both counts times 2^(K/2), so each level doubles the points and
    divides the spacing by sqrt(2); the pole-free family takes the same npoint."""
    if isinstance(level, bool) or int(level) != level or not 0 <= level <= MAX_LEVEL:
        raise MeshError(f"mesh level: expected an integer in [0, {MAX_LEVEL}], received {level!r}")
    f = 2.0 ** (level / 2.0)
    segments = int(round(LEVEL0_SEGMENTS * f))
    rings = int(round((LEVEL0_RINGS - 1) * f)) + 1
    return segments, rings, segments * (rings - 1) + 2
