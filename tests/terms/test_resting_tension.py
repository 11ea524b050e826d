"""A sheet's tension at rest (hybrid.terms.resting_tension): nothing at rest and no net force,
the force minus the gradient of the prestress's work T/2 sum_f A0_f |F_f|^2 - F0 . x (F_f each
triangle's deformation gradient), a stiffness that is positive semi-definite (the sheet's area,
the first version's energy, was not), and a flat sheet's first-order stiffness against a push
across it, which a stress-free membrane lacks (its force grows as the cube)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import forces_at

from hybrid.mesh import ring_sphere
from hybrid.model import compile_scene
from hybrid.scene import Masses, RestingTension, Scene
from hybrid.terms.membrane import add_membrane_serial, lame_moduli, membrane_rest
from hybrid.terms.resting_tension import (
    add_resting_tension,
    cot_weights,
    resting_tension_energy,
    resting_tension_product,
)

T = 25.0  # N/m


def _forces(model, pos):
    return forces_at(model, pos)[0]


def test_cotangents_are_the_angles():
    p = np.random.default_rng(3).normal(size=(6, 3, 3))
    for a in range(3):
        u, v = p[:, (a + 1) % 3] - p[:, a], p[:, (a + 2) % 3] - p[:, a]
        angle = np.arccos(np.sum(u * v, axis=1) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1))
        assert cot_weights(p)[:, a] == pytest.approx(1.0 / np.tan(angle), rel=1e-12, abs=1e-12)


def _dirichlet(x, x0, face):
    """sum_f A0_f |F_f|^2 / 2: F_f maps triangle f's rest edges onto its edges at x (in its rest
    plane's frame: the pseudo-inverse of the rest edges)."""
    total = 0.0
    for f in face:
        rest = np.c_[x0[f[1]] - x0[f[0]], x0[f[2]] - x0[f[0]]]
        now = np.c_[x[f[1]] - x[f[0]], x[f[2]] - x[f[0]]]
        grad = now @ np.linalg.pinv(rest)
        total += 0.25 * np.linalg.norm(np.cross(rest[:, 0], rest[:, 1])) * np.sum(grad * grad)
    return total


def _model():
    return compile_scene(
        Scene(mesh=ring_sphere(300, 0.1), masses=Masses(total_kg=1.0), forces=(RestingTension(tension_n_per_m=T),)),
    )


def test_nothing_at_rest_no_net_force_and_minus_the_prestress_work_gradient():
    model = _model()
    x0 = model.mesh.vert_pos.copy()
    face = model.mesh.face_vert
    assert np.abs(_forces(model, x0)).max() < 1e-12
    x = x0 + 0.01 * np.random.default_rng(0).normal(size=x0.shape)
    f = _forces(model, x)
    assert np.abs(f.sum(axis=0)).max() < 1e-10 * np.abs(f).sum()
    # W(x) = T sum A0 |F|^2 / 2 - F0 . x with F0 its gradient at rest: F = -grad W, on three points
    # by central differences (W is quadratic: the difference is exact but for rounding)
    w0 = np.zeros_like(x0)
    for i in (5, 17, 222):
        for k in range(3):
            d = np.zeros_like(x0)
            d[i, k] = 1e-6
            w0[i, k] = T * (_dirichlet(x0 + d, x0, face) - _dirichlet(x0 - d, x0, face)) / 2e-6
            num = -(T * (_dirichlet(x + d, x0, face) - _dirichlet(x - d, x0, face)) / 2e-6 - w0[i, k])
            assert f[i, k] == pytest.approx(num, rel=1e-6, abs=1e-9)


def test_the_stiffness_is_positive_semi_definite():
    """The force is linear in the displacement, K u = -F(x0 + u): K's eigenvalues are >= 0 (the
    first version's energy, T times the area, had -1.5 N/m in the sheet's plane on this sphere,
    which a soft membrane does not cover: a mesh-scale instability that grew with refinement)."""
    model = _model()
    x0 = model.mesh.vert_pos
    n = x0.size
    stiff = np.zeros((n, n))
    for j in range(n):
        u = np.zeros(n)
        u[j] = 1e-3
        stiff[:, j] = -_forces(model, x0 + u.reshape(-1, 3)).ravel() / 1e-3
    assert np.abs(stiff - stiff.T).max() < 1e-9 * np.abs(stiff).max()
    eig = np.linalg.eigvalsh(stiff)
    # rounding: the forces are sums of T cot |edge| terms, about 1e-16 relative of the largest
    assert eig[0] > -1e-9 * eig[-1]
    # and not a zero matrix: out-of-plane stiffness of order T
    assert eig[-1] > T


def test_implicit_eulers_energy_and_product_are_the_forces():
    """What the Newton solve reads (`hybrid.implicit`): the energy whose minus gradient is the
    force (central differences, exact for a quadratic but for rounding) and the product K u =
    -(F(x + u) - F(x)) (exact: the force is linear)."""
    model = _model()
    a = model.arrays
    x0 = model.mesh.vert_pos
    rng = np.random.default_rng(1)
    x = x0 + 0.01 * rng.normal(size=x0.shape)
    f = np.zeros_like(x)
    add_resting_tension(a.rt_vert, a.rt_par, x, f)
    assert resting_tension_energy(a.rt_vert, a.rt_par, x0) == 0.0  # nothing stored at rest
    for i, k in ((5, 0), (17, 2), (222, 1)):
        d = np.zeros_like(x)
        d[i, k] = 1e-6
        de = resting_tension_energy(a.rt_vert, a.rt_par, x + d) - resting_tension_energy(a.rt_vert, a.rt_par, x - d)
        assert -de / 2e-6 == pytest.approx(f[i, k], rel=1e-6, abs=1e-9)
    u = rng.normal(size=x.shape)
    ku = np.zeros_like(u)
    resting_tension_product(a.rt_vert, a.rt_par, 1.0, u, ku)
    fu = np.zeros_like(x)
    add_resting_tension(a.rt_vert, a.rt_par, x + u, fu)
    assert np.abs(ku + (fu - f)).max() <= 1e-12 * np.abs(ku).max()


def _flat_sheet(n=9, size_m=0.2):
    """A square grid of triangles in the plane z = 0: points (n*n, 3), faces, the centre's index."""
    s = np.linspace(-size_m / 2, size_m / 2, n)
    xx, yy = np.meshgrid(s, s, indexing="ij")
    pos = np.c_[xx.ravel(), yy.ravel(), np.zeros(n * n)]
    face = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            face += [(a, b, c), (a, c, d)]
    return pos, np.asarray(face, np.int32), (n // 2) * n + n // 2


def test_a_taut_flat_sheet_resists_a_push_across_it_to_first_order():
    pos, face, centre = _flat_sheet()
    p = pos[face]
    edges = np.stack([p[:, (a + 2) % 3] - p[:, (a + 1) % 3] for a in range(3)], axis=1)
    par = np.c_[0.5 * T * cot_weights(p), edges.reshape(len(face), 9)]

    def push(w):  # the force across the sheet on its centre, pushed out by w (m)
        x = pos.copy()
        x[centre, 2] = w
        f = np.zeros_like(x)
        add_resting_tension(face, par, x, f)
        return f[centre, 2]

    f1, f2 = push(1e-4), push(2e-4)
    assert f1 < 0.0  # back toward the sheet
    assert f2 / f1 == pytest.approx(2.0, rel=1e-3)  # linear: a stiffness at rest
    # on this grid of right triangles the tension's stiffness is the five-point Laplacian's: 4 T
    assert -f1 / 1e-4 == pytest.approx(4.0 * T, rel=1e-3)


def test_a_stress_free_flat_sheet_has_no_first_order_stiffness():
    # the same push on the membrane alone: the force grows as the cube of the push
    pos, face, centre = _flat_sheet()
    lam, mu = lame_moduli(20.0, 0.3)
    par = np.c_[membrane_rest(pos, face), np.full(len(face), lam), np.full(len(face), mu), np.zeros(len(face))]

    def push(w):
        x = pos.copy()
        x[centre, 2] = w
        f = np.zeros_like(x)
        add_membrane_serial(face, par, False, x, np.zeros_like(x), f)
        return f[centre, 2]

    assert push(2e-4) / push(1e-4) == pytest.approx(8.0, rel=1e-2)
