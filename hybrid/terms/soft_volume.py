"""The soft (compressible) volume of paper 6.2, or of a bulk modulus: the enclosed volume
(`hybrid.terms.volume`, whose cubic it solves) held by a force instead of a projection.
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..errors import SceneError
from ..kernel import kernel
from .base import Term, force, param
from .volume import PROJ_OK, centroid, ring_cross_sum, solve_cubic_near_zero, volume_cubic

__all__ = ["SoftVolume", "soft_volume_force", "soft_volume_step"]


@force("soft_volume")
class SoftVolume(Term):
    """A compressible fill. Give `bulk_modulus_pa` (formulation "continuum"): a
    fill of bulk modulus K (Pa) at the pressure p = -K (V - V0) / V0, force
    F_i = p grad_i V, energy K (V - V0)^2 / (2 V0); or `stiffness_n_per_m`
    (formulation "paper", paper 6.2): each point pulled with that stiffness
    toward the position the exact volume projection would give it, whose bulk
    modulus grows with the number of points."""

    # soft_stiff N/m (paper), soft_bulk Pa (continuum): the one given, the other 0
    arrays = {"soft_stiff": lambda n: 0.0, "soft_bulk": lambda n: 0.0}
    stiffness_n_per_m: float = param("positive", None, hi=checks.MAX_STIFFNESS_N_PER_M, formulation="paper")
    bulk_modulus_pa: float = param("positive", None, hi=checks.MAX_MODULUS_PA, formulation="continuum")

    def compile(self, b, what):
        super().compile(b, what)
        if (self.stiffness_n_per_m is None) == (self.bulk_modulus_pa is None):
            raise SceneError(
                f"{what}: expected exactly one of bulk_modulus_pa or stiffness_n_per_m, received "
                f"bulk_modulus_pa={self.bulk_modulus_pa!r} stiffness_n_per_m={self.stiffness_n_per_m!r}"
            )
        if self.stiffness_n_per_m is not None:
            b.out["soft_stiff"] = self.value("stiffness_n_per_m", what)
        else:
            b.out["soft_bulk"] = self.value("bulk_modulus_pa", what)
        b.mesh.require_closed(f"{what} (compressible volume) needs a closed surface")
        b.mesh.require_one_piece(f"{what} (compressible volume) needs a surface bounding one region")
        b.mesh.require_no_self_crossing(f"{what} (compressible volume) needs a surface bounding one region")
        b.out["vol0"] = float(b.mesh.volume())
        if self.bulk_modulus_pa is not None:
            # the energy's Hessian on the diagonal, K/V0 |grad_i V|^2: each point's
            # stiffness for the stability estimate
            g = b.mesh.volume_gradient()
            b.vert_stiffness += b.out["soft_bulk"] / b.out["vol0"] * np.sum(g * g, axis=1)


@kernel
def soft_volume_force(ring_ptr, ring_vert, vol0, stiff, bulk, vert_pos, grad, cubic, chunk_acc, vert_force):
    """Compressibility: with a bulk modulus K > 0, the pressure p = -K (V - V0) / V0;
    otherwise (paper 6.2) the attraction toward the volume-satisfying positions:
    phi solves V(X + phi grad V(X)) = V0 and each point is pulled toward its
    target X_i + phi grad_i with stiffness k, a uniform pressure p = k phi (Pa).
    Either way F_i = p grad_i V. Returns p.
    # Model: ring_ptr, ring_vert (closed fans), vol0 m^3, stiff N/m, bulk Pa (0: paper 6.2)
    # Data in: vert_pos
    # Data out: vert_force; scratch grad, cubic, chunk_acc (chunk_count(nvert), >= 3)
    """
    ref = centroid(vert_pos, chunk_acc, None)  # serial: the multi-core build is not compiled for it
    vol = 0.0
    c1 = 0.0
    for i in range(vert_pos.shape[0]):
        gx, gy, gz = ring_cross_sum(ring_ptr, ring_vert, vert_pos, i)
        gx /= 6.0
        gy /= 6.0
        gz /= 6.0
        grad[i, 0] = gx
        grad[i, 1] = gy
        grad[i, 2] = gz
        vol += (vert_pos[i, 0] - ref[0]) * gx + (vert_pos[i, 1] - ref[1]) * gy + (vert_pos[i, 2] - ref[2]) * gz
        c1 += gx * gx + gy * gy + gz * gz
    if bulk > 0.0:
        p = -bulk * (vol / 3.0 - vol0) / vol0
    else:
        volume_cubic(ring_ptr, ring_vert, ref, vert_pos, grad, chunk_acc, cubic, None)
        phi, status = solve_cubic_near_zero(vol / 3.0 - vol0, c1, cubic[0], cubic[1])
        if status != PROJ_OK:
            return np.nan
        p = stiff * phi
    for i in range(grad.shape[0]):
        vert_force[i, 0] += p * grad[i, 0]
        vert_force[i, 1] += p * grad[i, 1]
        vert_force[i, 2] += p * grad[i, 2]
    return p


@kernel
def soft_volume_step(m, s, w):
    """The soft volume's force (`soft_volume_force`) on the step's points;
    returns its pressure (Pa). Compiled apart, for the models that have the term (`hybrid.step_work.StepWork.calls`).
    # Model: m.ring_ptr, m.ring_vert, m.vol0, m.soft_stiff, m.soft_bulk   # Data in: s.vert_pos
    # Data out: w.vert_force (added to), s.grad   # Scratch: w.cubic, w.vert_acc
    """
    ring_ptr, ring_vert, vol0, stiff, bulk = m.ring_ptr, m.ring_vert, m.vol0, m.soft_stiff, m.soft_bulk
    return soft_volume_force(
        ring_ptr, ring_vert, vol0, stiff, bulk, s.vert_pos, s.grad, w.cubic, w.vert_acc, w.vert_force
    )
