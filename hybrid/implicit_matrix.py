"""Implicit Euler's Newton matrix assembled (`hybrid.implicit`): the conjugate gradients'
products, their preconditioner (a symmetric Gauss-Seidel sweep) and the conjugate
gradients themselves in Eisenstat's implementation (`split_cg`).

Once per Newton iteration the free points' 3 x 3 blocks of M + h^2 K + h C are
assembled into a block-sparse matrix A, its upper triangle alone (`NewtonMatrix`: its
rows, built once per model, and each element's slots) from the terms' tangent caches
(`hybrid.terms.tangent_blocks`), K the exact Hessian, with the diagonal blocks D of
the matrix whose K is projected per element (positive definite). A product with the
assembled matrix reads each block once, where the element-by-element product
(`hybrid.implicit.newton_product`) computes each element's part anew. The
preconditioner is the symmetric successive over-relaxation (SSOR) sweep z = (D + U)^-1 D
(D + L)^-1 r, L and U the lower and upper blocks of A, D = P / SSOR_OMEGA, P the projected
diagonal blocks: symmetric positive definite for any symmetric L = U^T since D is, and
about one product's cost. On the breathing scene the Gauss-Seidel sweep (omega = 1) took
about a third of the conjugate-gradient iterations of P^-1 alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .kernel import kernel
from .switches import T_DAMPING, T_MEMBRANE, T_MUSCLE_FIBRES, T_PASSIVE_FIBRES, T_RESTING_TENSION
from .terms.resting_tension import resting_tension_blocks
from .terms.slide_planes import plane_blocks
from .terms.tangent_blocks import fibre_tangent_blocks, membrane_tangent_blocks, passive_fibres_tangent_blocks

__all__ = [
    "NewtonMatrix",
    "newton_matrix",
    "assemble",
    "matrix_product",
    "sgs_sweep",
    "upper_solve",
    "lower_solve",
    "split_cg",
    "half_sweep",
    "add_rank_one",
    "dot",
    "cg_update",
    "gather",
    "scatter",
    "scatter_add",
]

# the sweep's over-relaxation: conjugate-gradient iterations a step of the breathing scene
# (implicit Euler), omega 1 -> 1.4: level 8 at 30 ms, tol 1e-2, 15.1 -> 11.7; level 6 at
# 10 ms, tol 1e-3, 4.1 -> 3.7; level 4 at 10 ms, tol 1e-6, 8.4 -> 9.1 (1.2: 13.0; 1.6: 11.9
# and 1.8: 14.7 at level 8)
SSOR_OMEGA = 1.4


class NewtonMatrix(NamedTuple):
    """The free points' blocks, the upper triangle of the symmetric matrix alone (a block
    (f, g), f < g, stands for itself and its transpose at (g, f): half the memory each
    product and sweep reads, and each element pair assembled once), in the free points'
    own numbering: row f is point free[f], and the vectors the products, sweeps and
    conjugate gradients take are (nfree, 3), contiguous (on the breathing scene half the
    points are held: vectors of every point left half of each cache line unused, and the
    triangular solves took 0.38 against 0.30 ms at level 8). free (nfree,): the free
    points; row_ptr (nfree + 1,), col (nblocks,) sorted in each row, from the diagonal
    block on (col >= row); mem_slot, fib_slot, pf_slot, rt_slot (nrows, 9): the block of each
    element's corner pair (m, n), m <= n, at 3 m + n (the block of the smaller to the
    larger row), -1 with a fixed corner and for m > n; amat (nblocks, 9): the blocks
    (row-major); pdiag (nvert, 9): each point's diagonal block with K projected (by
    point: the terms add to it by corner); sdiag (nfree, 9): the sweep's D = pdiag /
    SSOR_OMEGA; dinv (nfree, 9): their inverses; acc (nfree, 3): the forward sweep's
    scratch; gchol (nfree, 6): the Cholesky factors G of D = G G^T (g00, g10, g11, g20,
    g21, g22); ediag (nfree, 9): E = D_A - 2 D, D_A the exact diagonal blocks
    (`split_cg`)."""

    free: np.ndarray
    row_ptr: np.ndarray
    col: np.ndarray
    mem_slot: np.ndarray
    fib_slot: np.ndarray
    pf_slot: np.ndarray
    rt_slot: np.ndarray
    amat: np.ndarray
    pdiag: np.ndarray
    sdiag: np.ndarray
    dinv: np.ndarray
    acc: np.ndarray
    gchol: np.ndarray
    ediag: np.ndarray


def newton_matrix(nvert: int, vert_free, mem_vert, fib_vert, pf_vert, rt_vert) -> NewtonMatrix:
    """The pattern of the blocks coupling free points through the given triangles' (nf, 3) corners."""
    free = np.flatnonzero(np.asarray(vert_free) != 0).astype(np.int64)
    nf = free.size
    row_of = np.full(nvert, -1, np.int64)  # each point's row, -1 for a fixed one
    row_of[free] = np.arange(nf)
    every = np.arange(nf, dtype=np.int64)
    # each triangle's corner pairs (m, n) at 3 m + n, m <= n, as (smaller row) * nfree + larger;
    # -1 with a fixed corner and for m > n
    upper = np.arange(9) // 3 <= np.arange(9) % 3
    pair_keys = []
    for t in (mem_vert, fib_vert, pf_vert, rt_vert):
        t = row_of[np.asarray(t, np.int64).reshape(-1, 3)]
        i, j = np.repeat(t, 3, axis=1), np.tile(t, (1, 3))
        key = np.minimum(i, j) * nf + np.maximum(i, j)
        pair_keys.append(np.where((i >= 0) & (j >= 0) & upper[None, :], key, -1))
    keys = np.unique(np.concatenate([every * nf + every] + [k[k >= 0] for k in pair_keys]))
    row, col = keys // max(nf, 1), keys % max(nf, 1)
    row_ptr = np.zeros(nf + 1, np.int64)
    np.cumsum(np.bincount(row, minlength=nf), out=row_ptr[1:])
    slots = [np.where(k >= 0, np.searchsorted(keys, k), -1) for k in pair_keys]
    nb = keys.size
    return NewtonMatrix(
        free,
        row_ptr,
        col.astype(np.int64),
        *slots,
        amat=np.zeros((nb, 9)),
        pdiag=np.zeros((nvert, 9)),
        sdiag=np.zeros((nf, 9)),
        dinv=np.zeros((nf, 9)),
        acc=np.zeros((nf, 3)),
        gchol=np.zeros((nf, 6)),
        ediag=np.zeros((nf, 9)),
    )


@kernel
def assemble(m, rows, face, fib, pf, h, mat, planes=None, project=False):
    """mat.amat = M + h^2 K + h C on the free points (K projected element by element when
    `project`), mat.pdiag its diagonal blocks with K projected, from the tangent caches of `rows` (`hybrid.implicit.newton_caches`) and the sliding
    links' planes when given (`hybrid.terms.slide_planes.SlidePlanes`: diagonal blocks); mat.sdiag,
    mat.dinv, mat.gchol, mat.ediag. One thread in both builds (threads summing into shared blocks
    would change their last bits from one build to the other).
    # Model: m (vert_mass kg, damp_coef kg/s, term_on); rows (NewtonRows): mem_vert, mem_par, fib_vert, pf_vert, rt_vert, rt_par;
    #        mat's pattern: free, row_ptr, mem_slot, fib_slot, pf_slot, rt_slot
    # Data in: face, fib, pf (the tangent caches), h (s), planes.normal, project
    # Data out: mat.amat (nblocks, 9) kg, mat.pdiag (nvert, 9) kg (the free points' rows), mat.sdiag (nfree, 9) kg,
    #           mat.dinv (nfree, 9) 1/kg, mat.gchol (nfree, 6) kg^1/2, mat.ediag (nfree, 9) kg
    """
    amat, pdiag = mat.amat, mat.pdiag
    for k in range(amat.shape[0]):
        for r in range(9):
            amat[k, r] = 0.0
    on = m.term_on
    free, ptr = mat.free, mat.row_ptr
    for f in range(free.shape[0]):
        i = free[f]
        c = m.vert_mass[i] + (h * m.damp_coef[i] if on[T_DAMPING] else 0.0)
        for r in range(9):
            pdiag[i, r] = c if r % 4 == 0 else 0.0
            amat[ptr[f], r] = pdiag[i, r]
    if on[T_MEMBRANE]:
        membrane_tangent_blocks(rows.mem_vert, rows.mem_par, face, h * h, h, mat.mem_slot, amat, pdiag, project)
    if on[T_MUSCLE_FIBRES]:
        fibre_tangent_blocks(rows.fib_vert, fib, h * h, mat.fib_slot, amat, pdiag, project)
    if on[T_PASSIVE_FIBRES]:
        passive_fibres_tangent_blocks(rows.pf_vert, pf, h * h, mat.pf_slot, amat, pdiag, project)
    if on[T_RESTING_TENSION]:
        resting_tension_blocks(rows.rt_vert, rows.rt_par, h * h, mat.rt_slot, amat, pdiag)
    if planes is not None:
        plane_blocks(planes, h * h, ptr, amat, pdiag)
    for f in range(free.shape[0]):
        i = free[f]
        d, b, g, e, da = mat.sdiag[f], mat.dinv[f], mat.gchol[f], mat.ediag[f], amat[ptr[f]]
        for r in range(9):
            d[r] = pdiag[i, r] / SSOR_OMEGA
        _invert(d, b)
        _cholesky(d, g)
        for r in range(9):
            e[r] = da[r] - 2.0 * d[r]


@kernel(inline="always")
def _cholesky(a, g):
    """g = the lower Cholesky factor of the 3 x 3 block a (row-major), (g00, g10, g11, g20, g21,
    g22); of its diagonal's absolute values if a is not positive definite (a pivot not > 0,
    which the projection rules out).
    # Model: none   # Data in: a (9,), symmetric (its lower triangle read)   # Data out: g (6,)
    """
    d0 = a[0]
    if d0 > 0.0:
        g00 = math.sqrt(d0)
        g10, g20 = a[3] / g00, a[6] / g00
        d1 = a[4] - g10 * g10
        if d1 > 0.0:
            g11 = math.sqrt(d1)
            g21 = (a[7] - g20 * g10) / g11
            d2 = a[8] - g20 * g20 - g21 * g21
            if d2 > 0.0:
                g[0], g[1], g[2], g[3], g[4], g[5] = g00, g10, g11, g20, g21, math.sqrt(d2)
                return
    # as _invert's Jacobi fallback: dinv is then the diagonal's inverse
    g[0], g[2], g[5] = math.sqrt(abs(a[0])), math.sqrt(abs(a[4])), math.sqrt(abs(a[8]))
    g[1] = g[3] = g[4] = 0.0


@kernel
def upper_solve(mat, u, t):
    """t = (D + U)^-1 u (D = sdiag; (nfree, 3); t may be u: row i reads u_i before writing
    t_i, and t_j of the rows after it).
    # Model: mat.row_ptr (nfree + 1,), mat.col (nblocks,)
    # Data in: mat.amat (U: its off-diagonal blocks), mat.dinv (D^-1), u (nfree, 3)   # Data out: t (nfree, 3)
    """
    a, col, ptr, dinv = mat.amat, mat.col, mat.row_ptr, mat.dinv
    for i in range(ptr.shape[0] - 2, -1, -1):
        sx, sy, sz = u[i, 0], u[i, 1], u[i, 2]
        for k in range(ptr[i] + 1, ptr[i + 1]):
            b, j = a[k], col[k]
            tx, ty, tz = t[j, 0], t[j, 1], t[j, 2]
            sx -= b[0] * tx + b[1] * ty + b[2] * tz
            sy -= b[3] * tx + b[4] * ty + b[5] * tz
            sz -= b[6] * tx + b[7] * ty + b[8] * tz
        b = dinv[i]
        t[i, 0] = b[0] * sx + b[1] * sy + b[2] * sz
        t[i, 1] = b[3] * sx + b[4] * sy + b[5] * sz
        t[i, 2] = b[6] * sx + b[7] * sy + b[8] * sz


@kernel
def lower_solve(mat, v, s):
    """s = (D + L)^-1 v (D = sdiag, L = U^T read by rows of U; (nfree, 3)).
    # Model: mat.row_ptr, mat.col   # Data in: mat.amat (U), mat.dinv (D^-1), v (nfree, 3)
    # Data out: s (nfree, 3)   # Scratch: mat.acc (nfree, 3)
    """
    a, col, ptr, dinv, acc = mat.amat, mat.col, mat.row_ptr, mat.dinv, mat.acc
    n = ptr.shape[0] - 1
    for i in range(n):
        acc[i, 0] = acc[i, 1] = acc[i, 2] = 0.0
    for i in range(n):
        sx, sy, sz = v[i, 0] - acc[i, 0], v[i, 1] - acc[i, 1], v[i, 2] - acc[i, 2]
        b = dinv[i]
        zx = b[0] * sx + b[1] * sy + b[2] * sz
        zy = b[3] * sx + b[4] * sy + b[5] * sz
        zz = b[6] * sx + b[7] * sy + b[8] * sz
        s[i, 0], s[i, 1], s[i, 2] = zx, zy, zz
        for k in range(ptr[i] + 1, ptr[i + 1]):
            b, j = a[k], col[k]
            acc[j, 0] += b[0] * zx + b[3] * zy + b[6] * zz
            acc[j, 1] += b[1] * zx + b[4] * zy + b[7] * zz
            acc[j, 2] += b[2] * zx + b[5] * zy + b[8] * zz


@kernel(inline="always")
def _invert(a, b):
    """b = the inverse of the 3 x 3 block a (row-major); its diagonal's inverse (Jacobi)
    if its determinant is not > 0 (a not positive definite, which the projection rules out;
    the test is the determinant's alone, unlike `_cholesky`'s pivots).
    # Model: none   # Data in: a (9,)   # Data out: b (9,)
    """
    c00 = a[4] * a[8] - a[5] * a[7]
    c01 = a[2] * a[7] - a[1] * a[8]
    c02 = a[1] * a[5] - a[2] * a[4]
    det = a[0] * c00 + a[3] * c01 + a[6] * c02
    if not det > 0.0:
        for r in range(9):
            b[r] = 0.0
        b[0], b[4], b[8] = 1.0 / a[0], 1.0 / a[4], 1.0 / a[8]
        return
    inv = 1.0 / det
    b[0], b[1], b[2] = c00 * inv, c01 * inv, c02 * inv
    b[3], b[4], b[5] = (
        (a[5] * a[6] - a[3] * a[8]) * inv,
        (a[0] * a[8] - a[2] * a[6]) * inv,
        (a[2] * a[3] - a[0] * a[5]) * inv,
    )
    b[6], b[7], b[8] = (
        (a[3] * a[7] - a[4] * a[6]) * inv,
        (a[1] * a[6] - a[0] * a[7]) * inv,
        (a[0] * a[4] - a[1] * a[3]) * inv,
    )


@kernel
def matrix_product(mat, u, y):
    """y = A u ((nfree, 3)), A the assembled matrix: each upper block B at (i, j) adds B u_j
    to row i and B^T u_i to row j.
    # Model: mat.row_ptr, mat.col   # Data in: mat.amat (nblocks, 9), u (nfree, 3)
    # Data out: y (nfree, 3) (zeroed first: not u)
    """
    a, col, ptr = mat.amat, mat.col, mat.row_ptr
    n = ptr.shape[0] - 1
    for i in range(n):
        y[i, 0] = y[i, 1] = y[i, 2] = 0.0
    for i in range(n):
        b = a[ptr[i]]  # the diagonal block
        ux, uy, uz = u[i, 0], u[i, 1], u[i, 2]
        sx = b[0] * ux + b[1] * uy + b[2] * uz
        sy = b[3] * ux + b[4] * uy + b[5] * uz
        sz = b[6] * ux + b[7] * uy + b[8] * uz
        for k in range(ptr[i] + 1, ptr[i + 1]):
            b, j = a[k], col[k]
            vx, vy, vz = u[j, 0], u[j, 1], u[j, 2]
            sx += b[0] * vx + b[1] * vy + b[2] * vz
            sy += b[3] * vx + b[4] * vy + b[5] * vz
            sz += b[6] * vx + b[7] * vy + b[8] * vz
            y[j, 0] += b[0] * ux + b[3] * uy + b[6] * uz
            y[j, 1] += b[1] * ux + b[4] * uy + b[7] * uz
            y[j, 2] += b[2] * ux + b[5] * uy + b[8] * uz
        y[i, 0] += sx
        y[i, 1] += sy
        y[i, 2] += sz


@kernel
def sgs_sweep(mat, r, z):
    """z = (D + U)^-1 D (D + L)^-1 r ((nfree, 3)), L = U^T: `lower_solve`, D, `upper_solve`
    (in place).
    # Model: mat.row_ptr, mat.col   # Data in: mat.amat, mat.sdiag (D), mat.dinv, r (nfree, 3)
    # Data out: z (nfree, 3)   # Scratch: mat.acc
    """
    lower_solve(mat, r, z)
    sdiag = mat.sdiag
    for i in range(sdiag.shape[0]):
        b = sdiag[i]
        zx, zy, zz = z[i, 0], z[i, 1], z[i, 2]
        z[i, 0] = b[0] * zx + b[1] * zy + b[2] * zz
        z[i, 1] = b[3] * zx + b[4] * zy + b[5] * zz
        z[i, 2] = b[6] * zx + b[7] * zy + b[8] * zz
    upper_solve(mat, z, z)


@kernel
def dot(a, b):
    """a . b of two (n, 3) arrays.
    # Model: none   # Data in: a, b (n, 3)   # Data out: returns the sum
    """
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i, 0] * b[i, 0] + a[i, 1] * b[i, 1] + a[i, 2] * b[i, 2]
    return s


@kernel(inline="always")
def cg_update(alpha, p, q, x, r):
    """x += alpha p, r -= alpha q ((n, 3)); returns |r|^2.
    # Model: none   # Data in: alpha, p, q (n, 3)   # Data in/out: x, r (n, 3)   # Data out: returns |r|^2
    """
    rr = 0.0
    for i in range(p.shape[0]):
        for a in range(3):
            x[i, a] += alpha * p[i, a]
            r[i, a] -= alpha * q[i, a]
        rr += r[i, 0] * r[i, 0] + r[i, 1] * r[i, 1] + r[i, 2] * r[i, 2]
    return rr


@kernel(inline="always")
def add_rank_one(c, u, p, q):
    """q += c u (u . p) ((n, 3)).
    # Model: none   # Data in: c, u, p (n, 3)   # Data in/out: q (n, 3)
    """
    s = c * dot(u, p)
    for i in range(q.shape[0]):
        for a in range(3):
            q[i, a] += s * u[i, a]


@kernel
def half_sweep(mat, u, out):
    """out = C^-1 u = G^T (D + L)^-1 u, the half of the sweep `split_cg` iterates with (C C^T its
    preconditioner; (nfree, 3)).
    # Model: mat.row_ptr, mat.col   # Data in: mat.amat, mat.dinv, mat.gchol, u (nfree, 3)
    # Data out: out (nfree, 3)   # Scratch: mat.acc
    """
    lower_solve(mat, u, out)
    g = mat.gchol
    for i in range(out.shape[0]):
        _gt(g[i], out[i, 0], out[i, 1], out[i, 2], out, i)


@kernel
def split_cg(w, target, cg_max, rank_c=0.0, rank_g=None, rank_gh=None):
    """x = the solution of A x = r (A the assembled Newton matrix, plus c g g^T when rank_g
    is given: the lungs' rank-one stiffness, `hybrid.implicit_lungs`; vectors (nfree, 3), in the
    matrix's numbering) by the preconditioned conjugate gradients of `hybrid.implicit._solve` in
    Eisenstat's implementation: with P = (D + L) D^-1 (D + U) = C C^T, C = (D + L) G^-T
    (D = G G^T, D the sweep's diagonal blocks sdiag, L = U^T the assembled off-diagonal
    ones), they iterate on C^-1 A C^-T, whose product is two triangular solves (A = (D +
    L) + (D + U) + E, E = D_A - 2 D, D_A the exact diagonal blocks): t = (D + U)^-1 G p,
    C^-1 A C^-T p = G^T (t + (D + L)^-1 (G p + E t)). The iterates of the
    conjugate gradients preconditioned with the sweep `sgs_sweep` (their x = C^-T y), for two
    triangular solves an iteration instead of a product and a sweep (three). Stops when the residual b - A x is at most
    target, looked at when |C^-1 r| has fallen by target / |r_0| (then replacing the
    recursive C^-1 r if not yet), or at negative curvature (p^T A p not > 0). Returns the
    iterations, or -1 - k at negative curvature after k of them. The rank-one term adds
    c ^g (^g . p) to the
    product (^g = C^-1 g = rank_gh, `half_sweep`): a rank-one change of the matrix adds at
    most one iteration in exact arithmetic, where solving A^-1 g apart for Sherman-Morrison took
    a second solve (a smooth vector over the whole dome, 18 iterations against the first's 8 on
    the breathing scene at level 8).
    # Model: w.mat.row_ptr, w.mat.col   # Data in: w.mat.amat, .dinv, .gchol, .ediag, target, cg_max
    # Data in: rank_c (kg/m^4), rank_g (nfree, 3) m^2 or None, rank_gh (nfree, 3): C^-1 rank_g
    # Data in/out: r = w.cg_r (nfree, 3) (out: the recursive C^-1 r)   # Data out: x = w.cg_x (nfree, 3)
    # Scratch: y, p, q, t, b = w.cg_z, w.cg_p, w.cg_q, w.cg_t, w.cg_b (nfree, 3), w.mat.acc
    """
    mat, r, x, y, p, q, t, b = w.mat, w.cg_r, w.cg_x, w.cg_z, w.cg_p, w.cg_q, w.cg_t, w.cg_b
    g, e = mat.gchol, mat.ediag
    n = r.shape[0]
    for i in range(x.shape[0]):
        for c in range(3):
            x[i, c] = y[i, c] = p[i, c] = q[i, c] = t[i, c] = 0.0
            b[i, c] = r[i, c]
    r0 = math.sqrt(dot(r, r))
    lower_solve(mat, r, t)  # r^ = C^-1 r = G^T (D + L)^-1 r
    for i in range(n):
        _gt(g[i], t[i, 0], t[i, 1], t[i, 2], r, i)
        for c in range(3):
            p[i, c] = r[i, c]
    rr = dot(r, r)
    stop = target / r0 * math.sqrt(rr) if r0 > 0.0 else 0.0
    k = 0
    while k < cg_max:
        # q = C^-1 A C^-T p
        for i in range(n):
            _g(g[i], p[i, 0], p[i, 1], p[i, 2], q, i)  # q = G p for now
        upper_solve(mat, q, x)  # x (scratch till the end) = t = (D + U)^-1 G p
        for i in range(n):
            d = e[i]
            tx, ty, tz = x[i, 0], x[i, 1], x[i, 2]
            q[i, 0] += d[0] * tx + d[1] * ty + d[2] * tz
            q[i, 1] += d[3] * tx + d[4] * ty + d[5] * tz
            q[i, 2] += d[6] * tx + d[7] * ty + d[8] * tz
        lower_solve(mat, q, t)
        for i in range(n):
            _gt(g[i], x[i, 0] + t[i, 0], x[i, 1] + t[i, 1], x[i, 2] + t[i, 2], q, i)
        if rank_g is not None and rank_c != 0.0:  # + c ^g ^g^T p
            add_rank_one(rank_c, rank_gh, p, q)
        pq = dot(p, q)
        if not pq > 0.0:  # negative curvature (or p = 0): the caller solves with the projected matrix
            return -1 - k
        alpha = rr / pq
        rr_new = cg_update(alpha, p, q, y, r)
        k += 1
        # the preconditioned residual's reduction says when to look at the residual itself,
        # b - A x at x = C^-T y (the recursive one drifts from it at tight tolerances); if it is
        # not yet small enough, r^ = C^-1 (b - A x) replaces the recursive one
        if math.sqrt(rr_new) <= stop:
            if _true_residual(mat, g, y, b, x, q, t, rank_c, rank_g) <= target:
                break
            lower_solve(mat, q, t)
            rr_new = 0.0
            for i in range(n):
                _gt(g[i], t[i, 0], t[i, 1], t[i, 2], r, i)
                rr_new += r[i, 0] * r[i, 0] + r[i, 1] * r[i, 1] + r[i, 2] * r[i, 2]
        beta = rr_new / rr
        rr = rr_new
        for i in range(n):
            for c in range(3):
                p[i, c] = r[i, c] + beta * p[i, c]
    for i in range(n):  # x = C^-T y = (D + U)^-1 G y
        _g(g[i], y[i, 0], y[i, 1], y[i, 2], q, i)
    upper_solve(mat, q, x)
    return k


@kernel
def _true_residual(mat, g, y, b, x, q, t, rank_c, rank_g):
    """x = C^-T y = (D + U)^-1 G y; q = b - (A + c g g^T) x (t: scratch; no rank-one term when
    rank_g is None); |q|.
    # Model: mat.row_ptr, mat.col   # Data in: mat.amat, mat.dinv, g (nfree, 6) (mat.gchol), y, b (nfree, 3)
    # Data in: rank_c (kg/m^4), rank_g (nfree, 3) m^2 or None
    # Data out: x, q (nfree, 3); returns |q|   # Scratch: t (nfree, 3)
    """
    n = y.shape[0]
    for i in range(n):
        _g(g[i], y[i, 0], y[i, 1], y[i, 2], t, i)
    upper_solve(mat, t, x)
    matrix_product(mat, x, q)
    if rank_g is not None and rank_c != 0.0:
        add_rank_one(rank_c, rank_g, x, q)
    rr = 0.0
    for i in range(n):
        for c in range(3):
            q[i, c] = b[i, c] - q[i, c]
        rr += q[i, 0] * q[i, 0] + q[i, 1] * q[i, 1] + q[i, 2] * q[i, 2]
    return math.sqrt(rr)


@kernel(inline="always")
def _g(g, vx, vy, vz, out, i):
    """out[i] = G v, G lower triangular (g00, g10, g11, g20, g21, g22).
    # Model: none   # Data in: g (6,) (a row of mat.gchol), v = (vx, vy, vz), i   # Data out: out[i] (3,)
    """
    out[i, 0] = g[0] * vx
    out[i, 1] = g[1] * vx + g[2] * vy
    out[i, 2] = g[3] * vx + g[4] * vy + g[5] * vz


@kernel(inline="always")
def _gt(g, vx, vy, vz, out, i):
    """out[i] = G^T v.
    # Model: none   # Data in: g (6,) (a row of mat.gchol), v = (vx, vy, vz), i   # Data out: out[i] (3,)
    """
    out[i, 0] = g[0] * vx + g[1] * vy + g[3] * vz
    out[i, 1] = g[2] * vy + g[4] * vz
    out[i, 2] = g[5] * vz


# ---------------------------------------------------------------- the matrix's numbering


@kernel(inline="always")
def gather(rows_of, c, full, out):
    """out[f] = c full[rows_of[f]]: a vector of every point to the Newton matrix's numbering.
    # Model: rows_of (nfree,) int64 (NewtonMatrix.free)   # Data in: c, full (nvert, 3)   # Data out: out (nfree, 3)
    """
    for f in range(rows_of.shape[0]):
        for a in range(3):
            out[f, a] = c * full[rows_of[f], a]


@kernel(inline="always")
def scatter(rows_of, x, full):
    """full[rows_of[f]] = x[f]: the Newton matrix's numbering to a vector of every point.
    # Model: rows_of (nfree,) int64 (NewtonMatrix.free)   # Data in: x (nfree, 3)
    # Data out: full (nvert, 3), its free points' rows (the others left as they are)
    """
    for f in range(rows_of.shape[0]):
        for a in range(3):
            full[rows_of[f], a] = x[f, a]


@kernel(inline="always")
def scatter_add(rows_of, c, x, full):
    """full[rows_of[f]] += c x[f].
    # Model: rows_of (nfree,) int64 (NewtonMatrix.free)   # Data in: c, x (nfree, 3)
    # Data in/out: full (nvert, 3), its free points' rows
    """
    for f in range(rows_of.shape[0]):
        for a in range(3):
            full[rows_of[f], a] += c * x[f, a]
