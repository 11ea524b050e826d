"""Named vertex sets of a membrane, chosen by indices or by geometry.

A region is a selector evaluated once, on the rest positions, when the model
is compiled. Selectors combine (`Union`, `Intersection`, `Difference`) so
that a segmented anatomy mesh can be split without writing indices by hand.
A `Patch` is a region of physical size: its area on the mesh is checked
against the area its radius implies.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np

from .errors import SceneError
from .mesh.geometry import region_faces, vertex_area

__all__ = [
    "Indices",
    "HalfSpace",
    "Ball",
    "Box",
    "Wedge",
    "Nearest",
    "Patch",
    "All",
    "Border",
    "Union_",
    "Intersection",
    "Difference",
    "Selector",
    "select",
    "contains",
    "select_faces",
]


def _vec3(v, name):
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise SceneError(f"{name}: expected a 3-vector of finite floats, received {v!r}")
    return a


@dataclass(frozen=True)
class All:
    """Every vertex."""


@dataclass(frozen=True)
class Border:
    """The border vertices of an open surface."""


@dataclass(frozen=True)
class Indices:
    """Explicit vertex indices."""

    indices: tuple[int, ...]


@dataclass(frozen=True)
class HalfSpace:
    """Vertices with (x - point) . normal >= 0 (m)."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]


@dataclass(frozen=True)
class Ball:
    """Vertices within `radius` (m) of `center` (m)."""

    center: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Box:
    """Vertices inside the axis-aligned box [lo, hi] (m)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


#: angular tolerance (rad) of a wedge's borders: a mesh conforming to them
#: (`mesh.conform_azimuth_deg`) has its border columns in the wedges on both sides
WEDGE_TOL_RAD = 1e-9


@dataclass(frozen=True)
class Wedge:
    """Vertices whose azimuth about the vertical (z) axis through `center` (m) lies
    from `from_deg` to `to_deg` (degrees from +x toward +y, counter-clockwise seen
    from +z; the wedge may cross 180), borders included."""

    from_deg: float
    to_deg: float
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Nearest:
    """For each given point (m), the nearest vertex."""

    points: tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class Patch:
    """A disc of the surface: the points within `radius_m` (m, straight-line distance)
    of the surface point nearest to `center` (m). Its points' cells (a third of
    each face's area per point) must cover pi radius_m^2 (the area a ball centred
    on a sphere cuts from it, exactly, and on any smooth surface to second order)
    within a rim of one local edge length; otherwise the region is refused."""

    center: tuple[float, float, float]
    radius_m: float


@dataclass(frozen=True)
class Union_:
    parts: tuple


@dataclass(frozen=True)
class Intersection:
    parts: tuple


@dataclass(frozen=True)
class Difference:
    """Vertices of `base` that are not in `minus`."""

    base: object
    minus: object


Selector = Union[
    All, Border, Indices, HalfSpace, Ball, Box, Wedge, Nearest, Patch, Union_, Intersection, Difference, str
]


def select_on(sel: Selector, mesh, *, name: str, regions: dict | None = None) -> np.ndarray:
    """`select` on a `hybrid.mesh.Mesh`: its rest positions, border, faces and, for a mesh
    refined from a file, its `refinement` (what every region of a scene is evaluated with)."""
    return select(
        sel,
        mesh.vert_pos,
        name=name,
        regions=regions,
        border_vert=mesh.border_vert,
        face_vert=mesh.face_vert,
        refinement=mesh.refinement,
    )


def faces_on(sel: Selector, mesh, selectors: dict, verts: np.ndarray, *, name: str) -> np.ndarray:
    """`faces_of` on a `hybrid.mesh.Mesh` (its refinement included)."""
    return faces_of(sel, mesh.vert_pos, mesh.face_vert, selectors, verts, name=name, refinement=mesh.refinement)


def contains(sel, cls) -> bool:
    """Whether selector `sel` uses a selector of class `cls` (region names not followed)."""
    if isinstance(sel, cls):
        return True
    if isinstance(sel, (Union_, Intersection)):
        return any(contains(p, cls) for p in sel.parts)
    if isinstance(sel, Difference):
        return contains(sel.base, cls) or contains(sel.minus, cls)
    return False


def select(
    sel: Selector,
    vert_pos: np.ndarray,
    *,
    name: str,
    regions: dict | None = None,
    border_vert: np.ndarray | None = None,
    face_vert: np.ndarray | None = None,
    refinement=None,
) -> np.ndarray:
    """Evaluate a selector on rest positions vert_pos (nvert, 3) m.

    Returns sorted unique int32 indices. A string names a region already
    defined in `regions`. Raises SceneError, naming the region, when the
    selector is malformed or selects no vertex, or a `Patch` (which needs the
    faces face_vert) covers an area its radius does not explain.
    """
    idx = _select(sel, vert_pos, name, regions or {}, (border_vert, face_vert, refinement))
    if refinement is not None and refinement.carry_geometry and not contains(sel, (Nearest, Patch, Border)):
        # the region on the file's points (which keep their indices and positions), carried
        n0 = len(refinement.coarse_pos)
        carried = refinement.carry_points(idx[idx < n0], len(vert_pos))
        idx = carried if carried.size else idx
    idx = np.unique(idx).astype(np.int32)
    if idx.size == 0:
        raise SceneError(
            f"region {name!r}: expected at least one vertex, the selector {sel!r} "
            f"selects none of the {len(vert_pos)} vertices"
        )
    return idx


def _names_in(sel, depth: int = 0) -> list:
    """The region names a selector refers to (not "all")."""
    if depth > MAX_SELECTOR_DEPTH:
        return []
    if isinstance(sel, str):
        return [] if sel == "all" else [sel]
    if isinstance(sel, (Union_, Intersection)):
        return [n for p in sel.parts for n in _names_in(p, depth + 1)]
    if isinstance(sel, Difference):
        return _names_in(sel.base, depth + 1) + _names_in(sel.minus, depth + 1)
    return []


def check_region_names(regions: dict) -> None:
    """A scene's regions: none named "all" (the built-in region of every point, which a
    definition would silently shadow) and none that refers to itself through others (a
    cycle), each refused on one line naming it."""
    if "all" in regions:
        raise SceneError(
            f"regions.all: expected a name other than 'all' (the built-in region of every point), "
            f"received a definition of it: {regions['all']!r:.80}"
        )
    refs = {name: _names_in(sel) for name, sel in regions.items()}
    done: set = set()  # regions whose references hold no cycle
    for start in refs:
        if start in done:
            continue
        path, todo = [start], [iter(refs[start])]
        while todo:  # depth first, each region left once done: linear in the references
            nxt = next(todo[-1], None)
            if nxt is None:
                done.add(path.pop())
                todo.pop()
            elif nxt in path:
                cycle = path[path.index(nxt) :] + [nxt]
                raise SceneError(
                    f"region {nxt!r}: expected a region that does not refer to itself, received the cycle "
                    f"{' -> '.join(map(repr, cycle))}"
                )
            elif nxt in refs and nxt not in done:
                path.append(nxt)
                todo.append(iter(refs[nxt]))


#: how deep union, intersection and difference may nest (a scene needs a few levels)
MAX_SELECTOR_DEPTH = 32


def _select(sel, vert_pos, name, regions, surface, depth=0) -> np.ndarray:
    nvert = len(vert_pos)
    border_vert, face_vert, refinement = surface
    if depth > MAX_SELECTOR_DEPTH:
        raise SceneError(
            f"region {name!r}: selectors nested more than {MAX_SELECTOR_DEPTH} levels deep; "
            f"expected at most {MAX_SELECTOR_DEPTH} (name an inner part as a region instead)"
        )
    if isinstance(sel, str):
        if sel == "all":
            return np.arange(nvert)
        if sel not in regions:
            raise SceneError(
                f"region {name!r}: refers to region {sel!r}, which is not defined; "
                f"defined regions: {sorted(regions) + ['all']}"
            )
        return regions[sel]
    if isinstance(sel, All):
        return np.arange(nvert)
    if isinstance(sel, Border):
        return np.asarray(border_vert if border_vert is not None else [], dtype=np.int64)
    if isinstance(sel, Indices):
        idx = np.asarray(sel.indices)
        if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
            raise SceneError(f"region {name!r}: expected a list of vertex indices, received {sel.indices!r}")
        # on a mesh refined from a file, the indices are the file's points (they keep theirs)
        given = nvert if refinement is None else len(refinement.coarse_pos)
        bad = idx[(idx < 0) | (idx >= given)]
        if bad.size:
            raise SceneError(f"region {name!r}: vertex indices must lie in [0, {given}), received {bad[:5].tolist()}")
        return idx if refinement is None else refinement.carry_points(idx, nvert)
    if isinstance(sel, HalfSpace):
        p, n = _vec3(sel.point, f"region {name!r}.point"), _vec3(sel.normal, f"region {name!r}.normal")
        if np.linalg.norm(n) == 0:
            raise SceneError(f"region {name!r}.normal: expected a non-zero vector, received {sel.normal!r}")
        return np.nonzero((vert_pos - p) @ n >= 0)[0]
    if isinstance(sel, Ball):
        c = _vec3(sel.center, f"region {name!r}.center")
        if not (sel.radius > 0):
            raise SceneError(f"region {name!r}.radius: expected > 0 m, received {sel.radius!r}")
        return np.nonzero(np.linalg.norm(vert_pos - c, axis=1) <= sel.radius)[0]
    if isinstance(sel, Box):
        lo, hi = _vec3(sel.lo, f"region {name!r}.lo"), _vec3(sel.hi, f"region {name!r}.hi")
        if np.any(hi < lo):
            raise SceneError(f"region {name!r}: expected lo <= hi componentwise, received lo={sel.lo!r} hi={sel.hi!r}")
        return np.nonzero(np.all((vert_pos >= lo) & (vert_pos <= hi), axis=1))[0]
    if isinstance(sel, Wedge):
        return _wedge(sel, vert_pos, name)
    if isinstance(sel, Nearest):
        pts = np.asarray(sel.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
            raise SceneError(f"region {name!r}.points: expected a list of 3-vectors, received {sel.points!r}")
        d2 = ((vert_pos[None, :, :] - pts[:, None, :]) ** 2).sum(-1)
        return np.argmin(d2, axis=1)
    if isinstance(sel, Patch):
        return _patch(sel, vert_pos, face_vert, name)
    if isinstance(sel, (Union_, Intersection)):
        parts = [set(_select(p, vert_pos, name, regions, surface, depth + 1).tolist()) for p in sel.parts]
        if not parts:
            return np.zeros(0, np.int64)
        out = set.union(*parts) if isinstance(sel, Union_) else set.intersection(*parts)
        return np.array(sorted(out), dtype=np.int64)
    if isinstance(sel, Difference):
        a = _select(sel.base, vert_pos, name, regions, surface, depth + 1)
        b = _select(sel.minus, vert_pos, name, regions, surface, depth + 1)
        return np.setdiff1d(a, b)
    raise SceneError(
        f"region {name!r}: expected a selector (indices, half_space, ball, box, wedge, nearest, patch, "
        f"all, border, union, intersection, difference or a region name), received {sel!r}"
    )


def _wedge(sel: Wedge, vert_pos: np.ndarray, name: str) -> np.ndarray:
    c = _vec3(sel.center, f"region {name!r}.center")
    lo, hi = float(sel.from_deg), float(sel.to_deg)
    if not (np.isfinite(lo) and np.isfinite(hi) and abs(lo) <= 360.0 and abs(hi) <= 360.0):
        raise SceneError(
            f"region {name!r}: expected from_deg and to_deg in [-360, 360] degrees, "
            f"received from_deg={sel.from_deg!r} to_deg={sel.to_deg!r}"
        )
    d = vert_pos - c
    az = np.arctan2(d[:, 1], d[:, 0])
    # the angle turned counter-clockwise from the wedge's first border, in [0, 2 pi)
    span = np.deg2rad(np.mod(hi - lo, 360.0) if np.mod(hi - lo, 360.0) or hi == lo else 360.0)
    turn = np.mod(az - np.deg2rad(lo), 2.0 * np.pi)
    turn = np.where(turn > 2.0 * np.pi - WEDGE_TOL_RAD, turn - 2.0 * np.pi, turn)  # just below the first border
    on_axis = np.hypot(d[:, 0], d[:, 1]) == 0.0  # no azimuth
    return np.nonzero((turn <= span + WEDGE_TOL_RAD) & ~on_axis)[0]


def _patch(sel: Patch, vert_pos, face_vert, name) -> np.ndarray:
    """The points of a Patch, its area checked (see `Patch`)."""
    c = _vec3(sel.center, f"region {name!r}.center")
    r = sel.radius_m
    if not (isinstance(r, (int, float)) and not isinstance(r, bool) and 0 < r < np.inf):
        raise SceneError(f"region {name!r}.radius_m: expected a number > 0 m, received {r!r}")
    if face_vert is None:
        raise SceneError(f"region {name!r}: a patch needs the surface's faces; expected select(..., face_vert=...)")
    pos = np.asarray(vert_pos, float)
    face = np.asarray(face_vert)
    q = nearest_surface_point(pos, face, c)
    idx = np.nonzero(np.linalg.norm(pos - q, axis=1) <= r)[0]
    if idx.size == 0:
        return idx  # refused by `select`, naming the region
    area = float(vertex_area(pos, face)[idx].sum())
    touched = face[np.isin(face, idx).any(axis=1)]
    p = pos[touched]
    h = float(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).mean())  # the edge length at the patch
    want = np.pi * r * r
    tol = 2 * np.pi * r * h + np.pi * h * h  # a rim of one edge length
    if abs(area - want) > tol:
        raise SceneError(
            f"region {name!r}: a patch of radius_m = {r:g} m covers {area:.4g} m^2 of this mesh, "
            f"expected pi r^2 = {want:.4g} m^2 within {tol:.3g} m^2 (a rim of one edge length, "
            f"{h:.3g} m); widen the patch or refine the mesh (or the patch leaves the surface)"
        )
    return idx


def nearest_surface_point(vert_pos: np.ndarray, face_vert: np.ndarray, point) -> np.ndarray:
    """The point of the triangle surface (vert_pos, face_vert) nearest to `point` (3,) m:
    on each face the projection on its plane when it falls inside, else the nearest
    point of its edges; the nearest of these."""
    pos = np.asarray(vert_pos, float)
    x = np.asarray(point, float)
    a, b, c = (pos[np.asarray(face_vert)[:, k]] for k in range(3))
    cand: list[np.ndarray] = []
    for p0, p1 in ((a, b), (b, c), (c, a)):  # the nearest point of each edge segment
        d = p1 - p0
        t = np.clip(np.sum((x - p0) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), 1e-300), 0.0, 1.0)
        cand.append(p0 + t[:, None] * d)
    n = np.cross(b - a, c - a)
    nn = np.sum(n * n, axis=1)
    ok = nn > 0
    proj = x - (np.sum((x - a) * n, axis=1) / np.where(ok, nn, 1.0))[:, None] * n
    inside = ok.copy()
    for p0, p1 in ((a, b), (b, c), (c, a)):  # the projection lies left of every edge
        inside &= np.sum(np.cross(p1 - p0, proj - p0) * n, axis=1) >= 0
    cand.append(np.where(inside[:, None], proj, cand[0]))
    cands = np.stack(cand)  # (4, nface, 3)
    d2 = np.sum((cands - x) ** 2, axis=2)
    k, f = np.unravel_index(np.argmin(d2), d2.shape)
    return cands[k, f]


def _expand(sel, selectors: dict, depth: int = 0):
    """`sel` with every region name replaced by its selector (recursively)."""
    if depth > MAX_SELECTOR_DEPTH:
        raise SceneError(f"selectors nested more than {MAX_SELECTOR_DEPTH} levels deep")
    if isinstance(sel, str):
        return All() if sel == "all" else _expand(selectors[sel], selectors, depth + 1)
    if isinstance(sel, Union_):
        return Union_(tuple(_expand(p, selectors, depth + 1) for p in sel.parts))
    if isinstance(sel, Intersection):
        return Intersection(tuple(_expand(p, selectors, depth + 1) for p in sel.parts))
    if isinstance(sel, Difference):
        return Difference(_expand(sel.base, selectors, depth + 1), _expand(sel.minus, selectors, depth + 1))
    return sel


def select_faces(
    sel: Selector, vert_pos: np.ndarray, face_vert: np.ndarray, selectors: dict, *, name: str
) -> np.ndarray | None:
    """The faces whose centroid the selector holds, for a selector of geometry only
    (half-spaces, balls, boxes and their combinations, names of such regions): on
    a mesh whose edges follow the region's border (e.g. `mesh.conform_z_m`) these
    are exactly the faces inside it. None for a selector of points (indices,
    border, nearest, patch), whose faces are then those with two points in it."""
    try:
        geo = _expand(sel, selectors)
    except KeyError:
        return None
    if any(contains(geo, cls) for cls in (Indices, Border, Nearest, Patch)):
        return None
    tri = np.asarray(vert_pos)[np.asarray(face_vert)]
    return np.unique(_select(geo, tri.mean(axis=1), name, {}, (None, None, None))).astype(np.int64)


def faces_of(
    sel: Selector,
    vert_pos: np.ndarray,
    face_vert: np.ndarray,
    selectors: dict,
    verts: np.ndarray,
    *,
    name: str,
    refinement=None,
) -> np.ndarray:
    """A region's faces, by the one rule the terms and the readouts share: those whose
    centroid it holds for a region of geometry (`select_faces`), else those with two
    of their points among its points `verts`. On a mesh refined from a file
    (`refinement`), a region given by the file's points (`Indices`) has the faces inside
    its faces on the file's mesh: its border follows the file's edges at every level."""
    if refinement is not None and refinement.carry_geometry and not _topological(sel, selectors):
        # the faces inside the region's faces on the file's mesh, by the same rule there
        coarse, coarse_face = refinement.coarse_pos, refinement.coarse_face
        own = select_faces(sel, coarse, coarse_face, selectors, name=name)
        if own is None:
            own = region_faces(coarse_face, verts[verts < len(coarse)], len(coarse))
        return np.nonzero(np.isin(refinement.face_parent, own))[0]
    faces = select_faces(sel, vert_pos, face_vert, selectors, name=name)
    if faces is not None:
        return faces
    if refinement is not None and _given_by_points(sel, selectors):
        coarse = refinement.coarse_pos
        pts = _select(_expand(sel, selectors), coarse, name, {}, (None, refinement.coarse_face, None))
        own = region_faces(refinement.coarse_face, pts, len(coarse))
        return np.nonzero(np.isin(refinement.face_parent, own))[0]
    return region_faces(face_vert, verts, len(vert_pos))


def _topological(sel, selectors) -> bool:
    """Whether a selector depends on the mesh's topology (nearest point, patch, border),
    which a coarser mesh does not share."""
    try:
        return contains(_expand(sel, selectors), (Nearest, Patch, Border))
    except KeyError:
        return True


def _given_by_points(sel, selectors) -> bool:
    try:
        return contains(_expand(sel, selectors), Indices)
    except KeyError:
        return False
