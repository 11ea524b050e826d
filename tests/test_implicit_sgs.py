"""Implicit Euler's symmetric Gauss-Seidel preconditioner (hybrid.implicit_sgs): the
assembled blocks are those of the projected Newton matrix, and the sweep is
(D + U)^-1 D (D + L)^-1, on a small irregular mesh with every tangent term and
points that are not integrated."""

import numpy as np

from hybrid import Damping, HalfSpace, Masses, Membrane, MuscleFibres, PassiveFibres, Scene
from hybrid.implicit import _preconditioner, newton_caches, newton_product, newton_rows
from hybrid.implicit_sgs import sgs_apply, sgs_assemble, sgs_pattern
from hybrid.mesh import irregular_sphere
from hybrid.model import compile_scene
from hybrid.terms.tangents import NCACHE, NFIB_CACHE, NPF_CACHE

R = 0.12


def test_the_sweep_is_that_of_the_projected_newton_matrix():
    mesh = irregular_sphere(40, R, seed=3)
    a = compile_scene(Scene(mesh=mesh, masses=Masses(total_kg=1.0), integrator="implicit_euler", forces=(
        Membrane(800.0, damping_time_s=0.02), PassiveFibres(modulus_n_per_m=600.0, around_axis=(0.0, 0.0, 1.0)),
        MuscleFibres(HalfSpace((0.0, 0.0, -0.03), (0.0, 0.0, 1.0)), 40.0, toward_m=(0.0, 0.0, R),
                     force_length_width=0.5),
        Damping(drag_n_s_per_m3=30.0)))).arrays
    # points below z = -0.06 m not integrated (as linked ones): their rows and columns are not assembled
    a = a._replace(vert_free=(a.vert_rest[:, 2] >= -0.06).astype(np.uint8))
    free = np.repeat(a.vert_free != 0, 3)
    n = a.vert_rest.shape[0]
    # compressed (negative stress: the projection matters) and stretched triangles
    x = a.vert_rest + 0.01 * np.random.default_rng(4).standard_normal((n, 3))
    sv = np.full((a.sched.kind.shape[0], 3), 40.0)
    h = 2e-3
    rows = newton_rows(a)
    face, fib = np.zeros((rows.mem_vert.shape[0], NCACHE)), np.zeros((rows.fib_vert.shape[0], NFIB_CACHE))
    pf = np.zeros((rows.pf_vert.shape[0], NPF_CACHE))
    newton_caches(a, rows, sv, x, face, fib, pf)
    assert (face[:, 6:9] != face[:, 9:12]).any(axis=1).sum() > 0  # clamped stresses
    assert 0 < (pf[:, 9] != 0.0).sum() < pf.shape[0]  # stretched and slack passive fibres
    assert (fib[:, 9] != fib[:, 10]).sum() > 0 or (fib[:, 11:14] != fib[:, 14:17]).any()  # projected fibres
    mat = np.zeros((3 * n, 3 * n))  # the projected Newton matrix, column by column
    for j in range(3 * n):
        u, y = np.zeros((n, 3)), np.zeros((n, 3))
        u.flat[j] = 1.0
        newton_product(a, rows, face, fib, pf, h, True, u, y)
        mat[:, j] = y.ravel()
    mat = mat[np.ix_(free, free)]
    assert np.abs(mat - mat.T).max() <= 1e-12 * np.abs(mat).max()
    exact_mat = mat.copy()
    sgs = sgs_pattern(n, a.vert_free, rows.mem_vert, rows.fib_vert, rows.pf_vert)
    sgs_assemble(a, rows, face, fib, pf, h, sgs)
    blocks = np.zeros((n, 9))
    _preconditioner(a, rows, sv, x, face, h, blocks)
    got = np.zeros((3 * n, 3 * n))
    for i in range(n):
        got[3 * i:3 * i + 3, 3 * i:3 * i + 3] = np.linalg.inv(blocks[i].reshape(3, 3))
        for k in range(sgs.row_ptr[i], sgs.row_ptr[i + 1]):
            j = sgs.col[k]
            got[3 * i:3 * i + 3, 3 * j:3 * j + 3] = sgs.amat[k].reshape(3, 3)
    got = got[np.ix_(free, free)]
    assert np.abs(got - exact_mat).max() <= 1e-12 * np.abs(exact_mat).max()
    off = exact_mat - np.kron(np.eye(exact_mat.shape[0] // 3), np.ones((3, 3))) * exact_mat
    assert np.abs(off).max() > 1e-3 * np.abs(exact_mat).max()  # the blocks couple points
    # the sweep
    r = np.random.default_rng(5).standard_normal((n, 3))
    r[a.vert_free == 0] = 0.0
    z = np.zeros_like(r)
    sgs_apply(sgs, blocks, r, z)
    lower, upper = np.tril(exact_mat), np.triu(exact_mat)
    diag = np.kron(np.eye(exact_mat.shape[0] // 3), np.ones((3, 3))) * exact_mat
    lower = lower - np.tril(diag) + diag
    upper = upper - np.triu(diag) + diag
    want = np.linalg.solve(upper, diag @ np.linalg.solve(lower, r[a.vert_free != 0].ravel()))
    assert np.abs(z[a.vert_free != 0].ravel() - want).max() <= 1e-10 * np.abs(want).max()
    assert np.abs(z[a.vert_free == 0]).max() == 0.0
