"""Implicit Euler's assembled Newton matrix (hybrid.implicit_matrix): its blocks are those
of the element-by-element product, its product is theirs, its diagonal blocks P those of
the projected product, and the preconditioner's sweep is (D + U)^-1 D (D + L)^-1, D = P /
omega; on a small irregular mesh with every tangent term and points that are not integrated."""

import numpy as np
import pytest
from helpers import dense_matrix, no_planes

from hybrid import Damping, HalfSpace, Masses, Membrane, MuscleFibres, PassiveFibres, RestingTension, Scene
from hybrid.implicit import newton_caches, newton_product, newton_rows
from hybrid.implicit_matrix import SSOR_OMEGA, assemble, matrix_product, newton_matrix, sgs_sweep
from hybrid.mesh import irregular_sphere
from hybrid.model import compile_scene
from hybrid.terms.tangents import NCACHE, NFIB_CACHE, NPF_CACHE

R = 0.12
H = 2e-3


def assembled():
    """The module's matrix: (arrays, rows, face, fib, pf, mat), assembled."""
    mesh = irregular_sphere(40, R, seed=3)
    a = compile_scene(
        Scene(
            mesh=mesh,
            masses=Masses(total_kg=1.0),
            integrator="implicit_euler",
            forces=(
                Membrane(800.0, damping_time_s=0.02),
                PassiveFibres(modulus_n_per_m=600.0, around_axis=(0.0, 0.0, 1.0)),
                MuscleFibres(
                    HalfSpace((0.0, 0.0, -0.03), (0.0, 0.0, 1.0)), 40.0, toward_m=(0.0, 0.0, R), force_length_width=0.5
                ),
                RestingTension(tension_n_per_m=25.0, region=HalfSpace((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))),
                Damping(drag_n_s_per_m3=30.0),
            ),
        )
    ).arrays
    # points below z = -0.06 m not integrated (as linked ones): their rows and columns are not assembled
    free = (a.vert_rest[:, 2] >= -0.06).astype(np.uint8)
    free.flags.writeable = False  # as a model's: the solve's own compiled kernels then serve these calls
    a = a._replace(vert_free=free)
    n = a.vert_rest.shape[0]
    # compressed (negative stress: the projection matters) and stretched triangles
    x = a.vert_rest + 0.01 * np.random.default_rng(4).standard_normal((n, 3))
    sv = np.full((a.sched.kind.shape[0], 3), 40.0)
    rows = newton_rows(a)
    face, fib = np.zeros((rows.mem_vert.shape[0], NCACHE)), np.zeros((rows.fib_vert.shape[0], NFIB_CACHE))
    pf = np.zeros((rows.pf_vert.shape[0], NPF_CACHE))
    newton_caches(a, rows, sv, x, face, fib, pf)
    mat = newton_matrix(n, a.vert_free, rows.mem_vert, rows.fib_vert, rows.pf_vert, rows.rt_vert)
    assemble(a, rows, face, fib, pf, H, mat, no_planes(a))
    return a, rows, face, fib, pf, mat


@pytest.fixture(scope="module")
def setup():
    a, rows, face, fib, pf, mat = assembled()
    assert (face[:, 6:9] != face[:, 9:12]).any(axis=1).sum() > 0  # clamped stresses
    assert 0 < (pf[:, 9] != 0.0).sum() < pf.shape[0]  # stretched and slack passive fibres
    assert (fib[:, 9] != fib[:, 10]).any() or (fib[:, 11:14] != fib[:, 14:17]).any()  # projected fibres
    return a, rows, face, fib, pf, mat


def blocks_of(mat, n, blocks):
    """The whole matrix of the upper blocks (each also its transpose's), on every point."""
    out = np.zeros((3 * n, 3 * n))
    for f in range(mat.free.size):
        for k in range(mat.row_ptr[f], mat.row_ptr[f + 1]):
            assert mat.col[k] >= f
            i, j = mat.free[f], mat.free[mat.col[k]]
            out[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] = blocks[k].reshape(3, 3)
            out[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] = blocks[k].reshape(3, 3).T
    return out


def on_every_point(mat, kernel):
    """kernel(u, y) on the matrix's (nfree, 3) vectors as a map of (n, 3) ones (zero on fixed points)."""

    def apply(u, y):
        out = np.zeros((mat.free.size, 3))
        kernel(np.ascontiguousarray(u[mat.free]), out)
        y[:] = 0.0
        y[mat.free] = out

    return apply


def test_the_assembled_blocks_are_the_element_products(setup):
    a, rows, face, fib, pf, mat = setup
    n = a.vert_rest.shape[0]
    free = np.repeat(a.vert_free != 0, 3)
    want, proj = (
        dense_matrix(n, lambda u, y: newton_product(a, rows, face, fib, pf, H, project, u, y, no_planes(a)))
        for project in (False, True)
    )
    for m_ in (want, proj):
        m_[~free, :] = 0.0
        m_[:, ~free] = 0.0
    scale = np.abs(want).max()
    assert np.abs(blocks_of(mat, n, mat.amat) - want).max() <= 1e-12 * scale
    one = np.kron(np.eye(n), np.ones((3, 3)))
    assert np.abs(want - one * want).max() > 1e-3 * scale  # the blocks couple points
    product = on_every_point(mat, lambda u, y: matrix_product(mat, u, y))
    assert np.abs(dense_matrix(n, product) - want).max() <= 1e-12 * scale
    pdiag = np.stack([proj[3 * i : 3 * i + 3, 3 * i : 3 * i + 3].ravel() for i in range(n)])
    exact_diag = np.stack([want[3 * i : 3 * i + 3, 3 * i : 3 * i + 3].ravel() for i in range(n)])
    assert np.abs(pdiag - exact_diag).max() > 0.0  # the projection changes some
    fr = a.vert_free != 0
    assert np.abs(mat.pdiag[fr] - pdiag[fr]).max() <= 1e-12 * scale
    # the sweep's, over-relaxed (to the rounding of a division taken as a reciprocal's product)
    assert np.abs(mat.sdiag - mat.pdiag[fr] / SSOR_OMEGA).max() <= 1e-15 * np.abs(mat.pdiag).max()


def test_the_projected_assembly_is_the_projected_element_product(setup):
    """The matrix implicit Euler solves with at negative curvature: assembled with every
    element's Hessian projected, it is the projected element-by-element product (and its
    diagonal blocks the preconditioner's, the same as the exact assembly's)."""
    a, rows, face, fib, pf, exact = setup
    n = a.vert_rest.shape[0]
    free = np.repeat(a.vert_free != 0, 3)
    proj = dense_matrix(n, lambda u, y: newton_product(a, rows, face, fib, pf, H, True, u, y, no_planes(a)))
    proj[~free, :] = 0.0
    proj[:, ~free] = 0.0
    mat = newton_matrix(n, a.vert_free, rows.mem_vert, rows.fib_vert, rows.pf_vert, rows.rt_vert)
    assemble(a, rows, face, fib, pf, H, mat, no_planes(a), True)
    scale = np.abs(proj).max()
    # a sum of the same products in another order: to rounding
    assert np.abs(blocks_of(mat, n, mat.amat) - proj).max() <= 1e-12 * scale
    assert np.abs(blocks_of(mat, n, mat.amat) - blocks_of(exact, n, exact.amat)).max() > 1e-6 * scale
    assert np.array_equal(mat.pdiag, exact.pdiag) and np.array_equal(mat.sdiag, exact.sdiag)
    # the projection only adds stiffness (a compressed triangle's stress and a fibre's negative
    # coefficients clamped at zero): the difference is positive semi-definite, to rounding
    added = np.linalg.eigvalsh((proj - blocks_of(exact, n, exact.amat))[np.ix_(free, free)])
    assert added.min() >= -1e-12 * scale and added.max() > 1e-6 * scale


def sweep_diagonal(mat, n):
    """The sweep's D on every point (zero on fixed points)."""
    diag = np.zeros((3 * n, 3 * n))
    for f, i in enumerate(mat.free):
        diag[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = mat.sdiag[f].reshape(3, 3)
    return diag


def test_the_sweep_is_ssor_with_the_projected_diagonal(setup):
    a, rows, face, fib, pf, mat = setup
    n = a.vert_rest.shape[0]
    fr = a.vert_free != 0
    free = np.repeat(fr, 3)
    exact = blocks_of(mat, n, mat.amat)
    one = np.kron(np.eye(n), np.ones((3, 3)))
    diag = sweep_diagonal(mat, n)
    off = exact - one * exact
    lower = (np.tril(off) + diag)[np.ix_(free, free)]
    upper = (np.triu(off) + diag)[np.ix_(free, free)]
    d = diag[np.ix_(free, free)]
    assert np.linalg.eigvalsh(d).min() > 0.0
    r = np.random.default_rng(5).standard_normal((n, 3))
    r[~fr] = 0.0
    z = np.zeros_like(r)
    on_every_point(mat, lambda u, y: sgs_sweep(mat, u, y))(r, z)
    want = np.linalg.solve(upper, d @ np.linalg.solve(lower, r[fr].ravel()))
    assert np.abs(z[fr].ravel() - want).max() <= 1e-10 * np.abs(want).max()


def sweep_parts(mat, n):
    """The dense (D + L), (D + U) and D of the sweep on the free points (the matrix's numbering)."""
    full = blocks_of(mat, n, mat.amat)
    one = np.kron(np.eye(n), np.ones((3, 3)))
    off = full - one * full
    diag = sweep_diagonal(mat, n)
    free = np.repeat(np.isin(np.arange(n), mat.free), 3)
    sub = np.ix_(free, free)
    return (np.tril(off) + diag)[sub], (np.triu(off) + diag)[sub], diag[sub]


def swept_cg(big, lower, upper, d, r, iters):
    """The reference: `iters` iterations of the conjugate gradients on big x = r preconditioned
    with the sweep (D + U)^-1 D (D + L)^-1, dense, from x = 0; x as (nfree, 3)."""
    res = r.ravel().copy()
    x = np.zeros_like(res)

    def sweep(v):
        return np.linalg.solve(upper, d @ np.linalg.solve(lower, v))

    z = sweep(res)
    p = z.copy()
    rz = res @ z
    for _ in range(iters):
        q = big @ p
        alpha = rz / (p @ q)
        x += alpha * p
        res -= alpha * q
        z = sweep(res)
        rz, rz_old = res @ z, rz
        p = z + rz / rz_old * p
    return x.reshape(r.shape)


def test_eisenstats_conjugate_gradients_take_the_same_iterates_as_the_swept_ones(setup):
    """`split_cg` (two triangular solves an iteration) iterates on C^-1 A C^-T what the
    conjugate gradients with the preconditioner C C^T (the sweep) iterate on A: after the same
    number of iterations both have the same x, to round-off (1e-9 of x: the iterates differ
    by the rounding of a few dozen products; the reference is dense, `swept_cg`)."""
    from hybrid.implicit import implicit_work
    from hybrid.implicit_matrix import lower_solve, split_cg, upper_solve

    def _solve_split(w, target, cg_max):
        return split_cg(w, target, cg_max, 0.0, w.lung_gf, w.lung_gh)  # the solve's arguments, no rank-one term

    a, rows, face, fib, pf, mat = setup
    n = a.vert_rest.shape[0]
    fr = a.vert_free != 0
    # the triangular solves against dense ones
    full = blocks_of(mat, n, mat.amat)
    diag = sweep_diagonal(mat, n)
    one = np.kron(np.eye(n), np.ones((3, 3)))
    off = full - one * full
    free = np.repeat(fr, 3)
    lower, upper = ((np.tril(off) + diag)[np.ix_(free, free)], (np.triu(off) + diag)[np.ix_(free, free)])
    r = np.random.default_rng(8).standard_normal((mat.free.size, 3))  # the matrix's numbering
    t = np.zeros_like(r)
    upper_solve(mat, r, t)
    assert np.abs(upper @ t.ravel() - r.ravel()).max() <= 1e-12 * np.abs(r).max()
    lower_solve(mat, r, t)
    assert np.abs(lower @ t.ravel() - r.ravel()).max() <= 1e-12 * np.abs(r).max()
    # the iterates
    w = implicit_work(a)._replace(rows=rows, face=face, fib=fib, pf=pf, mat=mat)
    b = np.abs(np.linalg.eigvalsh(full[np.ix_(free, free)]))
    assert b.min() > 0.0
    for iters in (1, 3, 6):
        swept = swept_cg(full[np.ix_(free, free)], lower, upper, diag[np.ix_(free, free)], r, iters)
        w.cg_r[:] = r
        assert _solve_split(w, 0.0, iters) == iters
        assert np.abs(w.cg_x - swept).max() <= 1e-9 * np.abs(swept).max(), iters
    # to a tolerance: |A x - r| <= target, checked on the residual itself
    w.cg_r[:] = r
    k = _solve_split(w, 1e-6 * np.linalg.norm(r), 10 * n)
    y = np.zeros_like(r)
    matrix_product(mat, w.cg_x, y)
    assert 0 < k < 10 * n and np.linalg.norm(y - r) <= 1e-6 * np.linalg.norm(r)


def test_a_rank_one_term_in_the_conjugate_gradients_costs_at_most_an_iteration_more(setup):
    """The lungs' stiffness c g g^T (`hybrid.implicit_lungs`) in `split_cg`'s product: it
    solves (A + c g g^T) x = r to its target against the dense matrix, takes the iterates
    of the swept conjugate gradients on that matrix (to round-off, as without it), and, a rank-one
    change of the matrix adding at most one iteration in exact arithmetic, needs at most 2 more
    iterations than A alone (one for rounding) for a term up to A's largest eigenvalue: the
    Sherman-Morrison it replaced solved A^-1 g apart, a second solve each Newton iteration."""
    from hybrid.implicit import implicit_work
    from hybrid.implicit_matrix import half_sweep, split_cg

    a, rows, face, fib, pf, mat = setup
    n = a.vert_rest.shape[0]
    fr = a.vert_free != 0
    free = np.repeat(fr, 3)
    big = blocks_of(mat, n, mat.amat)[np.ix_(free, free)]  # A on the free points (the matrix's numbering)
    # g: the closed surface's volume gradient (smooth over the whole body, as the cavity's over the dome)
    x = a.vert_rest
    g_all = np.zeros_like(x)
    for i, j, k in a.face_vert:
        g_all[i] += np.cross(x[j], x[k]) / 6.0
        g_all[j] += np.cross(x[k], x[i]) / 6.0
        g_all[k] += np.cross(x[i], x[j]) / 6.0
    g = np.ascontiguousarray(g_all[mat.free])
    gh = np.zeros_like(g)
    half_sweep(mat, g, gh)
    w = implicit_work(a)._replace(rows=rows, face=face, fib=fib, pf=pf, mat=mat)
    r = np.random.default_rng(9).standard_normal(g.shape)
    target = 1e-8 * np.linalg.norm(r)
    lam = np.linalg.eigvalsh(big).max()

    def run(*rank, cg_max=10 * n):
        w.cg_r[:] = r
        k = split_cg(w, target, cg_max, *(rank or (0.0, w.lung_gf, w.lung_gh)))
        return k, w.cg_x.copy()

    plain, _ = run()
    # c |g|^2 against A's largest eigenvalue (on the breathing scene far below 1: A's largest are the
    # sheet's stiff modes); measured 15 iterations without, 15 and 17 with (at 10, 18 and iterates
    # 4e-8 apart: the stiff term's rounding)
    for stiff in (1e-2, 1.0):
        c = stiff * lam / np.sum(g * g)
        k, sol = run(c, g, gh)
        want = big + c * np.outer(g.ravel(), g.ravel())
        assert np.linalg.norm(want @ sol.ravel() - r.ravel()) <= target * (1 + 1e-6), stiff
        assert 0 < k <= plain + 2, (stiff, k, plain)
        for iters in (1, 3, 6):
            swept = swept_cg(want, *sweep_parts(mat, n), r, iters)
            assert run(c, g, gh, cg_max=iters)[0] == iters
            assert np.abs(w.cg_x - swept).max() <= 1e-9 * np.abs(swept).max(), (stiff, iters)


# `assembled()` in a process of its own, its matrix saved to argv[1]
ASSEMBLE_SCRIPT = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[2])
from test_implicit_matrix import assembled
a, rows, face, fib, pf, mat = assembled()
np.save(sys.argv[1], np.concatenate([mat.amat.ravel(), mat.pdiag.ravel(), mat.gchol.ravel()]))
"""


def test_the_assembled_matrix_is_the_same_compiled_or_loaded_from_the_cache(tmp_path):
    """A run's last bits must not depend on whether its kernels were just compiled or loaded
    from the cache. With fused multiply-adds in the blocks' kernels they did: this matrix
    differed in 7 entries (by up to 7e-18), and the breathing scene's implicit steps by
    6e-16 m after 60 steps at level 5 (`hybrid.kernel.FAST_NO_FMA`). Two processes, a new
    cache: the first compiles (about 8 s here), the second loads."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    out = []
    for k in range(2):
        path = tmp_path / f"matrix{k}.npy"
        subprocess.run(
            [sys.executable, "-c", ASSEMBLE_SCRIPT, str(path), os.path.dirname(__file__)], env=env, check=True
        )
        out.append(np.load(path))
    assert (tmp_path / "cache").is_dir() and any((tmp_path / "cache").rglob("*.nbi"))  # the second run loaded
    assert np.array_equal(out[0], out[1])
