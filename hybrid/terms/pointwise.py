"""Gravity and viscous damping, and the step's fused per-point force pass.

Both act on each point alone, so the step computes them in one pass over the
points together with the shape memory's second pass (`point_forces`), which
starts the force sum.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .. import checks
from ..errors import SceneError
from ..kernel import CHUNK_VERTS, kernel, kernel_twin
from ..mesh.geometry import vertex_area
from .base import Term, force, param
from .shape_memory import shape_memory_force

__all__ = ["Gravity", "Damping", "point_forces_serial", "point_forces_parallel"]


@force("gravity")
class Gravity(Term):
    """Uniform gravity on the integrated points, F = m g."""

    arrays = {"accel": lambda n: np.zeros(3)}  # (3,) m/s^2
    accel_m_s2: tuple = param("vec3", (0.0, 0.0, -9.81))

    def compile(self, b, what):
        super().compile(b, what)
        b.out["accel"] = b.out.get("accel", np.zeros(3)) + np.asarray(self.value("accel_m_s2", what))


@force("damping")
class Damping(Term):
    """Viscous damping F = -c v on the points of `region`.

    Give `drag_n_s_per_m3` (formulation "continuum": a drag b per area,
    c_i = b A_i with A_i the point's share of the surface area, a third of its
    faces' areas, so the same b damps the same on every mesh), or, in
    formulation "paper", `coef_n_s_per_m` (c directly) or `critical_fraction`
    (c = fraction x 2 sqrt(k_i m_i) per point, k_i the point's elastic
    stiffness from shape memory and springs; 0.3 is comfortable; on the
    breathing membrane the non-conservative shape-memory force excites itself
    below 0.15, as `hybrid study stability` measures).
    """

    arrays = {"damp_coef": lambda n: np.zeros(n)}  # (nvert,) N s/m
    finish_last = True
    coef_n_s_per_m: float = param("nonneg", None, formulation="paper")
    critical_fraction: float = param("nonneg", None, formulation="paper", unit="of critical")
    drag_n_s_per_m3: float = param("nonneg", None, formulation="continuum")
    region: object = param("selector", "all")

    def compile(self, b, what):
        super().compile(b, what)
        b.rows["damping"].append((self, b.region(self.region, f"{what}.region"), what))

    @classmethod
    def finish(cls, b):
        damp_coef = np.zeros(b.mesh.nvert)
        for term, idx, what in b.rows["damping"]:
            given = {k: getattr(term, k) for k in ("drag_n_s_per_m3", "coef_n_s_per_m", "critical_fraction")}
            if sum(v is not None for v in given.values()) != 1:
                raise SceneError(
                    f"{what}: expected exactly one of drag_n_s_per_m3, coef_n_s_per_m or "
                    f"critical_fraction, received " + " ".join(f"{k}={v!r}" for k, v in given.items())
                )
            if term.drag_n_s_per_m3 is not None:
                drag = checks.number(
                    f"{what}.drag_n_s_per_m3",
                    term.drag_n_s_per_m3,
                    lo=0,
                    lo_open=False,
                    hi=checks.MAX_DRAG_N_S_PER_M3,
                    hi_open=False,
                )
                damp_coef[idx] = drag * vertex_area(b.mesh.vert_pos, b.mesh.face_vert)[idx]
            elif term.coef_n_s_per_m is not None:
                damp_coef[idx] = term.value("coef_n_s_per_m", what)
            else:
                frac = term.value("critical_fraction", what)
                soft = idx[b.vert_stiffness[idx] <= 0]
                if soft.size:
                    raise SceneError(
                        f"{what}.critical_fraction: vertices {soft[:8].tolist()} have no elastic "
                        f"stiffness to define critical damping; give coef_n_s_per_m instead"
                    )
                damp_coef[idx] = frac * 2.0 * np.sqrt(b.vert_stiffness[idx] * b.vert_mass[idx])
        b.out["damp_coef"] = damp_coef


# ---------------------------------------------------------------- the fused pass


@kernel(inline="always")
def _first_at_least(idx, lo):
    """The first k with idx[k] >= lo in the sorted array idx (len(idx) if none), unsigned.
    # Model: idx (sorted)   # Data in: lo   # Data out: returns k
    """
    a, b = np.uint64(0), np.uint64(idx.shape[0])
    while a < b:
        mid = (a + b) >> np.uint64(1)
        if idx[mid] < lo:
            a = mid + np.uint64(1)
        else:
            b = mid
    return a


def _point_forces(
    terms_on,
    vert_free,
    vert_mass,
    accel,
    damp_coef,
    sm_vert,
    sm_stiff,
    sm_coef,
    sm_sums,
    vert_pos,
    vert_vel,
    vert_force,
):
    """Start the force sum with the terms that need only the point itself, in
    one pass that sets vert_force (no separate clearing): gravity F = m g
    (integrated points), viscous damping F = -c v (paper eq. 4) and, when
    add_sm, the shape memory's second pass (`hybrid.terms.shape_memory.shape_memory_force`,
    its frames already gathered into sm_sums). The points run in chunks of
    CHUNK_VERTS, each walking the sorted sm_vert from its first point on.
    # Model: terms_on (gravity_on, damping_on, add_sm): bools; vert_free (nvert,) uint8,
    #        vert_mass (nvert,) kg, accel (3,) m/s^2, damp_coef (nvert,) N s/m;
    #        sm_vert (nsm,) int32 sorted, sm_stiff (nsm,) N/m, sm_coef (nsm, 3) m
    # Data in: sm_sums (nsm, 9), vert_pos (nvert, 3) m, vert_vel (nvert, 3) m/s
    # Data out: vert_force (nvert, 3) N
    """
    gravity_on, damping_on, add_sm = terms_on
    n = vert_pos.shape[0]
    nsm = np.uint64(sm_vert.shape[0])
    for c in prange((n + CHUNK_VERTS - 1) // CHUNK_VERTS):
        # unsigned indices: numba then skips its negative-index wraparound
        lo, hi = np.uint64(c * CHUNK_VERTS), np.uint64(min((c + 1) * CHUNK_VERTS, n))
        k = _first_at_least(sm_vert, lo) if add_sm else nsm  # the next shape-memory point
        for i in range(lo, hi):
            fx = fy = fz = 0.0
            if gravity_on and vert_free[i]:
                m = vert_mass[i]
                fx = m * accel[0]
                fy = m * accel[1]
                fz = m * accel[2]
            if damping_on:
                cd = damp_coef[i]
                fx -= cd * vert_vel[i, 0]
                fy -= cd * vert_vel[i, 1]
                fz -= cd * vert_vel[i, 2]
            if k < nsm and np.uint64(sm_vert[k]) == i:
                gx, gy, gz = shape_memory_force(
                    sm_stiff, sm_coef, sm_sums, k, vert_pos[i, 0], vert_pos[i, 1], vert_pos[i, 2]
                )
                fx += gx
                fy += gy
                fz += gz
                k += np.uint64(1)
            vert_force[i, 0] = fx
            vert_force[i, 1] = fy
            vert_force[i, 2] = fz


point_forces_serial, point_forces_parallel = kernel_twin(_point_forces)
