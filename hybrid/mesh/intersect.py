"""Self-intersection of a triangle surface: the pairs of faces that cross.

A volume constraint needs a surface that bounds one region: a surface that
passes through itself counts the overlap twice (or with opposite signs), so
its "volume" is not the body's. trimesh has no test for it (its collision
manager needs python-fcl and compares separate meshes), hence this one: a
uniform grid of cells about the size of a face (each face listed in every
cell its bounding box touches, numpy) gives the candidate pairs, and a
compiled loop tests each pair once with the signs of signed volumes (a
40,962-point icosphere takes about half a second).

Two triangles that are not coplanar meet when an edge of one meets the
other. Faces sharing no corner must not meet at all (touching counts: the
surface would be in contact with itself); faces sharing an edge meet along it
and are not tested; faces sharing one vertex cross when the edge opposite
that vertex in one of them meets the other. Coplanar overlaps are not found.

A small surface (up to `PLAIN_MAX_FACES` faces) is tested by the same functions
run as plain Python: that takes less than compiling them on a first run.
"""

from __future__ import annotations

import functools
import types

import numpy as np

from ..kernel import jit

__all__ = ["crossing_faces"]

#: grid cells per face beyond which the cell is doubled (a few huge faces)
_CELLS_PER_FACE = 16
#: faces up to which the pairs are tested in plain Python (about 0.3 ms a face,
#: against about 1.5 s to compile the test once)
PLAIN_MAX_FACES = 600


@jit
def _orient(p, q, r, s):
    """Sign of the signed volume of the tetrahedron (p, q, r, s), each a (3,) row."""
    ux, uy, uz = q[0] - p[0], q[1] - p[1], q[2] - p[2]
    vx, vy, vz = r[0] - p[0], r[1] - p[1], r[2] - p[2]
    wx, wy, wz = s[0] - p[0], s[1] - p[1], s[2] - p[2]
    d = ux * (vy * wz - vz * wy) + uy * (vz * wx - vx * wz) + uz * (vx * wy - vy * wx)
    return int(d > 0.0) - int(d < 0.0)  # int: plain Python cannot subtract numpy booleans


@jit
def _segment_meets(p, q, a, b, c):
    """Whether segment pq meets triangle abc (touching counts; lying in its plane does not)."""
    sp, sq = _orient(a, b, c, p), _orient(a, b, c, q)
    if sp * sq > 0 or (sp == 0 and sq == 0):
        return False
    e1, e2, e3 = _orient(p, q, a, b), _orient(p, q, b, c), _orient(p, q, c, a)
    if e1 == 0 and e2 == 0 and e3 == 0:
        return False
    return (e1 >= 0 and e2 >= 0 and e3 >= 0) or (e1 <= 0 and e2 <= 0 and e3 <= 0)


@jit
def _faces_meet(pos, face, f, g):
    """Whether faces f and g cross (see the module docstring for the rules)."""
    shared = 0
    kf = kg = 0
    for i in range(3):
        for j in range(3):
            if face[f, i] == face[g, j]:
                shared += 1
                kf, kg = i, j
    if shared >= 2:
        return False
    if shared == 1:  # the edge opposite the shared corner, of each face, against the other
        return _segment_meets(
            pos[face[f, (kf + 1) % 3]], pos[face[f, (kf + 2) % 3]], pos[face[g, 0]], pos[face[g, 1]], pos[face[g, 2]]
        ) or _segment_meets(
            pos[face[g, (kg + 1) % 3]], pos[face[g, (kg + 2) % 3]], pos[face[f, 0]], pos[face[f, 1]], pos[face[f, 2]]
        )
    for t, o in ((f, g), (g, f)):
        for k in range(3):
            if _segment_meets(
                pos[face[t, k]], pos[face[t, (k + 1) % 3]], pos[face[o, 0]], pos[face[o, 1]], pos[face[o, 2]]
            ):
                return True
    return False


@jit
def _test_cells(pos, face, lo, hi, origin, cell, key, fid, cell_of, out):
    """Every pair of faces listed in one cell (entries sorted by cell key), tested
    once: in the cell holding the lowest corner of the overlap of their boxes.
    The first len(out) crossing pairs go to out; returns how many cross."""
    n = key.shape[0]
    found = 0
    start = 0
    while start < n:
        end = start
        while end < n and key[end] == key[start]:
            end += 1
        for x in range(start, end):
            f = fid[x]
            for y in range(x + 1, end):
                g = fid[y]
                apart = False
                lowest = True
                for a in range(3):
                    if lo[f, a] > hi[g, a] or lo[g, a] > hi[f, a]:
                        apart = True
                    if np.floor((max(lo[f, a], lo[g, a]) - origin[a]) / cell) != cell_of[x, a]:
                        lowest = False
                if apart or not lowest or not _faces_meet(pos, face, f, g):
                    continue
                if found < out.shape[0]:
                    out[found, 0] = min(f, g)
                    out[found, 1] = max(f, g)
                found += 1
        start = end
    return found


@functools.cache
def _plain_test_cells():
    """`_test_cells` as plain Python, calling the plain Python of its compiled callees."""
    space = dict(globals())
    for name in ("_orient", "_segment_meets", "_faces_meet", "_test_cells"):
        py = globals()[name].py_func
        space[name] = types.FunctionType(py.__code__, space, name, py.__defaults__, py.__closure__)
    return space["_test_cells"]


def crossing_faces(vert_pos: np.ndarray, face_vert: np.ndarray, *, most: int = 1000):
    """The pairs of faces that meet though they should not: ((k, 2) int64 array
    of the first `most` pairs (f, g), f < g, sorted; the number of pairs).

    vert_pos (nvert, 3) m, face_vert (nface, 3) int (a validated surface).
    """
    pos = np.asarray(vert_pos, dtype=np.float64)
    face = np.ascontiguousarray(face_vert, dtype=np.int64)
    pos = np.ascontiguousarray(pos - pos.mean(axis=0))  # signed volumes of the size of the body
    corner = pos[face]
    lo, hi = corner.min(axis=1), corner.max(axis=1)
    nface = len(face)
    origin = lo.min(axis=0)
    cell = max(float(np.median(np.max(hi - lo, axis=1))), 1e-300)
    while True:
        ilo = np.floor((lo - origin) / cell).astype(np.int64)
        span = np.floor((hi - origin) / cell).astype(np.int64) - ilo + 1
        count = np.prod(span, axis=1)
        if count.sum() <= _CELLS_PER_FACE * nface:
            break
        cell *= 2.0
    dims = ilo.max(axis=0) + span.max(axis=0) + 1
    fid = np.repeat(np.arange(nface), count)
    local = np.arange(len(fid)) - np.repeat(np.cumsum(count) - count, count)
    sx, sy = span[fid, 0], span[fid, 1]
    cell_of = np.stack(
        [ilo[fid, 0] + local % sx, ilo[fid, 1] + (local // sx) % sy, ilo[fid, 2] + local // (sx * sy)], axis=1
    )
    key = (cell_of[:, 2] * dims[1] + cell_of[:, 1]) * dims[0] + cell_of[:, 0]
    order = np.argsort(key, kind="stable")
    out = np.empty((most, 2), dtype=np.int64)
    test = _plain_test_cells() if nface <= PLAIN_MAX_FACES else _test_cells
    found = test(
        pos,
        face,
        lo,
        hi,
        origin,
        cell,
        key[order],
        fid[order],
        np.ascontiguousarray(cell_of[order], dtype=np.float64),
        out,
    )
    pairs = out[: min(found, most)]
    return pairs[np.lexsort(pairs.T[::-1])], int(found)
