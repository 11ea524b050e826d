"""Muscle as a sheet of fibres that pull both of their ends (issue 11, item 3),
with the active force-length relation of skeletal muscle.

The active stress of a muscle sheet of fibre tension T (N/m, force per unit
rest width) is T g(lambda) along the fibres, lambda the fibres' stretch and
g the force-length relation: g = 1 (`force_length_width = 0`, a tension that
does not depend on length) or the Gaussian g = exp(-((lambda - 1) / w)^2) of
width w (Thelen 2003 in OpenSim: w = 0.67), the tension at rest length (the
optimal length) falling as the fibres shorten or lengthen. A shortening fibre
pulls less: without it, a contracting sheet has no length at which it stops,
and shortens until its passive membrane collapses in compression, at a length
that depends on the mesh.

On each rest triangle of the muscle, f is the scene's direction field at the
centroid projected on the triangle's plane, written exactly as three edge
dyads, f (x) f = sum_k c_k u_k (x) u_k (u_k = e_k / L_k the rest edges; three
equations, three unknowns). The fibre stretch of the deformed triangle is then
exact from its edge lengths l_k: lambda^2 = f . C f = sum_k g_k l_k^2 with
g_k = c_k / L_k^2. The triangle's work function is A T Psi(lambda), Psi' = g,
A its rest area: its force, minus the gradient, is A T g(lambda) / lambda g_k
(x_j - x_i) on i along each edge k and the opposite on j, so net force and net
moment vanish identically. At rest every edge k carries the tension T A c_k / L_k
(`fibre_shares`).

Why this rule: a uniform stress is carried exactly by any triangulation (the
patch test of a constant-stress triangle), so the force across any cut of a
flat sheet of uniform fibres is T times the cut's width at every resolution and
on every mesh; on curved sheets and varying fields the error is that of the
field sampled at the centroids.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, force, param
from .muscle import fibre_direction, schedule_peak

__all__ = [
    "MuscleFibres",
    "fibre_shares",
    "fibre_coefficients",
    "add_muscle_fibres",
    "fibre_rows",
    "force_length",
    "NPAR",
]

# fib_par columns: g_k = c_k / L_k^2 (1/m^2) for the edges k = 0, 1, 2 (corner k to
# k + 1), the rest area A (m^2) and the force-length width w (0: none)
NPAR = 5
#: the largest slope of exp(-(x / w)^2) is sqrt(2 / e) / w (at x = -w / sqrt 2)
FORCE_LENGTH_MAX_SLOPE = math.sqrt(2.0 / math.e)


@force("muscle_fibres")
class MuscleFibres(Term):
    """Muscle as fibres that pull both ends: an active fibre tension
    `tension_n_per_m` (N/m, force per unit rest width of muscle sheet, at the
    fibres' rest length; a number, a `Breathing` waveform, a `Table` or a
    function of time) in the triangles of `region` (`Build.face_region`: the
    triangles whose centroid it holds, or with two points in it for a region of
    points), the fibres along the direction toward the point `toward_m` (m) or
    along `axis`, projected on the surface. `force_length_width` (a fraction of
    the rest length, dimensionless): the width w of the force-length relation
    exp(-((stretch - 1) / w)^2), the tension falling as the fibres shorten (0:
    the same tension at every length)."""

    formulations = ("continuum",)
    # fib_vert (n, 3) int32: each muscle triangle; fib_par (n, NPAR): its g_k, area, width;
    # fib_sched (n,) int64: the tension's schedule row
    arrays = {"fib_vert": Rows(np.int32, 3), "fib_par": Rows(float, NPAR), "fib_sched": Rows(np.int64)}
    triangle_rows = "fib_vert"
    region: object = param("selector")
    tension_n_per_m: object = param("schedule", ncomp=1)
    toward_m: tuple = param("vec3", None)
    axis: tuple = param("vec3", None)
    force_length_width: float = param("nonneg", 0.0, hi=10.0)

    def compile(self, b, what):
        idx = super().compile(b, what)
        toward, axis = fibre_direction(self, what)
        s = b.schedule(self.tension_n_per_m, f"{what}.tension_n_per_m", 1)
        width = self.value("force_length_width", what)
        if 0.0 < width < 0.01:
            raise SceneError(
                f"{what}.force_length_width: expected 0 (no force-length relation) or a width of at "
                f"least 0.01 of the rest length, received {width!r}"
            )
        mesh = b.mesh
        faces = mesh.face_vert[b.face_region(self.region, what, idx)]
        tri, par = fibre_rows(mesh.vert_pos, faces, width, toward=toward, axis=axis)
        if tri.shape[0] == 0:
            raise SceneError(
                f"{what}.region: expected triangles in the region "
                f"and fibres not normal to them, found none among the region's {idx.size} points"
            )
        # stable-step estimate at each corner: the tension's geometric stiffness A T sum_k |g_k|,
        # and the force-length slope's A T g'max (sum_k |g_k| L_k)^2
        peak = schedule_peak(b.schedules[s])
        g = np.abs(par[:, :3])
        p = mesh.vert_pos[tri]
        length = np.linalg.norm(np.roll(p, -1, axis=1) - p, axis=2)
        k = par[:, 3] * peak * g.sum(axis=1)
        if width > 0:
            k = k + par[:, 3] * peak * FORCE_LENGTH_MAX_SLOPE / width * np.sum(g * length, axis=1) ** 2
        for corner in range(3):
            np.add.at(b.vert_stiffness, tri[:, corner], k)
        b.add_rows(fib_vert=tri, fib_par=par, fib_sched=np.full(len(tri), s))


def fibre_coefficients(vert_pos, face_vert, direction):
    """(ok (nf,) bool, c (n_ok, 3)): for each triangle whose fibre direction is not
    normal to it (`direction` (nf, 3) at the triangle, projected on its plane), the
    coefficients of f (x) f = sum_k c_k u_k (x) u_k over its unit edges u_k (edge k
    from corner k to corner k + 1): three equations, three unknowns."""
    pos = np.asarray(vert_pos, float)
    face = np.asarray(face_vert, np.int64).reshape(-1, 3)
    p = pos[face]  # (nf, 3 corners, 3)
    e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
    length = np.linalg.norm(e, axis=2)
    normal = np.cross(e[:, 0], -e[:, 2])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    d = np.asarray(direction, float)
    f = d - np.sum(d * normal, axis=1)[:, None] * normal
    fn = np.linalg.norm(f, axis=1)
    ok = fn > 1e-9 * np.linalg.norm(d, axis=1)
    f = f[ok] / fn[ok, None]
    e, length, normal = e[ok], length[ok], normal[ok]
    # in-plane basis (b1, b2); three equations in the (11, 12, 22) components
    b1 = e[:, 0] / length[:, 0, None]
    b2 = np.cross(normal, b1)
    u = e / length[:, :, None]
    ua, ub = np.einsum("fkx,fx->fk", u, b1), np.einsum("fkx,fx->fk", u, b2)
    fa, fb = np.sum(f * b1, axis=1), np.sum(f * b2, axis=1)
    mat = np.stack([ua * ua, ua * ub, ub * ub], axis=1)  # (nf, 3 components, 3 edges)
    rhs = np.stack([fa * fa, fa * fb, fb * fb], axis=1)
    return ok, np.linalg.solve(mat, rhs[:, :, None])[:, :, 0]


def fibre_shares(vert_pos, face_vert, *, toward=None, axis=None):
    """Each edge's share of a unit fibre tension over the triangles face_vert.

    Returns (edge (n, 2) int32 with i < j, share (n,) m): the edge carries the
    tension T share (N) for a fibre tension T (N/m). Triangles whose fibre
    direction is normal to them (or that hold the point `toward`) carry none.
    """
    pos = np.asarray(vert_pos, float)
    face, par = fibre_rows(pos, face_vert, 0.0, toward=toward, axis=axis)
    face = face.astype(np.int64)
    p = pos[face]
    length = np.linalg.norm(np.roll(p, -1, axis=1) - p, axis=2)
    share = par[:, :3] * par[:, 3:4] * length  # c_k A / L_k = g_k A L_k
    i = face
    j = np.roll(face, -1, axis=1)  # edge k runs from corner k to corner k+1
    lo, hi = np.minimum(i, j).ravel(), np.maximum(i, j).ravel()
    key, inv = np.unique(lo * len(pos) + hi, return_inverse=True)
    total = np.bincount(inv.ravel(), weights=share.ravel(), minlength=key.size)
    keep = np.abs(total) > 1e-12 * (np.abs(total).max() if total.size else 0.0)
    edge = np.stack([key // len(pos), key % len(pos)], axis=1)[keep].astype(np.int32)
    return edge, total[keep]


def fibre_rows(vert_pos, face_vert, width, *, toward=None, axis=None):
    """(tri (n, 3) int32, par (n, NPAR)) of the triangles whose fibres are not normal
    to them (nor hold the point `toward`): g_k = c_k / L_k^2, rest area, width."""
    pos = np.asarray(vert_pos, float)
    face = np.asarray(face_vert, np.int64).reshape(-1, 3)
    p = pos[face]
    d = (
        (np.asarray(toward, float) - p.mean(axis=1))
        if toward is not None
        else np.tile(np.asarray(axis, float), (len(face), 1))
    )
    ok, c = fibre_coefficients(pos, face, d)
    face, p = face[ok], p[ok]
    e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
    area = 0.5 * np.linalg.norm(np.cross(e[:, 0], -e[:, 2]), axis=1)
    par = np.concatenate([c / np.sum(e * e, axis=2), area[:, None], np.full((len(face), 1), float(width))], axis=1)
    return face.astype(np.int32), par


@kernel
def force_length(stretch, width):
    """(g, g') of the force-length relation at fibre stretch `stretch` (module docstring).
    # Model: width (the relation's)   # Data in: stretch   # Data out: returns (g, g')
    """
    if width <= 0.0:
        return 1.0, 0.0
    x = (stretch - 1.0) / width
    g = math.exp(-x * x)
    return g, -2.0 * x / width * g


#: the smallest fibre stretch the force divides by: below it a triangle pulls in proportion
#: to its stretch, to nothing at 0 (work function A T (Psi(s) + g(s) (lambda^2 - s^2) / (2 s)),
#: s = MIN_STRETCH, smooth in the positions). A work function A T Psi(lambda) has a kink where
#: lambda = 0, the pull there without a direction: a sheet that yields in compression lets the
#: fibres collapse a triangle, and an implicit step's Newton solve then finds no force balance
#: (the breathing scene without a force-length relation from mesh level 5 on)
MIN_STRETCH = 0.05


@kernel
def add_muscle_fibres(fib_vert, fib_par, fib_sched, sched_val, vert_pos, vert_force):
    """Each muscle triangle pulls along its edges: A T g(lambda) / lambda g_k (x_j - x_i) on i, the opposite on j.
    # Model: fib_vert (n, 3) int32, fib_par (n, NPAR), fib_sched (n,) int64
    # Data in: sched_val (tension N/m in column 0), vert_pos   # Data out: vert_force
    """
    for f in range(fib_vert.shape[0]):
        sq = 0.0
        for k in range(3):
            i = fib_vert[f, k]
            j = fib_vert[f, (k + 1) % 3]
            dx = vert_pos[j, 0] - vert_pos[i, 0]
            dy = vert_pos[j, 1] - vert_pos[i, 1]
            dz = vert_pos[j, 2] - vert_pos[i, 2]
            sq += fib_par[f, k] * (dx * dx + dy * dy + dz * dz)
        stretch = max(math.sqrt(max(sq, 0.0)), MIN_STRETCH)
        g, _ = force_length(stretch, fib_par[f, 4])
        coef = fib_par[f, 3] * sched_val[fib_sched[f], 0] * g / stretch
        for k in range(3):
            i = fib_vert[f, k]
            j = fib_vert[f, (k + 1) % 3]
            c = coef * fib_par[f, k]
            for x in range(3):
                d = c * (vert_pos[j, x] - vert_pos[i, x])
                vert_force[i, x] += d
                vert_force[j, x] -= d
