"""Validation of a triangle surface and the building of its ordered one-ring fans.

`check_vert_pos` and `check_face_vert` turn user input into fresh, typed
arrays; `validate_and_build` then checks the surface (degenerate, duplicate
and unused elements, manifold edges and vertices, orientation, closed
surfaces facing outward) and builds the topology fields of `Mesh`: unique
edges, border vertices and the one-ring fans in CSR form (the fan layout is
described in `hybrid.mesh.surface`). Everything is vectorized; only error
paths loop in Python. Every fault raises `MeshError` naming the first few
culprits.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import MeshError

from .geometry import cross_rows, volume

__all__ = [
    "check_vert_pos",
    "check_face_vert",
    "validate_and_build",
    "merge_identical_vertices",
    "border_edges",
    "few",
    "FEW",
]

#: a face is degenerate if its area is below this times the mean edge length squared
_AREA_RTOL = 1e-14

#: how many culprits an error message lists before "and N more"
FEW = 5


def few(culprits, describe=str) -> str:
    """'a, b, c' or 'a, b, c, d, e and 7 more': the first FEW of `culprits` (a
    sequence or an index array), each as describe(culprit), and how many more."""
    shown = [describe(k) for k in culprits[:FEW]]
    text = ", ".join(shown)
    if len(culprits) > len(shown):
        text += f" and {len(culprits) - len(shown)} more"
    return text


def _refuse(where: str, culprits, problem: str, describe, expected: str) -> None:
    """Raise MeshError '{where}: {n} {problem}: {the first few culprits}; {expected}'
    if there are any culprits (describe(culprit) names one)."""
    if len(culprits):
        raise MeshError(f"{where}: {len(culprits)} {problem}: {few(culprits, describe)}; {expected}")


def _face(face: np.ndarray, f: int) -> str:
    """'face 3 [0, 4, 5]': face f and its corners."""
    return f"face {f} {face[f].tolist()}"


def _rows_of_three(value, field: str, rows: str, min_rows: int, kinds: str, of_what: str, name: str) -> np.ndarray:
    """value as an array of shape (rows, 3) with at least min_rows rows and a dtype
    kind in `kinds` (not yet copied); MeshError naming `field` otherwise.

    rows: the name of the row count ("nvert"); of_what: the element type in the
    message ("integers").
    """
    expected = f"mesh {name!r}: {field} must be an ({rows}, 3) array of {of_what}"
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as exc:
        raise MeshError(f"{expected}; received a ragged or non-numeric sequence ({exc})") from None
    if arr.dtype.kind not in kinds:
        raise MeshError(f"{expected}; received dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < min_rows:
        raise MeshError(
            f"mesh {name!r}: {field} must have shape ({rows}, 3) with {rows} >= {min_rows}; received shape {arr.shape}"
        )
    return arr


def check_vert_pos(vert_pos, name: str) -> np.ndarray:
    """vert_pos as a fresh C-contiguous (nvert, 3) float64 array of finite numbers."""
    arr = _rows_of_three(vert_pos, "vert_pos", "nvert", 3, "iuf", "real numbers (m)", name)
    if arr.shape[0] >= 2**31:
        raise MeshError(f"mesh {name!r}: at most 2**31 - 1 vertices; received {arr.shape[0]}")
    pos = np.array(arr, dtype=np.float64, order="C", copy=True)
    bad = np.flatnonzero(~np.isfinite(pos).all(axis=1))
    if bad.size:
        listed = few(bad, lambda v: f"vertex {v} {pos[v].tolist()}")
        raise MeshError(
            f"mesh {name!r}: vert_pos must be finite; {bad.size} vertices have non-finite coordinates: {listed}"
        )
    return pos


def check_face_vert(face_vert, nvert: int, name: str) -> np.ndarray:
    """face_vert as a fresh C-contiguous (nface, 3) int32 array of indices in [0, nvert)."""
    arr = _rows_of_three(face_vert, "face_vert", "nface", 1, "iu", "integers", name)
    bad = np.flatnonzero(((arr < 0) | (arr >= nvert)).any(axis=1))
    if bad.size:
        raise MeshError(
            f"mesh {name!r}: face_vert indices must be in [0, {nvert}) (nvert = {nvert}); "
            f"{bad.size} faces are out of range: {few(bad, lambda f: _face(arr, f))}"
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


def merge_identical_vertices(vert_pos, face_vert):
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


def border_edges(face: np.ndarray, nvert: int) -> np.ndarray:
    """Directed border edges (i, j) as they appear in their face, (nborder_edge, 2), sorted."""
    he_from = face.ravel().astype(np.int64)
    he_to = face[:, [1, 2, 0]].ravel().astype(np.int64)
    key = np.minimum(he_from, he_to) * nvert + np.maximum(he_from, he_to)
    _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    border = count[inverse] == 1
    edges = np.stack([he_from[border], he_to[border]], axis=1)
    return edges[np.lexsort(edges.T[::-1])]


def validate_and_build(pos: np.ndarray, face: np.ndarray, name: str) -> dict:
    """Check the surface and build its edges and fans; raise MeshError at the first fault.

    pos (nvert, 3) float64 finite, face (nface, 3) int32 in range (already checked).
    Returns the topology fields of `Mesh`.
    """
    nvert, nface = len(pos), len(face)
    where = f"mesh {name!r}"

    # Degenerate: a repeated index.
    repeated = np.flatnonzero((face[:, 0] == face[:, 1]) | (face[:, 1] == face[:, 2]) | (face[:, 2] == face[:, 0]))
    _refuse(
        where,
        repeated,
        "degenerate faces repeat a vertex index",
        lambda f: _face(face, f),
        "expected three distinct vertices per face",
    )

    # Duplicate faces: the same vertex set, whatever the order or orientation.
    first = _first_identical(np.sort(face, axis=1))
    dup = np.flatnonzero(first != np.arange(nface))
    _refuse(
        where,
        dup,
        "duplicate faces (same vertices in any order)",
        lambda f: f"{_face(face, f)} repeats {_face(face, first[f])}",
        "expected each triangle once",
    )

    # Duplicate vertices: identical coordinates (they would split the surface).
    first = _first_identical(pos)
    dup = np.flatnonzero(first != np.arange(nvert))
    _refuse(
        where,
        dup,
        "duplicate vertices (identical coordinates)",
        lambda v: f"vertex {v} repeats vertex {first[v]} at {pos[v].tolist()}",
        "expected distinct points (merge them and re-index face_vert)",
    )

    # Unused vertices: in no face (they would be mass points with no neighbours).
    used = np.zeros(nvert, dtype=bool)
    used[face.ravel()] = True
    unused = np.flatnonzero(~used)
    if unused.size:
        raise MeshError(
            f"{where}: {unused.size} vertices are in no face: vertices {few(unused)}; expected every vertex in a face"
        )

    # Degenerate: zero area relative to the mean edge length squared.
    a, b, c = pos[face[:, 0]], pos[face[:, 1]], pos[face[:, 2]]
    area = 0.5 * np.linalg.norm(cross_rows(b - a, c - a), axis=1)
    edge_len = np.linalg.norm(np.concatenate([b - a, c - b, a - c]), axis=1)
    area_min = _AREA_RTOL * np.mean(edge_len) ** 2
    flat = np.flatnonzero(area < area_min)
    _refuse(
        where,
        flat,
        "degenerate faces have (nearly) zero area",
        lambda f: f"{_face(face, f)} (area {area[f]:.3g} m^2)",
        f"expected area >= {area_min:.3g} m^2 ({_AREA_RTOL:g} * mean edge length^2)",
    )

    # Edges: half-edge a->b of face f is (he_from, he_to, he_face).
    he_from = face.ravel().astype(np.int64)
    he_to = face[:, [1, 2, 0]].ravel().astype(np.int64)
    he_face = np.repeat(np.arange(nface), 3)
    undirected = np.minimum(he_from, he_to) * nvert + np.maximum(he_from, he_to)
    edge_key, he_edge, edge_count = np.unique(undirected, return_inverse=True, return_counts=True)
    he_edge = he_edge.ravel()

    crowded = np.flatnonzero(edge_count > 2)
    _refuse(
        where,
        crowded,
        "non-manifold edges",
        lambda e: (
            f"edge ({edge_key[e] // nvert}, {edge_key[e] % nvert}) in {edge_count[e]} faces "
            f"{he_face[he_edge == e].tolist()}"
        ),
        "expected each edge in one face (border) or two faces",
    )

    directed = he_from * nvert + he_to
    order = np.argsort(directed, kind="stable")
    same = np.flatnonzero(directed[order][1:] == directed[order][:-1])
    if same.size:
        listed = few(
            same,
            lambda k: (
                f"edge ({he_from[order[k]]} -> {he_to[order[k]]}) in faces "
                f"{he_face[order[k]]} {face[he_face[order[k]]].tolist()} and "
                f"{he_face[order[k + 1]]} {face[he_face[order[k + 1]]].tolist()}"
            ),
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

    def fans_of(v):
        faces = np.sort(face_of[centre == v])
        return f"vertex {v} ({_count_fans(face[faces], v)} fans from faces {faces.tolist()})"

    _refuse(
        f"mesh {name!r}",
        bad_vert,
        "non-manifold vertices, whose faces do not form a single fan (surfaces touching at a point)",
        fans_of,
        "expected the faces around each vertex to form one closed or open fan",
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
