"""Linear stability of one integration step (paper 6.1).

For a point of mass m held by an elastic restoring force of stiffness k and
a viscous force of coefficient c (N s/m), one step of the integrator is a
linear map of (x, v) per direction. Its eigenvalues decide stability. The
paper's Table 1 gives them in closed form for explicit Euler; here they are
computed for both integrators, and the largest stable step is found by
bisection on the spectral radius. The model uses this to suggest a time step
when a run diverges.
"""

from __future__ import annotations

import numpy as np

__all__ = ["step_matrix", "spectral_radius", "max_stable_dt", "table1_eigenvalues"]


def step_matrix(h, k, c, m, integrator: str = "explicit_euler") -> np.ndarray:
    """(..., 2, 2) matrix of one step acting on (x, v), with F = -k x - c v."""
    h, k, c, m = np.broadcast_arrays(*(np.asarray(a, float) for a in (h, k, c, m)))
    out = np.empty(h.shape + (2, 2))
    if integrator == "explicit_euler":  # paper eq. 4
        out[..., 0, 0] = 1.0
        out[..., 0, 1] = h
        out[..., 1, 0] = -h * k / m
        out[..., 1, 1] = 1.0 - h * c / m
    elif integrator == "symplectic_euler":  # v first, then x with the new v
        damp = 1.0 - h * c / m
        out[..., 0, 0] = 1.0 - h * h * k / m
        out[..., 0, 1] = h * damp
        out[..., 1, 0] = -h * k / m
        out[..., 1, 1] = damp
    else:
        raise ValueError(f"integrator: expected 'explicit_euler' or 'symplectic_euler', received {integrator!r}")
    return out


def spectral_radius(mat: np.ndarray) -> np.ndarray:
    """Largest |eigenvalue| of (..., 2, 2) real matrices, closed form.

    The discriminant is formed as ((a - d) / 2)^2 + b c rather than
    tr^2 / 4 - det, which cancels catastrophically for small steps.
    """
    a, b, c, d = mat[..., 0, 0], mat[..., 0, 1], mat[..., 1, 0], mat[..., 1, 1]
    disc = 0.25 * (a - d) ** 2 + b * c
    det = a * d - b * c
    half_tr = 0.5 * (a + d)
    real = np.abs(half_tr) + np.sqrt(np.maximum(disc, 0.0))
    return np.where(disc < 0.0, np.sqrt(np.abs(det)), real)


def _stable(h, k, c, m, integrator):
    rho = spectral_radius(step_matrix(h, k, c, m, integrator))
    if integrator == "symplectic_euler":
        # undamped symplectic Euler keeps |lambda| = 1 exactly below 2/omega
        return rho <= 1.0 + 1e-12
    # explicit Euler: without stiffness the position's eigenvalue is exactly 1 (a
    # free drift, bounded); the step is stable while the velocity's 1 - h c/m is
    return np.where(np.asarray(k) == 0.0, rho <= 1.0 + 1e-12, rho < 1.0)


def max_stable_dt(m, k, c, integrator: str, *, h_hi: float = 10.0) -> np.ndarray:
    """Largest step h (s) keeping the step bounded, per point (vectorized).

    0 where no step is stable (explicit Euler without damping), h_hi where
    every step up to h_hi is. The stable set is an interval (0, h_max) for
    both integrators with c >= 0, so bisection applies.
    """
    m, k, c = np.broadcast_arrays(*(np.asarray(a, float) for a in (m, k, c)))
    lo = np.zeros(m.shape)
    hi = np.full(m.shape, h_hi)
    stable_hi = _stable(hi, k, c, m, integrator)
    stable_tiny = _stable(np.full(m.shape, 1e-9), k, c, m, integrator)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        ok = _stable(mid, k, c, m, integrator)
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    out = np.where(stable_hi, h_hi, lo)
    return np.where(stable_tiny | stable_hi, out, 0.0)


def table1_eigenvalues(model: str, h: float, k: float, kv: float, m: float) -> np.ndarray:
    """The paper's Table 1: eigenvalues of one explicit Euler step of the
    three-point system (two fixed neighbours, one free point, in the plane),
    with k the unified weight (k_sm = k, k_ms = 2k/3)."""
    root = np.sqrt(complex(h * h * kv * kv - (16.0 / 3.0 if model == "mass_spring" else 4.0) * m * h * h * k))
    pair = [(2 * m - h * kv + root) / (2 * m), (2 * m - h * kv - root) / (2 * m)]
    if model == "mass_spring":
        return np.array([1.0, 1.0 - h * kv / m] + pair, dtype=complex)
    if model == "shape_memory":
        return np.array(pair + pair, dtype=complex)
    raise ValueError(f"model: expected 'mass_spring' or 'shape_memory', received {model!r}")
