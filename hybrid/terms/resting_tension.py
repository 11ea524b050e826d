"""A sheet's tension at rest (continuum): the stress stiffness a stress-free membrane lacks.

Living sheets are taut at rest: the diaphragm carries the transdiaphragmatic pressure
(Laplace: P = 2 T / R on a dome of radius R), the abdominal wall the abdomen's. A membrane
whose rest shape is stress-free resists a motion of its points only as far as the motion
stretches it: a flat or cylindrical panel, a concave groove or a shallow dome can bend
without stretching (an inextensional motion) at no cost to first order, and its restoring
force grows as the cube of the deflection.

The term is the prestress of the membrane's law: a second Piola-Kirchhoff stress S0 = T I
(`tension_n_per_m` T, isotropic) in the rest shape, whose work on the Green-Lagrange strain
E = (F^T F - I) / 2 is W = sum_f A0_f S0 : E_f = sum_f A0_f T (|F_f|^2 - 2) / 2, F_f the
deformation gradient of triangle f from its rest shape. On linear triangles
A0 |F|^2 = 1/2 sum_a cot(theta_a) |x_b - x_c|^2 (theta_a the rest angle at corner a, b and c
the others): W is quadratic in the points, its Hessian T times the rest shape's cotangent
Laplacian, positive semi-definite, the exact geometric stiffness of a prestressed sheet (a taut
drum: T |grad w|^2 / 2 against a push w across it, and as much against in-plane shear). The
loads that hold the rest shape (the pressures across the sheet, the organs behind it) are kept
as they are at rest: each point takes F_i = -grad_i W(x) + grad_i W(x0), nothing at rest and
no net force, linear in the displacement: on corner b of edge (b, c) opposite corner a,
k_a ((x_c - x_b) - (x0_c - x0_b)) with k_a = T cot(theta_a) / 2.

A first version took W = T A(x), the sheet's area: the same force to first order across the
sheet, but the area of a triangle is not convex in its corners (det F), and its Hessian had
negative eigenvalues in the sheet's plane (-1.5 N/m against 163 on a 300-point sphere at
T = 25 N/m), which a soft membrane (shear modulus 7.7 N/m on the fitted trunk) did not cover:
refined, the fitted trunk's swept volume grew 10%, then 16%, a level (0.8 s of a breath).
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..errors import SceneError
from ..integrators import IMPLICIT_EULER_ID
from ..kernel import kernel
from .base import Rows, Term, force, param

__all__ = [
    "RestingTension",
    "add_resting_tension",
    "resting_tension_energy",
    "resting_tension_product",
    "resting_tension_blocks",
    "cot_weights",
    "NPAR",
]

# rt_par columns: k_a = T cot(theta_a) / 2 (N/m) for corners a = 0, 1, 2, then the rest edge
# opposite each corner, x0_c - x0_b (m, 3 each)
NPAR = 12


def cot_weights(p: np.ndarray) -> np.ndarray:
    """(n, 3) : the cotangent of each triangle's angle at each corner, p (n, 3 corners, 3) m
    (cot = (u . v) / |u x v|, u and v the edges from the corner; 0 for a degenerate triangle)."""
    cot = np.zeros(p.shape[:2])
    for a in range(3):
        u, v = p[:, (a + 1) % 3] - p[:, a], p[:, (a + 2) % 3] - p[:, a]
        cross = np.linalg.norm(np.cross(u, v), axis=1)
        cot[:, a] = np.divide(np.sum(u * v, axis=1), cross, out=np.zeros(len(p)), where=cross > 0)
    return cot


@kernel
def add_resting_tension(rt_vert, rt_par, vert_pos, vert_force):
    """F += the prestress's force less its rest value: on corners b, c of the edge opposite
    corner a, +k_a d and -k_a d, d = (x_c - x_b) - (x0_c - x0_b) (module docstring).
    # Model: rt_vert (n, 3) int32, rt_par (n, NPAR)
    # Data in: vert_pos (nvert, 3) m   # Data out: vert_force (nvert, 3) N, added to
    """
    for f in range(rt_vert.shape[0]):
        for a in range(3):
            ib, ic = rt_vert[f, (a + 1) % 3], rt_vert[f, (a + 2) % 3]
            k = rt_par[f, a]
            for j in range(3):
                d = k * (vert_pos[ic, j] - vert_pos[ib, j] - rt_par[f, 3 + 3 * a + j])
                vert_force[ib, j] += d
                vert_force[ic, j] -= d


@kernel
def resting_tension_energy(rt_vert, rt_par, vert_pos):
    """The work whose minus gradient `add_resting_tension` adds: sum over triangles and
    corners of k_a |d_a|^2 / 2 (J), the prestress's work less its rest force's, up to a constant.
    # Model: rt_vert (n, 3) int32, rt_par (n, NPAR)   # Data in: vert_pos (nvert, 3) m   # Data out: returns J
    """
    total = 0.0
    for f in range(rt_vert.shape[0]):
        for a in range(3):
            ib, ic = rt_vert[f, (a + 1) % 3], rt_vert[f, (a + 2) % 3]
            dd = 0.0
            for j in range(3):
                d = vert_pos[ic, j] - vert_pos[ib, j] - rt_par[f, 3 + 3 * a + j]
                dd += d * d
            total += 0.5 * rt_par[f, a] * dd
    return total


@kernel
def resting_tension_product(rt_vert, rt_par, kx, u, y):
    """y += kx K u, K = -dF/dx the term's stiffness (constant: T times the rest cotangent
    Laplacian, each triangle's part positive semi-definite).
    # Model: rt_vert (n, 3) int32, rt_par (n, NPAR)   # Data in: kx (s^2 in the Newton matrix), u (nvert, 3)
    # Data out: y (nvert, 3), added to
    """
    for f in range(rt_vert.shape[0]):
        for a in range(3):
            ib, ic = rt_vert[f, (a + 1) % 3], rt_vert[f, (a + 2) % 3]
            k = kx * rt_par[f, a]
            for j in range(3):
                d = k * (u[ic, j] - u[ib, j])
                y[ib, j] -= d
                y[ic, j] += d


@kernel
def resting_tension_blocks(rt_vert, rt_par, kx, slot, amat, pdiag):
    """amat[slot] += the blocks of kx K (each a multiple of the identity); pdiag[corner] += the
    diagonal ones (each triangle's part is positive semi-definite: its projection is itself).
    # Model: rt_vert, rt_par   # Data in: kx, slot (n, 9) int64 (`hybrid.implicit_matrix.NewtonMatrix`)
    # Data out: amat (nblocks, 9), pdiag (nvert, 9) row-major blocks, added to
    """
    for f in range(rt_vert.shape[0]):
        for a in range(3):
            b, c = (a + 1) % 3, (a + 2) % 3
            k = kx * rt_par[f, a]
            for m, n, v in ((b, b, k), (c, c, k), (min(b, c), max(b, c), -k)):
                s = slot[f, 3 * m + n]
                if s < 0:
                    continue
                for r in (0, 4, 8):
                    amat[s, r] += v
                if m == n:
                    for r in (0, 4, 8):
                        pdiag[rt_vert[f, m], r] += v


@kernel
def resting_tension_step_force(m, s, w, c):
    """The step's call (`Term.step_force`); under implicit Euler the Newton solve takes the
    force instead (`hybrid.implicit.implicit_forces`).
    # Model: m.rt_vert, m.rt_par, m.integrator   # Data in: s.vert_pos   # Data out: w.vert_force (added to)
    """
    if m.integrator != IMPLICIT_EULER_ID:
        add_resting_tension(m.rt_vert, m.rt_par, s.vert_pos, w.vert_force)


@force("resting_tension")
class RestingTension(Term):
    """An isotropic tension `tension_n_per_m` (N/m) the triangles of `region` hold at
    rest, balanced there by the loads that hold the rest shape (module docstring): the
    prestress T I of the membrane's law, its force less its rest value, nothing at rest, and
    the sheet gains the (positive semi-definite) stress stiffness of a taut membrane. Implicit
    Euler takes it in its Newton solve, its constant stiffness in the Newton matrix."""

    formulations = ("continuum",)
    # rt_vert (n, 3) int32: each triangle; rt_par (n, NPAR): k_a per corner, then the rest edges
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
        k = 0.5 * t * cot_weights(p)
        edges = np.stack([p[:, (a + 2) % 3] - p[:, (a + 1) % 3] for a in range(3)], axis=1)
        par = np.concatenate([k, edges.reshape(len(tri), 9)], axis=1)
        # stable-step estimate: a row-sum (Gershgorin) bound of the stiffness, as the membrane's:
        # each edge's |k_a| on the diagonal and again off it
        for a in range(3):
            for c in ((a + 1) % 3, (a + 2) % 3):
                np.add.at(b.vert_stiffness, tri[:, c], 2.0 * np.abs(k[:, a]))
        b.add_rows(rt_vert=tri, rt_par=par)
