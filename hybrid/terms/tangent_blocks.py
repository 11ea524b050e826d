"""The off-diagonal 3 x 3 blocks of the projected element Hessians (`hybrid.terms.tangents`),
added into an assembled block-sparse matrix: what implicit Euler's symmetric Gauss-Seidel
preconditioner sweeps with (`hybrid.implicit_sgs`).

Each element adds, for each ordered pair of its corners (m, n), m != n, its block K_mn
to the matrix slot `slot[element, 3 m + n]` (-1: a corner is fixed, no slot). With the
corner weights w_n of F = sum_n x_n w_n^T (`membrane_tangent_diag`), q_n = F w_n:

    membrane  A0 [kx (w_m^T S+ w_n) I + cm (lambda q_m q_n^T + mu q_n q_m^T + mu (w_m . w_n) F F^T)],
    fibres    kx (r+ G_m G_n^T - c+_k I), G_n = grad_n lambda (or grad_n e), k the edge m-n,

S+ the clamped stress, r+ and c+_k the projected rank-one and edge coefficients (the
tangent caches' projected columns), cm = kx + kv tau. The diagonal blocks are
`hybrid.terms.tangents`' *_tangent_diag.
"""

from __future__ import annotations

from ..kernel import kernel
from .membrane import P_AREA, P_D00, P_D01, P_D11, P_LAM, P_MU, P_TAU

__all__ = ["membrane_tangent_blocks", "fibre_tangent_blocks", "passive_fibres_tangent_blocks"]


@kernel(inline="always")
def _corner_weights(d00, d01, d11, n):
    if n == 0:
        return -d00, -(d01 + d11)
    if n == 1:
        return d00, d01
    return 0.0, d11


@kernel
def membrane_tangent_blocks(mem_vert, mem_par, cache, kx, kv, slot, amat):
    """amat[slot] += the membrane's off-diagonal blocks of kx K + kv C, K projected.
    # Model: mem_vert, mem_par   # Data in: cache (membrane_tangent_cache), slot (nf, 9) int64
    # Data out: amat (nblocks, 9) row-major blocks, added to
    """
    for k in range(mem_vert.shape[0]):
        p = mem_par[k]
        q = cache[k]
        d00, d01, d11 = p[P_D00], p[P_D01], p[P_D11]
        lam, mu, area = p[P_LAM], p[P_MU], p[P_AREA]
        cm = (kx + kv * p[P_TAU]) * area
        kg = kx * area
        for m in range(3):
            wm0, wm1 = _corner_weights(d00, d01, d11, m)
            for n in range(3):
                s = slot[k, 3 * m + n]
                if m == n or s < 0:
                    continue
                wn0, wn1 = _corner_weights(d00, d01, d11, n)
                geo = kg * (wm0 * wn0 * q[9] + (wm0 * wn1 + wm1 * wn0) * q[10] + wm1 * wn1 * q[11])
                ww = mu * (wm0 * wn0 + wm1 * wn1)
                b = amat[s]
                for r in range(3):
                    qmr = wm0 * q[r] + wm1 * q[3 + r]
                    qnr = wn0 * q[r] + wn1 * q[3 + r]
                    for c in range(3):
                        qmc = wm0 * q[c] + wm1 * q[3 + c]
                        qnc = wn0 * q[c] + wn1 * q[3 + c]
                        v = cm * (lam * qmr * qnc + mu * qnr * qmc + ww * (q[r] * q[c] + q[3 + r] * q[3 + c]))
                        if r == c:
                            v += geo
                        b[3 * r + c] += v


@kernel(inline="always")
def _edge_gradient(c, n):
    """Corner n's part of sum_k +-(edge vector k) from columns 0..8 (edge k: corner k to k + 1)."""
    kp = (n + 2) % 3  # the edge that ends at n
    return (c[3 * kp] - c[3 * n], c[3 * kp + 1] - c[3 * n + 1], c[3 * kp + 2] - c[3 * n + 2])


@kernel(inline="always")
def _edge_blocks(c, scale, rank1, e0, slot, amat):
    for m in range(3):
        gmx, gmy, gmz = _edge_gradient(c, m)
        for n in range(3):
            s = slot[3 * m + n]
            if m == n or s < 0:
                continue
            gnx, gny, gnz = _edge_gradient(c, n)
            k = m if n == (m + 1) % 3 else n  # the edge joining m and n
            lap = -scale * c[e0 + k]
            r1 = scale * rank1
            b = amat[s]
            b[0] += r1 * gmx * gnx + lap
            b[1] += r1 * gmx * gny
            b[2] += r1 * gmx * gnz
            b[3] += r1 * gmy * gnx
            b[4] += r1 * gmy * gny + lap
            b[5] += r1 * gmy * gnz
            b[6] += r1 * gmz * gnx
            b[7] += r1 * gmz * gny
            b[8] += r1 * gmz * gnz + lap


@kernel
def fibre_tangent_blocks(fib_vert, cache, kx, slot, amat):
    """amat[slot] += the muscle fibres' off-diagonal blocks of kx K, K projected, from
    `fibre_tangent_cache`."""
    for f in range(fib_vert.shape[0]):
        c = cache[f]
        if c[17] != 0.0:
            _edge_blocks(c, kx, c[10], 14, slot[f], amat)


@kernel
def passive_fibres_tangent_blocks(pf_vert, cache, kx, slot, amat):
    """amat[slot] += the passive fibres' off-diagonal blocks of kx K, K projected, from
    `passive_fibres_tangent_cache`."""
    for f in range(pf_vert.shape[0]):
        c = cache[f]
        if c[9] != 0.0:
            _edge_blocks(c, kx * c[9], 1.0, 13, slot[f], amat)
