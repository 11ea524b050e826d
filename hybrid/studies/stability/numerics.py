"""The numerical tools of the stability study: the Jacobian of one step by central
differences, eigenvalue matching, bisection for the largest stable value, and
the runs' settings (no runaway heuristics, numpy's BLAS on one thread).
"""

from __future__ import annotations

import numpy as np

from hybrid.simulation import Simulation

__all__ = ["no_runaway_check", "single_thread_blas", "multiset_error", "step_jacobian", "bisect", "largest_true"]


def no_runaway_check(model):
    """The same model without the runaway heuristics (dimensionless runs move
    farther than the body's size in one step while still converging);
    divergence is then non-finite values, or our own bound in `_relax`."""
    return model.without_speed_limit()


class single_thread_blas:
    """Numpy's OpenBLAS on one thread while inside (best effort, restored after):
    dense eigenvalues of a few hundred unknowns take 0.1 s on one thread and
    seconds when its threads compete with other work on a loaded 2-core machine."""

    def __enter__(self):
        self._lib, self._n = None, None
        try:
            import ctypes
            import glob
            import os

            libs = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*"))
            lib = ctypes.CDLL(libs[0])
            self._n = int(lib.scipy_openblas_get_num_threads64_())
            lib.scipy_openblas_set_num_threads64_(1)
            self._lib = lib
        except Exception:  # another BLAS: leave it as it is
            pass
        return self

    def __exit__(self, *exc):
        if self._lib is not None:
            self._lib.scipy_openblas_set_num_threads64_(self._n)
        return False


def multiset_error(got, want) -> float:
    from scipy.optimize import linear_sum_assignment

    got, want = np.asarray(got, complex), np.asarray(want, complex)
    cost = np.abs(got[:, None] - want[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())


def step_jacobian(sim: Simulation, verts, dx: float, dv: float, x0=None, v0=None) -> np.ndarray:
    """(6n, 6n) Jacobian of one step w.r.t. (x, v) of `verts` (state order: x of
    every vertex, then v), by central differences from (x0, v0) (default rest, 0)."""
    verts = np.asarray(verts, int)
    n = verts.size
    rest = sim.model.arrays.vert_rest
    x0 = rest.copy() if x0 is None else np.asarray(x0, float)
    v0 = np.zeros_like(rest) if v0 is None else np.asarray(v0, float)
    jac = np.zeros((6 * n, 6 * n))
    for col in range(6 * n):
        half, rem = divmod(col, 3 * n)
        i, a = divmod(rem, 3)
        out = []
        for sign in (1.0, -1.0):
            x, v = x0.copy(), v0.copy()
            if half == 0:
                x[verts[i], a] += sign * dx
            else:
                v[verts[i], a] += sign * dv
            sim.reset()
            sim.set_state(vert_pos=x, vert_vel=v)
            sim.step(1)
            out.append(np.concatenate([sim.vert_pos[verts].ravel(), sim.vert_vel[verts].ravel()]))
        jac[:, col] = (out[0] - out[1]) / (2.0 * (dx if half == 0 else dv))
    return jac


def bisect(pred, lo: float, hi: float, n: int) -> tuple[float, float]:
    """(lo, hi) after n halvings of [lo, hi] keeping pred(lo) true and pred(hi) false."""
    for _ in range(n):
        mid = 0.5 * (lo + hi)
        if pred(mid):
            lo = mid
        else:
            hi = mid
    return lo, hi


def largest_true(pred, grid, n_bisect: int, *, from_top: bool = False):
    """Largest h with pred true, on the ascending `grid` refined by bisection
    between a success and the next grid point (a failure). Returns (h, first_fail).

    from_top=False: the largest h with pred true at every grid point up to it
    (a stability bound). from_top=True: the largest grid point where pred holds,
    scanning down (for runs that may also fail at small h for another reason,
    e.g. not reaching equilibrium within the time allowed)."""
    grid = list(grid)
    lo = hi = None
    if from_top:
        for j in range(len(grid) - 1, -1, -1):
            if pred(grid[j]):
                lo = grid[j]
                hi = grid[j + 1] if j + 1 < len(grid) else None
                break
        if lo is None:
            return 0.0, grid[0]
    else:
        for h in grid:
            if pred(h):
                lo = h
            else:
                hi = h
                break
        if lo is None:
            return 0.0, hi
    if hi is None:
        return lo, None
    return bisect(pred, lo, hi, n_bisect)
