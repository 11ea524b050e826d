"""Refinement of a triangle surface by splitting every face into four.

Each level puts a new point on every edge (numbered after the old points, which
keep their indices) and replaces each face (a, b, c) by (a, ab, ca),
(b, bc, ab), (c, ca, bc) and (ab, bc, ca): the orientation is kept, the points
are multiplied by about 4 and the spacing halved. Three ways to place the points:

- `split_faces`: at the edges' midpoints, the old points kept, which keeps the
  polyhedron's surface exactly; with `center` and `radius_m`, the new points
  projected along the ray from the centre onto that sphere (the sphere families);
- `loop_subdivide`: Loop's scheme (Loop 1987), every point moved: its levels
  approach a smooth limit surface (C2 but at the points of other than six
  neighbours, C1 there), which shrinks away from the coarse points;
- `refine_smooth`: the points of every level on one smooth surface that passes
  through the given points, the Loop limit surface of the control mesh solved
  for (`interpolating_control`): the given points keep their indices and
  positions at every level, and the levels sample that one surface ever more
  finely, as the sphere families sample their sphere. This is how `mesh.level`
  refines a closed mesh read from a file that is not a sphere
  (`refine_file_mesh`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hybrid.errors import MeshError

__all__ = [
    "split_faces",
    "fit_sphere",
    "loop_subdivide",
    "loop_limit",
    "loop_beta",
    "interpolating_control",
    "refine_smooth",
    "refine_file_mesh",
    "Refinement",
    "refinement_of",
    "SPHERE_FIT_REL_TOL",
]


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
        key, mid_index = _edge_keys(face, n)
        mid = 0.5 * (pos[key // n] + pos[key % n])
        if ctr is not None:
            rel = mid - ctr
            mid = ctr + rel / (np.linalg.norm(rel, axis=1, keepdims=True) / radius_m)
        pos = np.concatenate([pos, mid])
        face = _split_topology(face, mid_index)
    return pos, face


@dataclasses.dataclass(frozen=True)
class Refinement:
    """How a mesh was made from a coarser one by splitting each face into four `level`
    times (the file's points keep their indices): the coarse mesh (coarse_pos (n0, 3) m,
    coarse_face (nf0, 3)); each new point's parents, the ends of the edge it split
    (vert_parent (n - n0, 2), in index order; the points of level k start at level_start[k],
    their parents all below it); and each face's coarse face (face_parent (nface,)).
    carry_geometry: regions of geometry too are taken on the coarse mesh and carried (their
    borders then follow the coarse edges at every level: a fixed region, whose results
    converge at the surface's own order), not only regions of the file's points."""

    coarse_pos: np.ndarray
    coarse_face: np.ndarray
    vert_parent: np.ndarray
    level_start: tuple
    face_parent: np.ndarray
    carry_geometry: bool = False

    def carry_points(self, coarse_points: np.ndarray, nvert: int) -> np.ndarray:
        """The points of the fine mesh in a set given on the coarse mesh's points: its own
        points, and each new point whose parents both are (the set's inside: an edge
        between the set and the rest gives a point of neither)."""
        inside = np.zeros(nvert, bool)
        inside[np.asarray(coarse_points, np.int64)] = True
        n0 = len(self.coarse_pos)
        ends = (*self.level_start[1:], nvert)
        for start, end in zip(self.level_start, ends):
            a, b = self.vert_parent[start - n0 : end - n0].T
            inside[start:end] = inside[a] & inside[b]
        return np.nonzero(inside)[0]


def refinement_of(
    coarse_pos: np.ndarray, coarse_face: np.ndarray, level: int, *, carry_geometry: bool = False
) -> Refinement:
    """The `Refinement` of splitting (coarse_pos, coarse_face) `level` times, as
    `split_faces` and `refine_smooth` split them (the same topology)."""
    face = np.asarray(coarse_face, np.int64)
    n = len(coarse_pos)
    parents, starts = [], []
    face_parent = np.arange(len(face))
    for _ in range(int(level)):
        key, mid_index = _edge_keys(face, n)
        starts.append(n)
        parents.append(np.stack([key // n, key % n], axis=1))
        face = _split_topology(face, mid_index)
        face_parent = np.tile(face_parent, 4)  # _split_topology's four blocks, each in its parent's order
        n += len(key)
    return Refinement(
        coarse_pos=np.asarray(coarse_pos, float).copy(),
        coarse_face=np.asarray(coarse_face, np.int64).copy(),
        vert_parent=np.concatenate(parents) if parents else np.zeros((0, 2), np.int64),
        level_start=tuple(starts),
        face_parent=face_parent,
        carry_geometry=carry_geometry,
    )


def _edge_keys(face: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(key (nedge,) int64, mid_index (nface, 3)): the unique edges as lo * n + hi, sorted,
    and for each face's edges ab, bc, ca the index of its new point (n + the edge's rank)."""
    corner = face[:, [0, 1, 2]], face[:, [1, 2, 0]]
    lo, hi = np.minimum(*corner), np.maximum(*corner)  # (nface, 3): edges ab, bc, ca
    key, inverse = np.unique(lo * n + hi, return_inverse=True)
    return key, n + inverse.reshape(-1, 3)


def _split_topology(face: np.ndarray, mid_index: np.ndarray) -> np.ndarray:
    """Each face (a, b, c) as (a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)."""
    a, b, c = face.T
    ab, bc, ca = mid_index.T
    return np.concatenate(
        [
            np.stack([a, ab, ca], axis=1),
            np.stack([b, bc, ab], axis=1),
            np.stack([c, ca, bc], axis=1),
            np.stack([ab, bc, ca], axis=1),
        ]
    )


def _scatter(index: np.ndarray, value: np.ndarray, n: int) -> np.ndarray:
    """Sum the rows of value (m, 3) into rows index (m,) of an (n, 3) array."""
    out = np.empty((n, 3))
    for k in range(3):
        out[:, k] = np.bincount(index, weights=value[:, k], minlength=n)
    return out


def loop_beta(valence: np.ndarray) -> np.ndarray:
    """Loop's weight of each neighbour of a point of `valence` neighbours:
    beta(k) = (5/8 - (3/8 + cos(2 pi / k) / 4)^2) / k (Loop 1987; trimesh's too)."""
    k = np.asarray(valence, dtype=np.float64)
    return (0.625 - (0.375 + 0.25 * np.cos(2.0 * np.pi / k)) ** 2) / k


def _one_ring(pos: np.ndarray, face: np.ndarray):
    """(key, mid_index, valence (n,), sum of the neighbours' positions (n, 3)) of a closed surface."""
    n = len(pos)
    key, mid_index = _edge_keys(face, n)
    lo, hi = key // n, key % n
    ends = np.concatenate([lo, hi])
    valence = np.bincount(ends, minlength=n)
    nb_sum = _scatter(ends, np.concatenate([pos[hi], pos[lo]]), n)
    return key, mid_index, valence, nb_sum


def _require_closed_topology(face: np.ndarray, n: int, who: str) -> None:
    key, mid_index = _edge_keys(face, n)
    count = np.bincount((mid_index - n).ravel(), minlength=len(key))
    if np.any(count != 2):
        raise MeshError(
            f"{who}: expected a closed surface (every edge in two faces), received "
            f"{int(np.sum(count == 1))} border edges"
        )


def loop_subdivide(vert_pos: np.ndarray, face_vert: np.ndarray, times: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(vert_pos, face_vert) of a closed surface after `times` levels of Loop subdivision,
    numbered and split as `split_faces` numbers and splits them: an edge's new point
    3/8 of its ends and 1/8 of the two points facing it; an old point of k neighbours
    moved to (1 - k beta) x + beta sum(neighbours), `loop_beta`."""
    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert, dtype=np.int64)
    _require_closed_topology(face, len(pos), "loop_subdivide")
    for _ in range(int(times)):
        n = len(pos)
        key, mid_index, valence, nb_sum = _one_ring(pos, face)
        # the point facing each face's edges ab, bc, ca: c, a, b; each edge has two
        facing = _scatter((mid_index - n).ravel(), pos[face[:, [2, 0, 1]]].reshape(-1, 3), len(key))
        odd = 0.375 * (pos[key // n] + pos[key % n]) + 0.125 * facing
        beta = loop_beta(valence)[:, None]
        even = (1.0 - valence[:, None] * beta) * pos + beta * nb_sum
        pos = np.concatenate([even, odd])
        face = _split_topology(face, mid_index)
    return pos, face


def _limit_weights(valence: np.ndarray) -> np.ndarray:
    """Each neighbour's weight chi in the limit position of a point of `valence` k:
    x_lim = (1 - k chi) x + chi sum(neighbours), chi = 1 / (3 / (8 beta) + k): the left
    eigenvector of eigenvalue 1 of Loop's subdivision of a one-ring."""
    k = np.asarray(valence, dtype=np.float64)
    return 1.0 / (3.0 / (8.0 * loop_beta(k)) + k)


def loop_limit(vert_pos: np.ndarray, face_vert: np.ndarray) -> np.ndarray:
    """The points (nvert, 3) m where Loop subdivision of the closed control mesh
    (vert_pos, face_vert) takes each of its points in the limit (`_limit_weights`)."""
    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert, dtype=np.int64)
    _, _, valence, nb_sum = _one_ring(pos, face)
    chi = _limit_weights(valence)[:, None]
    return (1.0 - valence[:, None] * chi) * pos + chi * nb_sum


#: how far the solved control points may be from giving back the given points (of the size
#: of the body): the solve's round-off is about 1e-15 of it; more means a singular system
INTERPOLATION_REL_TOL = 1e-9


def interpolating_control(vert_pos: np.ndarray, face_vert: np.ndarray, who: str = "refine_smooth") -> np.ndarray:
    """The control points (nvert, 3) m, on the same faces, whose Loop limit surface passes
    through `vert_pos`: the solution of loop_limit(P) = vert_pos, a sparse system with a
    half or more of each row on its diagonal at six neighbours (a well-conditioned averaging;
    its least eigenvalue is 1/4 on a regular mesh). MeshError naming `who` when it has no
    solution to INTERPOLATION_REL_TOL of the body's size."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert, dtype=np.int64)
    n = len(pos)
    key, _ = _edge_keys(face, n)
    lo, hi = key // n, key % n
    valence = np.bincount(np.concatenate([lo, hi]), minlength=n)
    chi = _limit_weights(valence)
    rows = np.concatenate([np.arange(n), lo, hi])
    cols = np.concatenate([np.arange(n), hi, lo])
    vals = np.concatenate([1.0 - valence * chi, chi[lo], chi[hi]])
    lim = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
    center = pos.mean(axis=0)  # solved about the centre: no digits lost far from the origin
    size = float(np.ptp(pos, axis=0).max())
    try:
        ctrl = splu(lim).solve(pos - center)
    except RuntimeError:  # an exactly singular system
        ctrl = np.full_like(pos, np.nan)
    resid = float(np.max(np.abs(lim @ ctrl - (pos - center)))) if np.all(np.isfinite(ctrl)) else np.inf
    if not resid <= INTERPOLATION_REL_TOL * size:
        raise MeshError(
            f"{who}: expected a mesh whose points a Loop limit surface can pass through, received one "
            f"whose interpolation system is singular (residual {resid:.3g} m for a body of {size:.3g} m)"
        )
    return ctrl + center


def refine_smooth(
    vert_pos: np.ndarray, face_vert: np.ndarray, times: int, who: str = "refine_smooth"
) -> tuple[np.ndarray, np.ndarray]:
    """(vert_pos, face_vert) of a closed surface `times` levels finer, every point on the
    smooth surface through the given points (module docstring): the control points that
    interpolate them (`interpolating_control`), Loop-subdivided `times` times, each then
    taken to its limit position. The given points keep their indices and positions
    exactly (their limit positions, equal to them up to round-off, are replaced by them);
    the faces are split as `split_faces` splits them."""
    from ..checks import mesh_points

    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert, dtype=np.int64)
    mesh_points(
        who,
        len(pos) + (4 ** int(times) - 1) * len(face) // 2,
        f"{int(times)} levels of splitting {len(face)} faces give about ",
        error=MeshError,
    )
    _require_closed_topology(face, len(pos), who)
    if int(times) == 0:
        return pos.copy(), face.copy()
    ctrl, fine = loop_subdivide(interpolating_control(pos, face, who), face, times)
    out = loop_limit(ctrl, fine)
    out[: len(pos)] = pos
    return out, fine


def _sphere_fit(pos: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(center (3,) m, radius m, the largest distance of a point from that sphere over its
    radius) of the sphere through the points by least squares on |p|^2 = 2 c.p + r^2 - |c|^2."""
    o = pos.mean(axis=0)
    rel = pos - o  # relative to the mean: no digits lost far from the origin
    a = np.hstack([2.0 * rel, np.ones((len(rel), 1))])
    sol = np.linalg.lstsq(a, np.einsum("ij,ij->i", rel, rel), rcond=None)[0]
    c = sol[:3]
    radius = float(np.sqrt(sol[3] + c @ c))
    off = float(np.max(np.abs(np.linalg.norm(rel - c, axis=1) - radius)) / radius)
    return o + c, radius, off


def fit_sphere(vert_pos: np.ndarray, rel_tol: float, who: str) -> tuple[np.ndarray, float]:
    """(center (3,) m, radius m) of the sphere through the points (least squares on
    |p|^2 = 2 c.p + r^2 - |c|^2). Raises MeshError naming `who` when a point is off it by
    more than rel_tol of the radius."""
    center, radius, off = _sphere_fit(np.asarray(vert_pos, dtype=np.float64))
    if not off <= rel_tol:
        raise MeshError(
            f"{who}: expected points on a sphere (within {rel_tol:g} of its radius), received points "
            f"off the best-fitting sphere (radius {radius:.6g} m) by up to {off:.3g} of it"
        )
    return center, radius


#: how far (of the radius) a file mesh's points may be off a sphere for its levels to be
#: projected onto that sphere (a sphere written with 17 digits is on it to about 1e-16;
#: single-precision STL to 1e-7)
SPHERE_FIT_REL_TOL = 1e-6


def refine_file_mesh(
    vert_pos: np.ndarray, face_vert: np.ndarray, level: int, who: str = "mesh.level"
) -> tuple[np.ndarray, np.ndarray, str]:
    """(vert_pos, face_vert, scheme) of a mesh read from a file, `level` times finer:
    its faces split into four a level, the new points on the surface the file samples.
    That surface is the sphere through the file's points when they are on one (within
    SPHERE_FIT_REL_TOL of its radius; scheme "sphere", as the sphere families), else, for
    a closed surface, the smooth surface through them (`refine_smooth`; scheme "loop").
    MeshError naming `who` for an open surface off a sphere."""
    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.asarray(face_vert, dtype=np.int64)
    center, radius, off = _sphere_fit(pos)
    if off <= SPHERE_FIT_REL_TOL:
        return (*split_faces(pos, face, level, center=center, radius_m=radius), "sphere")
    try:
        _require_closed_topology(face, len(pos), who)
    except MeshError:
        border = int(np.sum(np.bincount((_edge_keys(face, len(pos))[1] - len(pos)).ravel()) == 1))
        raise MeshError(
            f"{who}: expected a closed surface (refined toward the smooth surface through its points) or "
            f"points on a sphere, received an open surface ({border} border edges) off its best-fitting "
            f"sphere by up to {off:.3g} of its radius; or no mesh.level"
        ) from None
    return (*refine_smooth(pos, face, level, who), "loop")
