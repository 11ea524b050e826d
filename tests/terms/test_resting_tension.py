"""A sheet's tension at rest (hybrid.terms.resting_tension): nothing at rest and no net force,
the force minus the gradient of T A(x) - F0 . x, and a flat sheet's first-order stiffness
against a push across it, which a stress-free membrane lacks (its force grows as the cube)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import forces_at

from hybrid.mesh import ring_sphere
from hybrid.model import compile_scene
from hybrid.scene import Masses, RestingTension, Scene
from hybrid.terms.membrane import add_membrane_serial, lame_moduli, membrane_rest
from hybrid.terms.resting_tension import add_resting_tension, area_gradients

T = 25.0  # N/m


def _forces(model, pos):
    return forces_at(model, pos)[0]


def test_area_gradient_is_the_finite_difference():
    p = np.random.default_rng(3).normal(size=(6, 3, 3))

    def area(q):
        return 0.5 * np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)

    num = np.zeros_like(p)
    for a in range(3):
        for k in range(3):
            d = np.zeros_like(p)
            d[:, a, k] = 1e-6
            num[:, a, k] = (area(p + d) - area(p - d)) / 2e-6
    assert np.abs(area_gradients(p) - num).max() < 1e-8


def test_nothing_at_rest_no_net_force_and_minus_the_energy_gradient():
    mesh = ring_sphere(300, 0.1)
    model = compile_scene(
        Scene(mesh=mesh, masses=Masses(total_kg=1.0), forces=(RestingTension(tension_n_per_m=T),)),
    )
    x0 = model.mesh.vert_pos.copy()
    assert np.abs(_forces(model, x0)).max() < 1e-12
    x = x0 + 0.01 * np.random.default_rng(0).normal(size=x0.shape)
    f = _forces(model, x)
    assert np.abs(f.sum(axis=0)).max() < 1e-10 * np.abs(f).sum()
    # W(x) = T A(x) - F0 . x, F0 = T grad A(x0): F = -grad W, checked on one point
    face = model.mesh.face_vert
    f0 = np.zeros_like(x0)
    g0 = area_gradients(x0[face])
    for a in range(3):
        np.add.at(f0, face[:, a], T * g0[:, a])

    def energy(y):
        p = y[face]
        return T * 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum() - np.sum(f0 * y)

    i = 17
    num = np.zeros(3)
    for k in range(3):
        d = np.zeros_like(x)
        d[i, k] = 1e-7
        num[k] = -(energy(x + d) - energy(x - d)) / 2e-7
    assert f[i] == pytest.approx(num, rel=1e-5, abs=1e-9)


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
    par = np.c_[np.full(len(face), T), T * area_gradients(pos[face]).reshape(len(face), 9)]

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
