"""Sliding links' planes in implicit Euler's Newton solve (`hybrid.implicit`).

A sliding point i (`RigidLink.slide_stiffness_n_per_m3`) is held to the plane through its
site s, normal n (the site's z axis), by f_i = -k g n, g = (x_i - s) . n: minus the gradient
of 1/2 k g^2, whose Hessian k n n^T is one positive semi-definite 3 x 3 block on the point's
diagonal (its projection is itself). Explicit, the plane (k ~ 1e7 N/m^3 times the point's
area) bounds the stable step; in the solve it adds h^2 k n n^T to the Newton matrix's
diagonal block, -f to the residual and 1/2 k g^2 to the line search's potential.

The solve holds the point to the plane where MuJoCo's step left its body (`carry_planes`,
from `hybrid.loop.rigid_phase`), as the linked points are put on their sites: position and
plane at the same time t + h. The body takes the reaction at the step's start
(`hybrid.loop.slide_forces`): the force the last solve ended with.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernel import FAST_NO_FMA, kernel

__all__ = [
    "SlidePlanes",
    "slide_planes",
    "carry_planes",
    "add_plane_forces",
    "plane_energy",
    "plane_product",
    "plane_blocks",
]


class SlidePlanes(NamedTuple):
    """The ns sliding points as implicit Euler's solve sees them: vert (ns,) int32, the points
    (`hybrid.loop.SlideArrays` order); row (ns,) int64, each point's row of the Newton matrix
    (-1: not integrated); stiffness (ns,) N/m; origin (ns, 3) m and normal (ns, 3): each
    plane after the step's MuJoCo step (`carry_planes`). Empty without sliding links."""

    vert: np.ndarray
    row: np.ndarray
    stiffness: np.ndarray
    origin: np.ndarray
    normal: np.ndarray


def slide_planes(vert_free, vert=None, stiffness_n_per_m=None) -> SlidePlanes:
    """The `SlidePlanes` of the points `vert` (none when None), their planes not yet placed."""
    # a copy, writable whatever it came as: the flag is part of the compiled loop's type
    vert = np.zeros(0, np.int32) if vert is None else np.array(vert, np.int32)
    k = np.zeros(0) if stiffness_n_per_m is None else np.asarray(stiffness_n_per_m, float)
    free = np.asarray(vert_free) != 0
    row_of = np.full(free.size, -1, np.int64)
    row_of[free] = np.arange(np.count_nonzero(free))  # `hybrid.implicit_matrix.NewtonMatrix.free`'s numbering
    ns = vert.size
    return SlidePlanes(vert, row_of[vert], k.copy(), np.zeros((ns, 3)), np.zeros((ns, 3)))


@kernel
def carry_planes(site_id, site_xpos, site_xmat, p):
    """The planes p's origins and normals: the sites' positions and z axes now (after MuJoCo's
    step). Nothing for an explicit integrator, whose planes are empty (`hybrid.implicit_work.no_implicit_work`).
    # Model: site_id (ns,) int64 (`hybrid.loop.SlideArrays`)   # Data in: site_xpos (nsite, 3) m, site_xmat (nsite, 9)
    # Data out: p.origin (ns, 3) m, p.normal (ns, 3) (`SlidePlanes`)
    """
    for j in range(p.origin.shape[0]):  # ns, or 0
        sid = site_id[j]
        for a in range(3):
            p.origin[j, a] = site_xpos[sid, a]
            p.normal[j, a] = site_xmat[sid, 3 * a + 2]


@kernel
def add_plane_forces(p, x, out):
    """out += -k g n on each sliding point, g = (x_i - origin) . n.
    # Model: p.vert, p.stiffness   # Data in: p.origin (m), p.normal, x (nvert, 3) m   # Data out: out (nvert, 3) N, added to
    """
    for j in range(p.vert.shape[0]):
        i = p.vert[j]
        n = p.normal[j]
        g = (x[i, 0] - p.origin[j, 0]) * n[0] + (x[i, 1] - p.origin[j, 1]) * n[1] + (x[i, 2] - p.origin[j, 2]) * n[2]
        f = -p.stiffness[j] * g
        for a in range(3):
            out[i, a] += f * n[a]


@kernel
def plane_energy(p, x):
    """sum 1/2 k g^2 (J): the potential whose minus gradient `add_plane_forces` adds.
    # Model: p.vert, p.stiffness   # Data in: p.origin (m), p.normal, x (nvert, 3) m   # Data out: returns J
    """
    total = 0.0
    for j in range(p.vert.shape[0]):
        i = p.vert[j]
        n = p.normal[j]
        g = (x[i, 0] - p.origin[j, 0]) * n[0] + (x[i, 1] - p.origin[j, 1]) * n[1] + (x[i, 2] - p.origin[j, 2]) * n[2]
        total += 0.5 * p.stiffness[j] * g * g
    return total


@kernel
def plane_product(p, kx, u, y):
    """y += kx k n (n . u) on each sliding point: kx times the planes' stiffness times u.
    # Model: p.vert, p.stiffness   # Data in: p.normal, kx (s^2 in the Newton matrix), u (nvert, 3)
    # Data out: y (nvert, 3), added to
    """
    for j in range(p.vert.shape[0]):
        i = p.vert[j]
        n = p.normal[j]
        c = kx * p.stiffness[j] * (n[0] * u[i, 0] + n[1] * u[i, 1] + n[2] * u[i, 2])
        for a in range(3):
            y[i, a] += c * n[a]


@kernel(fastmath=FAST_NO_FMA)
def plane_blocks(p, kx, row_ptr, amat, pdiag):
    """amat's diagonal block of each sliding point's row += kx k n n^T, and pdiag's (positive
    semi-definite: the projection is itself). Without fused multiply-adds, as the other blocks
    (`hybrid.terms.tangent_blocks`).
    # Model: p.vert, p.row, p.stiffness, row_ptr (nfree + 1,) int64 (`hybrid.implicit_matrix.NewtonMatrix`)
    # Data in: p.normal, kx (s^2)   # Data out: amat (nblocks, 9), pdiag (nvert, 9) row-major blocks, added to
    """
    for j in range(p.vert.shape[0]):
        f = p.row[j]
        if f < 0:
            continue
        i = p.vert[j]
        n = p.normal[j]
        c = kx * p.stiffness[j]
        b = amat[row_ptr[f]]
        for r in range(3):
            for q in range(3):
                v = c * n[r] * n[q]
                b[3 * r + q] += v
                pdiag[i, 3 * r + q] += v
