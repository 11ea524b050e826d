"""Triangle surfaces: loading, validation, ordered one-ring fans, volume and its gradient.

A `Mesh` holds the topology and rest geometry of a membrane: mass points
(`vert_pos`, m) on a triangle surface (`face_vert`, counter-clockwise seen
from outside, so that face normals point outward). It is validated once, when
it is built, and is immutable afterwards: every array is read-only.

Beyond the faces, a mesh stores what the force and constraint kernels need:

- the ordered one-ring of every vertex (paper section 3.4, the neighbours
  N_1 .. N_eta of a point), in CSR form `ring_ptr` / `ring_vert`: each
  consecutive pair (N_j, N_j+1) spans a face (a, N_j, N_j+1) of the mesh, i.e.
  the ring turns counter-clockwise around the outward normal. A closed fan
  starts at its smallest neighbour index and wraps (N_eta, N_1 is a face too);
  an open (border) fan runs from one border neighbour to the other;
- the unique undirected edges `edge_vert` and the border vertices.

The volume of a closed, outward surface (paper section 4.3) is
V = 1/6 sum_f a . (b x c), and dV/dx_a = 1/6 sum_{f containing a} b x c with
(a, b, c) rotated so that a comes first. Both are evaluated relative to the
mean of the positions, which keeps the terms of the size of the body rather
than of its distance to the origin (a body 100 m away loses no digits).

The paper's test body is `uv_sphere()`: 80 points, 156 faces. `icosphere`
gives evenly spaced spheres for convergence studies.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hybrid.errors import MeshError

if TYPE_CHECKING:  # trimesh is imported only when a file is loaded or exported
    import trimesh

__all__ = [
    "Mesh",
    "uv_sphere",
    "icosahedron",
    "icosphere",
    "volume",
    "volume_gradient",
]

#: file suffixes `Mesh.load` accepts (read by trimesh)
LOAD_SUFFIXES = (".stl", ".obj", ".ply", ".off")

#: a face is degenerate if its area is below this times the mean edge length squared
_AREA_RTOL = 1e-14

#: how many culprits an error message lists before "and N more"
_FEW = 5


# ---------------------------------------------------------------------------
# Free functions on arrays
# ---------------------------------------------------------------------------


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
    return float(np.sum(a * _cross(b, c)) / 6.0)


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
    return _scatter_corners(face, _cross(b, c), _cross(c, a), _cross(a, b), len(pos)) / 6.0


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise cross product of two (n, 3) arrays (cheaper than np.cross on small arrays)."""
    out = np.empty_like(u)
    out[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    out[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    out[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


def _scatter_corners(face_vert, val_a, val_b, val_c, nvert) -> np.ndarray:
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


# ---------------------------------------------------------------------------
# Mesh
# ---------------------------------------------------------------------------


class Mesh:
    """An immutable, validated triangle surface with its one-ring fans.

    Attributes (all arrays read-only)
    ----------
    vert_pos : (nvert, 3) float64, m       rest positions, C-contiguous
    face_vert : (nface, 3) int32           corners, counter-clockwise seen from outside
    nvert, nface : int
    closed : bool                          every edge is shared by exactly two faces
    ring_ptr : (nvert + 1,) int32          CSR offsets into ring_vert
    ring_vert : (ring_ptr[-1],) int32      ordered one-ring of each vertex (see module doc)
    ring_closed : (nvert,) bool            False for border vertices (open fan)
    edge_vert : (nedge, 2) int32           unique undirected edges, i < j, lexicographic order
    border_vert : (nborder,) int32         sorted border vertices (empty if closed)
    name : str

    Build one with `Mesh.from_arrays`, `Mesh.load`, `uv_sphere`, `icosahedron`
    or `icosphere`; every one of them validates (see `from_arrays`).
    """

    __slots__ = (
        "vert_pos", "face_vert", "nvert", "nface", "closed", "ring_ptr", "ring_vert",
        "ring_closed", "edge_vert", "border_vert", "name",
    )

    def __init__(self, vert_pos, face_vert, *, name: str = "mesh"):
        name = str(name)
        pos = _check_vert_pos(vert_pos, name)
        face = _check_face_vert(face_vert, len(pos), name)
        topo = _validate_and_build(pos, face, name)
        fields = dict(
            vert_pos=pos, face_vert=face, nvert=len(pos), nface=len(face), name=name, **topo,
        )
        for key, value in fields.items():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            object.__setattr__(self, key, value)

    # -- construction -------------------------------------------------------

    @classmethod
    def from_arrays(cls, vert_pos, face_vert, *, name: str = "mesh") -> Mesh:
        """Validate arrays and build a mesh (the arrays are copied).

        vert_pos (nvert, 3) real, m; face_vert (nface, 3) int in [0, nvert),
        counter-clockwise seen from outside. Raises `MeshError`, naming the
        faulty faces or vertices, for: wrong shapes or types, non-finite
        coordinates, out-of-range indices, degenerate faces (a repeated index,
        or area < 1e-14 * mean edge length^2), duplicate faces (same vertex
        set in any order), duplicate vertices (identical coordinates), unused
        vertices, non-manifold edges (> 2 faces), inconsistent orientation
        (an edge used twice in the same direction), non-manifold vertices
        (incident faces not a single fan) and closed surfaces that face
        inward (negative volume). Open surfaces are allowed; see
        `require_closed`.
        """
        return cls(vert_pos, face_vert, name=name)

    @classmethod
    def load(cls, path, *, name: str | None = None) -> Mesh:
        """Read a mesh file (STL, OBJ, PLY or OFF) with trimesh and validate it.

        The file is read with `trimesh.load(path, process=False, force="mesh")`,
        so vertices keep their order. STL stores each triangle's corners
        separately (no shared vertices), so for STL files exactly identical
        vertices are merged first (kept in order of first appearance); any
        other format must already share its vertices. `name` defaults to the
        file stem. Raises `MeshError` naming the path if the file is missing,
        has an unsupported suffix or cannot be read.
        """
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in LOAD_SUFFIXES:
            raise MeshError(
                f"mesh file {str(path)!r}: unsupported suffix {path.suffix!r}; "
                f"expected one of {', '.join(LOAD_SUFFIXES)}"
            )
        if not path.is_file():
            raise MeshError(f"mesh file {str(path)!r} does not exist or is not a file")
        import trimesh

        try:
            loaded = trimesh.load(str(path), process=False, force="mesh")
            vert_pos = np.asarray(loaded.vertices, dtype=np.float64)
            face_vert = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
        except Exception as exc:  # trimesh raises many types on bad input
            raise MeshError(
                f"mesh file {str(path)!r} cannot be read as a triangle mesh: "
                f"{type(exc).__name__}: {exc}"
            ) from exc
        if suffix == ".stl":
            vert_pos, face_vert = _merge_identical_vertices(vert_pos, face_vert)
        if name is None:
            name = path.stem
        try:
            return cls(vert_pos, face_vert, name=name)
        except MeshError as exc:
            raise MeshError(f"mesh file {str(path)!r}: {exc}") from None

    # -- immutability -------------------------------------------------------

    def __setattr__(self, key, value):
        raise AttributeError(f"Mesh is immutable: cannot set {key!r}; build a new Mesh")

    def __delattr__(self, key):
        raise AttributeError(f"Mesh is immutable: cannot delete {key!r}")

    def __reduce__(self):
        # __slots__ + a blocking __setattr__ defeat the default pickling; rebuild instead.
        return (_rebuild_mesh, (np.array(self.vert_pos), np.array(self.face_vert), self.name))

    def __repr__(self) -> str:
        kind = "closed" if self.closed else f"open, {len(self.border_vert)} border vertices"
        return f"Mesh({self.name!r}, nvert={self.nvert}, nface={self.nface}, {kind})"

    # -- geometry -----------------------------------------------------------

    def _pos(self, vert_pos) -> np.ndarray:
        """The rest positions, or `vert_pos` checked to be (nvert, 3)."""
        if vert_pos is None:
            return self.vert_pos
        pos = np.asarray(vert_pos, dtype=np.float64)
        if pos.shape != (self.nvert, 3):
            raise MeshError(
                f"mesh {self.name!r}: vert_pos must have shape ({self.nvert}, 3); "
                f"received shape {pos.shape}"
            )
        return pos

    def volume(self, vert_pos=None) -> float:
        """Signed enclosed volume (m^3) at `vert_pos` (nvert, 3) m, default the rest shape.

        Positive for a closed, outward surface. For an open surface it is
        relative to the mean of the positions (see module function `volume`).
        """
        return volume(self._pos(vert_pos), self.face_vert)

    def volume_gradient(self, vert_pos=None) -> np.ndarray:
        """dV/dx at `vert_pos` (default rest), (nvert, 3) m^2 (see module function)."""
        return volume_gradient(self._pos(vert_pos), self.face_vert)

    def vert_area_vector(self, vert_pos=None) -> np.ndarray:
        """Area-weighted outward normal of each vertex, (nvert, 3) m^2.

        Sum over the incident faces of (face area * unit outward normal) / 3,
        i.e. (x_b - x_a) x (x_c - x_a) / 6 per face corner. Sums to zero over a
        closed surface, and sum_i a_i . x_i = 3 V.
        """
        pos = self._pos(vert_pos)
        face = self.face_vert
        a, b, c = pos[face[:, 0]], pos[face[:, 1]], pos[face[:, 2]]
        third = _cross(b - a, c - a) / 6.0
        return _scatter_corners(face, third, third, third, self.nvert)

    def edge_length_mean(self, vert_pos=None) -> float:
        """Mean length of the unique edges (m) at `vert_pos`, default rest."""
        pos = self._pos(vert_pos)
        edge = pos[self.edge_vert[:, 1]] - pos[self.edge_vert[:, 0]]
        return float(np.mean(np.sqrt(np.sum(edge * edge, axis=1))))

    def require_closed(self, why: str) -> None:
        """Raise `MeshError` if the surface is open, naming its first border edges and `why`.

        why: what needs the closed surface, e.g. "a volume constraint needs a
        closed surface".
        """
        if self.closed:
            return
        edges = _border_edges(self.face_vert, self.nvert)
        listed = _few([f"({i}, {j})" for i, j in edges[:_FEW]], len(edges))
        raise MeshError(
            f"{why}; mesh {self.name!r} is open: {len(edges)} border edges "
            f"(used by one face only), e.g. {listed}; expected every edge shared by two faces"
        )

    def to_trimesh(self) -> trimesh.Trimesh:
        """A trimesh.Trimesh copy of the rest shape (vertices and faces kept as they are)."""
        import trimesh

        return trimesh.Trimesh(
            vertices=np.array(self.vert_pos), faces=np.array(self.face_vert, dtype=np.int64),
            process=False, validate=False,
        )


def _rebuild_mesh(vert_pos, face_vert, name):
    return Mesh(vert_pos, face_vert, name=name)


# ---------------------------------------------------------------------------
# Validation and topology (vectorized; only error paths loop in Python)
# ---------------------------------------------------------------------------


def _few(items, total: int | None = None) -> str:
    """'a, b, c' or 'a, b, c, d, e and 7 more' (items: the first few culprits)."""
    items = [str(s) for s in items]
    total = len(items) if total is None else total
    shown = items[:_FEW]
    text = ", ".join(shown)
    if total > len(shown):
        text += f" and {total - len(shown)} more"
    return text


def _face_list(face: np.ndarray, index: np.ndarray) -> str:
    """'face 3 [0, 4, 5], face 9 [...] and 2 more' for the faces in `index`."""
    return _few([f"face {f} {face[f].tolist()}" for f in index[:_FEW]], len(index))


def _check_vert_pos(vert_pos, name: str) -> np.ndarray:
    """vert_pos as a fresh C-contiguous (nvert, 3) float64 array of finite numbers."""
    try:
        arr = np.asarray(vert_pos)
    except (ValueError, TypeError) as exc:
        raise MeshError(
            f"mesh {name!r}: vert_pos must be an (nvert, 3) array of real numbers (m); "
            f"received a ragged or non-numeric sequence ({exc})"
        ) from None
    if arr.dtype.kind not in "iuf":
        raise MeshError(
            f"mesh {name!r}: vert_pos must be an (nvert, 3) array of real numbers (m); "
            f"received dtype {arr.dtype}"
        )
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 3:
        raise MeshError(
            f"mesh {name!r}: vert_pos must have shape (nvert, 3) with nvert >= 3; "
            f"received shape {arr.shape}"
        )
    if arr.shape[0] >= 2**31:
        raise MeshError(f"mesh {name!r}: at most 2**31 - 1 vertices; received {arr.shape[0]}")
    pos = np.array(arr, dtype=np.float64, order="C", copy=True)
    bad = np.flatnonzero(~np.isfinite(pos).all(axis=1))
    if bad.size:
        listed = _few([f"vertex {v} {pos[v].tolist()}" for v in bad[:_FEW]], bad.size)
        raise MeshError(
            f"mesh {name!r}: vert_pos must be finite; {bad.size} vertices have "
            f"non-finite coordinates: {listed}"
        )
    return pos


def _check_face_vert(face_vert, nvert: int, name: str) -> np.ndarray:
    """face_vert as a fresh C-contiguous (nface, 3) int32 array of indices in [0, nvert)."""
    try:
        arr = np.asarray(face_vert)
    except (ValueError, TypeError) as exc:
        raise MeshError(
            f"mesh {name!r}: face_vert must be an (nface, 3) array of integers; "
            f"received a ragged or non-numeric sequence ({exc})"
        ) from None
    if arr.dtype.kind not in "iu":
        raise MeshError(
            f"mesh {name!r}: face_vert must be an (nface, 3) array of integers; "
            f"received dtype {arr.dtype}"
        )
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 1:
        raise MeshError(
            f"mesh {name!r}: face_vert must have shape (nface, 3) with nface >= 1; "
            f"received shape {arr.shape}"
        )
    bad = np.flatnonzero(((arr < 0) | (arr >= nvert)).any(axis=1))
    if bad.size:
        raise MeshError(
            f"mesh {name!r}: face_vert indices must be in [0, {nvert}) (nvert = {nvert}); "
            f"{bad.size} faces are out of range: {_face_list(arr, bad)}"
        )
    return np.array(arr, dtype=np.int32, order="C", copy=True)


def _first_identical(rows: np.ndarray) -> np.ndarray:
    """For each row of rows (n, k), the smallest index of a row equal to it, (n,) int64.

    A row that is unique maps to itself. Uses ==, so -0.0 equals 0.0.
    """
    n = rows.shape[0]
    order = np.lexsort(rows.T[::-1])
    srt = rows[order]
    new = np.empty(n, dtype=bool)
    new[0] = True
    new[1:] = np.any(srt[1:] != srt[:-1], axis=1)
    group = np.cumsum(new) - 1
    group_min = np.minimum.reduceat(order, np.flatnonzero(new))
    first = np.empty(n, dtype=np.int64)
    first[order] = group_min[group]
    return first


def _merge_identical_vertices(vert_pos, face_vert):
    """Merge vertices with identical coordinates (STL soups), keeping first-appearance order.

    Returns (vert_pos (n', 3), face_vert (nface, 3)) with faces re-indexed.
    Only exact equality merges: nearly equal points stay apart, and then
    validation reports them (e.g. as a border or a degenerate face).
    """
    if len(vert_pos) == 0:
        return vert_pos, face_vert
    first = _first_identical(vert_pos)
    keep = np.flatnonzero(first == np.arange(len(vert_pos)))
    new_index = np.empty(len(vert_pos), dtype=np.int64)
    new_index[keep] = np.arange(len(keep))
    return vert_pos[keep], new_index[first][face_vert]


def _border_edges(face: np.ndarray, nvert: int) -> np.ndarray:
    """Directed border edges (i, j) as they appear in their face, (nborder_edge, 2), sorted."""
    he_from = face.ravel().astype(np.int64)
    he_to = face[:, [1, 2, 0]].ravel().astype(np.int64)
    key = np.minimum(he_from, he_to) * nvert + np.maximum(he_from, he_to)
    _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    border = count[inverse] == 1
    edges = np.stack([he_from[border], he_to[border]], axis=1)
    return edges[np.lexsort(edges.T[::-1])]


def _validate_and_build(pos: np.ndarray, face: np.ndarray, name: str) -> dict:
    """Check the surface and build its edges and fans; raise MeshError at the first fault.

    pos (nvert, 3) float64 finite, face (nface, 3) int32 in range (already checked).
    Returns the topology fields of `Mesh`.
    """
    nvert, nface = len(pos), len(face)
    where = f"mesh {name!r}"

    # Degenerate: a repeated index.
    repeated = np.flatnonzero(
        (face[:, 0] == face[:, 1]) | (face[:, 1] == face[:, 2]) | (face[:, 2] == face[:, 0])
    )
    if repeated.size:
        raise MeshError(
            f"{where}: {repeated.size} degenerate faces repeat a vertex index: "
            f"{_face_list(face, repeated)}; expected three distinct vertices per face"
        )

    # Duplicate faces: the same vertex set, whatever the order or orientation.
    first = _first_identical(np.sort(face, axis=1))
    dup = np.flatnonzero(first != np.arange(nface))
    if dup.size:
        listed = _few(
            [f"face {f} {face[f].tolist()} repeats face {first[f]} {face[first[f]].tolist()}"
             for f in dup[:_FEW]], dup.size,
        )
        raise MeshError(
            f"{where}: {dup.size} duplicate faces (same vertices in any order): {listed}; "
            f"expected each triangle once"
        )

    # Duplicate vertices: identical coordinates (they would split the surface).
    first = _first_identical(pos)
    dup = np.flatnonzero(first != np.arange(nvert))
    if dup.size:
        listed = _few(
            [f"vertex {v} repeats vertex {first[v]} at {pos[v].tolist()}" for v in dup[:_FEW]],
            dup.size,
        )
        raise MeshError(
            f"{where}: {dup.size} duplicate vertices (identical coordinates): {listed}; "
            f"expected distinct points (merge them and re-index face_vert)"
        )

    # Unused vertices: in no face (they would be mass points with no neighbours).
    used = np.zeros(nvert, dtype=bool)
    used[face.ravel()] = True
    unused = np.flatnonzero(~used)
    if unused.size:
        raise MeshError(
            f"{where}: {unused.size} vertices are in no face: vertices "
            f"{_few(unused[:_FEW].tolist(), unused.size)}; expected every vertex in a face"
        )

    # Degenerate: zero area relative to the mean edge length squared.
    a, b, c = pos[face[:, 0]], pos[face[:, 1]], pos[face[:, 2]]
    area = 0.5 * np.linalg.norm(_cross(b - a, c - a), axis=1)
    edge_len = np.linalg.norm(np.concatenate([b - a, c - b, a - c]), axis=1)
    area_min = _AREA_RTOL * np.mean(edge_len) ** 2
    flat = np.flatnonzero(area < area_min)
    if flat.size:
        listed = _few(
            [f"face {f} {face[f].tolist()} (area {area[f]:.3g} m^2)" for f in flat[:_FEW]],
            flat.size,
        )
        raise MeshError(
            f"{where}: {flat.size} degenerate faces have (nearly) zero area: {listed}; "
            f"expected area >= {area_min:.3g} m^2 ({_AREA_RTOL:g} * mean edge length^2)"
        )

    # Edges: half-edge a->b of face f is (he_from, he_to, he_face).
    he_from = face.ravel().astype(np.int64)
    he_to = face[:, [1, 2, 0]].ravel().astype(np.int64)
    he_face = np.repeat(np.arange(nface), 3)
    undirected = np.minimum(he_from, he_to) * nvert + np.maximum(he_from, he_to)
    edge_key, he_edge, edge_count = np.unique(
        undirected, return_inverse=True, return_counts=True
    )
    he_edge = he_edge.ravel()

    crowded = np.flatnonzero(edge_count > 2)
    if crowded.size:
        listed = _few(
            [f"edge ({edge_key[e] // nvert}, {edge_key[e] % nvert}) in {edge_count[e]} faces "
             f"{he_face[he_edge == e].tolist()}" for e in crowded[:_FEW]], crowded.size,
        )
        raise MeshError(
            f"{where}: {crowded.size} non-manifold edges: {listed}; "
            f"expected each edge in one face (border) or two faces"
        )

    directed = he_from * nvert + he_to
    order = np.argsort(directed, kind="stable")
    same = np.flatnonzero(directed[order][1:] == directed[order][:-1])
    if same.size:
        listed = _few(
            [f"edge ({he_from[order[k]]} -> {he_to[order[k]]}) in faces "
             f"{he_face[order[k]]} {face[he_face[order[k]]].tolist()} and "
             f"{he_face[order[k + 1]]} {face[he_face[order[k + 1]]].tolist()}"
             for k in same[:_FEW]], same.size,
        )
        raise MeshError(
            f"{where}: inconsistent face orientation, {same.size} edges are used twice in "
            f"the same direction: {listed}; expected neighbouring faces to run along "
            f"their shared edge in opposite directions (all counter-clockwise seen from outside)"
        )

    border_he = edge_count[he_edge] == 1
    closed = not border_he.any()
    border_vert = np.unique(np.concatenate([he_from[border_he], he_to[border_he]]))
    edge_vert = np.stack([edge_key // nvert, edge_key % nvert], axis=1)

    ring_ptr, ring_vert, ring_closed = _build_fans(face, nvert, name)

    if closed:
        vol = volume(pos, face)
        if vol < 0:
            raise MeshError(
                f"{where}: the closed surface is inward-facing (volume {vol:.6g} m^3); "
                f"expected a positive volume with faces counter-clockwise seen from outside; "
                f"flip the face orientation (face_vert[:, ::-1])"
            )
        scale = np.ptp(pos, axis=0).max()
        if vol <= 1e-12 * scale**3:
            raise MeshError(
                f"{where}: the closed surface encloses no volume ({vol:.6g} m^3 for a "
                f"bounding box of {scale:.6g} m); expected a positive volume"
            )

    return dict(
        closed=closed,
        ring_ptr=ring_ptr,
        ring_vert=ring_vert,
        ring_closed=ring_closed,
        edge_vert=edge_vert.astype(np.int32),
        border_vert=border_vert.astype(np.int32),
    )


def _build_fans(face: np.ndarray, nvert: int, name: str):
    """Ordered one-ring of every vertex; MeshError for a vertex whose faces are not one fan.

    face (nface, 3) int32, consistently oriented, every vertex used, no edge in
    more than two faces (all checked before). Returns ring_ptr (nvert + 1,),
    ring_vert (ring_ptr[-1],) int32 and ring_closed (nvert,) bool.

    Every face corner is a wedge (centre a, from b, to c): face (a, b, c) seen
    from a. The wedge whose `from` equals this wedge's `to`, around the same
    centre, is the next one counter-clockwise. Consistent orientation makes
    this successor map one-to-one, so the wedges of a vertex form paths
    (open fans) and cycles (closed fans); a valid vertex has exactly one.
    """
    centre = face.ravel().astype(np.int64)
    frm = face[:, [1, 2, 0]].ravel().astype(np.int64)
    to = face[:, [2, 0, 1]].ravel().astype(np.int64)
    nwedge = len(centre)

    # Sort wedges by (centre, from): each centre's wedges are contiguous and its
    # first wedge starts at the smallest neighbour (the start of a closed fan).
    key = centre * nvert + frm
    order = np.argsort(key, kind="stable")
    key, centre, frm, to = key[order], centre[order], frm[order], to[order]
    face_of = order // 3
    count = np.bincount(centre, minlength=nvert)
    wedge_ptr = np.concatenate([[0], np.cumsum(count)])

    succ_key = centre * nvert + to
    succ = np.searchsorted(key, succ_key)
    succ[succ == nwedge] = 0
    succ = np.where(key[succ] == succ_key, succ, -1)

    has_pred = np.zeros(nwedge, dtype=bool)
    has_pred[succ[succ >= 0]] = True
    open_start = np.flatnonzero(~has_pred)
    nopen = np.bincount(centre[open_start], minlength=nvert)
    if np.any(nopen > 1):
        _raise_fan_error(np.flatnonzero(nopen > 1), centre, face_of, face, name)

    start = wedge_ptr[:-1].copy()
    start[centre[open_start]] = open_start
    ring_closed = nopen == 0

    # Walk every fan from its start, all vertices at once; the walk stops at the
    # end of a path or back at the start of a cycle. A fan shorter than the
    # vertex's wedge count means there is more than one fan.
    rank = np.empty(nwedge, dtype=np.int64)
    rank[start] = 0
    vert = np.arange(nvert)
    cur = start
    step = 0
    while vert.size:
        step += 1
        nxt = succ[cur]
        done = (nxt < 0) | (nxt == start[vert])
        short = vert[done][count[vert[done]] != step]
        if short.size:
            _raise_fan_error(short, centre, face_of, face, name)
        vert, cur = vert[~done], nxt[~done]
        rank[cur] = step

    ring_len = count + ~ring_closed
    ring_ptr = np.concatenate([[0], np.cumsum(ring_len)])
    ring_vert = np.empty(ring_ptr[-1], dtype=np.int64)
    ring_vert[ring_ptr[centre] + rank] = frm
    # An open fan of k faces has k + 1 neighbours: close it with the last wedge's `to`.
    last = np.flatnonzero(~ring_closed[centre] & (rank == count[centre] - 1))
    ring_vert[ring_ptr[centre[last] + 1] - 1] = to[last]
    return ring_ptr.astype(np.int32), ring_vert.astype(np.int32), ring_closed


def _raise_fan_error(bad_vert, centre, face_of, face, name):
    """Raise MeshError for vertices whose faces form several fans (error path only)."""
    items = []
    for v in bad_vert[:_FEW]:
        faces = np.sort(face_of[centre == v])
        items.append(f"vertex {v} ({_count_fans(face[faces], v)} fans from faces "
                     f"{faces.tolist()})")
    raise MeshError(
        f"mesh {name!r}: {len(bad_vert)} non-manifold vertices, whose faces do not form "
        f"a single fan (surfaces touching at a point): {_few(items, len(bad_vert))}; "
        f"expected the faces around each vertex to form one closed or open fan"
    )


def _count_fans(faces: np.ndarray, v: int) -> int:
    """Number of edge-connected groups among the faces around vertex v (error path only)."""
    groups: list[set[int]] = []
    for tri in faces.tolist():
        others = {u for u in tri if u != v}
        touching = [g for g in groups if g & others]
        merged = others.union(*touching)
        groups = [g for g in groups if not (g & others)] + [merged]
    return len(groups)


# ---------------------------------------------------------------------------
# Spheres
# ---------------------------------------------------------------------------


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
