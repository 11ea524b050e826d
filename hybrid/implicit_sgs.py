"""Implicit Euler's preconditioner: one symmetric Gauss-Seidel sweep of the Newton
matrix with the Hessian projected per element (`hybrid.implicit`).

The free points' 3 x 3 off-diagonal blocks are assembled once per Newton iteration
into a block-sparse matrix (`SgsPattern`: its rows, built once per model, and each
element's slots) from the terms' tangent caches (`hybrid.terms.tangent_blocks`); the
diagonal blocks' inverses are the block-Jacobi preconditioner's. The sweep
z = (D + U)^-1 D (D + L)^-1 r (L, U the lower and upper blocks, D the diagonal) is
symmetric positive definite with the projected matrix, and costs about one product
with the matrix; on the breathing scene it took about half the conjugate-gradient
iterations of the diagonal blocks alone.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .kernel import kernel
from .terms import Membrane, MuscleFibres, PassiveFibres
from .terms.tangent_blocks import fibre_tangent_blocks, membrane_tangent_blocks, passive_fibres_tangent_blocks

__all__ = ["SgsPattern", "sgs_pattern", "sgs_assemble", "sgs_apply"]

T_MEMBRANE, T_FIBRES, T_PASSIVE = Membrane.id, MuscleFibres.id, PassiveFibres.id


class SgsPattern(NamedTuple):
    """The free points' off-diagonal blocks: row_ptr (nvert + 1,), col (nblocks,) sorted in
    each row, upper (nvert,): the first block of each row right of the diagonal;
    mem_slot, fib_slot, pf_slot (nrows, 9): the block of each element's corner pair
    (m, n) at 3 m + n, -1 on the diagonal or with a fixed corner; amat (nblocks, 9): the
    blocks (row-major), assembled by `sgs_assemble`."""
    row_ptr: np.ndarray
    col: np.ndarray
    upper: np.ndarray
    mem_slot: np.ndarray
    fib_slot: np.ndarray
    pf_slot: np.ndarray
    amat: np.ndarray


def sgs_pattern(nvert: int, vert_free, mem_vert, fib_vert, pf_vert) -> SgsPattern:
    """The pattern of the free points' blocks coupled by the given triangles' (nf, 3) corners."""
    free = np.asarray(vert_free) != 0
    tris = [np.asarray(t, np.int64).reshape(-1, 3) for t in (mem_vert, fib_vert, pf_vert)]
    pairs = []
    for t in tris:
        for m in range(3):
            for n in range(3):
                if m != n:
                    i, j = t[:, m], t[:, n]
                    ok = free[i] & free[j]
                    pairs.append(i[ok] * nvert + j[ok])
    keys = np.unique(np.concatenate(pairs)) if pairs else np.zeros(0, np.int64)
    row, col = keys // nvert, keys % nvert
    row_ptr = np.zeros(nvert + 1, np.int64)
    np.cumsum(np.bincount(row, minlength=nvert), out=row_ptr[1:])
    upper = np.searchsorted(keys, np.arange(nvert, dtype=np.int64) * nvert + np.arange(nvert))
    slots = []
    for t in tris:
        slot = np.full((t.shape[0], 9), -1, np.int64)
        for m in range(3):
            for n in range(3):
                if m != n:
                    i, j = t[:, m], t[:, n]
                    ok = free[i] & free[j]
                    slot[ok, 3 * m + n] = np.searchsorted(keys, i[ok] * nvert + j[ok])
        slots.append(slot)
    return SgsPattern(row_ptr, col.astype(np.int64), upper.astype(np.int64), *slots, amat=np.zeros((keys.size, 9)))


@kernel
def sgs_assemble(m, rows, face, fib, pf, h, sgs):
    """sgs.amat = the off-diagonal blocks of h^2 K + h C on the free points, K projected,
    from the tangent caches of `rows` (`hybrid.implicit.newton_caches`)."""
    amat = sgs.amat
    for k in range(amat.shape[0]):
        for r in range(9):
            amat[k, r] = 0.0
    on = m.term_on
    if on[T_MEMBRANE]:
        membrane_tangent_blocks(rows.mem_vert, rows.mem_par, face, h * h, h, sgs.mem_slot, amat)
    if on[T_FIBRES]:
        fibre_tangent_blocks(rows.fib_vert, fib, h * h, sgs.fib_slot, amat)
    if on[T_PASSIVE]:
        passive_fibres_tangent_blocks(rows.pf_vert, pf, h * h, sgs.pf_slot, amat)


@kernel
def sgs_apply(sgs, dinv, r, z):
    """z = (D + U)^-1 D (D + L)^-1 r, dinv (nvert, 9) the inverse diagonal blocks (rows
    without blocks, the fixed points', are dinv r)."""
    amat, col, ptr, up = sgs.amat, sgs.col, sgs.row_ptr, sgs.upper
    n = r.shape[0]
    for i in range(n):  # forward: (D + L) z = r
        sx, sy, sz = r[i, 0], r[i, 1], r[i, 2]
        for k in range(ptr[i], up[i]):
            a, j = amat[k], col[k]
            zx, zy, zz = z[j, 0], z[j, 1], z[j, 2]
            sx -= a[0] * zx + a[1] * zy + a[2] * zz
            sy -= a[3] * zx + a[4] * zy + a[5] * zz
            sz -= a[6] * zx + a[7] * zy + a[8] * zz
        b = dinv[i]
        z[i, 0] = b[0] * sx + b[1] * sy + b[2] * sz
        z[i, 1] = b[3] * sx + b[4] * sy + b[5] * sz
        z[i, 2] = b[6] * sx + b[7] * sy + b[8] * sz
    for i in range(n - 1, -1, -1):  # backward: (D + U) z' = D z
        if up[i] == ptr[i + 1]:
            continue
        sx = sy = sz = 0.0
        for k in range(up[i], ptr[i + 1]):
            a, j = amat[k], col[k]
            zx, zy, zz = z[j, 0], z[j, 1], z[j, 2]
            sx += a[0] * zx + a[1] * zy + a[2] * zz
            sy += a[3] * zx + a[4] * zy + a[5] * zz
            sz += a[6] * zx + a[7] * zy + a[8] * zz
        b = dinv[i]
        z[i, 0] -= b[0] * sx + b[1] * sy + b[2] * sz
        z[i, 1] -= b[3] * sx + b[4] * sy + b[5] * sz
        z[i, 2] -= b[6] * sx + b[7] * sy + b[8] * sz
