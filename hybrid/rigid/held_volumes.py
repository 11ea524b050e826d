"""The held volumes' pressures on the rigid bodies: the gain that decides whether their coupling
is stable (`hybrid inspect`, a warning at the start of `hybrid run`, and the message of a
divergence).

The exact volume projection holds the abdomen's volume, and the lungs' while the airway is
occluded (`hybrid.terms.lungs.project_occluded`), by moving the membrane's free points only. The
bodies that carry the volumes' other points (the linked points, the lungs' carried wall) take
the projection's pressures at the next step: staggered. Pressures p (Pa, one per held volume) on
the bodies move them by h^2 (M + h B)^-1 Gq^T p, Gq the volumes' gradients through the bodies'
degrees of freedom (m^3 per unit of each), M + h B MuJoCo's mass matrix with the damping its Euler
step takes implicitly; that changes the volumes by h^2 H p, H = Gq (M + h B)^-1 Gq^T, and the next
projection takes it back from the membrane at the pressures -G^-1 H p, G the free points' Gram
matrix of the volumes' gradients over their masses (sum_i grad_i V_j . grad_i V_k / m_i). Each
step multiplies the pressures by -G^-1 H, whatever its size: the coupling is stable while the
spectral radius rho of that map is below 1, as for any enclosed incompressible compartment in a
staggered coupling. A smaller step does not help; heavier bodies, or more damping on their
joints, do.

While the airway is occluded the cavity's hold is shared with the bodies
(`hybrid.wall_coupling.hold_with_bodies`: MuJoCo's step taken again with the hold's change
S (p_m - p_n) / (S + H_cc), S the cavity's mobility with the abdomen's held), which takes the
cavity's part of the map away: what is left is -G^-1 H + s G^-1 H e_c e_c^T (G^-1 H + I),
s = S / (S + H_cc), zero for the cavity alone. Under MuJoCo's RK4 (one call, no step taken again)
the hold stays staggered, and RK4 moves the bodies less in a step than Euler: there the estimate
is an upper bound.

The estimate is linear, at the model's start, and leaves out the joints' springs (h^2 K against
M) and gravity. Against the growth measured on `breathing_lungs` at level 0 with an undamped upper
rib pair, occluded and staggered (before the shared hold): 3.05 against 3.35 (2 g ribs), 1.80
against 1.93 (3.4 g); near 1 what it leaves out decides (at 5.8 g it read 1.06 and the run held),
hence a warning from 0.9 and a divergence's advice from 1. The packaged trunks read about 0.14 at
level 0 (`hybrid inspect`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ..mesh.geometry import volume_gradient
from ..terms.lung_cavity import cavity_volume_rate_gradient
from ..terms.lungs import P_REF, Lungs
from ..terms.volume import Volume
from .modes import implicit_joint_damping

__all__ = ["HeldVolumesGain", "held_volumes_gain", "may_occlude", "WARN_GAIN"]

#: the gain above which a warning is given: the estimate is about a tenth low
WARN_GAIN = 0.9


@dataclass(frozen=True)
class HeldVolumesGain:
    """rho (module docstring) with the abdomen's volume held alone (an open airway, or no lungs:
    `open`) and with the lungs' held too (`occluded`, None without lungs whose cavity the bodies
    carry), at the step `dt_s`."""

    open: float
    occluded: float | None
    dt_s: float

    def worst(self) -> float:
        return max(self.open, self.occluded or 0.0)

    def line(self) -> str:
        """One line for `hybrid inspect`, the run's warning and a divergence's message."""
        both = "" if self.occluded is None else f", {self.occluded:.3g} with the airway occluded"
        return (
            f"held volumes' gain on the rigid bodies {self.open:.3g}{both} at dt_s = {self.dt_s:g} s "
            "(stable below about 1, whatever the step: docs/lungs.md)"
        )


def held_volumes_gain(model) -> HeldVolumesGain | None:
    """rho of `model` (a `hybrid.model.Model`) at its start and step (module docstring), or None
    without a rigid part or an exact volume constraint."""
    a, rig = model.arrays, model.rigid
    if rig is None or not a.term_on[Volume.id]:
        return None
    mjm = rig.model
    data = mujoco.MjData(mjm)
    data.qpos[:] = rig.data.qpos
    mujoco.mj_forward(mjm, data)
    pos = np.array(a.vert_rest, float)
    pos[rig.link_vert] = data.site_xpos[rig.site_id]
    nvert = pos.shape[0]
    grads = [volume_gradient(pos, a.face_vert)]
    carried = [None]
    lungs = bool(a.term_on[Lungs.id]) and a.lung_face.shape[0] > 0
    if lungs:
        wall = np.array(a.lung_wall, float)
        cavity = np.zeros((nvert + wall.shape[0], 3))
        zero_v, zero_w = np.zeros_like(pos), np.zeros_like(wall)
        cavity_volume_rate_gradient(a.lung_face, a.lung_point, a.lung_par[P_REF:], pos, zero_v, wall, zero_w, cavity)
        grads.append(cavity[:nvert])
        carried.append(cavity[nvert:])
    free = np.asarray(a.vert_free, bool)
    inv_mass = 1.0 / np.asarray(a.vert_mass, float)[free]
    gram = np.array([[np.sum(inv_mass[:, None] * gi[free] * gj[free]) for gj in grads] for gi in grads])
    jac = np.zeros((3, mjm.nv))
    through = np.zeros((len(grads), mjm.nv))
    for k, (g, wall_g) in enumerate(zip(grads, carried)):
        for i, sid in zip(rig.link_vert, rig.site_id):
            mujoco.mj_jacSite(mjm, data, jac, None, int(sid))
            through[k] += jac.T @ g[i]
        if wall_g is not None:
            for p, share, sid in zip(rig.wall_point, rig.wall_weight, rig.wall_site_id):
                mujoco.mj_jacSite(mjm, data, jac, None, int(sid))
                through[k] += share * (jac.T @ wall_g[p])
    inertia = np.zeros((mjm.nv, mjm.nv))
    mujoco.mj_fullM(mjm, data, inertia)
    h = float(a.dt)
    inertia += h * np.diag(implicit_joint_damping(mjm))
    response = through @ np.linalg.solve(inertia, through.T)  # H
    open_ = float(response[0, 0] / gram[0, 0]) if gram[0, 0] > 0 else math.inf
    occluded = None
    if lungs:
        growth = -np.linalg.solve(gram, response)  # -G^-1 H: the pressures' map over a staggered step
        if int(mjm.opt.integrator) != int(mujoco.mjtIntegrator.mjINT_RK4):  # the cavity's hold shared
            c = len(grads) - 1
            mobility = gram[c, c] - (gram[0, c] ** 2 / gram[0, 0] if c else 0.0)  # S, the abdomen held
            share = mobility / (mobility + response[c, c])
            growth = growth + share * np.outer(np.linalg.solve(gram, response[:, c]), np.eye(len(grads))[c] - growth[c])
        occluded = float(np.max(np.abs(np.linalg.eigvals(growth))))
    return HeldVolumesGain(open_, occluded, h)


def may_occlude(scene) -> bool:
    """Whether a scene's lungs may close their airway (`Lungs.airway_occluded` not zero at all times)."""
    from ..schedule import Constant

    for f in scene.forces:
        if isinstance(f, Lungs):
            v = f.airway_occluded
            v = v.value if isinstance(v, Constant) else v
            if not (isinstance(v, (int, float)) and v == 0):
                return True
    return False
