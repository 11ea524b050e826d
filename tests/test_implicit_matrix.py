"""Implicit Euler's assembled Newton matrix (hybrid.implicit_matrix): its blocks, exact
and projected, are those of the element-by-element product, its product is theirs, and
the preconditioner's sweep is (D + U)^-1 D (D + L)^-1 of the projected one; on a small
irregular mesh with every tangent term and points that are not integrated."""

import numpy as np
import pytest

from hybrid import Damping, HalfSpace, Masses, Membrane, MuscleFibres, PassiveFibres, Scene
from hybrid.implicit import newton_caches, newton_product, newton_rows
from hybrid.implicit_matrix import assemble, matrix_product, newton_matrix, sgs_sweep
from hybrid.mesh import irregular_sphere
from hybrid.model import compile_scene
from hybrid.terms.tangents import NCACHE, NFIB_CACHE, NPF_CACHE

R = 0.12
H = 2e-3


@pytest.fixture(scope="module")
def setup():
    mesh = irregular_sphere(40, R, seed=3)
    a = compile_scene(Scene(mesh=mesh, masses=Masses(total_kg=1.0), integrator="implicit_euler", forces=(
        Membrane(800.0, damping_time_s=0.02), PassiveFibres(modulus_n_per_m=600.0, around_axis=(0.0, 0.0, 1.0)),
        MuscleFibres(HalfSpace((0.0, 0.0, -0.03), (0.0, 0.0, 1.0)), 40.0, toward_m=(0.0, 0.0, R),
                     force_length_width=0.5),
        Damping(drag_n_s_per_m3=30.0)))).arrays
    # points below z = -0.06 m not integrated (as linked ones): their rows and columns are not assembled
    a = a._replace(vert_free=(a.vert_rest[:, 2] >= -0.06).astype(np.uint8))
    n = a.vert_rest.shape[0]
    # compressed (negative stress: the projection matters) and stretched triangles
    x = a.vert_rest + 0.01 * np.random.default_rng(4).standard_normal((n, 3))
    sv = np.full((a.sched.kind.shape[0], 3), 40.0)
    rows = newton_rows(a)
    face, fib = np.zeros((rows.mem_vert.shape[0], NCACHE)), np.zeros((rows.fib_vert.shape[0], NFIB_CACHE))
    pf = np.zeros((rows.pf_vert.shape[0], NPF_CACHE))
    newton_caches(a, rows, sv, x, face, fib, pf)
    assert (face[:, 6:9] != face[:, 9:12]).any(axis=1).sum() > 0  # clamped stresses
    assert 0 < (pf[:, 9] != 0.0).sum() < pf.shape[0]  # stretched and slack passive fibres
    assert (fib[:, 9] != fib[:, 10]).any() or (fib[:, 11:14] != fib[:, 14:17]).any()  # projected fibres
    mat = newton_matrix(n, a.vert_free, rows.mem_vert, rows.fib_vert, rows.pf_vert)
    assemble(a, rows, face, fib, pf, H, mat)
    return a, rows, face, fib, pf, mat


def dense(n, product):
    out = np.zeros((3 * n, 3 * n))
    for j in range(3 * n):
        u, y = np.zeros((n, 3)), np.zeros((n, 3))
        u.flat[j] = 1.0
        product(u, y)
        out[:, j] = y.ravel()
    return out


@pytest.mark.parametrize("project", [False, True], ids=["exact", "projected"])
def test_the_assembled_blocks_are_the_element_products(setup, project):
    a, rows, face, fib, pf, mat = setup
    n = a.vert_rest.shape[0]
    free = np.repeat(a.vert_free != 0, 3)
    want = dense(n, lambda u, y: newton_product(a, rows, face, fib, pf, H, project, u, y))
    want[~free, :] = 0.0
    want[:, ~free] = 0.0
    blocks = mat.pmat if project else mat.amat
    got = np.zeros((3 * n, 3 * n))
    for i in range(n):
        for k in range(mat.row_ptr[i], mat.row_ptr[i + 1]):
            j = mat.col[k]
            got[3 * i:3 * i + 3, 3 * j:3 * j + 3] = blocks[k].reshape(3, 3)
    scale = np.abs(want).max()
    assert np.abs(got - want).max() <= 1e-12 * scale
    off = want - np.kron(np.eye(n), np.ones((3, 3))) * want
    assert np.abs(off).max() > 1e-3 * scale  # the blocks couple points
    assert np.abs(dense(n, lambda u, y: matrix_product(mat, project, u, y)) - want).max() <= 1e-12 * scale


def test_the_sweep_is_that_of_the_projected_matrix(setup):
    a, rows, face, fib, pf, mat = setup
    n = a.vert_rest.shape[0]
    fr = a.vert_free != 0
    free = np.repeat(fr, 3)
    proj = dense(n, lambda u, y: matrix_product(mat, True, u, y))[np.ix_(free, free)]
    exact = dense(n, lambda u, y: matrix_product(mat, False, u, y))[np.ix_(free, free)]
    assert np.abs(proj - exact).max() > 0.0
    assert np.linalg.eigvalsh(proj).min() > 0.0
    diag = np.kron(np.eye(proj.shape[0] // 3), np.ones((3, 3))) * proj
    lower = np.tril(proj) - np.tril(diag) + diag
    upper = np.triu(proj) - np.triu(diag) + diag
    r = np.random.default_rng(5).standard_normal((n, 3))
    r[~fr] = 0.0
    z = np.zeros_like(r)
    sgs_sweep(mat, r, z)
    want = np.linalg.solve(upper, diag @ np.linalg.solve(lower, r[fr].ravel()))
    assert np.abs(z[fr].ravel() - want).max() <= 1e-10 * np.abs(want).max()
    assert np.abs(z[~fr]).max() == 0.0
