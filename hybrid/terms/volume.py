"""The enclosed volume (paper 4): the exact constant-volume projection and a uniform
pressure load (the soft, compressible volume: `hybrid.terms.soft_volume`).

After free integration to X*, X = X* + phi d with d_i = w_i grad_i V(X*), and
V(X* + phi d) - V0 is a cubic in phi; its real root nearest 0 is found to machine precision;
the velocities are adjusted by phi d / h, and p = phi / h^2 is the gauge
pressure inside the body. The same cubic gives the soft volume's force.

Every volume sum is taken about the body's current centroid: for a closed
surface the origin does not change the volume, but its terms are then of the
size of the body, not of its distance from a fixed point (a small or flat body
that moved far from where it started keeps its digits).
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import prange

from ..errors import SceneError
from ..kernel import CHUNK_VERTS, kernel, kernel_twin
from .base import Rows, Term, constraint, force, param

__all__ = [
    "Volume",
    "Pressure",
    "add_pressure",
    "Projection",
    "centroid",
    "face_volume",
    "ring_cross_sum",
    "volume_cubic",
    "solve_cubic_near_zero",
    "project_volume",
    "PROJ_OK",
    "PROJ_NO_GRADIENT",
    "PROJ_NO_ROOT",
]


class Projection(IntEnum):
    """Status of the volume projection, read by the simulation."""

    OK = 0
    NO_GRADIENT = 1  # the volume gradient vanished on the free points
    NO_ROOT = 2  # the cubic has no real root


PROJ_OK, PROJ_NO_GRADIENT, PROJ_NO_ROOT = int(Projection.OK), int(Projection.NO_GRADIENT), int(Projection.NO_ROOT)


@force("pressure")
class Pressure(Term):
    """A uniform pressure load on a closed surface, `pressure_pa` (Pa, positive
    pushing outward; a number, a `Breathing` waveform, a `Table` or a function
    of time): F_i = p(t) grad_i V, the work of p on the enclosed volume."""

    # pres_sched (nterm,) int64: the schedule row of each pressure term (their sum acts)
    arrays = {"pres_sched": Rows(np.int64)}
    pressure_pa: object = param("schedule", ncomp=1)

    def compile(self, b, what):
        super().compile(b, what)
        b.mesh.require_closed(f"{what} (a pressure on the enclosed volume) needs a closed surface")
        b.add_rows(pres_sched=[b.schedule(self.pressure_pa, f"{what}.pressure_pa", 1)])

    @classmethod
    def finish(cls, b):  # rows are schedules, not points: every one kept
        b.out["pres_sched"] = cls.arrays["pres_sched"].build(b.rows["pres_sched"])


@constraint("volume")
class Volume(Term):
    """The exact constant-volume constraint (paper 4.3); needs a closed surface in one piece."""

    def compile(self, b, what):
        super().compile(b, what)
        b.mesh.require_closed(f"{what}: a constant-volume constraint needs a closed surface")
        b.mesh.require_one_piece(f"{what}: a constant-volume constraint needs a surface bounding one region")
        b.mesh.require_no_self_crossing(f"{what}: a constant-volume constraint needs a surface bounding one region")
        b.out["vol0"] = float(b.mesh.volume())
        b.rows["volume"].append(what)

    @classmethod
    def finish(cls, b):
        if not np.any(b.out["vert_weight"] > 0):
            raise SceneError(
                f"{b.rows['volume'][0]}: every point is nailed, prescribed or linked; "
                "expected at least one free point to carry the volume correction"
            )


# ---------------------------------------------------------------- kernels


@kernel(inline="always")
def ring_cross_sum(ring_ptr, ring_vert, vec, i):
    """sum_j (N_j - N_1) x (N_j+1 - N_1) over the closed fan of point i, with
    N_j = vec[ring_vert[j]]: six times the volume gradient at i of a surface
    whose points are `vec` (for a closed fan the sum does not depend on the
    origin, so N_1 keeps it local and exact).
    # Model: ring_ptr (nvert + 1,) int, ring_vert (closed fans)   # Data in: vec (nvert, 3), i
    # Data out: returns (gx, gy, gz)
    """
    # unsigned indices: numba then skips its negative-index wraparound, a
    # fifth of the instructions of each neighbour
    i = np.uint64(i)
    b, e = np.uint64(ring_ptr[i]), np.uint64(ring_ptr[i + np.uint64(1)])
    v = np.uint64(ring_vert[b])
    x1, y1, z1 = vec[v, 0], vec[v, 1], vec[v, 2]
    ax = ay = az = 0.0
    gx = gy = gz = 0.0
    for j in range(b + np.uint64(1), e):
        v = np.uint64(ring_vert[j])
        bx, by, bz = vec[v, 0] - x1, vec[v, 1] - y1, vec[v, 2] - z1
        gx += ay * bz - az * by
        gy += az * bx - ax * bz
        gz += ax * by - ay * bx
        ax, ay, az = bx, by, bz
    return gx, gy, gz


def _position_sums(vert_pos, chunk_acc):
    """Sum of the positions of each chunk of CHUNK_VERTS points into chunk_acc[:, :3].
    # Model: none   # Data in: vert_pos (nvert, 3) m
    # Data out: chunk_acc[:, :3] (chunk_count(nvert), >= 3) m
    """
    n = vert_pos.shape[0]
    for c in prange((n + CHUNK_VERTS - 1) // CHUNK_VERTS):
        sx = sy = sz = 0.0
        for i in range(np.uint64(c * CHUNK_VERTS), np.uint64(min((c + 1) * CHUNK_VERTS, n))):
            sx += vert_pos[i, 0]
            sy += vert_pos[i, 1]
            sz += vert_pos[i, 2]
        chunk_acc[c, 0] = sx
        chunk_acc[c, 1] = sy
        chunk_acc[c, 2] = sz


_position_sums_serial, _position_sums_parallel = kernel_twin(_position_sums)


@kernel
def centroid(vert_pos, chunk_acc, parallel):
    """The mean of the positions (m), a tuple (x, y, z): the origin of the volume
    sums. The chunks' sums are added in order, so both builds agree to the bit.
    # Model: none   # Data in: vert_pos (nvert, 3) m   # Scratch: chunk_acc (chunk_count(nvert), >= 3)
    # Data out: returns (x, y, z) m
    # parallel: a bool, the build to run; None: the serial one, the other not even compiled
    """
    if parallel is not None and parallel:
        _position_sums_parallel(vert_pos, chunk_acc)
    else:
        _position_sums_serial(vert_pos, chunk_acc)
    sx = sy = sz = 0.0
    for c in range((vert_pos.shape[0] + CHUNK_VERTS - 1) // CHUNK_VERTS):
        sx += chunk_acc[c, 0]
        sy += chunk_acc[c, 1]
        sz += chunk_acc[c, 2]
    n = vert_pos.shape[0]
    return sx / n, sy / n, sz / n


@kernel
def face_volume(face_vert, vert_pos):
    """V = 1/6 sum_f a.(b x c) (m^3), coordinates relative to the centroid of
    the points: the volume measured independently of the projection, for observers.
    # Model: face_vert (nface, 3) int32   # Data in: vert_pos (nvert, 3) m
    # Data out: returns V m^3
    """
    sx = sy = sz = 0.0
    for i in range(vert_pos.shape[0]):
        sx += vert_pos[i, 0]
        sy += vert_pos[i, 1]
        sz += vert_pos[i, 2]
    n = vert_pos.shape[0]
    ref = (sx / n, sy / n, sz / n)
    vol = 0.0
    for f in range(face_vert.shape[0]):
        a, b, c = face_vert[f, 0], face_vert[f, 1], face_vert[f, 2]
        ax, ay, az = vert_pos[a, 0] - ref[0], vert_pos[a, 1] - ref[1], vert_pos[a, 2] - ref[2]
        bx, by, bz = vert_pos[b, 0] - ref[0], vert_pos[b, 1] - ref[1], vert_pos[b, 2] - ref[2]
        cx, cy, cz = vert_pos[c, 0] - ref[0], vert_pos[c, 1] - ref[1], vert_pos[c, 2] - ref[2]
        vol += ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    return vol / 6.0


def _cubic_terms(ring_ptr, ring_vert, ref, vert_pos, dirn, chunk_acc):
    """Sums of x_i . grad_i V(D) and D_i . grad_i V(D), times 6, over each
    chunk of CHUNK_VERTS points, into chunk_acc[:, :2].
    # Model: ring_ptr, ring_vert   # Data in: ref (x, y, z) m, vert_pos m, dirn (nvert, 3)
    # Data out: chunk_acc[:, :2] (chunk_count(nvert), >= 2)
    """
    n = vert_pos.shape[0]
    for c in prange((n + CHUNK_VERTS - 1) // CHUNK_VERTS):
        s2 = s3 = 0.0
        # unsigned indices: numba then skips its negative-index wraparound
        for i in range(np.uint64(c * CHUNK_VERTS), np.uint64(min((c + 1) * CHUNK_VERTS, n))):
            gx, gy, gz = ring_cross_sum(ring_ptr, ring_vert, dirn, i)
            s2 += (vert_pos[i, 0] - ref[0]) * gx + (vert_pos[i, 1] - ref[1]) * gy + (vert_pos[i, 2] - ref[2]) * gz
            s3 += dirn[i, 0] * gx + dirn[i, 1] * gy + dirn[i, 2] * gz
        chunk_acc[c, 0] = s2
        chunk_acc[c, 1] = s3


_cubic_terms_serial, _cubic_terms_parallel = kernel_twin(_cubic_terms)


@kernel
def volume_cubic(ring_ptr, ring_vert, ref, vert_pos, dirn, chunk_acc, out, parallel):
    """Coefficients c2, c3 of V(X + phi D) - V(X) = c1 phi + c2 phi^2 + c3 phi^3.

    V is a symmetric cubic form T(X, X, X), so c2 = 3 T(X, D, D) = X . grad V(D)
    and c3 = T(D, D, D) = V(D) = D . grad V(D) / 3, with grad_i V(D) gathered
    from the closed fan of i like the gradient itself (a surface needs to be
    closed to have a volume constraint). This equals the per-face expansion
    of (a + phi da).((b + phi db) x (c + phi dc)) summed over the faces, without its
    six gathers per face; c1 = D . grad V(X) is left to the caller.
    # Model: ring_ptr, ring_vert   # Data in: ref (x, y, z) m, the origin of the sums
    # Data in: vert_pos (m), dirn (nvert, 3) (projection direction D)
    # Scratch: chunk_acc (chunk_count(nvert), >= 2): the sums of each chunk of points
    # Data out: out (2,) = (c2, c3)   # parallel: as `centroid`
    """
    if parallel is not None and parallel:
        _cubic_terms_parallel(ring_ptr, ring_vert, ref, vert_pos, dirn, chunk_acc)
    else:
        _cubic_terms_serial(ring_ptr, ring_vert, ref, vert_pos, dirn, chunk_acc)
    c2 = c3 = 0.0
    for c in range((vert_pos.shape[0] + CHUNK_VERTS - 1) // CHUNK_VERTS):
        c2 += chunk_acc[c, 0]
        c3 += chunk_acc[c, 1]
    out[0] = c2 / 6.0
    out[1] = c3 / 18.0


@kernel
def _cubic_at(c0, c1, c2, c3, x):
    """c0 + c1 x + c2 x^2 + c3 x^3, by Horner's rule.
    # Model: none   # Data in: c0..c3, x   # Data out: returns the value
    """
    return ((c3 * x + c2) * x + c1) * x + c0


@kernel
def _root_between(c0, c1, c2, c3, a, b):
    """The root of the cubic on [a, b], where it is monotone and changes sign:
    Newton kept inside a shrinking bracket (bisection when it leaves it).
    # Model: none   # Data in: c0..c3 (the cubic), a, b (the bracket)   # Data out: returns the root
    """
    fa = _cubic_at(c0, c1, c2, c3, a)
    x = 0.5 * (a + b)
    for _ in range(200):
        fx = _cubic_at(c0, c1, c2, c3, x)
        if fx == 0.0:
            return x
        if (fx < 0.0) == (fa < 0.0):
            a, fa = x, fx
        else:
            b = x
        fp = (3.0 * c3 * x + 2.0 * c2) * x + c1
        xn = x - fx / fp if fp != 0.0 else 0.5 * (a + b)
        if not (a < xn < b):
            xn = 0.5 * (a + b)
        if xn == x or b - a <= 4e-16 * max(abs(a), abs(b)):
            return xn
        x = xn
    return x


@kernel
def _monotone_pieces(c0, c1, c2, c3):
    """(lo, k1, k2, hi): a bound R on every real root (lo = -R, hi = R) and the
    cubic's critical points k1 <= k2 clipped into [lo, hi] (equal to lo or hi
    when absent). Between consecutive ones the cubic is monotone.
    # Model: none   # Data in: c0..c3 (the cubic)   # Data out: returns (lo, k1, k2, hi)
    """
    lead = abs(c3) if c3 != 0.0 else (abs(c2) if c2 != 0.0 else abs(c1))
    r = 1.0 + max(abs(c0), abs(c1), abs(c2)) / lead  # Cauchy's bound
    k1, k2 = -r, r
    q2, q1, q0 = 3.0 * c3, 2.0 * c2, c1  # the derivative
    if q2 != 0.0:
        disc = q1 * q1 - 4.0 * q2 * q0
        if disc > 0.0:
            sq = math.sqrt(disc)
            # the stable pair of quadratic roots
            qq = -0.5 * (q1 + (sq if q1 >= 0.0 else -sq))
            u, v = qq / q2, (q0 / qq if qq != 0.0 else -qq / q2)
            k1, k2 = min(u, v), max(u, v)
    elif q1 != 0.0:
        k1 = k2 = -q0 / q1
    return -r, min(max(k1, -r), r), min(max(k2, -r), r), r


@kernel
def solve_cubic_near_zero(c0, c1, c2, c3):
    """Real root of c0 + c1 x + c2 x^2 + c3 x^3 nearest 0. Returns (root, status).

    Newton from 0 first (c0 is the small volume error, c1 > 0 the squared
    gradient norm, so it converges in a few iterations). Its root is kept
    when it lies in the monotone piece around 0 and no other piece is nearer
    to 0; otherwise every monotone piece with a sign change is searched and
    the root nearest 0 wins. No allocation, so the step stays free of
    reference counting.
    # Model: none   # Data in: c0..c3 (the cubic)   # Data out: returns (root, status PROJ_*)
    """
    if not (c1 > 0.0):
        return 0.0, PROJ_NO_GRADIENT
    x = 0.0
    last = np.inf
    converged = False
    for _ in range(60):
        f = _cubic_at(c0, c1, c2, c3, x)
        fp = (3.0 * c3 * x + 2.0 * c2) * x + c1
        if fp == 0.0:
            break
        dx = f / fp
        if abs(dx) >= last:  # roundoff floor reached: the current iterate is the root
            converged = True
            break
        x -= dx
        last = abs(dx)
        if abs(dx) <= 4e-16 * abs(x):
            converged = True
            break
    lo, k1, k2, hi = _monotone_pieces(c0, c1, c2, c3)
    # the piece around 0 (f'(0) = c1 > 0, so 0 is not a critical point)
    a = lo
    b = hi
    for k in (k1, k2):
        if k < 0.0:
            a = max(a, k)
        elif k > 0.0:
            b = min(b, k)
    # a true root (residual at the roundoff of its terms), in the piece around 0, nearest
    scale = abs(c0) + abs(c1 * x) + abs(c2 * x * x) + abs(c3 * x * x * x)
    if (
        converged
        and abs(_cubic_at(c0, c1, c2, c3, x)) <= 1e-12 * scale
        and a <= x <= b
        and abs(x) <= min(abs(a), abs(b))
    ):
        return x, PROJ_OK
    best = np.inf
    bounds = (lo, k1, k2, hi)
    for j in range(3):
        p, q = bounds[j], bounds[j + 1]
        if q <= p:
            continue
        fp_, fq = _cubic_at(c0, c1, c2, c3, p), _cubic_at(c0, c1, c2, c3, q)
        if fp_ == 0.0:
            r = p
        elif fq == 0.0:
            r = q
        elif (fp_ < 0.0) != (fq < 0.0):
            r = _root_between(c0, c1, c2, c3, p, q)
        else:
            continue
        if abs(r) < abs(best):
            best = r
    if best == np.inf:
        return 0.0, PROJ_NO_ROOT
    return best, PROJ_OK


def _volume_gather(ring_ptr, ring_vert, ref, vert_weight, vert_pos, grad, dirn, chunk_acc, shake):
    """Per point: grad_i V (closed fan), D_i = w_i grad_i V (kept as given when
    `shake`: taken at the step's start); per chunk of CHUNK_VERTS points, the sums
    of the terms of 3 V and c1, x_i . g_i and D_i . g_i, into chunk_acc[:, :2].
    # Model: ring_ptr, ring_vert (closed fans), vert_weight (nvert,) 1/kg   # Data in: ref (x, y, z) m,
    #        vert_pos (nvert, 3) m, dirn when `shake`
    # Data out: grad (nvert, 3) m^2, dirn (unless `shake`), chunk_acc[:, :2] (chunk_count(nvert), >= 2)
    """
    sixth = 1.0 / 6.0
    n = vert_weight.shape[0]
    for c in prange((n + CHUNK_VERTS - 1) // CHUNK_VERTS):
        s_vol = s_c1 = 0.0
        # unsigned indices: numba then skips its negative-index wraparound
        for i in range(np.uint64(c * CHUNK_VERTS), np.uint64(min((c + 1) * CHUNK_VERTS, n))):
            gx, gy, gz = ring_cross_sum(ring_ptr, ring_vert, vert_pos, i)
            gx *= sixth
            gy *= sixth
            gz *= sixth
            grad[i, 0] = gx
            grad[i, 1] = gy
            grad[i, 2] = gz
            px, py, pz = vert_pos[i, 0] - ref[0], vert_pos[i, 1] - ref[1], vert_pos[i, 2] - ref[2]
            if shake:
                dx, dy, dz = dirn[i, 0], dirn[i, 1], dirn[i, 2]
            else:
                w = vert_weight[i]
                dx, dy, dz = w * gx, w * gy, w * gz
                dirn[i, 0] = dx
                dirn[i, 1] = dy
                dirn[i, 2] = dz
            s_vol += px * gx + py * gy + pz * gz
            s_c1 += dx * gx + dy * gy + dz * gz
        chunk_acc[c, 0] = s_vol
        chunk_acc[c, 1] = s_c1


def _volume_direction(ring_ptr, ring_vert, vert_weight, vert_pos, dirn):
    """D_i = w_i grad_i V at vert_pos: SHAKE's projection direction, taken at the
    positions where the step starts (the constraint force's line of action over the
    step), which keeps the scheme symplectic: a free body's energy stays bounded.
    # Model: ring_ptr, ring_vert (closed fans), vert_weight (nvert,) 1/kg   # Data in: vert_pos (nvert, 3) m
    # Data out: dirn (nvert, 3)
    """
    sixth = 1.0 / 6.0
    for i in prange(vert_weight.shape[0]):
        w = vert_weight[i] * sixth
        gx, gy, gz = ring_cross_sum(ring_ptr, ring_vert, vert_pos, i)
        dirn[i, 0] = w * gx
        dirn[i, 1] = w * gy
        dirn[i, 2] = w * gz


def _volume_update(vert_weight, phi, dirn, h, vert_pos, vert_vel):
    """X += phi D, v += phi D / h on the points that carry the correction.
    # Model: vert_weight (nvert,) 1/kg (0: not corrected)   # Data in: phi kg/m, dirn, h s
    # Data in/out: vert_pos m, vert_vel m/s
    """
    s = phi / h
    for i in prange(vert_weight.shape[0]):
        if vert_weight[i] != 0.0:
            for a in range(3):
                vert_pos[i, a] += phi * dirn[i, a]
                vert_vel[i, a] += s * dirn[i, a]


_volume_gather_serial, _volume_gather_parallel = kernel_twin(_volume_gather)
_volume_update_serial, _volume_update_parallel = kernel_twin(_volume_update)
volume_direction_serial, volume_direction_parallel = kernel_twin(_volume_direction)


@kernel
def project_volume(ring_ptr, ring_vert, vol0, vert_weight, h, vert_pos, vert_vel, scratch, parallel, shake=False):
    """Exact constant-volume projection (paper 4.2-4.3).

    X = X* + phi D, D_i = w_i grad_i V(X*) (with `shake`, D as given: the gradient
    where the step started, `volume_direction_*`, which keeps the scheme
    symplectic), w_i = 1/m_i (0 for points that are
    not integrated), phi the root nearest 0 of the cubic V(X* + phi D) = V0;
    velocities v_i += phi D_i / h, the impulse of the constraint force
    (phi / h^2) grad_i V. Returns (phi, status); phi is in kg/m, and
    p = phi / h^2 (Pa) is the gauge pressure inside the body.

    The gradient is gathered per point from its closed fan of neighbours,
    grad_i V = 1/6 sum_j (N_j - N_1) x (N_j+1 - N_1), which is the face
    formula summed around the point (for a closed fan the sum does not depend
    on the origin), and V = 1/3 sum_i (x_i - ref) . grad_i V (V is
    homogeneous of degree 3), ref the centroid of X*: one pass, no scatter.

    The quadratic and cubic coefficients take a second gather (D is needed
    at every neighbour first). They are always computed: in quiet breathing
    the quadratic term still moves the volume by about 2.5e-11 per step.
    # Model: ring_ptr, ring_vert (closed fans), vol0 m^3, vert_weight (nvert,) 1/kg
    # Data in/out: vert_pos, vert_vel
    # Scratch: scratch = (grad, dirn, cubic, chunk_acc): grad (volume gradient at X*, kept
    #          for the rib coupling), dirn, cubic (2,), chunk_acc (chunk_count(nvert), >= 3):
    #          the sums of each chunk of points
    # parallel: as `centroid`
    """
    grad, dirn, cubic, chunk_acc = scratch
    ref = centroid(vert_pos, chunk_acc, parallel)
    if parallel is not None and parallel:
        _volume_gather_parallel(ring_ptr, ring_vert, ref, vert_weight, vert_pos, grad, dirn, chunk_acc, shake)
    else:
        _volume_gather_serial(ring_ptr, ring_vert, ref, vert_weight, vert_pos, grad, dirn, chunk_acc, shake)
    vol = 0.0
    c1 = 0.0
    # the chunks' sums in order: both builds agree to the last bit
    for c in range((vert_pos.shape[0] + CHUNK_VERTS - 1) // CHUNK_VERTS):
        vol += chunk_acc[c, 0]
        c1 += chunk_acc[c, 1]
    c0 = vol / 3.0 - vol0
    if not (c1 > 0.0):
        return 0.0, PROJ_NO_GRADIENT
    volume_cubic(ring_ptr, ring_vert, ref, vert_pos, dirn, chunk_acc, cubic, parallel)
    phi, status = solve_cubic_near_zero(c0, c1, cubic[0], cubic[1])
    if status != PROJ_OK:
        return 0.0, status
    if parallel is not None and parallel:
        _volume_update_parallel(vert_weight, phi, dirn, h, vert_pos, vert_vel)
    else:
        _volume_update_serial(vert_weight, phi, dirn, h, vert_pos, vert_vel)
    return phi, PROJ_OK


@kernel
def add_pressure(ring_ptr, ring_vert, pres_sched, sched_val, vert_pos, vert_force):
    """A uniform pressure load: F_i += p(t) grad_i V, p the sum of the terms' schedules (Pa).
    # Model: ring_ptr, ring_vert (closed fans), pres_sched (nterm,) int64
    # Data in: sched_val (pressure Pa in column 0), vert_pos   # Data out: vert_force
    """
    p = 0.0
    for k in range(pres_sched.shape[0]):
        p += sched_val[pres_sched[k], 0]
    c = p / 6.0
    for i in range(vert_pos.shape[0]):
        gx, gy, gz = ring_cross_sum(ring_ptr, ring_vert, vert_pos, i)
        vert_force[i, 0] += c * gx
        vert_force[i, 1] += c * gy
        vert_force[i, 2] += c * gz
