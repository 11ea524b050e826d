"""The membrane's compiled step and its state (paper 3.5 and 4).

One step, membrane only:
1. forces at time t (only the terms the model has);
2. free integration of the points that are not nailed, prescribed or linked
   (explicit Euler, the paper's eq. 4, symplectic Euler, or implicit Euler: hybrid.implicit);
3. local constraints: prescribed trajectories, keep-in-region;
4. the exact volume projection, velocities adjusted; p = phi / h^2;
5. the divergence check: non-finite values, or a point that moved farther
   in one step than the body's size.

Phase 1 is `membrane_forces`, phases 2-5 `membrane_advance` (what they read and write:
`hybrid.step_work`); the one compiled loop
(`hybrid.loop.run_steps`) calls them, with MuJoCo's step between them for scenes
with rigid parts. The step reads its inputs (muscle tensions, pressures, applied
forces, prescribed motions) from `ControlArrays`, filled from the scene's schedules
or set by the user's program (`hybrid.Control`).
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import prange

from .calls import call_at
from .implicit import (
    implicit_pressure,
)
from .integrators import EXPLICIT_EULER_ID, IMPLICIT_EULER_ID
from .kernel import CHUNK_VERTS, kernel, kernel_twin
from .schedule import KIND_PYTHON, schedule_eval
from .step_work import CALL_IMPLICIT_START, CALL_IMPLICIT_STEP, CALL_OCCLUDED, CALL_SOFT_VOLUME
from .switches import (  # each term's flag in MembraneArrays.term_on and its call counter
    T_APPLIED,
    T_ATTRACTION,
    T_DAMPING,
    T_GRAVITY,
    T_KEEP_IN,
    T_LUNGS,
    T_MASS_SPRING,
    T_MEMBRANE,
    T_MUSCLE,
    T_MUSCLE_FIBRES,
    T_PASSIVE_FIBRES,
    T_PRESCRIBED,
    T_PRESSURE,
    T_SHAPE_MEMORY,
    T_SOFT_VOLUME,
    T_VOLUME,
    step_par,
)
from .terms.fibres import add_muscle_fibres
from .terms.local import apply_keep_in, apply_prescribed
from .terms.lungs import (
    L_ALVEOLAR,
    L_HOLD,
    L_OCCLUDED,
    L_PLEURAL,
)
from .terms.membrane import add_membrane_serial, membrane_faces_parallel, membrane_gather_parallel
from .terms.muscle import add_muscle
from .terms.passive_fibres import add_passive_fibres
from .terms.pointwise import point_forces_parallel, point_forces_serial
from .terms.shape_memory import shape_memory_frames, shape_memory_frames_parallel
from .terms.springs import add_applied, add_attraction, add_mass_spring
from .terms.volume import (
    PROJ_NO_ROOT,
    PROJ_OK,
    add_pressure,
    project_volume,
    volume_direction_parallel,
    volume_direction_serial,
)

__all__ = [
    "Scal",
    "StepStatus",
    "FrameColumn",
    "membrane_forces",
    "membrane_advance",
    "step_par",
]


class Scal(IntEnum):
    """The slots of `MembraneState.scal`."""

    TIME = 0  # s
    PRESSURE = 1  # Pa, from the last volume projection
    PHI = 2  # the last projection's multiplier
    KE = 3  # J, of the last step before its constraints
    MAXDISP = 4  # m, the largest displacement of the last step
    ORIGIN = 5  # s, the time of step index 0: step k runs from ORIGIN + k h, however the run is cut in calls


class StepStatus(IntEnum):
    """What a step returns, and `MembraneState.status[0]` after a failing one."""

    OK = 0
    DIVERGED_NONFINITE = 1
    DIVERGED_RUNAWAY = 2
    VOLUME_FAILED = 3


S_TIME, S_PRESSURE, S_PHI, S_KE, S_MAXDISP, S_ORIGIN = Scal
OK, DIVERGED_NONFINITE, DIVERGED_RUNAWAY, VOLUME_FAILED = StepStatus


@kernel
def eval_schedules(sched, user, t, out):
    """The compiled schedules at time t into out (nsched, 3), except the rows the user's
    program sets (user[row] = 1); Python ones are set by the caller.
    # Model: sched (ScheduleTable)   # Data in: user (nsched,) uint8   # Data out: out (nsched, 3)
    """
    for row in range(sched.kind.shape[0]):
        if sched.kind[row] != KIND_PYTHON and not user[row]:
            schedule_eval(sched, row, t, out[row])


@kernel(inline="always")
def membrane_forces(m, s, w, imp, c, t, par=True):
    """Step phase 1: the force of every term the model has (its flag in m.term_on), at
    time t. `par`: None when the model never runs the multi-core build (`step_par`),
    which is then not even compiled; else m.parallel chooses at run time.
    # Model: m (MembraneArrays)   # Data in: s.vert_pos, s.vert_vel
    # Data out: w.vert_force, c.value, s.term_calls (and pressure for soft volume)
    """
    eval_schedules(m.sched, c.user, t, c.value)
    on = m.term_on
    # implicit Euler: the terms it treats implicitly once, kept for its solve (`implicit_start_forces`)
    implicit = m.integrator == IMPLICIT_EULER_ID
    _pointwise_forces(m, s, w, par, implicit)
    if on[T_MEMBRANE] and not implicit:
        if par is not None and m.parallel:
            membrane_faces_parallel(m.mem_vert, m.mem_par, m.kv_on, s.vert_pos, s.vert_vel, w.face_force)
            membrane_gather_parallel(m.mvf_ptr, m.mvf_slot, w.face_force, w.vert_force)
        else:
            add_membrane_serial(m.mem_vert, m.mem_par, m.kv_on, s.vert_pos, s.vert_vel, w.vert_force)
        s.term_calls[T_MEMBRANE] += 1
    if on[T_APPLIED]:
        add_applied(m.app_vert, m.app_sched, c.value, w.vert_force)
        s.term_calls[T_APPLIED] += 1
    if on[T_ATTRACTION]:
        add_attraction(m.att_vert, m.att_stiff, m.att_target, m.att_sched, c.value, s.vert_pos, w.vert_force)
        s.term_calls[T_ATTRACTION] += 1
    if on[T_MASS_SPRING]:
        add_mass_spring(m.spring_vert, m.spring_stiff, m.spring_rest, s.vert_pos, w.vert_force)
        s.term_calls[T_MASS_SPRING] += 1
    if on[T_MUSCLE]:
        add_muscle(m.mus_vert, m.mus_nbr, m.mus_sched, c.value, s.vert_pos, w.vert_force)
        s.term_calls[T_MUSCLE] += 1
    if on[T_SOFT_VOLUME]:
        s.scal[S_PRESSURE] = call_at(w.calls[CALL_SOFT_VOLUME], 0.0, (m, s, w))  # `soft_volume_step`
        s.term_calls[T_SOFT_VOLUME] += 1
    if on[T_PRESSURE]:
        add_pressure(m.ring_ptr, m.ring_vert, m.pres_sched, c.value, s.vert_pos, w.vert_force)
        s.term_calls[T_PRESSURE] += 1
    if on[T_MUSCLE_FIBRES] and not implicit:
        add_muscle_fibres(m.fib_vert, m.fib_par, m.fib_sched, c.value, s.vert_pos, w.vert_force)
        s.term_calls[T_MUSCLE_FIBRES] += 1
    if on[T_PASSIVE_FIBRES] and not implicit:
        add_passive_fibres(m.pf_vert, m.pf_par, s.vert_pos, w.vert_force)
        s.term_calls[T_PASSIVE_FIBRES] += 1
    for k in range(w.force_calls.shape[0]):  # the model's terms with their own kernel (`Term.step_force`)
        call_at(w.force_calls[k, 1], None, (m, s, w, c))
        s.term_calls[w.force_calls[k, 0]] += 1
    if implicit:  # `implicit_start_forces`, compiled apart (`StepWork.calls`)
        call_at(w.calls[CALL_IMPLICIT_START], None, (m, c.value, s.vert_pos, s.vert_vel, s.lung, imp, w.vert_force))
        for k in (T_MEMBRANE, T_MUSCLE_FIBRES, T_PASSIVE_FIBRES):
            s.term_calls[k] += on[k]


def _integrate(vert_free, vert_mass, explicit, h, vert_force, vert_pos, vert_vel, chunk_acc):
    """Free integration of the points that are not nailed, prescribed or linked,
    with the sums the divergence check reads, per chunk of points: (sum of
    squared step lengths, twice the kinetic energy, largest squared step, its
    vertex) into chunk_acc (hybrid.kernel). (Fused with the force pass it ran slower:
    each point's dependent square roots and divisions then stall the loop.)
    # Model: vert_free (nvert,) uint8, vert_mass (nvert,) kg; explicit: the paper's
    #        explicit Euler (eq. 4, position with the old velocity), else symplectic
    # Data in: vert_force (N)   # Data in/out: vert_pos, vert_vel   # Scratch: chunk_acc (chunk_count(nvert), 4)
    """
    n = vert_pos.shape[0]
    for c in prange((n + CHUNK_VERTS - 1) // CHUNK_VERTS):
        dsum = ke = dmax = 0.0
        worst = np.uint64(0)
        # unsigned indices: numba then skips its negative-index wraparound
        for i in range(np.uint64(c * CHUNK_VERTS), np.uint64(min((c + 1) * CHUNK_VERTS, n))):
            if not vert_free[i]:
                continue
            inv_m = 1.0 / vert_mass[i]
            d2 = 0.0
            for a in range(3):
                if explicit:
                    dx = h * vert_vel[i, a]
                    vert_vel[i, a] += h * vert_force[i, a] * inv_m
                else:  # velocity first, position with the new velocity
                    vert_vel[i, a] += h * vert_force[i, a] * inv_m
                    dx = h * vert_vel[i, a]
                vert_pos[i, a] += dx
                d2 += dx * dx
            dsum += d2
            ke += vert_mass[i] * (vert_vel[i, 0] ** 2 + vert_vel[i, 1] ** 2 + vert_vel[i, 2] ** 2)
            if d2 > dmax:
                dmax = d2
                worst = i
        chunk_acc[c, 0] = dsum
        chunk_acc[c, 1] = ke
        chunk_acc[c, 2] = dmax
        chunk_acc[c, 3] = worst


_integrate_serial, _integrate_parallel = kernel_twin(_integrate)


@kernel(inline="always")
def _pointwise_forces(m, s, w, par, implicit=False):
    """Step phase 1 for gravity, damping and shape memory: the shape memory's
    ring gathers, then the fused pass
    `hybrid.terms.pointwise.point_forces` (serial or parallel build).
    # Model: m (term_on, accel, damp_coef, sm_*, ring_*, vert_free, vert_mass)   # Data in: s.vert_pos, s.vert_vel
    # Data out: w.vert_force (added to), s.term_calls   # Scratch: w.sm_sums
    """
    on = m.term_on
    sm = on[T_SHAPE_MEMORY] != 0
    grav, damp = on[T_GRAVITY] != 0, on[T_DAMPING] != 0 and not implicit  # implicit Euler's drag: its own
    if par is not None and m.parallel:
        if sm:
            shape_memory_frames_parallel(m.sm_vert, m.ring_ptr, m.ring_vert, m.ring_closed, s.vert_pos, w.sm_sums)
        point_forces_parallel(
            (grav, damp, sm),
            m.vert_free,
            m.vert_mass,
            m.accel,
            m.damp_coef,
            m.sm_vert,
            m.sm_stiff,
            m.sm_coef,
            w.sm_sums,
            s.vert_pos,
            s.vert_vel,
            w.vert_force,
        )
    else:
        if sm:
            shape_memory_frames(m.sm_vert, m.ring_ptr, m.ring_vert, m.ring_closed, s.vert_pos, w.sm_sums)
        point_forces_serial(
            (grav, damp, sm),
            m.vert_free,
            m.vert_mass,
            m.accel,
            m.damp_coef,
            m.sm_vert,
            m.sm_stiff,
            m.sm_coef,
            w.sm_sums,
            s.vert_pos,
            s.vert_vel,
            w.vert_force,
        )
    s.term_calls[T_GRAVITY] += on[T_GRAVITY]
    s.term_calls[T_DAMPING] += on[T_DAMPING]
    s.term_calls[T_SHAPE_MEMORY] += on[T_SHAPE_MEMORY]


@kernel(inline="always")
def integrate(m, s, w, imp, c, step, par):
    """Step phase 2 with the model's integrator (`hybrid.integrators`): implicit Euler's
    Newton solve (`implicit_step`, compiled apart: `StepWork.calls`), else
    explicit or symplectic Euler by the model's id. Returns a status code.
    # Model: m   # Data in: w.vert_force, c.value   # Data in/out: s.vert_pos, s.vert_vel, imp (`ImplicitWork`)
    # Data out: w.vert_acc (the divergence check's sums per chunk), s.status on failure
    """
    if m.integrator == IMPLICIT_EULER_ID:
        return call_at(w.calls[CALL_IMPLICIT_STEP], 0, (m, s, c.value, step, imp, w.vert_acc))
    explicit = m.integrator == EXPLICIT_EULER_ID
    if par is not None and m.parallel:
        _integrate_parallel(m.vert_free, m.vert_mass, explicit, m.dt, w.vert_force, s.vert_pos, s.vert_vel, w.vert_acc)
    else:
        _integrate_serial(m.vert_free, m.vert_mass, explicit, m.dt, w.vert_force, s.vert_pos, s.vert_vel, w.vert_acc)
    return 0  # OK


@kernel(inline="always")
def membrane_advance(m, s, w, imp, c, t, step, par=True):
    """Step phases 2-5: integrate, project, check. Returns a status code. `par`: as
    `membrane_forces`.
    # Model: m   # Data in: w.vert_force   # Data out: s.vert_pos, s.vert_vel, s.scal, s.status
    """
    pos = s.vert_pos
    # the projection's direction where the step starts
    if m.volume_shake and m.term_on[T_VOLUME]:
        if par is not None and m.parallel:
            volume_direction_parallel(m.ring_ptr, m.ring_vert, m.vert_weight, pos, w.dirn)
        else:
            volume_direction_serial(m.ring_ptr, m.ring_vert, m.vert_weight, pos, w.dirn)
    code = integrate(m, s, w, imp, c, step, par)
    if code != OK:
        return code
    code = _after_integration(m, s, w, c, t, step, par)
    if code == OK and m.term_on[T_VOLUME]:  # implicit Euler's solve carried part of the pressure
        s.scal[S_PRESSURE] = implicit_pressure(m, imp.info, s.scal[S_PRESSURE])
    return code


@kernel(inline="always")
def _after_integration(m, s, w, c, t, step, par):
    """Step phases 3-5 after `_integrate`: check, local constraints, volume. Returns a status code.
    # Model: m   # Data in: w.vert_acc (the integration's sums per chunk), c.user
    # Data in/out: s.vert_pos, s.vert_vel   # Data out: s.scal, s.status on failure, s.grad, c.value_next
    # Scratch: w.dirn, w.cubic
    """
    h = m.dt
    pos, vel = s.vert_pos, s.vert_vel
    dmax = 0.0
    dsum = 0.0
    worst = 0
    ke = 0.0
    acc = w.vert_acc
    for ch in range(acc.shape[0]):  # the chunks in order: both builds agree, the first largest step wins
        dsum += acc[ch, 0]
        ke += acc[ch, 1]
        if acc[ch, 2] > dmax:
            dmax = acc[ch, 2]
            worst = int(acc[ch, 3])
    s.scal[S_KE] = 0.5 * ke
    s.scal[S_MAXDISP] = math.sqrt(dmax)
    if not (dsum < np.inf and ke < np.inf):
        return _fail(s, DIVERGED_NONFINITE, step, _first_nonfinite(pos, vel, np.int64(worst)))
    # runaway: a speed above max_speed (the volume projection can keep an unstable
    # run bounded but fast). Not the body's size: a small body falling freely
    # travels its size in a step while nothing is unstable, and an unstable step
    # grows the speed geometrically, past any max_speed within a few steps.
    lim = m.max_speed * h
    if dmax > lim * lim:
        return _fail(s, DIVERGED_RUNAWAY, step, worst)
    on = m.term_on
    if on[T_PRESCRIBED]:
        eval_schedules(m.sched, c.user, t + h, c.value_next)
        apply_prescribed(m.pre_vert, m.pre_rest, m.pre_sched, c.value_next, h, pos, vel)
        s.term_calls[T_PRESCRIBED] += 1
    if on[T_KEEP_IN]:
        apply_keep_in(m.kin_vert, m.kin_shape, m.shape_kind, m.shape_par, pos, vel)
        s.term_calls[T_KEEP_IN] += 1
    if on[T_LUNGS] and s.lung[L_OCCLUDED] > 0.0:  # the occluded airway: both volumes
        abdomen = on[T_VOLUME] != 0
        phi, phi_hold, held = call_at(w.calls[CALL_OCCLUDED], (0.0, 0.0, False), (m, s, w, h, abdomen))
        s.term_calls[T_VOLUME] += abdomen
        if not held:
            s.status[3] = PROJ_NO_ROOT
            return _fail(s, VOLUME_FAILED, step, 0)
        # the step's readouts: the law at its start, this projection's hold (implicit Euler's solve
        # carried the last one, `hybrid.implicit.implicit_step`: the projection corrects it)
        hold = phi_hold / (h * h) + (s.lung[L_HOLD] if m.integrator == IMPLICIT_EULER_ID else 0.0)
        s.lung[L_PLEURAL] += hold - s.lung[L_HOLD]
        s.lung[L_ALVEOLAR] += hold - s.lung[L_HOLD]
        s.lung[L_HOLD] = hold
        if abdomen:
            s.scal[S_PHI] = phi
            s.scal[S_PRESSURE] = phi / (h * h)
    elif on[T_VOLUME]:
        if par is None:  # a None argument: the multi-core build is not compiled
            phi, st = project_volume(
                m.ring_ptr,
                m.ring_vert,
                m.vol0,
                m.vert_weight,
                h,
                pos,
                vel,
                (s.grad, w.dirn, w.cubic, w.vert_acc),
                None,
                m.volume_shake,
            )
        else:
            phi, st = project_volume(
                m.ring_ptr,
                m.ring_vert,
                m.vol0,
                m.vert_weight,
                h,
                pos,
                vel,
                (s.grad, w.dirn, w.cubic, w.vert_acc),
                m.parallel,
                m.volume_shake,
            )
        s.term_calls[T_VOLUME] += 1
        if st != PROJ_OK:
            s.status[3] = st
            return _fail(s, VOLUME_FAILED, step, 0)
        if not (abs(phi) < np.inf):
            return _fail(s, DIVERGED_NONFINITE, step, _first_nonfinite(pos, vel, np.int64(worst)))
        s.scal[S_PHI] = phi
        s.scal[S_PRESSURE] = phi / (h * h)
    return OK


@kernel(inline="always")
def _fail(s, code, step, vert):
    """Record a failing step; returns its code.
    # Model: none   # Data in: code, step, vert   # Data out: s.status[0:3]
    """
    s.status[0] = code
    s.status[1] = step
    s.status[2] = vert
    return code


@kernel
def _first_nonfinite(pos, vel, fallback):
    """The first vertex with a non-finite coordinate, else `fallback` (the point
    that moved most: finite values whose kinetic energy overflowed).
    # Model: none   # Data in: pos (nvert, 3) m, vel (nvert, 3) m/s   # Data out: returns a vertex
    """
    for i in range(pos.shape[0]):
        for a in range(3):
            if not (abs(pos[i, a]) < np.inf and abs(vel[i, a]) < np.inf):
                return i
    return fallback


class FrameColumn(IntEnum):
    """The numbers captured at each frame by the frame kernels (`Frames.scal` columns)."""

    TIME = 0  # s
    VOLUME = 1  # m^3
    PRESSURE = 2  # Pa
    KE = 3  # J
    LUNG_VOLUME = 4  # m^3, the thoracic cavity's (scenes with lungs, else 0)
    FLOW = 5  # m^3/s, into the lungs: the last step's volume change over h
    PLEURAL = 6  # Pa, at the last step's start
    ALVEOLAR = 7  # Pa, at the last step's start
    AIRWAY = 8  # Pa, the airway-opening pressure at the last step's start


F_TIME, F_VOLUME, F_PRESSURE, F_KE, F_LUNG_VOLUME, F_FLOW, F_PLEURAL, F_ALVEOLAR, F_AIRWAY = FrameColumn
