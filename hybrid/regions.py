"""Named vertex sets of a membrane, chosen by indices or by geometry.

A region is a selector evaluated once, on the rest positions, when the model
is compiled. Selectors combine (`Union`, `Intersection`, `Difference`) so
that a segmented anatomy mesh can be split without writing indices by hand.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np

from .errors import SceneError

__all__ = ["Indices", "HalfSpace", "Ball", "Box", "Nearest", "All", "Border",
           "Union_", "Intersection", "Difference", "Selector", "select", "contains"]


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


@dataclass(frozen=True)
class Nearest:
    """For each given point (m), the nearest vertex."""
    points: tuple[tuple[float, float, float], ...]


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


Selector = Union[All, Border, Indices, HalfSpace, Ball, Box, Nearest, Union_, Intersection,
                 Difference, str]


def contains(sel, cls) -> bool:
    """Whether selector `sel` uses a selector of class `cls` (region names not followed)."""
    if isinstance(sel, cls):
        return True
    if isinstance(sel, (Union_, Intersection)):
        return any(contains(p, cls) for p in sel.parts)
    if isinstance(sel, Difference):
        return contains(sel.base, cls) or contains(sel.minus, cls)
    return False


def select(sel: Selector, vert_pos: np.ndarray, *, name: str, regions: dict | None = None,
           border_vert: np.ndarray | None = None) -> np.ndarray:
    """Evaluate a selector on rest positions vert_pos (nvert, 3) m.

    Returns sorted unique int32 indices. A string names a region already
    defined in `regions`. Raises SceneError, naming the region, when the
    selector is malformed or selects no vertex.
    """
    idx = _select(sel, vert_pos, name, regions or {}, border_vert)
    idx = np.unique(idx).astype(np.int32)
    if idx.size == 0:
        raise SceneError(f"region {name!r}: expected at least one vertex, the selector {sel!r} "
                         f"selects none of the {len(vert_pos)} vertices")
    return idx


#: how deep union, intersection and difference may nest (a scene needs a few levels)
MAX_SELECTOR_DEPTH = 32


def _select(sel, vert_pos, name, regions, border_vert, depth=0) -> np.ndarray:
    nvert = len(vert_pos)
    if depth > MAX_SELECTOR_DEPTH:
        raise SceneError(f"region {name!r}: selectors nested more than {MAX_SELECTOR_DEPTH} levels deep; "
                         f"expected at most {MAX_SELECTOR_DEPTH} (name an inner part as a region instead)")
    if isinstance(sel, str):
        if sel == "all":
            return np.arange(nvert)
        if sel not in regions:
            raise SceneError(f"region {name!r}: refers to region {sel!r}, which is not defined; "
                             f"defined regions: {sorted(regions) + ['all']}")
        return regions[sel]
    if isinstance(sel, All):
        return np.arange(nvert)
    if isinstance(sel, Border):
        return np.asarray(border_vert if border_vert is not None else [], dtype=np.int64)
    if isinstance(sel, Indices):
        idx = np.asarray(sel.indices)
        if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
            raise SceneError(f"region {name!r}: expected a list of vertex indices, received {sel.indices!r}")
        bad = idx[(idx < 0) | (idx >= nvert)]
        if bad.size:
            raise SceneError(f"region {name!r}: vertex indices must lie in [0, {nvert}), "
                             f"received {bad[:5].tolist()}")
        return idx
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
    if isinstance(sel, Nearest):
        pts = np.asarray(sel.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
            raise SceneError(f"region {name!r}.points: expected a list of 3-vectors, received {sel.points!r}")
        d2 = ((vert_pos[None, :, :] - pts[:, None, :]) ** 2).sum(-1)
        return np.argmin(d2, axis=1)
    if isinstance(sel, (Union_, Intersection)):
        parts = [set(_select(p, vert_pos, name, regions, border_vert, depth + 1).tolist()) for p in sel.parts]
        if not parts:
            return np.zeros(0, np.int64)
        out = set.union(*parts) if isinstance(sel, Union_) else set.intersection(*parts)
        return np.array(sorted(out), dtype=np.int64)
    if isinstance(sel, Difference):
        a = _select(sel.base, vert_pos, name, regions, border_vert, depth + 1)
        b = _select(sel.minus, vert_pos, name, regions, border_vert, depth + 1)
        return np.setdiff1d(a, b)
    raise SceneError(f"region {name!r}: expected a selector (indices, half_space, ball, box, nearest, "
                     f"all, border, union, intersection, difference or a region name), received {sel!r}")
