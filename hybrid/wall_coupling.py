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
implicit scale. Not with RK4 (MuJoCo's step is then one call).

**The occluded airway** holds the cavity's volume exactly: the membrane's projection
(`hybrid.terms.lungs.project_occluded`) finds the pressure p_m that holds it with the bodies where
their step, under the last hold p_n, put them. Taken so, the bodies would feel the hold a step
late, which light or freely moving ribs do not survive (`hybrid.rigid.held_volumes`). So the hold
is shared (`hold_with_bodies`): MuJoCo takes its step again from its start with the change
dp = S (p_m - p_n) / (S + g . a) as a generalized force g dp, S the membrane's mobility of the
cavity's volume with the abdomen's held (`LungSlot.HOLD_MOBILITY`) and g . a the bodies' own, so
that the bodies and the dome feel one pressure, as in a solve of the two together; the projection
then runs again for what is left (second order in the bodies' motion, and the abdomen's share).

Compiled apart (`wall_step_between`, called at its address by the rigid phase, and
`hold_between`, by the steps while the airway is occluded, compiled only for a run whose airway
may close: `hybrid.loop_compile.hold_call`), for scenes with such a wall only: inlined into the rigid phase, every coupled scene compiled it (6 s more of the
default scene's first run, which has no lungs).

MuJoCo stays behind its door: its C functions are called at the addresses the pack carries
(`hybrid.loop.MjViews`).
"""

from __future__ import annotations

import numpy as np

from .calls import ADDRESS_ONLY, args_from_memory, call_at, call_c
from .kernel import kernel
from .sites import add_point_wrench_kernel, site_vel_kernel
from .step import S_PHI, S_PRESSURE, VOLUME_FAILED
from .step_work import CALL_OCCLUDED
from .switches import T_VOLUME
from .terms.lungs import (
    L_ALVEOLAR,
    L_HOLD,
    L_MOBILITY,
    L_OCCLUDED,
    L_PLEURAL,
    L_RATE,
    L_VOLUME,
    P_K1,
    P_K2,
    lung_recoil,
)
from .terms.volume import PROJ_NO_ROOT

__all__ = [
    "carry_wall",
    "points_onto_sites",
    "step2_with_lungs",
    "wall_step_between",
    "wall_rate_gradient",
    "implicit_wall_correction",
    "hold_with_bodies",
    "hold_between",
]


@kernel
def carry_wall(wall, site_xpos, wall_pos, wall_vel):
    """The carried wall points where their bodies put them: p = p_rest + sum_e w_e (x_site_e -
    x_site_e,rest), v = sum_e w_e v_site_e over the point's bodies e (a blend of the sites'
    displacements; wall.vel holds the sites' velocities).
    # Model: wall (WallArrays)   # Data in: site_xpos (nsite, 3) m, wall.vel (nc, 3) m/s
    # Data out: wall_pos (nwall, 3) m, wall_vel (nwall, 3) m/s (the carried rows)
    """
    for j in range(wall.point.shape[0]):  # a point may have two bodies: from rest, then each one's share
        p = wall.point[j]
        for a in range(3):
            wall_pos[p, a] = wall.rest[j, a]
            wall_vel[p, a] = 0.0
    for j in range(wall.point.shape[0]):
        p = wall.point[j]
        share = wall.weight[j]
        sid = wall.site_id[j]
        for a in range(3):
            wall_pos[p, a] += share * (site_xpos[sid, a] - wall.site_rest[j, a])
            wall_vel[p, a] += share * wall.vel[j, a]


@kernel(inline="always")
def points_onto_sites(links, wall, mj, pos, vel, wall_pos, wall_vel):
    """The linked points onto their sites, with the sites' velocities, and the carried wall where
    its bodies put it (`carry_wall`), from MuJoCo's current state (after `mj_step1`).
    # Model: links (`hybrid.loop.LinkArrays`), wall   # Data in: MuJoCo's site_xpos, cvel, subtree_com
    # Data out: pos, vel (nvert, 3) at the linked points; wall_pos, wall_vel (nwall, 3) at the carried ones
    # Scratch: links.vel, wall.vel
    """
    site_vel_kernel(mj.site_xpos, mj.cvel, mj.subtree_com, links.site_id, links.site_body, links.site_root, links.vel)
    for j in range(links.vert.shape[0]):
        i = links.vert[j]
        sid = links.site_id[j]
        for a in range(3):
            pos[i, a] = mj.site_xpos[sid, a]
            vel[i, a] = links.vel[j, a]
    if wall.point.shape[0]:
        site_vel_kernel(mj.site_xpos, mj.cvel, mj.subtree_com, wall.site_id, wall.site_body, wall.site_root, wall.vel)
        carry_wall(wall, mj.site_xpos, wall_pos, wall_vel)


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
def _mobility(h, wall, mj):
    """a = (M + h B)^-1 g into wall.a, by Cholesky in place (M + h B is symmetric positive definite),
    at MuJoCo's current positions; returns g . a (m^6 per unit of inertia: the bodies' volume
    mobility). # Model: wall.damping (nv,) N m s/rad   # Data in: wall.qfrc (g), MuJoCo's mass matrix
    # Data out: wall.a; returns m^4/kg   # Scratch: wall.dense
    """
    g, a, dense = wall.qfrc, wall.a, wall.dense
    n = g.shape[0]
    call_c(mj.fn_full_m, (mj.model_ptr, mj.data_ptr, dense))
    for i in range(n):
        dense[i, i] += h * wall.damping[i]
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
    ga = 0.0
    for i in range(n):
        ga += g[i] * a[i]
    return ga


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
    g = wall.qfrc
    n = g.shape[0]
    if c <= 0.0 or lung[L_OCCLUDED] != 0.0:
        wall.wrench[:] = 0.0
        return False
    ga = _mobility(h, wall, mj)
    rate_mj = 0.0
    for i in range(n):
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
    # the step's start, to take the step again: with the correction, or the occluded airway's hold (`hold_with_bodies`)
    call_c(mj.fn_get_state, (mj.model_ptr, mj.data_ptr, wall.saved, wall.spec[0]))
    if lung[L_OCCLUDED] != 0.0:
        call_c(mj.fn_step2, (mj.model_ptr, mj.data_ptr))
        return
    wall_rate_gradient(grad, wall, mj)
    rate_before = 0.0
    for i in range(wall.qfrc.shape[0]):
        rate_before += wall.qfrc[i] * mj.qvel[i]
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


@kernel(inline="always")
def hold_with_bodies(m, s, w, rig, step, row, hold_before):
    """The occluded airway's hold shared with the bodies that carry the cavity (module docstring):
    after the membrane's projection took the whole hold, at the pressure p_m (s.lung[HOLD_PRESSURE]),
    with the bodies stepped under the last one, p_n (hold_before, Pa), MuJoCo takes its step again
    from its start with the pressure's change dp = S (p_m - p_n) / (S + g . a) on the cavity's
    rigid-borne points (S the membrane's mobility of the cavity's volume, s.lung[HOLD_MOBILITY];
    g . a the bodies', `_mobility`): both sides then feel one pressure, p_n + dp, as in a solve of
    the two together. The membrane's projection runs again for what is left (the bodies' motion to
    second order, and the abdomen's share). Returns a status code (`hybrid.step.StepStatus`).
    # Model: m, rig   # Data in: s.lung, w.lung_grad, wall.saved (MuJoCo's state at the step's start)
    # Data in/out: MuJoCo's state; s.vert_pos, s.vert_vel, s.lung_wall_pos, s.lung_wall_vel, s.lung, s.scal
    # Data out: wall.force_q, wall.wrench (the change's load on the bodies), rig.hist's row when recording
    """
    mj, wall, hist = rig.mj, rig.wall, rig.hist
    h = m.dt
    mobility = s.lung[L_MOBILITY]
    if not mobility > 0.0:
        return 0  # OK
    call_c(mj.fn_set_state, (mj.model_ptr, mj.data_ptr, wall.saved, wall.spec[0]))
    call_c(mj.fn_step1, (mj.model_ptr, mj.data_ptr))  # the start's kinematics and mass matrix
    wall_rate_gradient(w.lung_grad, wall, mj)
    dp = mobility * (s.lung[L_HOLD] - hold_before) / (mobility + _mobility(h, wall, mj))
    for i in range(wall.force_q.shape[0]):
        wall.force_q[i] = wall.qfrc[i] * dp
        wall.applied[i] = mj.qfrc_applied[i]
        mj.qfrc_applied[i] += wall.force_q[i]
    call_c(mj.fn_step2, (mj.model_ptr, mj.data_ptr))
    for i in range(wall.force_q.shape[0]):
        mj.qfrc_applied[i] = wall.applied[i]
    call_c(mj.fn_step1, (mj.model_ptr, mj.data_ptr))
    for b in range(wall.wrench.shape[0]):
        for k in range(6):
            wall.wrench[b, k] *= dp
    if rig.record:
        for a in range(hist.qpos.shape[1]):
            hist.qpos[row, a] = mj.qpos[a]
        for a in range(hist.qfrc.shape[1]):
            hist.qfrc[row, a] = wall.force_q[a]
    points_onto_sites(rig.links, wall, mj, s.vert_pos, s.vert_vel, s.lung_wall_pos, s.lung_wall_vel)
    abdomen = m.term_on[T_VOLUME] != 0
    phi, phi_hold, held = call_at(w.calls[CALL_OCCLUDED], (0.0, 0.0, False), (m, s, w, h, abdomen))
    if not held:
        s.status[0], s.status[1], s.status[2], s.status[3] = VOLUME_FAILED, step, 0, PROJ_NO_ROOT
        return VOLUME_FAILED
    rest = phi_hold / (h * h)
    s.lung[L_HOLD] += rest
    s.lung[L_PLEURAL] += rest
    s.lung[L_ALVEOLAR] += rest
    if abdomen:
        s.scal[S_PHI] += phi
        s.scal[S_PRESSURE] += phi / (h * h)
    return 0  # OK


@kernel(**ADDRESS_ONLY)
def hold_between(args_at, step, row, hold_before, args_type):
    """`hold_with_bodies`, its arrays read from the rigid phase's frame (`hybrid.loop.rigid_between`'s
    tuple (m, s, w, planes, rig)): the steps call it at its address (`StepWork.calls`) while the
    airway is occluded, so that only a scene whose lungs' wall the bodies carry compiles it.
    # Model: m, rig   # Data in: args_at (int64), step, row, hold_before (Pa), args_type
    # Data out: as `hold_with_bodies`; returns its status code
    """
    m, s = args_from_memory(args_at, 0, args_type), args_from_memory(args_at, 1, args_type)
    w, rig = args_from_memory(args_at, 2, args_type), args_from_memory(args_at, 4, args_type)
    return hold_with_bodies(m, s, w, rig, step, row, hold_before)
