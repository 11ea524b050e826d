"""A sheet's tension at rest (continuum): the stress stiffness a stress-free membrane lacks.

Living sheets are taut at rest: the diaphragm carries the transdiaphragmatic pressure
(Laplace: P = 2 T / R on a dome of radius R), the abdominal wall the abdomen's. A membrane
whose rest shape is stress-free resists a motion of its points only as far as the motion
stretches it: a flat or cylindrical panel, a concave groove or a shallow dome can bend
without stretching (an inextensional motion) at no cost to first order, and its restoring
force grows as the cube of the deflection. A sheet in tension T resists every out-of-plane
motion w to first order, with the energy T (|grad w|^2 / 2 + K w^2) per unit area (K the
Gaussian curvature): a taut drum's stiffness.

The term holds an isotropic in-plane tension `tension_n_per_m` in the triangles of its
region, W = T sum_f A_f(x), and keeps the loads that hold the rest shape (the pressures
across the sheet, the organs behind it) as they are at rest: each point takes the tension's
force minus its value at rest, F_i = -T (grad_i A(x) - grad_i A(x0)), with grad_a A =
n x (x_c - x_b) / 2 on corner a of a triangle (a, b, c) of unit normal n. It adds nothing at
rest and no net force (the area does not change under a translation); its stiffness is the
geometric stiffness of the prestressed sheet.
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, force, param

__all__ = ["RestingTension", "add_resting_tension", "area_gradients", "NPAR"]

# rt_par columns: the tension T (N/m) and T grad A at rest of corners 0, 1, 2 (N, 3 each)
NPAR = 10


def area_gradients(p: np.ndarray) -> np.ndarray:
    """(n, 3 corners, 3) m: the gradient of each triangle's area with respect to its corners,
    p (n, 3 corners, 3) m; zero for a degenerate triangle."""
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    norm = np.linalg.norm(n, axis=1)
    u = np.divide(n, norm[:, None], out=np.zeros_like(n), where=norm[:, None] > 0)
    g = np.empty_like(p)
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        g[:, a] = 0.5 * np.cross(u, p[:, c] - p[:, b])
    return g


@kernel
def add_resting_tension(rt_vert, rt_par, vert_pos, vert_force):
    """F += -T grad A(x) + T grad A(x0) on each triangle's corners (module docstring).
    # Model: rt_vert (n, 3) int32, rt_par (n, NPAR)
    # Data in: vert_pos (nvert, 3) m   # Data out: vert_force (nvert, 3) N, added to
    """
    for f in range(rt_vert.shape[0]):
        i0, i1, i2 = rt_vert[f, 0], rt_vert[f, 1], rt_vert[f, 2]
        ax, ay, az = (
            vert_pos[i1, 0] - vert_pos[i0, 0],
            vert_pos[i1, 1] - vert_pos[i0, 1],
            vert_pos[i1, 2] - vert_pos[i0, 2],
        )
        bx, by, bz = (
            vert_pos[i2, 0] - vert_pos[i0, 0],
            vert_pos[i2, 1] - vert_pos[i0, 1],
            vert_pos[i2, 2] - vert_pos[i0, 2],
        )
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        nn = np.sqrt(nx * nx + ny * ny + nz * nz)
        t = rt_par[f, 0]
        if nn > 0.0:
            s = 0.5 * t / nn
            nx, ny, nz = nx * s, ny * s, nz * s
        else:
            nx = ny = nz = 0.0
        for a in range(3):
            ib, ic = rt_vert[f, (a + 1) % 3], rt_vert[f, (a + 2) % 3]
            ex = vert_pos[ic, 0] - vert_pos[ib, 0]
            ey = vert_pos[ic, 1] - vert_pos[ib, 1]
            ez = vert_pos[ic, 2] - vert_pos[ib, 2]
            ia = rt_vert[f, a]
            k = 1 + 3 * a
            vert_force[ia, 0] += rt_par[f, k] - (ny * ez - nz * ey)
            vert_force[ia, 1] += rt_par[f, k + 1] - (nz * ex - nx * ez)
            vert_force[ia, 2] += rt_par[f, k + 2] - (nx * ey - ny * ex)


@kernel(inline="always")
def resting_tension_step_force(m, s, w, c):
    """The step's call (`Term.step_force`).
    # Model: m.rt_vert, m.rt_par   # Data in: s.vert_pos   # Data out: w.vert_force (added to)
    """
    add_resting_tension(m.rt_vert, m.rt_par, s.vert_pos, w.vert_force)


@force("resting_tension")
class RestingTension(Term):
    """An isotropic tension `tension_n_per_m` (N/m) the triangles of `region` hold at
    rest, balanced there by the loads that hold the rest shape (module docstring): the
    force is the tension's minus its rest value, nothing at rest, and the sheet gains the
    stress stiffness of a taut membrane against out-of-plane motion. Its force is taken at
    the step's start under every integrator (implicit Euler: not in the Newton solve)."""

    formulations = ("continuum",)
    # rt_vert (n, 3) int32: each triangle; rt_par (n, NPAR): T, then T grad A at rest per corner
    arrays = {"rt_vert": Rows(np.int32, 3), "rt_par": Rows(float, NPAR)}
    triangle_rows = "rt_vert"
    step_force = resting_tension_step_force
    tension_n_per_m: float = param("positive", hi=checks.MAX_STIFFNESS_N_PER_M)
    region: object = param("selector", "all")

    def compile(self, b, what):
        idx = super().compile(b, what)
        tri = b.mesh.face_vert[b.face_region(self.region, what, idx)]
        if not len(tri):
            raise SceneError(f"{what}.region: expected triangles in the region, found none among its {idx.size} points")
        t = self.value("tension_n_per_m", what)
        p = b.mesh.vert_pos[tri]
        g = area_gradients(p)
        par = np.concatenate([np.full((len(tri), 1), t), t * g.reshape(len(tri), 9)], axis=1)
        # stable-step estimate: the tension's geometric stiffness at each corner, T |x_c - x_b|^2 / (4 A)
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        for a in range(3):
            opp = np.sum((p[:, (a + 2) % 3] - p[:, (a + 1) % 3]) ** 2, axis=1)
            np.add.at(b.vert_stiffness, tri[:, a], t * opp / np.maximum(4.0 * area, 1e-300))
        b.add_rows(rt_vert=tri, rt_par=par)
