"""The continuum formulation's elastic membrane: linear triangles (constant strain)
with a Saint Venant-Kirchhoff law and Kelvin-Voigt viscosity.

Each triangle remembers its rest shape up to a rigid motion: its energy is
A0 W(E), E = (F^T F - I) / 2 the Green strain of its deformation gradient F
(3 x 2, from its rest edges), W = mu tr(E^2) + lambda/2 tr(E)^2 with the
plane-stress Lame moduli of the sheet's 2D Young's modulus Y (N/m, E times
thickness) and Poisson's ratio nu. The force is minus the gradient of that
energy: W depends on the edges only through their dot products, so it is
invariant under rigid motions and the net force and moment vanish identically;
a free undamped body conserves energy to the integrator's order. The energy is
the finite-element discretisation of a membrane's, so Y means the same on every
mesh (UV spheres, icospheres, files) and the patch test holds exactly.

Why triangles and not one-ring shape matching: the same continuum limit (the
rotation-free Dirichlet energy of the strain) without a best-fit rotation per
point (a 3x3 polar decomposition each step, exact only when iterated to
convergence), with a closed-form Hessian for implicit steps, and at the cost of
about one ring gather per point.

Viscosity (`damping_time_s`, tau): the viscous stress tau C:dE/dt, a damping of
relative motion only (a rigid motion has dE/dt = 0), never feeding energy in.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .. import checks
from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, force, param

__all__ = [
    "Membrane",
    "membrane_rest",
    "membrane_face_force",
    "add_membrane_serial",
    "membrane_faces_parallel",
    "membrane_gather_parallel",
    "membrane_energy",
    "lame_moduli",
]

# mem_par columns: rest inverse edge matrix (upper triangular: d00, d01, d11), rest Gram
# matrix of the edges (g11, g12, g22, m^2), rest area A0 (m^2), lambda, mu (N/m), tau (s)
P_D00, P_D01, P_D11, P_G11, P_G12, P_G22, P_AREA, P_LAM, P_MU, P_TAU = range(10)
NPAR = 10


def lame_moduli(youngs_n_per_m: float, poisson: float) -> tuple[float, float]:
    """Plane-stress Lame moduli (lambda, mu) in N/m of a sheet of 2D Young's modulus Y, Poisson ratio nu."""
    return youngs_n_per_m * poisson / (1.0 - poisson**2), youngs_n_per_m / (2.0 * (1.0 + poisson))


@force("membrane")
class Membrane(Term):
    """An elastic membrane (the continuum formulation's shape memory): each
    triangle of `region` (a face whose centroid a region of geometry holds,
    or with at least two of its points in a region of points: `Build.face_region`)
    resists the change of its shape with a sheet's 2D Young's modulus
    `youngs_modulus_n_per_m` (N/m: Young's modulus times thickness) and
    Poisson's ratio `poisson_ratio`, and its rate of strain with the
    Kelvin-Voigt time `damping_time_s` (s). A later term wins where regions
    overlap. Resolution independent; the force is minus an energy's gradient."""

    formulations = ("continuum",)
    # mem_vert (nface_m, 3) int32; mem_par (nface_m, NPAR) (the P_* columns);
    # mvf_ptr (nvert+1,) int32, mvf_slot (3 nface_m,) int32: each point's (face, corner)
    # slots 3 k + c in face order (the parallel build's gather); kv_on: any tau > 0
    arrays = {
        "mem_vert": Rows(np.int32, 3),
        "mem_par": Rows(float, NPAR),
        "mvf_ptr": lambda n: np.zeros(n + 1, np.int32),
        "mvf_slot": Rows(np.int32),
        "kv_on": lambda n: False,
    }
    youngs_modulus_n_per_m: float = param("positive", hi=checks.MAX_STIFFNESS_N_PER_M)
    poisson_ratio: float = param("nonneg", 0.3, hi=0.5)
    damping_time_s: float = param("nonneg", 0.0)
    region: object = param("selector", "all")

    def compile(self, b, what):
        idx = super().compile(b, what)
        nu = self.value("poisson_ratio", what)  # plane stress admits up to 1; tissue sheets lie in [0, 0.5]
        lam, mu = lame_moduli(self.value("youngs_modulus_n_per_m", what), nu)
        tau = self.value("damping_time_s", what)
        faces = b.face_region(self.region, what, idx)
        if faces.size == 0:
            raise SceneError(
                f"{what}.region: expected a region holding whole triangles, received "
                f"{idx.size} points of which no triangle has two"
            )
        b.rows["membrane"].append((faces, lam, mu, tau))

    @classmethod
    def finish(cls, b):
        mesh = b.mesh
        par = np.full((mesh.nface, 3), np.nan)
        for faces, lam, mu, tau in b.rows["membrane"]:
            par[faces] = (lam, mu, tau)  # a later term wins
        keep = ~np.isnan(par[:, 0]) & b.moving[mesh.face_vert].any(axis=1)  # a face of nailed points acts on none
        faces = np.nonzero(keep)[0]
        mem_vert = np.ascontiguousarray(mesh.face_vert[faces], np.int32)
        rest = membrane_rest(mesh.vert_pos, mem_vert, what="membrane")
        mem_par = np.concatenate([rest, par[faces]], axis=1)
        order = np.argsort(mem_vert.reshape(-1), kind="stable")  # by point, each point's faces in order
        counts = np.bincount(mem_vert.reshape(-1), minlength=mesh.nvert)
        b.out.update(
            mem_vert=mem_vert,
            mem_par=np.ascontiguousarray(mem_par),
            mvf_ptr=np.concatenate([[0], np.cumsum(counts)]).astype(np.int32),
            mvf_slot=order.astype(np.int32),
            kv_on=bool(np.any(mem_par[:, P_TAU] > 0)),
        )
        b.vert_stiffness += _vert_stiffness(mesh.nvert, mem_vert, mem_par)
        # Kelvin-Voigt: each triangle's viscosity is its stiffness times its damping time
        b.vert_viscosity += _vert_stiffness(mesh.nvert, mem_vert, mem_par, weight=mem_par[:, P_TAU])


def membrane_rest(vert_pos, mem_vert, what="membrane") -> np.ndarray:
    """Rest data of each triangle (columns P_D00..P_AREA): the inverse of its rest edge
    matrix in a frame of its own plane (first edge along x), its edges' Gram matrix and
    area. SceneError naming the faces whose rest area vanishes."""
    p = vert_pos[mem_vert]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    l1 = np.linalg.norm(e1, axis=1)
    area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    bad = np.nonzero(~(area2 > 1e-14 * np.maximum(l1, 1e-300) ** 2))[0]
    if bad.size:
        raise SceneError(
            f"{what}: triangles {bad[:8].tolist()} ({bad.size} in all) have no area at rest; "
            f"expected triangles with three distinct corners"
        )
    g12 = np.einsum("ij,ij->i", e1, e2)
    out = np.zeros((len(mem_vert), 7))
    out[:, P_D00] = 1.0 / l1
    out[:, P_D01] = -g12 / (area2 * l1)
    out[:, P_D11] = l1 / area2
    out[:, P_G11] = l1 * l1
    out[:, P_G12] = g12
    out[:, P_G22] = np.einsum("ij,ij->i", e2, e2)
    out[:, P_AREA] = 0.5 * area2
    return out


def _vert_stiffness(nvert, mem_vert, mem_par, weight=None) -> np.ndarray:
    """Each point's elastic stiffness (N/m) for the stable-step estimate: a row-sum
    (Gershgorin) bound of the linear stiffness, A0 (lambda + 2 mu) |grad phi_i| sum_j |grad phi_j|
    over its triangles (phi the linear shape functions); each triangle's share times
    `weight` (nface,) when given."""
    d00, d01, d11 = mem_par[:, P_D00], mem_par[:, P_D01], mem_par[:, P_D11]
    gb = np.hypot(d00, d01)
    gc = np.abs(d11)
    ga = np.hypot(d00, d01 + d11)
    tot = ga + gb + gc
    c = mem_par[:, P_AREA] * (mem_par[:, P_LAM] + 2.0 * mem_par[:, P_MU]) * tot
    if weight is not None:
        c = c * weight
    k = np.zeros(nvert)
    for corner, g in enumerate((ga, gb, gc)):
        np.add.at(k, mem_vert[:, corner], c * g)
    return k


# ---------------------------------------------------------------- kernels


@kernel(inline="always")
def _edges_and_strain(mem_vert, mem_par, k, vert_pos):
    """Triangle k's current edges e1 = b - a, e2 = c - a (m) and its Green strain
    E = D^T (G - G0) D / 2 (D its rest inverse edge matrix, upper triangular; G the
    edges' Gram matrix): (e1x, e1y, e1z, e2x, e2y, e2z, E00, E01, E11).
    # Model: mem_vert (nf, 3) int32, mem_par (nf, NPAR)   # Data in: k, vert_pos (nvert, 3) m
    # Data out: returns the 9-tuple above
    """
    a, b, c = mem_vert[k, 0], mem_vert[k, 1], mem_vert[k, 2]
    p = mem_par[k]
    e1x, e1y, e1z = vert_pos[b, 0] - vert_pos[a, 0], vert_pos[b, 1] - vert_pos[a, 1], vert_pos[b, 2] - vert_pos[a, 2]
    e2x, e2y, e2z = vert_pos[c, 0] - vert_pos[a, 0], vert_pos[c, 1] - vert_pos[a, 1], vert_pos[c, 2] - vert_pos[a, 2]
    d00, d01, d11 = p[P_D00], p[P_D01], p[P_D11]
    g11 = e1x * e1x + e1y * e1y + e1z * e1z - p[P_G11]
    g12 = e1x * e2x + e1y * e2y + e1z * e2z - p[P_G12]
    g22 = e2x * e2x + e2y * e2y + e2z * e2z - p[P_G22]
    t = g11 * d01 + g12 * d11
    return (
        e1x,
        e1y,
        e1z,
        e2x,
        e2y,
        e2z,
        0.5 * d00 * d00 * g11,
        0.5 * d00 * t,
        0.5 * (d01 * t + d11 * (g12 * d01 + g22 * d11)),
    )


@kernel(inline="always")
def membrane_face_force(mem_vert, mem_par, k, vert_pos, vert_vel, kv_on):
    """Forces (N) on corners b and c of membrane triangle k (corner a takes minus
    their sum): minus the gradient of A0 W(E) (+ the Kelvin-Voigt stress's).
    # Model: mem_vert, mem_par, kv_on (Kelvin-Voigt on)   # Data in: k, vert_pos m, vert_vel m/s
    # Data out: returns (fbx, fby, fbz, fcx, fcy, fcz) N
    """
    a, b, c = mem_vert[k, 0], mem_vert[k, 1], mem_vert[k, 2]
    p = mem_par[k]
    d00, d01, d11 = p[P_D00], p[P_D01], p[P_D11]
    e1x, e1y, e1z, e2x, e2y, e2z, s00, s01, s11 = _edges_and_strain(mem_vert, mem_par, k, vert_pos)
    if kv_on and p[P_TAU] > 0.0:  # add tau dE/dt: the same map applied to dG/dt
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
        tau = p[P_TAU]
        h11 = 2.0 * tau * (e1x * v1x + e1y * v1y + e1z * v1z)
        h12 = tau * (e1x * v2x + e1y * v2y + e1z * v2z + e2x * v1x + e2y * v1y + e2z * v1z)
        h22 = 2.0 * tau * (e2x * v2x + e2y * v2y + e2z * v2z)
        t = h11 * d01 + h12 * d11
        s00 += 0.5 * d00 * d00 * h11
        s01 += 0.5 * d00 * t
        s11 += 0.5 * (d01 * t + d11 * (h12 * d01 + h22 * d11))
    # second Piola-Kirchhoff stress S = lambda tr(E) I + 2 mu E
    lt = p[P_LAM] * (s00 + s11)
    m2 = 2.0 * p[P_MU]
    S00 = lt + m2 * s00
    S01 = m2 * s01
    S11 = lt + m2 * s11
    # dEnergy/dG = A0 D S D^T / 2; the edge forces are -2 dEnergy/dG times the edges
    q = d00 * S01 + d01 * S11
    A = p[P_AREA]
    c00 = A * ((d00 * S00 + d01 * S01) * d00 + q * d01)
    c01 = A * q * d11
    c11 = A * d11 * d11 * S11
    return (
        -(c00 * e1x + c01 * e2x),
        -(c00 * e1y + c01 * e2y),
        -(c00 * e1z + c01 * e2z),
        -(c01 * e1x + c11 * e2x),
        -(c01 * e1y + c11 * e2y),
        -(c01 * e1z + c11 * e2z),
    )


@kernel
def add_membrane_serial(mem_vert, mem_par, kv_on, vert_pos, vert_vel, vert_force):
    """F += the membrane's forces, triangle by triangle (each point's in face order,
    as the parallel build's gather adds them).
    # Model: mem_vert (nf, 3) int32, mem_par (nf, NPAR), kv_on bool
    # Data in: vert_pos (m), vert_vel (m/s)   # Data out: vert_force (N)
    """
    for k in range(mem_vert.shape[0]):
        bx, by, bz, cx, cy, cz = membrane_face_force(mem_vert, mem_par, k, vert_pos, vert_vel, kv_on)
        a, b, c = mem_vert[k, 0], mem_vert[k, 1], mem_vert[k, 2]
        vert_force[a, 0] += -(bx + cx)
        vert_force[a, 1] += -(by + cy)
        vert_force[a, 2] += -(bz + cz)
        vert_force[b, 0] += bx
        vert_force[b, 1] += by
        vert_force[b, 2] += bz
        vert_force[c, 0] += cx
        vert_force[c, 1] += cy
        vert_force[c, 2] += cz


@kernel(parallel=True)
def membrane_faces_parallel(mem_vert, mem_par, kv_on, vert_pos, vert_vel, face_force):
    """First pass of the parallel build: each triangle's forces on b and c into face_force (nf, 6).
    # Model: mem_vert, mem_par, kv_on   # Data in: vert_pos m, vert_vel m/s
    # Data out: face_force (nf, 6) N
    """
    for k in prange(mem_vert.shape[0]):
        bx, by, bz, cx, cy, cz = membrane_face_force(mem_vert, mem_par, k, vert_pos, vert_vel, kv_on)
        face_force[k, 0] = bx
        face_force[k, 1] = by
        face_force[k, 2] = bz
        face_force[k, 3] = cx
        face_force[k, 4] = cy
        face_force[k, 5] = cz


@kernel(parallel=True)
def membrane_gather_parallel(mvf_ptr, mvf_slot, face_force, vert_force):
    """Second pass: each point adds its triangles' forces in face order (bit for bit the serial sum).
    # Model: mvf_ptr (nvert + 1,), mvf_slot (each point's triangle corners)   # Data in: face_force (nf, 6) N
    # Data out: vert_force (nvert, 3) N, added to
    """
    n = vert_force.shape[0]
    for i in prange(n):
        fx, fy, fz = vert_force[i, 0], vert_force[i, 1], vert_force[i, 2]
        for s in range(mvf_ptr[i], mvf_ptr[i + 1]):
            k, corner = mvf_slot[s] // 3, mvf_slot[s] % 3
            if corner == 0:
                fx += -(face_force[k, 0] + face_force[k, 3])
                fy += -(face_force[k, 1] + face_force[k, 4])
                fz += -(face_force[k, 2] + face_force[k, 5])
            else:
                o = 3 * (corner - 1)
                fx += face_force[k, o]
                fy += face_force[k, o + 1]
                fz += face_force[k, o + 2]
        vert_force[i, 0] = fx
        vert_force[i, 1] = fy
        vert_force[i, 2] = fz


@kernel
def membrane_energy(mem_vert, mem_par, vert_pos):
    """The membrane's elastic energy sum A0 W(E) (J).
    # Model: mem_vert, mem_par   # Data in: vert_pos (nvert, 3) m   # Data out: returns the energy J
    """
    total = 0.0
    for k in range(mem_vert.shape[0]):
        p = mem_par[k]
        s00, s01, s11 = _edges_and_strain(mem_vert, mem_par, k, vert_pos)[6:]
        tr = s00 + s11
        total += p[P_AREA] * (p[P_MU] * (s00 * s00 + 2.0 * s01 * s01 + s11 * s11) + 0.5 * p[P_LAM] * tr * tr)
    return total
