"""Volume, its gradient and the vertex area vectors (hybrid.mesh.geometry), against trimesh,
finite differences and closed forms, near the origin and far from it."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import CLOSED, hemisphere

from hybrid.mesh import Mesh, icosphere, uv_sphere, volume, volume_gradient

OFFSET = np.array([100.0, -100.0, 100.0])  # far from the origin, in m


@pytest.mark.parametrize("offset", [0.0, 1.0], ids=["origin", "offset100m"])
@pytest.mark.parametrize("which", list(CLOSED))
def test_volume_matches_trimesh(which, offset):
    m = CLOSED[which](offset * OFFSET)
    assert m.volume() > 0
    assert m.volume() == pytest.approx(m.to_trimesh().volume, rel=1e-12)


@pytest.mark.parametrize("which", list(CLOSED))
def test_volume_is_translation_invariant(which):
    near, far = CLOSED[which]((0.0, 0.0, 0.0)), CLOSED[which](OFFSET)
    # Relative to the mean, the far copy loses no digits (1e-13, not 1e-16 * 100^3).
    assert far.volume() == pytest.approx(near.volume(), rel=1e-13)
    np.testing.assert_allclose(far.volume_gradient(), near.volume_gradient(), atol=1e-13)


def test_volume_of_deformed_positions():
    m = uv_sphere()
    stretched = m.vert_pos * [2.0, 1.0, 0.5]  # a linear map multiplies volume by its det
    assert m.volume(stretched) == pytest.approx(m.volume(), rel=1e-14)
    assert m.volume(2.0 * m.vert_pos) == pytest.approx(8.0 * m.volume(), rel=1e-14)
    assert volume(stretched, m.face_vert) == m.volume(stretched)


def central_difference_gradient(fun, pos, step):
    """Central differences of fun (nvert, 3) -> float, one coordinate at a time."""
    grad = np.empty_like(pos)
    for i in range(pos.shape[0]):
        for k in range(3):
            plus, minus = pos.copy(), pos.copy()
            plus[i, k] += step
            minus[i, k] -= step
            grad[i, k] = (fun(plus) - fun(minus)) / (2 * step)
    return grad


@pytest.mark.parametrize("offset", [0.0, 1.0], ids=["origin", "offset100m"])
@pytest.mark.parametrize("which", list(CLOSED))
def test_volume_gradient_matches_finite_differences(which, offset):
    m = CLOSED[which](offset * OFFSET)
    # Step size: V is affine in any single coordinate (each face term a.(b x c) is
    # linear in each corner), so central differences have no truncation error at
    # all; only roundoff remains, about eps * V / h, which a large step shrinks.
    # A tenth of an edge keeps the perturbed surface a mild deformation.
    step = 0.1 * m.edge_length_mean()
    fd = central_difference_gradient(m.volume, np.array(m.vert_pos), step)
    grad = m.volume_gradient()
    assert np.linalg.norm(fd - grad) / np.linalg.norm(grad) < 1e-7
    assert np.array_equal(grad, volume_gradient(m.vert_pos, m.face_vert))


def test_volume_gradient_sums_to_zero(closed_mesh):
    grad = closed_mesh.volume_gradient()
    # A rigid translation does not change the volume of a closed surface.
    assert np.abs(grad.sum(axis=0)).max() < 1e-14 * np.abs(grad).sum()


def test_open_surface_volume_is_relative_to_the_mean():
    m = hemisphere()
    apex = m.vert_pos.mean(axis=0)

    def cone_volume(pos):  # apex held fixed at the rest mean
        a, b, c = (pos[m.face_vert[:, k]] - apex for k in range(3))
        return np.sum(a * np.cross(b, c)) / 6

    assert m.volume() == pytest.approx(cone_volume(m.vert_pos), rel=1e-14)
    fd = central_difference_gradient(cone_volume, np.array(m.vert_pos), 0.01)
    grad = m.volume_gradient()
    assert np.linalg.norm(fd - grad) / np.linalg.norm(grad) < 1e-9


def test_vert_area_vector_closed_form(closed_mesh):
    area_vec = closed_mesh.vert_area_vector()
    assert area_vec.shape == (closed_mesh.nvert, 3)
    scale = np.abs(area_vec).sum()
    # Closed surface: the outward area vectors cancel ...
    assert np.abs(area_vec.sum(axis=0)).max() < 1e-14 * scale
    # ... and sum_i a_i . x_i = 3 V (each face contributes n_f . (a + b + c) / 6 = 3 a.(b x c) / 6).
    shifted = closed_mesh.vert_pos + [0.3, -0.2, 0.1]  # holds for any origin
    moment = np.sum(closed_mesh.vert_area_vector(shifted) * shifted)
    assert moment == pytest.approx(3 * closed_mesh.volume(), rel=1e-13)


def test_vert_area_vector_totals_the_surface_area():
    m = icosphere(2)
    area_vec = m.vert_area_vector()
    # On a convex surface centred at 0 each vertex's area vector points outward.
    assert np.all(np.sum(area_vec * m.vert_pos, axis=1) > 0)
    # For one flat face, the three vectors add up to the face area times its normal.
    tri = Mesh.from_arrays([[0, 0, 0], [2, 0, 0], [0, 3, 0]], [[0, 1, 2]])
    np.testing.assert_allclose(tri.vert_area_vector(), np.tile([0, 0, 1.0], (3, 1)))
