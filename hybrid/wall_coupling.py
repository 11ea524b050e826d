"""The lungs' pleural load on the rigid bodies that carry the thoracic cavity, implicit in their
velocities (`hybrid.loop.rigid_phase`).

The cavity's rigid-borne points are the lungs' carried wall (the upper ribs, `Lungs.wall_bodies`)
and the linked membrane points on it (the dome's border, on the lower ribs). Their load reaches the
bodies as the pleural pressure the step started with times the cavity's volume gradient. Taken so,
a step behind the bodies' motion, it is explicit in the airway's resistance and the lungs'
elastance: with g = dV/dq (m^3 per unit of each degree of freedom: the points' volume gradients
through their sites' Jacobians, `mj_applyFT`) the bodies feel a damping c g g^T, c = K1 + 2 K2 |Q|
+ h dP_L/dV (Pa s/m^3), which an explicit step keeps stable only while h c g . (M + h B)^-1 g < 2:
on `breathing_lungs` at level 0 that number is 1.98 at 20 ms with an obstructed airway of 20 cmH2O
s/L (the lower ribs' g, -7.4e-4 m^3/rad, through the dome's border), 3.96 at 40, 0.15 in quiet
breathing (1.5). It is the enclosed compartment's known instability in partitioned coupling; the
membrane's side is implicit already (`hybrid.implicit_lungs`). After MuJoCo's Euler step, the exact
rank-one correction that makes the damping implicit (Sherman-Morrison):

    (M + h B + h c g g^T) (v' - v) = h f    =>    v' = v_mj - h c a delta,
    a = (M + h B)^-1 g,   delta = g . (v_mj - v) / (1 + h c g . a),

v_mj MuJoCo's new velocities, B its joint damping (which its Euler step takes implicitly; under
implicit and implicitfast the joints' damping stands for their velocity derivatives). The
correction is the generalized force -c g delta: MuJoCo takes the step again from the state it
saved, with that force as `qfrc_applied` (`mj_getState`, `mj_setState`), so that its constraints
and integrator handle it as any load, and a replay of the recorded wrenches with it
(`Coupling.qfrc_history`) reproduces the run. Without constraints the step is then v' above to
rounding; with them a is the unconstrained one, an approximation that keeps the damping's
implicit scale. Not with RK4 (MuJoCo's step is then one call), nor while the airway is occluded
(its projection holds the volume: `hybrid.terms.lungs.project_occluded`).

Compiled apart (`wall_step_between`, called at its address by the rigid phase), for scenes with
such a wall only: inlined into the rigid phase, every coupled scene compiled it (6 s more of the
default scene's first run, which has no lungs).

MuJoCo stays behind its door: its C functions are called at the addresses the pack carries
(`hybrid.loop.MjViews`).
"""

from __future__ import annotations

import numpy as np

from .calls import ADDRESS_ONLY, args_from_memory, call_c
from .kernel import kernel
from .sites import add_point_wrench_kernel
from .terms.lungs import L_OCCLUDED, L_RATE, L_VOLUME, P_K1, P_K2, lung_recoil

__all__ = ["step2_with_lungs", "wall_step_between", "wall_rate_gradient", "implicit_wall_correction"]


@kernel
def wall_rate_gradient(grad, wall, mj):
    """g into wall.qfrc: the generalized force of a unit pleural pressure on the cavity's
    rigid-borne points (its volume gradient at them, the step's force pass's: the points have not
    moved since; at the carried wall's points by their shares at their sites and at the linked
    points at theirs, through MuJoCo's `mj_applyFT`), so that g . qvel is the volume's rate the
    bodies make. At MuJoCo's current positions (the step's start).
    # Model: wall (g_*), mj (fn_apply_ft)   # Data in: grad (nvert + nwall, 3) m^2 (w.lung_grad:
    #        `hybrid.terms.lung_cavity.cavity_volume_rate_gradient`), MuJoCo's state
    # Data out: wall.qfrc (nv,) m^3   # Scratch: wall.unit, .wrench
    """
    unit, wrench = wall.unit, wall.wrench
    for k in range(wall.g_points.shape[0]):
        for d in range(3):
            unit[k, d] = grad[wall.g_points[k], d]
    for b in range(wrench.shape[0]):
        for a in range(6):
            wrench[b, a] = 0.0
    add_point_wrench_kernel(mj.site_xpos, mj.xipos, wall.g_site, wall.g_body, wall.g_weight, unit, wrench)
    wall.qfrc[:] = 0.0
    for b in range(wrench.shape[0]):
        loaded = False
        for a in range(6):
            loaded = loaded or wrench[b, a] != 0.0
        if loaded:
            call_c(
                mj.fn_apply_ft,
                (mj.model_ptr, mj.data_ptr, wrench[b, 0:3], wrench[b, 3:6], mj.xipos[b], np.int32(b), wall.qfrc),
            )


@kernel
def implicit_wall_correction(par, h, lung, wall, mj, rate_before):
    """After MuJoCo's Euler step: the generalized force that makes the cavity's damping c g g^T on
    the bodies implicit, -c g delta (module docstring), into wall.force_q; the step is then
    taken again with it as `qfrc_applied` (`hybrid.loop.rigid_phase`). rate_before: g . qvel
    before the step. Returns whether there is a correction (lungs, the airway open, c > 0).
    # Model: par (m.lung_par), h (m.dt, s); wall.damping (nv,) N m s/rad   # Data in: lung (s.lung: rate,
    #        volume), wall.qfrc (g), MuJoCo's qvel
    # Data out: wall.force_q (nv,) [N, N m] (left as it is, zero, when there is no correction);
    #           wall.wrench (nbody, 6) [N, N m]: the correction's wrench on each body (force, and
    #           torque about its centre of mass), which force_q is (zero without a correction)
    # Data in:  wall.wrench: the unit pressure's (`wall_rate_gradient`)   # Scratch: wall.dense, .a
    """
    c = par[P_K1] + 2.0 * par[P_K2] * abs(lung[L_RATE]) + h * lung_recoil(par, lung[L_VOLUME])[1]
    g, a, dense = wall.qfrc, wall.a, wall.dense
    n = g.shape[0]
    if c <= 0.0 or lung[L_OCCLUDED] != 0.0:
        wall.wrench[:] = 0.0
        return False
    call_c(mj.fn_full_m, (mj.model_ptr, mj.data_ptr, dense))
    for i in range(n):
        dense[i, i] += h * wall.damping[i]
    # a = (M + h B)^-1 g by Cholesky in place (M + h B is symmetric positive definite)
    for j in range(n):
        d = dense[j, j]
        for k in range(j):
            d -= dense[j, k] * dense[j, k]
        d = np.sqrt(d)
        dense[j, j] = d
        for i in range(j + 1, n):
            e = dense[i, j]
            for k in range(j):
                e -= dense[i, k] * dense[j, k]
            dense[i, j] = e / d
    for i in range(n):
        e = g[i]
        for k in range(i):
            e -= dense[i, k] * a[k]
        a[i] = e / dense[i, i]
    for i in range(n - 1, -1, -1):
        e = a[i]
        for k in range(i + 1, n):
            e -= dense[k, i] * a[k]
        a[i] = e / dense[i, i]
    ga, rate_mj = 0.0, 0.0
    for i in range(n):
        ga += g[i] * a[i]
        rate_mj += g[i] * mj.qvel[i]
    delta = (rate_mj - rate_before) / (1.0 + h * c * ga)
    for i in range(n):
        wall.force_q[i] = -c * g[i] * delta
    wrench = wall.wrench  # g is the unit pressure's wrenches through the bodies' Jacobians
    for b in range(wrench.shape[0]):
        for k in range(6):
            wrench[b, k] *= -c * delta
    return True


@kernel
def step2_with_lungs(par, h, grad, lung, wall, mj):
    """MuJoCo's `mj_step2` with the lungs' load implicit in the bodies' velocities (module
    docstring): g and the rate g . qvel before the step, MuJoCo's step from its saved state, the
    correction, and the step again from that state with it as `qfrc_applied` (restored after).
    # Model: as `wall_rate_gradient`, `implicit_wall_correction`   # Data in: MuJoCo's state, grad
    #        (w.lung_grad), lung   # Data out: MuJoCo's state after the step; wall.force_q   # Scratch: wall's
    """
    wall_rate_gradient(grad, wall, mj)
    rate_before = 0.0
    for i in range(wall.qfrc.shape[0]):
        rate_before += wall.qfrc[i] * mj.qvel[i]
    call_c(mj.fn_get_state, (mj.model_ptr, mj.data_ptr, wall.saved, wall.spec[0]))
    call_c(mj.fn_step2, (mj.model_ptr, mj.data_ptr))
    if implicit_wall_correction(par, h, lung, wall, mj, rate_before):  # the step again, the correction applied
        call_c(mj.fn_set_state, (mj.model_ptr, mj.data_ptr, wall.saved, wall.spec[0]))
        for i in range(wall.force_q.shape[0]):
            wall.applied[i] = mj.qfrc_applied[i]
            mj.qfrc_applied[i] += wall.force_q[i]
        call_c(mj.fn_step2, (mj.model_ptr, mj.data_ptr))
        for i in range(wall.force_q.shape[0]):
            mj.qfrc_applied[i] = wall.applied[i]


@kernel(**ADDRESS_ONLY)
def wall_step_between(args_at, args_type):
    """`step2_with_lungs`, its arrays read from the rigid phase's frame (`hybrid.loop.rigid_between`'s
    tuple (m, s, w, planes, rig)): the rigid phase calls it at its address (`StepWork.calls`), so
    that only a scene whose lungs' wall the bodies carry compiles it.
    # Model: m, rig   # Data in: args_at (int64), args_type   # Data out: as `step2_with_lungs`
    """
    m, s = args_from_memory(args_at, 0, args_type), args_from_memory(args_at, 1, args_type)
    w, rig = args_from_memory(args_at, 2, args_type), args_from_memory(args_at, 4, args_type)
    # the arrays each kernel reads, not the model's and state's tuples: a kernel given those takes
    # every field of them as an argument, which numba compiles (7.3 s of a first lungs run for these)
    step2_with_lungs(m.lung_par, m.dt, w.lung_grad, s.lung, rig.wall, rig.mj)
