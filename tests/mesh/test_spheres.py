"""Sphere generators (hybrid.mesh.spheres): the paper's UV sphere, the icosahedron, icospheres."""

from __future__ import annotations

import numpy as np
import pytest

from hybrid.errors import MeshError
from hybrid.mesh import icosahedron, icosphere, uv_sphere


def test_uv_sphere_is_the_papers_80_point_sphere():
    m = uv_sphere(radius=0.12)
    assert (m.nvert, m.nface) == (80, 156)
    assert m.closed and len(m.border_vert) == 0
    assert m.vert_pos.shape == (80, 3) and m.face_vert.shape == (156, 3)
    np.testing.assert_allclose(m.vert_pos[0], [0, 0, 0.12], atol=1e-15)
    np.testing.assert_allclose(m.vert_pos[-1], [0, 0, -0.12], atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(m.vert_pos, axis=1), 0.12, rtol=1e-15)
    # six latitude circles of 13 points, north to south
    circle_z = m.vert_pos[1:-1, 2].reshape(6, 13)
    assert np.ptp(circle_z, axis=1).max() < 1e-15
    assert np.all(np.diff(circle_z[:, 0]) < 0)
    # Euler characteristic of a sphere
    assert m.nvert - len(m.edge_vert) + m.nface == 2


@pytest.mark.parametrize("segments, rings", [(3, 2), (4, 3), (13, 7), (20, 11)])
def test_uv_sphere_counts(segments, rings):
    m = uv_sphere(segments=segments, rings=rings, center=(1.0, 2.0, 3.0))
    assert m.nvert == 2 + segments * (rings - 1)
    assert m.nface == 2 * segments * (rings - 1)
    assert m.closed and m.volume() > 0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(segments=2), "segments"),
        (dict(rings=1), "rings"),
        (dict(radius=-1.0), "radius"),
        (dict(radius=np.nan), "radius"),
        (dict(center=(0, 0)), "center"),
    ],
)
def test_uv_sphere_rejects_bad_arguments(kwargs, match):
    with pytest.raises(MeshError, match=match):
        uv_sphere(**kwargs)


@pytest.mark.parametrize("subdivisions, nvert", list(enumerate([12, 42, 162, 642, 2562, 10242, 40962])))
def test_icosphere_vertex_counts(subdivisions, nvert):
    m = icosphere(subdivisions, radius=2.0, center=(1.0, 0.0, 0.0))
    assert m.nvert == nvert
    assert m.nface == 2 * nvert - 4
    assert m.closed
    np.testing.assert_allclose(np.linalg.norm(m.vert_pos - [1.0, 0.0, 0.0], axis=1), 2.0, rtol=1e-14)


def test_icosphere_rejects_bad_level():
    with pytest.raises(MeshError, match="subdivisions"):
        icosphere(-1)
    with pytest.raises(MeshError, match="subdivisions"):
        icosphere(1.5)


def test_icosahedron_closed_form():
    radius = 0.7
    m = icosahedron(radius)
    assert (m.nvert, m.nface, len(m.edge_vert)) == (12, 20, 30)
    edge = radius / np.sin(2 * np.pi / 5)  # circumradius = edge * sin(2 pi / 5)
    assert m.edge_length_mean() == pytest.approx(edge, rel=1e-14)
    assert m.volume() == pytest.approx(5 / 12 * (3 + np.sqrt(5)) * edge**3, rel=1e-14)


def test_icosphere6_is_a_closed_sphere_of_the_expected_counts():
    # (its build time is the benchmark's to measure: no timed assertion on a shared machine)
    m = icosphere(6)
    assert (m.nvert, m.nface) == (40962, 81920)
    assert m.nvert - len(m.edge_vert) + m.nface == 2  # a closed surface of genus 0
    assert np.allclose(np.linalg.norm(m.vert_pos, axis=1), 1.0, rtol=0, atol=1e-12)
