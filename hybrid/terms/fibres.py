"""Muscle as a sheet of fibres that pull both of their ends (issue 11, item 3).

The active stress of a muscle sheet of fibre tension T (N/m, force per unit
width) is sigma = T f (x) f, f the unit fibre direction in the sheet. On each
rest triangle of the muscle, f is the scene's direction field at the centroid
projected on the triangle's plane, and sigma is written exactly as three edge
dyads, f (x) f = sum_k c_k u_k (x) u_k (u_k = e_k / |e_k|; three equations,
three unknowns). For a triangle of area A under a linear displacement the
virtual work of A sigma : eps is then sum_k T c_k A / |e_k| d|e_k|: each edge
k carries the tension T s_k, s_k = c_k A / |e_k| (m), along its current
direction, on both ends. The shares s_k of the triangles are summed per edge
once at compile time; the kernel adds T(t) s (x_j - x_i) / |x_j - x_i| to i and
the opposite to j, so net force and net moment vanish identically, and the
force is minus the gradient of E = T sum_edges s |x_j - x_i|.

Why this rule: a uniform stress is carried exactly by any triangulation (the
patch test of a constant-stress triangle), so the force across any cut of a
flat sheet of uniform fibres is T times the cut's width at every resolution and
on every mesh; on curved sheets and varying fields the error is that of the
field sampled at the centroids.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, force, param
from .muscle import fibre_direction, schedule_peak

__all__ = ["MuscleFibres", "fibre_shares", "fibre_coefficients", "add_muscle_fibres"]


@force("muscle_fibres")
class MuscleFibres(Term):
    """Muscle as fibres that pull both ends: an active fibre tension
    `tension_n_per_m` (N/m, force per unit width of muscle sheet; a number, a
    `Breathing` waveform, a `Table` or a function of time) in the triangles of
    `region` (`Build.face_region`: the triangles whose centroid it holds, or with
    two points in it for a region of points), the fibres along
    the direction toward the point `toward_m` (m) or along `axis`, projected
    on the surface. Each edge carries its share of the tension on both ends."""
    formulations = ("continuum",)
    # fib_edge (nedge, 2) int32: i, j; fib_share (nedge,) m: the edge's tension per unit T;
    # fib_sched (nedge,) int64: the tension's schedule row
    arrays = {"fib_edge": Rows(np.int32, 2), "fib_share": Rows(float), "fib_sched": Rows(np.int64)}
    region: object = param("selector")
    tension_n_per_m: object = param("schedule", ncomp=1)
    toward_m: tuple = param("vec3", None)
    axis: tuple = param("vec3", None)

    def compile(self, b, what):
        idx = super().compile(b, what)
        toward, axis = fibre_direction(self, what)
        s = b.schedule(self.tension_n_per_m, f"{what}.tension_n_per_m", 1)
        mesh = b.mesh
        faces = mesh.face_vert[b.face_region(self.region, what, idx)]
        edge, share = fibre_shares(mesh.vert_pos, faces, toward=toward, axis=axis)
        if edge.shape[0] == 0:
            raise SceneError(f"{what}.region: expected triangles in the region "
                             f"and fibres not normal to them, found none among the region's {idx.size} points")
        length = np.linalg.norm(mesh.vert_pos[edge[:, 1]] - mesh.vert_pos[edge[:, 0]], axis=1)
        # a tension's geometric stiffness, |T s| / l across each edge, at both ends (stability estimate)
        k = np.abs(share) * schedule_peak(b.schedules[s]) / length
        np.add.at(b.vert_stiffness, edge[:, 0], k)
        np.add.at(b.vert_stiffness, edge[:, 1], k)
        b.add_rows(fib_edge=edge, fib_share=share, fib_sched=np.full(share.size, s))

    @classmethod
    def finish(cls, b):  # rows are edges: kept when either end moves
        edge = np.asarray(b.rows["fib_edge"], np.int64).reshape(-1, 2)
        keep = b.moving[edge[:, 0]] | b.moving[edge[:, 1]] if edge.size else np.zeros(0, bool)
        for name in cls.arrays:
            b.out[name] = cls.arrays[name].build(np.asarray(b.rows[name])[keep] if keep.size else [])


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
    face = np.asarray(face_vert, np.int64).reshape(-1, 3)
    p = pos[face]
    d = (np.asarray(toward, float) - p.mean(axis=1)) if toward is not None else np.tile(np.asarray(axis, float),
                                                                                      (len(face), 1))
    ok, c = fibre_coefficients(pos, face, d)
    face, p = face[ok], p[ok]
    e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
    length = np.linalg.norm(e, axis=2)
    area = 0.5 * np.linalg.norm(np.cross(e[:, 0], -e[:, 2]), axis=1)
    share = c * area[:, None] / length
    i = face
    j = np.roll(face, -1, axis=1)  # edge k runs from corner k to corner k+1
    lo, hi = np.minimum(i, j).ravel(), np.maximum(i, j).ravel()
    key, inv = np.unique(lo * len(pos) + hi, return_inverse=True)
    total = np.bincount(inv.ravel(), weights=share.ravel(), minlength=key.size)
    keep = np.abs(total) > 1e-12 * (np.abs(total).max() if total.size else 0.0)
    edge = np.stack([key // len(pos), key % len(pos)], axis=1)[keep].astype(np.int32)
    return edge, total[keep]


@kernel
def add_muscle_fibres(fib_edge, fib_share, fib_sched, sched_val, vert_pos, vert_force):
    """Each fibre edge pulls both ends together: F_i += T(t) s u, F_j -= T(t) s u, u = (x_j - x_i) / |x_j - x_i|.
    # Model: fib_edge (n, 2) int32, fib_share (n,) m, fib_sched (n,) int64
    # Data in: sched_val (tension N/m in column 0), vert_pos   # Data out: vert_force
    """
    for k in range(fib_edge.shape[0]):
        i = fib_edge[k, 0]
        j = fib_edge[k, 1]
        dx = vert_pos[j, 0] - vert_pos[i, 0]
        dy = vert_pos[j, 1] - vert_pos[i, 1]
        dz = vert_pos[j, 2] - vert_pos[i, 2]
        c = sched_val[fib_sched[k], 0] * fib_share[k] / np.sqrt(dx * dx + dy * dy + dz * dz)
        vert_force[i, 0] += c * dx
        vert_force[i, 1] += c * dy
        vert_force[i, 2] += c * dz
        vert_force[j, 0] -= c * dx
        vert_force[j, 1] -= c * dy
        vert_force[j, 2] -= c * dz
