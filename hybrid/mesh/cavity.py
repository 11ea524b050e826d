"""The thoracic cavity's closed surface over a membrane's dome (`hybrid.terms.lungs`): the
dome's faces reversed and a wall raised over their border loop to a top plane, and the check
that a triangle surface is closed and consistently oriented."""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from .validate import few

__all__ = ["WALL_RINGS", "open_edges", "thoracic_cavity"]

#: the wall's rings of points between the floor's border and the top (`thoracic_cavity`)
WALL_RINGS = 4


def open_edges(face: np.ndarray) -> list:
    """The directed edges (a, b) of the triangles `face` (n, 3) that no other triangle
    closes with its edge (b, a) exactly once: empty for a closed, consistently
    oriented surface."""
    e = np.concatenate([face[:, [0, 1]], face[:, [1, 2]], face[:, [2, 0]]]).astype(np.int64)
    n = int(e.max()) + 1 if e.size else 1
    key, count = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    seen = dict(zip(key.tolist(), count.tolist()))
    bad = [(int(a), int(b)) for a, b in e if seen.get(int(a) * n + int(b)) != 1 or seen.get(int(b) * n + int(a)) != 1]
    return sorted(set(bad))


def thoracic_cavity(vert_pos: np.ndarray, floor: np.ndarray, height_m: float, what: str):
    """The cavity over the membrane's faces `floor` (module docstring): returns
    (face (nf, 3) int64, wall (nwall, 3) m, border (nb,) int64, under (nwall,) int64, weight
    (nwall,)): the floor's faces reversed and the wall's, a point i >= nvert being wall point
    i - nvert; the floor's border loop; and each wall point's carriage: the border point below
    it (-1 for the top's centre) whose rigid body moves it by `weight` of that body's motion. SceneError (naming `what`) for a
    floor without exactly one border loop, a dome above the wall's top, or open edges."""
    nvert = len(vert_pos)
    floor = np.asarray(floor, np.int64).reshape(-1, 3)
    if not len(floor):
        raise SceneError(f"{what}.floor: expected a region with faces (the dome), received none")
    directed = np.concatenate([floor[:, [0, 1]], floor[:, [1, 2]], floor[:, [2, 0]]])
    edges = {(int(a), int(b)) for a, b in directed}
    border = [(a, b) for a, b in edges if (b, a) not in edges]
    nxt: dict = {}
    for a, b in border:
        if a in nxt:
            raise SceneError(
                f"{what}.floor: expected faces whose border is one loop, received a border that meets itself "
                f"at point {a}"
            )
        nxt[a] = b
    if not nxt:
        raise SceneError(f"{what}.floor: expected an open region of the surface (the dome), received a closed one")
    loop = [min(nxt)]
    while nxt[loop[-1]] != loop[0]:
        loop.append(nxt[loop[-1]])
    if len(loop) != len(nxt):
        raise SceneError(
            f"{what}.floor: expected faces whose border is one loop, received {len(nxt)} border points of which "
            f"one loop holds {len(loop)} (a region in pieces, or with holes)"
        )
    p = vert_pos[floor]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).sum(axis=0)
    up = normal / np.linalg.norm(normal)
    ring = vert_pos[loop]
    centre = ring.mean(axis=0)
    top = float(np.max((vert_pos[np.unique(floor)] - centre) @ up))
    if not height_m > top:
        raise SceneError(
            f"{what}.wall_height_m: expected a wall above the dome, higher than {top:.4g} m over its border's "
            f"centre, received {height_m!r}"
        )
    rise = height_m - (ring - centre) @ up  # each border point's way up to the top plane (m)
    # a fixed number of rings, not the membrane's edge length: the wall is the same surface at
    # every mesh level (only its border follows the membrane), so that the cavity converges
    nring = WALL_RINGS
    n = len(loop)
    wall = [ring + (k / nring) * rise[:, None] * up for k in range(1, nring + 1)] + [(centre + height_m * up)[None]]
    wall_pos = np.concatenate(wall)

    def at(k, j):  # point j of ring k (ring 0: the border, membrane points)
        return loop[j % n] if k == 0 else nvert + (k - 1) * n + j % n

    faces = [floor[:, [0, 2, 1]]]
    side = []
    for k in range(nring):
        for j in range(n):
            a0, b0, a1, b1 = at(k, j), at(k, j + 1), at(k + 1, j), at(k + 1, j + 1)
            side += [(a0, b0, b1), (a0, b1, a1)]
    apex = nvert + nring * n
    side += [(at(nring, j), at(nring, j + 1), apex) for j in range(n)]
    faces.append(np.asarray(side, np.int64))
    face = np.concatenate(faces).astype(np.int64)
    bad = open_edges(face)
    if bad:
        raise SceneError(
            f"{what}: expected a closed thoracic cavity, received {len(bad)} open edges (point pairs, points "
            f">= {nvert} on the wall): {few(bad)}"
        )
    # the wall's carriage: ring k over border point j moves with what holds j by 1 - k / nring
    # (the border's rib at its foot, nothing at the fixed top)
    under = np.concatenate([np.asarray(loop, np.int64)] * nring + [np.array([-1], np.int64)])
    weight = np.concatenate([np.full(n, 1.0 - k / nring) for k in range(1, nring + 1)] + [np.zeros(1)])
    return face, wall_pos, np.asarray(loop, np.int64), under, weight
