"""The Jacobians of the continuum formulation's forces, for implicit steps
(`hybrid.implicit`): products y += J u looped over the elements, no matrix stored.

Membrane (`hybrid.terms.membrane`). A triangle's energy is A0 W(E) with
F = [e1 e2] D its deformation gradient (3 x 2), E = (F^T F - I)/2 and the
second Piola-Kirchhoff stress S = lambda tr(E) I + 2 mu E. Its second
derivative along a change dF of F is

    d2 W[dF, dF] = S : (dF^T dF) + dE : C : dE,   dE = sym(F^T dF),

a geometric part (S, indefinite under compression) and a material part
(C = lambda I (x) I + 2 mu I, positive semi-definite for lambda, mu >= 0). The
out-of-plane changes dF = n (x) w see only the geometric part, w^T S w, so the
element Hessian is positive semi-definite exactly when S is. The projection
(`project`) clamps the negative eigenvalue(s) of the 2 x 2 stress S (closed
form): the projected Hessian is positive semi-definite, equals the exact one
wherever that one is, and on the out-of-plane subspace equals the
eigenvalue-clamped exact Hessian; in-plane under compression it drops the
negative stress also where the material part would have made up for it.
Kelvin-Voigt viscosity tau C : dE/dt
has the velocity Jacobian tau times the material part (its dependence on the
position through F is left to the Newton iteration's residual).

The nodes enter F through dF_0 = d00 (u_b - u_a), dF_1 = d01 (u_b - u_a) + d11 (u_c - u_a)
(D upper triangular), so an element product is a few dozen multiplications.

Muscle fibres (`hybrid.terms.fibres`): a triangle's work function A T Psi(lambda),
lambda^2 = q = sum_k g_k |d_k|^2 over its edges d_k, Psi' = g the force-length
relation, has the Hessian A T ((g' - g / lambda) a (x) a + g / lambda sum_k g_k D_k),
a = grad lambda, D_k the Laplacian of edge k; below the stretch MIN_STRETCH s, where the
work function is the quadratic A T (Psi(s) + g(s) (lambda^2 - s^2) / (2 s)), the second part
alone with lambda = s. The projection leaves out a
negative coefficient of the rank-one part and the edges of negative g_k (or
negative tension) in the second part; the rest is positive semi-definite.

Passive fibres (`hybrid.terms.passive_fibres`): a stretched triangle's energy
A0 E_f e^2 / 2, e = sum_k g_k (|d_k|^2 - L_k^2) / 2 over its edges d_k, has the
Hessian A0 E_f (grad e (x) grad e + e sum_k g_k D_k), D_k the Laplacian of edge k;
none where slack (e <= 0). The projection leaves out the edges of negative g_k in
the second part (the fibre decomposition's coefficients may be negative); the
rest is positive semi-definite.

Drag (`hybrid.terms.pointwise.Damping`): F = -c v, Jacobian -c I.

The conjugate gradients multiply by the same matrix dozens of times per Newton
iteration: the fibre terms' per-triangle data (the stretch, the force-length
relation, the gradient's edge vectors and the coefficients, exact and projected)
are computed once per iteration by `fibre_tangent_cache` and
`passive_fibres_tangent_cache`, and `fibre_cached_product` and
`passive_fibres_cached_product` read them (as `membrane_tangent_cache` does for the
membrane). `fibre_tangent_product` and `passive_fibres_tangent_product` compute
the same products from the positions (the formulas the cached ones are tested against).

The products return the Hessian's sign (positive semi-definite): the force
Jacobian is minus it.
"""

from __future__ import annotations

import math

from ..kernel import kernel
from .fibres import MIN_STRETCH, force_length
from .membrane import P_AREA, P_D00, P_D01, P_D11, P_LAM, P_MU, P_TAU, _edges_and_strain

__all__ = [
    "NCACHE",
    "NFIB_CACHE",
    "NPF_CACHE",
    "fibre_tangent_cache",
    "fibre_cached_product",
    "passive_fibres_tangent_cache",
    "passive_fibres_cached_product",
    "membrane_tangent_cache",
    "membrane_tangent_product",
    "fibre_tangent_product",
    "clamp_stress",
    "kelvin_voigt_dissipation",
    "fibre_energy",
    "passive_fibres_tangent_product",
    "passive_fibres_energy_kernel",
]

# membrane_tangent_cache columns: F's columns f0, f1 (3 each), the stress S00, S01, S11 (N/m), the
# projected stress (the same three, its negative eigenvalues clamped)
NCACHE = 12
# fibre_tangent_cache columns: per edge k the vector g_k d_k / lambda (9; their sum with signs is
# grad lambda), the rank-one coefficient exact and projected, the edges' coefficients A T g / lambda g_k
# exact (3) and projected (3), and A T (0: the triangle pulls nothing, no Hessian)
NFIB_CACHE = 18
# passive_fibres_tangent_cache columns: per edge k the vector g_k d_k (9), A0 E_f (0 where slack: no
# Hessian), e g_k exact (3) and projected (3)
NPF_CACHE = 16


@kernel(inline="always")
def clamp_stress(s00, s01, s11):
    """The 2 x 2 symmetric S with its negative eigenvalues set to 0 (closed form).
    # Model: none   # Data in: s00, s01, s11   # Data out: returns the clamped (s00, s01, s11)
    """
    m = 0.5 * (s00 + s11)
    r = math.sqrt(0.25 * (s00 - s11) ** 2 + s01 * s01)
    lo, hi = m - r, m + r
    if lo >= 0.0:
        return s00, s01, s11
    if hi <= 0.0:
        return 0.0, 0.0, 0.0
    c = hi / (hi - lo)  # hi times the projector (S - lo I) / (hi - lo) on hi's eigenvector
    return c * (s00 - lo), c * s01, c * (s11 - lo)


@kernel
def membrane_tangent_cache(mem_vert, mem_par, vert_pos, cache):
    """Per triangle, what its Hessian products read at vert_pos: F's columns, the
    stress S and S with its negative eigenvalues clamped.
    # Model: mem_vert (nf, 3) int32, mem_par (nf, NPAR)   # Data in: vert_pos (m)
    # Data out: cache (nf, NCACHE)
    """
    for k in range(mem_vert.shape[0]):
        p = mem_par[k]
        d00, d01, d11 = p[P_D00], p[P_D01], p[P_D11]
        e1x, e1y, e1z, e2x, e2y, e2z, s00, s01, s11 = _edges_and_strain(mem_vert, mem_par, k, vert_pos)
        lt = p[P_LAM] * (s00 + s11)
        m2 = 2.0 * p[P_MU]
        S00, S01, S11 = lt + m2 * s00, m2 * s01, lt + m2 * s11
        c = cache[k]
        c[0], c[1], c[2] = d00 * e1x, d00 * e1y, d00 * e1z
        c[3], c[4], c[5] = d01 * e1x + d11 * e2x, d01 * e1y + d11 * e2y, d01 * e1z + d11 * e2z
        c[6], c[7], c[8] = S00, S01, S11
        c[9], c[10], c[11] = clamp_stress(S00, S01, S11)


@kernel
def membrane_tangent_product(mem_vert, mem_par, cache, project, kx, kv, u, y):
    """y += (kx K + kv C) u: K the membrane's Hessian (projected when `project`), C its
    Kelvin-Voigt damping matrix (tau times the material part).
    # Model: mem_vert, mem_par   # Data in: cache (membrane_tangent_cache), u (nvert, 3)
    # Data out: y (nvert, 3), added to
    """
    col = 9 if project else 6
    for k in range(mem_vert.shape[0]):
        a, b, c = mem_vert[k, 0], mem_vert[k, 1], mem_vert[k, 2]
        p = mem_par[k]
        q = cache[k]
        d00, d01, d11 = p[P_D00], p[P_D01], p[P_D11]
        lam, mu = p[P_LAM], p[P_MU]
        cm = kx + kv * p[P_TAU]  # material part: stiffness and viscosity
        ubx, uby, ubz = u[b, 0] - u[a, 0], u[b, 1] - u[a, 1], u[b, 2] - u[a, 2]
        ucx, ucy, ucz = u[c, 0] - u[a, 0], u[c, 1] - u[a, 1], u[c, 2] - u[a, 2]
        g0x, g0y, g0z = d00 * ubx, d00 * uby, d00 * ubz  # dF's columns
        g1x, g1y, g1z = d01 * ubx + d11 * ucx, d01 * uby + d11 * ucy, d01 * ubz + d11 * ucz
        f0x, f0y, f0z, f1x, f1y, f1z = q[0], q[1], q[2], q[3], q[4], q[5]
        e00 = f0x * g0x + f0y * g0y + f0z * g0z
        e11 = f1x * g1x + f1y * g1y + f1z * g1z
        e01 = 0.5 * (f0x * g1x + f0y * g1y + f0z * g1z + f1x * g0x + f1y * g0y + f1z * g0z)
        lt = lam * (e00 + e11)
        t00, t01, t11 = cm * (lt + 2.0 * mu * e00), cm * 2.0 * mu * e01, cm * (lt + 2.0 * mu * e11)
        s00, s01, s11 = kx * q[col], kx * q[col + 1], kx * q[col + 2]
        # P_a = F dS_a (material) + sum_b S_ab dF_b (geometric)
        p0x = f0x * t00 + f1x * t01 + s00 * g0x + s01 * g1x
        p0y = f0y * t00 + f1y * t01 + s00 * g0y + s01 * g1y
        p0z = f0z * t00 + f1z * t01 + s00 * g0z + s01 * g1z
        p1x = f0x * t01 + f1x * t11 + s01 * g0x + s11 * g1x
        p1y = f0y * t01 + f1y * t11 + s01 * g0y + s11 * g1y
        p1z = f0z * t01 + f1z * t11 + s01 * g0z + s11 * g1z
        A = p[P_AREA]
        bx, by, bz = A * (d00 * p0x + d01 * p1x), A * (d00 * p0y + d01 * p1y), A * (d00 * p0z + d01 * p1z)
        cx, cy, cz = A * d11 * p1x, A * d11 * p1y, A * d11 * p1z
        y[a, 0] -= bx + cx
        y[a, 1] -= by + cy
        y[a, 2] -= bz + cz
        y[b, 0] += bx
        y[b, 1] += by
        y[b, 2] += bz
        y[c, 0] += cx
        y[c, 1] += cy
        y[c, 2] += cz


@kernel(inline="always")
def _fibre_state(fib_vert, fib_par, fib_sched, sched_val, vert_pos, f):
    """(lambda, A T, g, g') of muscle triangle f (`hybrid.terms.fibres`); below MIN_STRETCH
    (MIN_STRETCH, A T, g(MIN_STRETCH), g(MIN_STRETCH) / MIN_STRETCH): the Hessian of its quadratic.
    # Model: fib_vert, fib_par, fib_sched   # Data in: sched_val, vert_pos (nvert, 3) m, f
    # Data out: returns (lambda, A T, g, g')
    """
    sq = 0.0
    for k in range(3):
        i, j = fib_vert[f, k], fib_vert[f, (k + 1) % 3]
        dx, dy, dz = vert_pos[j, 0] - vert_pos[i, 0], vert_pos[j, 1] - vert_pos[i, 1], vert_pos[j, 2] - vert_pos[i, 2]
        sq += fib_par[f, k] * (dx * dx + dy * dy + dz * dz)
    lam = math.sqrt(max(sq, 0.0))
    if lam < MIN_STRETCH:  # the quadratic below MIN_STRETCH: no rank-one part (g' = g / lambda)
        g, _ = force_length(MIN_STRETCH, fib_par[f, 4])
        return MIN_STRETCH, fib_par[f, 3] * sched_val[fib_sched[f], 0], g, g / MIN_STRETCH
    g, dg = force_length(lam, fib_par[f, 4])
    return lam, fib_par[f, 3] * sched_val[fib_sched[f], 0], g, dg


@kernel
def fibre_tangent_product(fib_vert, fib_par, fib_sched, sched_val, vert_pos, project, kx, u, y):
    """y += kx K u for the muscle triangles' Hessian K at vert_pos (projected when `project`).
    # Model: fib_vert, fib_par, fib_sched   # Data in: sched_val, vert_pos, u   # Data out: y, added to
    """
    for f in range(fib_vert.shape[0]):
        lam, at, g, dg = _fibre_state(fib_vert, fib_par, fib_sched, sched_val, vert_pos, f)
        rank1 = at * (dg - g / lam)
        edges = at * g / lam
        if project:
            rank1 = max(rank1, 0.0)
        au = 0.0  # a . u, a = grad lambda = sum_k g_k d_k / lambda on j, minus on i
        for k in range(3):
            i, j = fib_vert[f, k], fib_vert[f, (k + 1) % 3]
            for c in range(3):
                au += fib_par[f, k] * (vert_pos[j, c] - vert_pos[i, c]) * (u[j, c] - u[i, c])
        au /= lam
        for k in range(3):
            i, j = fib_vert[f, k], fib_vert[f, (k + 1) % 3]
            gk = fib_par[f, k]
            ge = edges * gk
            if project and ge < 0.0:
                ge = 0.0
            for c in range(3):
                d = kx * (rank1 * au * gk * (vert_pos[j, c] - vert_pos[i, c]) / lam + ge * (u[j, c] - u[i, c]))
                y[j, c] += d
                y[i, c] -= d


@kernel
def fibre_tangent_cache(fib_vert, fib_par, fib_sched, sched_val, vert_pos, cache):
    """Per muscle triangle, what `fibre_cached_product` reads at vert_pos (NFIB_CACHE columns).
    # Model: fib_vert, fib_par, fib_sched   # Data in: sched_val, vert_pos   # Data out: cache (nf, NFIB_CACHE)
    """
    for f in range(fib_vert.shape[0]):
        lam, at, g, dg = _fibre_state(fib_vert, fib_par, fib_sched, sched_val, vert_pos, f)
        c = cache[f]
        rank1 = at * (dg - g / lam)
        edges = at * g / lam
        c[9], c[10] = rank1, max(rank1, 0.0)
        c[17] = at
        for k in range(3):
            i, j = fib_vert[f, k], fib_vert[f, (k + 1) % 3]
            gk = fib_par[f, k]
            for x in range(3):
                c[3 * k + x] = gk * (vert_pos[j, x] - vert_pos[i, x]) / lam
            ge = edges * gk
            c[11 + k], c[14 + k] = ge, max(ge, 0.0)


@kernel(inline="always")
def _edge_product(c, e0, s_scale, g_scale, i0, i1, i2, u, y):
    """One fibre triangle's cached Hessian product, added to y: with a = c[0:9] . du (du
    the edges' u_(k+1) - u_k), edge k pushes its end by t_k = s_scale a c[3k:3k+3] +
    g_scale c[e0 + k] du_k and its start by -t_k.
    # Model: e0 (the column of the Laplacian coefficients), i0, i1, i2 (the corners)
    # Data in: c (the cache row), s_scale, g_scale, u (nvert, 3)   # Data out: y (nvert, 3), added to
    """
    d0x, d0y, d0z = u[i1, 0] - u[i0, 0], u[i1, 1] - u[i0, 1], u[i1, 2] - u[i0, 2]
    d1x, d1y, d1z = u[i2, 0] - u[i1, 0], u[i2, 1] - u[i1, 1], u[i2, 2] - u[i1, 2]
    d2x, d2y, d2z = u[i0, 0] - u[i2, 0], u[i0, 1] - u[i2, 1], u[i0, 2] - u[i2, 2]
    s = s_scale * (
        c[0] * d0x
        + c[1] * d0y
        + c[2] * d0z
        + c[3] * d1x
        + c[4] * d1y
        + c[5] * d1z
        + c[6] * d2x
        + c[7] * d2y
        + c[8] * d2z
    )
    g0, g1, g2 = g_scale * c[e0], g_scale * c[e0 + 1], g_scale * c[e0 + 2]
    t0x, t0y, t0z = s * c[0] + g0 * d0x, s * c[1] + g0 * d0y, s * c[2] + g0 * d0z
    t1x, t1y, t1z = s * c[3] + g1 * d1x, s * c[4] + g1 * d1y, s * c[5] + g1 * d1z
    t2x, t2y, t2z = s * c[6] + g2 * d2x, s * c[7] + g2 * d2y, s * c[8] + g2 * d2z
    y[i0, 0] += t2x - t0x
    y[i0, 1] += t2y - t0y
    y[i0, 2] += t2z - t0z
    y[i1, 0] += t0x - t1x
    y[i1, 1] += t0y - t1y
    y[i1, 2] += t0z - t1z
    y[i2, 0] += t1x - t2x
    y[i2, 1] += t1y - t2y
    y[i2, 2] += t1z - t2z


@kernel
def fibre_cached_product(fib_vert, cache, project, kx, u, y):
    """y += kx K u for the muscle triangles' Hessian K (projected when `project`), from
    `fibre_tangent_cache`: `fibre_tangent_product` without recomputing the triangles.
    # Model: fib_vert   # Data in: cache, u   # Data out: y, added to
    """
    r1 = 10 if project else 9
    e0 = 14 if project else 11
    for f in range(fib_vert.shape[0]):
        c = cache[f]
        if c[17] == 0.0:  # no tension
            continue
        _edge_product(c, e0, kx * c[r1], kx, fib_vert[f, 0], fib_vert[f, 1], fib_vert[f, 2], u, y)


@kernel
def kelvin_voigt_dissipation(mem_vert, mem_par, vert_pos, vert_vel):
    """The membrane viscosity's dissipation function R = sum A0 tau W(dE/dt) (W),
    whose minus velocity gradient at fixed positions is the viscous force.
    # Model: mem_vert, mem_par   # Data in: vert_pos m, vert_vel m/s   # Data out: returns R W
    """
    total = 0.0
    for k in range(mem_vert.shape[0]):
        p = mem_par[k]
        tau = p[P_TAU]
        if tau <= 0.0:
            continue
        a, b, c = mem_vert[k, 0], mem_vert[k, 1], mem_vert[k, 2]
        d00, d01, d11 = p[P_D00], p[P_D01], p[P_D11]
        e1x, e1y, e1z = (
            vert_pos[b, 0] - vert_pos[a, 0],
            vert_pos[b, 1] - vert_pos[a, 1],
            vert_pos[b, 2] - vert_pos[a, 2],
        )
        e2x, e2y, e2z = (
            vert_pos[c, 0] - vert_pos[a, 0],
            vert_pos[c, 1] - vert_pos[a, 1],
            vert_pos[c, 2] - vert_pos[a, 2],
        )
        v1x, v1y, v1z = (
            vert_vel[b, 0] - vert_vel[a, 0],
            vert_vel[b, 1] - vert_vel[a, 1],
            vert_vel[b, 2] - vert_vel[a, 2],
        )
        v2x, v2y, v2z = (
            vert_vel[c, 0] - vert_vel[a, 0],
            vert_vel[c, 1] - vert_vel[a, 1],
            vert_vel[c, 2] - vert_vel[a, 2],
        )
        g11 = 2.0 * (e1x * v1x + e1y * v1y + e1z * v1z)  # dG/dt
        g12 = e1x * v2x + e1y * v2y + e1z * v2z + e2x * v1x + e2y * v1y + e2z * v1z
        g22 = 2.0 * (e2x * v2x + e2y * v2y + e2z * v2z)
        t = g11 * d01 + g12 * d11
        r00, r01, r11 = 0.5 * d00 * d00 * g11, 0.5 * d00 * t, 0.5 * (d01 * t + d11 * (g12 * d01 + g22 * d11))
        tr = r00 + r11
        total += p[P_AREA] * tau * (p[P_MU] * (r00 * r00 + 2.0 * r01 * r01 + r11 * r11) + 0.5 * p[P_LAM] * tr * tr)
    return total


@kernel
def fibre_energy(fib_vert, fib_par, fib_sched, sched_val, vert_pos):
    """The muscle's work function sum A T Psi(lambda) over its triangles (J), Psi(1) = 0:
    Psi = lambda - 1 without a force-length relation, w sqrt(pi) / 2 erf((lambda - 1) / w) with;
    below MIN_STRETCH s, Psi(s) + g(s) (lambda^2 - s^2) / (2 s).
    # Model: fib_vert, fib_par, fib_sched   # Data in: sched_val, vert_pos (nvert, 3) m
    # Data out: returns the work function J
    """
    total = 0.0
    for f in range(fib_vert.shape[0]):
        lam, at, g, dg = _fibre_state(fib_vert, fib_par, fib_sched, sched_val, vert_pos, f)
        w = fib_par[f, 4]
        if w > 0.0:
            total += at * w * 0.5 * math.sqrt(math.pi) * math.erf((lam - 1.0) / w)
        else:
            total += at * (lam - 1.0)
        if lam == MIN_STRETCH:  # possibly below it: add the quadratic's part
            sq = 0.0
            for k in range(3):
                i, j = fib_vert[f, k], fib_vert[f, (k + 1) % 3]
                for c in range(3):
                    sq += fib_par[f, k] * (vert_pos[j, c] - vert_pos[i, c]) ** 2
            if sq < lam * lam:
                total += at * g * (sq - lam * lam) / (2.0 * lam)
    return total


@kernel(inline="always")
def _passive_strain(pf_vert, pf_par, vert_pos, f):
    """The fibre strain e_f of triangle f (`hybrid.terms.passive_fibres`).
    # Model: pf_vert, pf_par   # Data in: vert_pos (nvert, 3) m, f   # Data out: returns e_f
    """
    e = 0.0
    for k in range(3):
        i, j = pf_vert[f, k], pf_vert[f, (k + 1) % 3]
        dx, dy, dz = vert_pos[j, 0] - vert_pos[i, 0], vert_pos[j, 1] - vert_pos[i, 1], vert_pos[j, 2] - vert_pos[i, 2]
        e += 0.5 * pf_par[f, k] * (dx * dx + dy * dy + dz * dz - pf_par[f, 3 + k])
    return e


@kernel
def passive_fibres_tangent_product(pf_vert, pf_par, vert_pos, project, kx, u, y):
    """y += kx K u for the passive fibres' Hessian K at vert_pos: per stretched triangle
    A0 E_f (grad e (x) grad e + e sum_k g_k D_k), D_k edge k's Laplacian; projected
    (`project`) by leaving out the edges of negative g_k in the second part, the rest
    being positive semi-definite. Slack triangles (e <= 0) have none.
    # Model: pf_vert, pf_par   # Data in: vert_pos, u   # Data out: y, added to
    """
    for f in range(pf_vert.shape[0]):
        e = _passive_strain(pf_vert, pf_par, vert_pos, f)
        if e <= 0.0:
            continue
        ae = kx * pf_par[f, 6]
        gu = 0.0  # grad e . u
        for k in range(3):
            i, j = pf_vert[f, k], pf_vert[f, (k + 1) % 3]
            for a in range(3):
                gu += pf_par[f, k] * (vert_pos[j, a] - vert_pos[i, a]) * (u[j, a] - u[i, a])
        for k in range(3):
            i, j = pf_vert[f, k], pf_vert[f, (k + 1) % 3]
            g = pf_par[f, k]
            gl = g if (g > 0.0 or not project) else 0.0
            for a in range(3):
                d = ae * (gu * g * (vert_pos[j, a] - vert_pos[i, a]) + e * gl * (u[j, a] - u[i, a]))
                y[j, a] += d
                y[i, a] -= d


@kernel
def passive_fibres_tangent_cache(pf_vert, pf_par, vert_pos, cache):
    """Per passive-fibre triangle, what `passive_fibres_cached_product` reads at vert_pos (NPF_CACHE columns).
    # Model: pf_vert, pf_par   # Data in: vert_pos   # Data out: cache (nf, NPF_CACHE)
    """
    for f in range(pf_vert.shape[0]):
        e = _passive_strain(pf_vert, pf_par, vert_pos, f)
        c = cache[f]
        if e <= 0.0:
            c[9] = 0.0
            continue
        c[9] = pf_par[f, 6]
        for k in range(3):
            i, j = pf_vert[f, k], pf_vert[f, (k + 1) % 3]
            g = pf_par[f, k]
            for x in range(3):
                c[3 * k + x] = g * (vert_pos[j, x] - vert_pos[i, x])
            c[10 + k], c[13 + k] = e * g, e * max(g, 0.0)


@kernel
def passive_fibres_cached_product(pf_vert, cache, project, kx, u, y):
    """y += kx K u for the passive fibres' Hessian K (projected when `project`), from
    `passive_fibres_tangent_cache`: `passive_fibres_tangent_product` without recomputing the triangles.
    # Model: pf_vert   # Data in: cache, u   # Data out: y, added to
    """
    e0 = 13 if project else 10
    for f in range(pf_vert.shape[0]):
        c = cache[f]
        if c[9] == 0.0:  # slack
            continue
        ae = kx * c[9]
        _edge_product(c, e0, ae, ae, pf_vert[f, 0], pf_vert[f, 1], pf_vert[f, 2], u, y)


@kernel
def passive_fibres_energy_kernel(pf_vert, pf_par, vert_pos):
    """sum over triangles of A0 E_f / 2 max(e_f, 0)^2 (J), compiled.
    # Model: pf_vert, pf_par   # Data in: vert_pos (nvert, 3) m   # Data out: returns the energy J
    """
    total = 0.0
    for f in range(pf_vert.shape[0]):
        e = _passive_strain(pf_vert, pf_par, vert_pos, f)
        if e > 0.0:
            total += 0.5 * pf_par[f, 6] * e * e
    return total
