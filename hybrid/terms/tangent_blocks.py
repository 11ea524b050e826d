"""The 3 x 3 blocks of the element Hessians (`hybrid.terms.tangents`), added into an
assembled block-sparse matrix, and the diagonal blocks of the projected ones: what
implicit Euler's conjugate gradients multiply by and precondition with
(`hybrid.implicit_matrix`).

Each element adds, for each pair of its corners (m, n), m <= n, its block K_mn to the
matrix slot `slot[element, 3 m + n]` (-1: a corner is fixed, no slot), transposed when
corner m is the larger point (the matrix keeps its upper triangle,
`hybrid.implicit_matrix.NewtonMatrix`), and its projected K_nn to the row of corner n
in `pdiag`. With the
corner weights w_n of F = sum_n x_n w_n^T (w_0 = -(d00, d01 + d11), w_1 = (d00, d01),
w_2 = (0, d11)) and q_n = F w_n:

    membrane  A0 [kx (w_m^T S w_n) I + cm (lambda q_m q_n^T + mu q_n q_m^T + mu (w_m . w_n) F F^T)],
    fibres    kx (r G_m G_n^T + L_mn I), G_n = grad_n lambda (or grad_n e),

cm = kx + kv tau, S the stress (the clamped one projected), r the rank-one coefficient
and L the edges' Laplacian with their coefficients (the tangent caches' exact or
projected columns). K_nm = K_mn^T: each pair is computed and stored once. Compiled
without fused multiply-adds (`hybrid.kernel.FAST_NO_FMA`): with them the blocks' last bits
differed between a kernel just compiled and one loaded from the cache.
"""

from __future__ import annotations

from ..kernel import FAST_NO_FMA, kernel
from .membrane import P_AREA, P_D00, P_D01, P_D11, P_LAM, P_MU, P_TAU

__all__ = ["membrane_tangent_blocks", "fibre_tangent_blocks", "passive_fibres_tangent_blocks"]


@kernel(inline="always", fastmath=FAST_NO_FMA)
def _add_block(mat, s, transpose, v, diag):
    """mat[s] += v + diag I (v row-major), or its transpose.
    # Model: none   # Data in: s, transpose, v (9,) tuple (a 3x3 block, row-major), diag
    # Data out: mat[s] (9,), added to
    """
    v0, v1, v2, v3, v4, v5, v6, v7, v8 = v
    b = mat[s]
    b[0] += v0 + diag
    b[4] += v4 + diag
    b[8] += v8 + diag
    if transpose:
        v1, v3 = v3, v1
        v2, v6 = v6, v2
        v5, v7 = v7, v5
    b[1] += v1
    b[2] += v2
    b[3] += v3
    b[5] += v5
    b[6] += v6
    b[7] += v7


@kernel(inline="always", fastmath=FAST_NO_FMA)
def _corner_weights(d00, d01, d11, n):
    """Corner n's row (w0, w1) of [-1 -1; 1 0; 0 1] D, D = [d00 d01; 0 d11] the triangle's
    rest inverse edge matrix: the corner's weights on the two columns of F.
    # Model: d00, d01, d11 (a triangle's rest inverse, 1/m)   # Data in: n (corner 0..2)
    # Data out: returns (w0, w1)
    """
    if n == 0:
        return -d00, -(d01 + d11)
    if n == 1:
        return d00, d01
    return 0.0, d11


@kernel(fastmath=FAST_NO_FMA)
def membrane_tangent_blocks(mem_vert, mem_par, cache, kx, kv, slot, amat, pdiag, project=False):
    """amat[slot] += the blocks of kx K + kv C (K projected when `project`); pdiag[corner] += the
    diagonal ones with K projected.
    # Model: mem_vert, mem_par   # Data in: cache (membrane_tangent_cache), slot (nf, 9) int64, project
    # Data out: amat (nblocks, 9), pdiag (nvert, 9) row-major blocks, added to
    """
    col = 9 if project else 6  # the stress, or the clamped one
    for k in range(mem_vert.shape[0]):
        p = mem_par[k]
        c = cache[k]
        d00, d01, d11 = p[P_D00], p[P_D01], p[P_D11]
        lam, mu, area = p[P_LAM], p[P_MU], p[P_AREA]
        cm = (kx + kv * p[P_TAU]) * area
        kg = kx * area
        cl, cu = cm * lam, cm * mu
        f0x, f0y, f0z, f1x, f1y, f1z = c[0], c[1], c[2], c[3], c[4], c[5]
        # F F^T
        a00, a01, a02 = f0x * f0x + f1x * f1x, f0x * f0y + f1x * f1y, f0x * f0z + f1x * f1z
        a11, a12, a22 = f0y * f0y + f1y * f1y, f0y * f0z + f1y * f1z, f0z * f0z + f1z * f1z
        for m in range(3):
            wm0, wm1 = _corner_weights(d00, d01, d11, m)
            qmx, qmy, qmz = wm0 * f0x + wm1 * f1x, wm0 * f0y + wm1 * f1y, wm0 * f0z + wm1 * f1z
            for n in range(m, 3):
                s = slot[k, 3 * m + n]
                if s < 0:
                    continue
                wn0, wn1 = _corner_weights(d00, d01, d11, n)
                qnx, qny, qnz = wn0 * f0x + wn1 * f1x, wn0 * f0y + wn1 * f1y, wn0 * f0z + wn1 * f1z
                w00, w01, w11 = wm0 * wn0, wm0 * wn1 + wm1 * wn0, wm1 * wn1
                geo_e = kg * (w00 * c[col] + w01 * c[col + 1] + w11 * c[col + 2])
                ww = cu * (w00 + w11)
                v0 = cl * qmx * qnx + cu * qnx * qmx + ww * a00
                v1 = cl * qmx * qny + cu * qnx * qmy + ww * a01
                v2 = cl * qmx * qnz + cu * qnx * qmz + ww * a02
                v3 = cl * qmy * qnx + cu * qny * qmx + ww * a01
                v4 = cl * qmy * qny + cu * qny * qmy + ww * a11
                v5 = cl * qmy * qnz + cu * qny * qmz + ww * a12
                v6 = cl * qmz * qnx + cu * qnz * qmx + ww * a02
                v7 = cl * qmz * qny + cu * qnz * qmy + ww * a12
                v8 = cl * qmz * qnz + cu * qnz * qmz + ww * a22
                _add_block(amat, s, mem_vert[k, m] > mem_vert[k, n], (v0, v1, v2, v3, v4, v5, v6, v7, v8), geo_e)
                if m == n:
                    geo_p = kg * (w00 * c[9] + w01 * c[10] + w11 * c[11])
                    _add_block(pdiag, mem_vert[k, m], False, (v0, v1, v2, v3, v4, v5, v6, v7, v8), geo_p)


@kernel(inline="always", fastmath=FAST_NO_FMA)
def _edge_blocks(tri, c, slot, scale, rank_e, rank_p, e_col, p_col, amat, pdiag):
    """The blocks of scale (rank G_m G_n^T + L_mn I) of a fibre triangle from its cache row c:
    columns 0..8 the edge vectors (edge k from corner k to k + 1), e_col / p_col the first
    of the edges' exact / projected Laplacian coefficients.
    # Model: tri (3,) the corners, slot (9,) int64   # Data in: c (the cache row), scale, rank_e, rank_p
    # Data out: amat (nblocks, 9), pdiag (nvert, 9), added to
    """
    re, rp = scale * rank_e, scale * rank_p
    for m in range(3):
        mp = (m + 2) % 3  # the edge that ends at m
        gmx, gmy, gmz = c[3 * mp] - c[3 * m], c[3 * mp + 1] - c[3 * m + 1], c[3 * mp + 2] - c[3 * m + 2]
        for n in range(m, 3):
            s = slot[3 * m + n]
            if s < 0:
                continue
            nq = (n + 2) % 3
            gnx, gny, gnz = c[3 * nq] - c[3 * n], c[3 * nq + 1] - c[3 * n + 1], c[3 * nq + 2] - c[3 * n + 2]
            if m == n:  # edges m and m - 1 meet at m
                lap_e = scale * (c[e_col + m] + c[e_col + mp])
            else:
                k = m if n == (m + 1) % 3 else n  # the edge joining m and n
                lap_e = -scale * c[e_col + k]
            g0, g1, g2 = gmx * gnx, gmx * gny, gmx * gnz
            g3, g4, g5 = gmy * gnx, gmy * gny, gmy * gnz
            g6, g7, g8 = gmz * gnx, gmz * gny, gmz * gnz
            _add_block(
                amat,
                s,
                tri[m] > tri[n],
                (re * g0, re * g1, re * g2, re * g3, re * g4, re * g5, re * g6, re * g7, re * g8),
                lap_e,
            )
            if m == n:
                lap_p = scale * (c[p_col + m] + c[p_col + mp])
                _add_block(
                    pdiag,
                    tri[m],
                    False,
                    (rp * g0, rp * g1, rp * g2, rp * g3, rp * g4, rp * g5, rp * g6, rp * g7, rp * g8),
                    lap_p,
                )


@kernel(fastmath=FAST_NO_FMA)
def fibre_tangent_blocks(fib_vert, cache, kx, slot, amat, pdiag, project=False):
    """amat[slot] += the muscle fibres' blocks of kx K (projected when `project`), pdiag[corner] +=
    the diagonal ones of K projected, from `fibre_tangent_cache`.
    # Model: fib_vert (nf, 3) int32   # Data in: cache (fibre_tangent_cache), kx, slot (nf, 9) int64, project
    # Data out: amat (nblocks, 9), pdiag (nvert, 9), added to
    """
    for f in range(fib_vert.shape[0]):
        c = cache[f]
        if c[17] != 0.0:
            if project:
                _edge_blocks(fib_vert[f], c, slot[f], kx, c[10], c[10], 14, 14, amat, pdiag)
            else:
                _edge_blocks(fib_vert[f], c, slot[f], kx, c[9], c[10], 11, 14, amat, pdiag)


@kernel(fastmath=FAST_NO_FMA)
def passive_fibres_tangent_blocks(pf_vert, cache, kx, slot, amat, pdiag, project=False):
    """amat[slot] += the passive fibres' blocks of kx K (projected when `project`), pdiag[corner]
    += the diagonal ones of K projected, from `passive_fibres_tangent_cache`.
    # Model: pf_vert (nf, 3) int32   # Data in: cache (passive_fibres_tangent_cache), kx, slot (nf, 9) int64, project
    # Data out: amat (nblocks, 9), pdiag (nvert, 9), added to
    """
    for f in range(pf_vert.shape[0]):
        c = cache[f]
        if c[9] != 0.0:
            _edge_blocks(pf_vert[f], c, slot[f], kx * c[9], 1.0, 1.0, 13 if project else 10, 13, amat, pdiag)
