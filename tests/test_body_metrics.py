"""Metrics defined on the body, not on a mesh point (docs/metrics.md): the dome's descent
where the surface crosses its axis, the rib region's area-weighted mean height, and the
return to rest as a root-mean-square over the surface; each exact where a closed form
exists and converging under refinement."""

from __future__ import annotations

import numpy as np
import pytest

import hybrid
from hybrid.readouts import axis_crossing_z, ring_faces


def _grid(n=6, tilt=(0.3, -0.2), c=0.5, jitter=0.0, seed=0):
    """A triangulated patch of the plane z = c + tilt . (x, y) over [-1, 1]^2, its interior
    points moved in x, y by up to `jitter` of a cell."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1))
    xy = np.stack([x.ravel(), y.ravel()], axis=1)
    inner = (np.abs(xy) < 1 - 1e-9).all(axis=1)
    xy[inner] += jitter * (2.0 / n) * rng.uniform(-0.5, 0.5, (inner.sum(), 2))
    z = c + xy @ np.asarray(tilt)
    pos = np.column_stack([xy, z])
    face = []
    for i in range(n):
        for j in range(n):
            a, b, d, e = i * (n + 1) + j, i * (n + 1) + j + 1, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1
            face += [(a, b, e), (a, e, d)]
    return pos, np.array(face)


@pytest.mark.parametrize("xy", [(0.0, 0.0), (0.123, -0.456), (1.0 / 3.0, 1.0 / 3.0)])
def test_the_axis_crossing_of_a_plane_is_the_plane_s_height_on_any_mesh(xy):
    """A plane is linear in every face: the crossing is exact, to rounding, on a regular and
    an irregular triangulation, at a point inside a face, on an edge and at a corner."""
    for jitter in (0.0, 0.6):
        pos, face = _grid(jitter=jitter)
        z = axis_crossing_z(face, pos[None], np.array(xy))[0]
        assert z == pytest.approx(0.5 + 0.3 * xy[0] - 0.2 * xy[1], abs=1e-15)
    # a line that misses the surface has no crossing
    assert np.isnan(axis_crossing_z(face, pos[None], np.array([3.0, 0.0]))[0])
    # the highest of two layers
    two = np.concatenate([pos, pos + [0.0, 0.0, 1.0]])
    faces = np.concatenate([face, face + len(pos)])
    assert axis_crossing_z(faces, two[None], np.array(xy))[0] == pytest.approx(1.5 + 0.3 * xy[0] - 0.2 * xy[1])


def test_the_rings_about_a_point_grow_outward():
    pos, face = _grid()
    centre = 3 * 7 + 3
    one, two = ring_faces(face, centre, 1), ring_faces(face, centre, 2)
    assert len(one) == 6 and set(one) < set(two)  # a regular grid's point has six faces


def test_the_body_metrics_converge_under_refinement():
    """One breath of the breathing trunk at levels 0-3: the change of each body metric from
    level to level falls (refinement converges), and the descent along the axis at rest is 0."""
    rows = []
    for level in range(4):
        out = hybrid.run(hybrid.load("breathing", overrides=[f"mesh.level={level}"]), 4.0)
        tr = out["trace"].arrays()
        assert tr["apex_descent_mm"][0] == 0.0 and tr["rib_lift_mm"][0] == 0.0
        s = out["summary"]
        rows.append((s["apex_descent_mm"], s["rib_lift_mm"]))
    change = np.abs(np.diff(np.array(rows), axis=0))
    assert (change[2] < change[1]).all() and (change[1] < change[0]).all(), rows
