"""The changing state of a run, and the step (paper 3.5 and 4; DESIGN.md).

One step, membrane only:
1. forces at time t (only the terms the model has);
2. free integration of the points that are not nailed, prescribed or linked
   (explicit Euler, the paper's eq. 4, or symplectic Euler);
3. local constraints: prescribed trajectories, keep-in-region;
4. the exact volume projection, velocities adjusted; p = phi / h^2;
5. the divergence check: non-finite values, or a point that moved farther
   in one step than the body's size.

The whole loop is compiled; `Simulation.step(n)` runs n steps in one call
unless the scene has Python schedules (evaluated between steps) or rigid
parts (MuJoCo steps between the membrane's force and integration phases).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import prange

from .kernel import CHUNK_VERTS, chunk_count, kernel, kernel_twin

from .constraints import (PROJ_NO_GRADIENT, PROJ_OK, apply_keep_in, apply_prescribed, face_volume,
                          project_volume, soft_volume_force)
from .errors import ConstraintError, SimulationDiverged
from .forces import (add_applied, add_attraction, add_mass_spring, add_muscle, shape_memory_force,
                     shape_memory_frames, shape_memory_frames_parallel)
from .model import (TERMS, T_APPLIED, T_ATTRACTION, T_DAMPING, T_GRAVITY, T_KEEP_IN, T_MASS_SPRING,
                    T_MUSCLE, T_PRESCRIBED, T_SHAPE_MEMORY, T_SOFT_VOLUME, T_VOLUME, MembraneArrays,
                    Model)
from .schedule import KIND_PYTHON, schedule_eval

__all__ = ["Simulation", "MembraneState"]

# scal slots
S_TIME, S_PRESSURE, S_PHI, S_KE, S_MAXDISP = range(5)
# status codes
OK, DIVERGED_NONFINITE, DIVERGED_RUNAWAY, VOLUME_FAILED = 0, 1, 2, 3
# below this fraction of critical damping the shape-memory force excites
# itself on the breathing membrane (measured by `hybrid study stability`)
SELF_EXCITATION_DAMPING = 0.15


class MembraneState(NamedTuple):
    """What changes during a run. vert_pos (nvert, 3) m; vert_vel (nvert, 3) m/s;
    vert_force (nvert, 3) N (forces of the last step, before constraints);
    grad (nvert, 3) m^2 volume gradient at the last projection; sm_sums (nsm, 9),
    dirn, cubic: scratch; vert_acc (chunk_count(nvert), 4): scratch, the sums
    of the per-point passes over each chunk of points (hybrid.kernel);
    sched_val / sched_next (nsched, 3): schedules at t and t + h;
    scal: time s, pressure Pa, phi, kinetic energy J, largest step displacement m;
    status: code, failing step, worst vertex, projection status;
    term_calls (nterm,): how many times each term's kernel ran."""
    vert_pos: np.ndarray
    vert_vel: np.ndarray
    vert_force: np.ndarray
    grad: np.ndarray
    sm_sums: np.ndarray
    vert_acc: np.ndarray
    dirn: np.ndarray
    cubic: np.ndarray
    sched_val: np.ndarray
    sched_next: np.ndarray
    scal: np.ndarray
    status: np.ndarray
    term_calls: np.ndarray


def new_state(arrays: MembraneArrays) -> MembraneState:
    n = arrays.vert_rest.shape[0]
    ns = arrays.sched.kind.shape[0]
    return MembraneState(
        vert_pos=arrays.vert_rest.copy(), vert_vel=np.zeros((n, 3)), vert_force=np.zeros((n, 3)),
        grad=np.zeros((n, 3)), sm_sums=np.zeros((arrays.sm_vert.shape[0], 9)),
        vert_acc=np.zeros((chunk_count(n), 4)), dirn=np.zeros((n, 3)),
        cubic=np.zeros(2),
        sched_val=np.zeros((ns, 3)), sched_next=np.zeros((ns, 3)), scal=np.zeros(8),
        status=np.zeros(4, np.int64), term_calls=np.zeros(len(TERMS), np.int64))


@kernel
def eval_schedules(sched, t, out):
    """All compiled schedules at time t into out (nsched, 3); Python ones are set by the caller."""
    for row in range(sched.kind.shape[0]):
        if sched.kind[row] != KIND_PYTHON:
            schedule_eval(sched, row, t, out[row])


@kernel(inline="always")
def membrane_forces(m, s, t):
    """Step phase 1: the force of every term the model has, at time t.
    # Model: m (MembraneArrays)   # Data in: s.vert_pos, s.vert_vel
    # Data out: s.vert_force, s.sched_val, s.term_calls (and pressure for soft volume)
    """
    eval_schedules(m.sched, t, s.sched_val)
    on = m.term_on
    _pointwise_forces(m, s)
    if on[T_APPLIED]:
        add_applied(m.app_vert, m.app_sched, s.sched_val, s.vert_force)
        s.term_calls[T_APPLIED] += 1
    if on[T_ATTRACTION]:
        add_attraction(m.att_vert, m.att_stiff, m.att_target, m.att_sched, s.sched_val, s.vert_pos,
                       s.vert_force)
        s.term_calls[T_ATTRACTION] += 1
    if on[T_MASS_SPRING]:
        add_mass_spring(m.spring_vert, m.spring_stiff, m.spring_rest, s.vert_pos, s.vert_force)
        s.term_calls[T_MASS_SPRING] += 1
    if on[T_MUSCLE]:
        add_muscle(m.mus_vert, m.mus_nbr, m.mus_sched, s.sched_val, s.vert_pos, s.vert_force)
        s.term_calls[T_MUSCLE] += 1
    if on[T_SOFT_VOLUME]:
        s.scal[S_PRESSURE] = soft_volume_force(m.ring_ptr, m.ring_vert, m.vol_ref, m.vol0, m.soft_stiff, s.vert_pos,
                                               s.grad, s.cubic, s.vert_acc, s.vert_force)
        s.term_calls[T_SOFT_VOLUME] += 1


@kernel(inline="always")
def _first_at_least(idx, lo):
    """The first k with idx[k] >= lo in the sorted array idx (len(idx) if none), unsigned."""
    a, b = np.uint64(0), np.uint64(idx.shape[0])
    while a < b:
        mid = (a + b) >> np.uint64(1)
        if idx[mid] < lo:
            a = mid + np.uint64(1)
        else:
            b = mid
    return a


def _point_forces(vert_free, vert_mass, accel, gravity_on, damp_coef, damping_on, sm_vert, sm_stiff, sm_coef,
                  sm_sums, add_sm, vert_pos, vert_vel, vert_force):
    """Start the force sum with the terms that need only the point itself, in
    one pass that sets vert_force (no separate clearing): gravity F = m g
    (integrated points), viscous damping F = -c v (paper eq. 4) and, when
    add_sm, the shape memory's second pass (`hybrid.forces.shape_memory_force`,
    its frames already gathered into sm_sums). The points run in chunks of
    CHUNK_VERTS, each walking the sorted sm_vert from its first point on.
    # Model: vert_free (nvert,) uint8, vert_mass (nvert,) kg, accel (3,) m/s^2,
    #        damp_coef (nvert,) N s/m; gravity_on, damping_on: bool;
    #        sm_vert (nsm,) int32 sorted, sm_stiff (nsm,) N/m, sm_coef (nsm, 3) m
    # Data in: sm_sums (nsm, 9), vert_pos (nvert, 3) m, vert_vel (nvert, 3) m/s
    # Data out: vert_force (nvert, 3) N
    """
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
                gx, gy, gz = shape_memory_force(sm_stiff, sm_coef, sm_sums, k, vert_pos[i, 0], vert_pos[i, 1],
                                                vert_pos[i, 2])
                fx += gx
                fy += gy
                fz += gz
                k += np.uint64(1)
            vert_force[i, 0] = fx
            vert_force[i, 1] = fy
            vert_force[i, 2] = fz


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


_point_forces_serial, _point_forces_parallel = kernel_twin(_point_forces)
_integrate_serial, _integrate_parallel = kernel_twin(_integrate)


@kernel(inline="always")
def _pointwise_forces(m, s):
    """Step phase 1 for gravity, damping and shape memory: the shape memory's
    ring gathers, then `_point_forces` (serial or parallel build)."""
    on = m.term_on
    sm = on[T_SHAPE_MEMORY] != 0
    grav, damp = on[T_GRAVITY] != 0, on[T_DAMPING] != 0
    if m.parallel:
        if sm:
            shape_memory_frames_parallel(m.sm_vert, m.ring_ptr, m.ring_vert, m.ring_closed, s.vert_pos, s.sm_sums)
        _point_forces_parallel(m.vert_free, m.vert_mass, m.accel, grav, m.damp_coef, damp, m.sm_vert, m.sm_stiff,
                               m.sm_coef, s.sm_sums, sm, s.vert_pos, s.vert_vel, s.vert_force)
    else:
        if sm:
            shape_memory_frames(m.sm_vert, m.ring_ptr, m.ring_vert, m.ring_closed, s.vert_pos, s.sm_sums)
        _point_forces_serial(m.vert_free, m.vert_mass, m.accel, grav, m.damp_coef, damp, m.sm_vert, m.sm_stiff,
                             m.sm_coef, s.sm_sums, sm, s.vert_pos, s.vert_vel, s.vert_force)
    s.term_calls[T_GRAVITY] += on[T_GRAVITY]
    s.term_calls[T_DAMPING] += on[T_DAMPING]
    s.term_calls[T_SHAPE_MEMORY] += on[T_SHAPE_MEMORY]


@kernel(inline="always")
def membrane_advance(m, s, t, step):
    """Step phases 2-5: integrate, project, check. Returns a status code.
    # Model: m   # Data in: s.vert_force   # Data out: s.vert_pos, s.vert_vel, s.scal, s.status
    """
    pos, vel = s.vert_pos, s.vert_vel
    if m.parallel:
        _integrate_parallel(m.vert_free, m.vert_mass, m.integrator == 0, m.dt, s.vert_force, pos, vel, s.vert_acc)
    else:
        _integrate_serial(m.vert_free, m.vert_mass, m.integrator == 0, m.dt, s.vert_force, pos, vel, s.vert_acc)
    return _after_integration(m, s, t, step)


@kernel(inline="always")
def _after_integration(m, s, t, step):
    """Step phases 3-5 after `_integrate`: check, local constraints, volume."""
    h = m.dt
    pos, vel = s.vert_pos, s.vert_vel
    dmax = 0.0
    dsum = 0.0
    worst = 0
    ke = 0.0
    acc = s.vert_acc
    for c in range(acc.shape[0]):  # the chunks in order: both builds agree, the first largest step wins
        dsum += acc[c, 0]
        ke += acc[c, 1]
        if acc[c, 2] > dmax:
            dmax = acc[c, 2]
            worst = int(acc[c, 3])
    s.scal[S_KE] = 0.5 * ke
    s.scal[S_MAXDISP] = math.sqrt(dmax)
    if not (dsum < np.inf and ke < np.inf):
        return _fail(s, DIVERGED_NONFINITE, step, _first_nonfinite(pos, vel, worst))
    # runaway: a step longer than the body's size, or a speed above max_speed
    # (the volume projection can keep an unstable run bounded but fast)
    lim = min(m.runaway_disp, m.max_speed * h)
    if dmax > lim * lim:
        return _fail(s, DIVERGED_RUNAWAY, step, worst)
    on = m.term_on
    if on[T_PRESCRIBED]:
        eval_schedules(m.sched, t + h, s.sched_next)
        apply_prescribed(m.pre_vert, m.pre_rest, m.pre_sched, s.sched_next, h, pos, vel)
        s.term_calls[T_PRESCRIBED] += 1
    if on[T_KEEP_IN]:
        apply_keep_in(m.kin_vert, m.kin_shape, m.shape_kind, m.shape_par, pos, vel)
        s.term_calls[T_KEEP_IN] += 1
    if on[T_VOLUME]:
        phi, st = project_volume(m.ring_ptr, m.ring_vert, m.vol_ref, m.vol0, m.vert_weight, h, pos, vel,
                                 s.grad, s.dirn, s.cubic, s.vert_acc, m.parallel)
        s.term_calls[T_VOLUME] += 1
        if st != PROJ_OK:
            s.status[3] = st
            return _fail(s, VOLUME_FAILED, step, 0)
        if not (abs(phi) < np.inf):
            return _fail(s, DIVERGED_NONFINITE, step, _first_nonfinite(pos, vel, worst))
        s.scal[S_PHI] = phi
        s.scal[S_PRESSURE] = phi / (h * h)
    return OK


@kernel
def _fail(s, code, step, vert):
    s.status[0] = code
    s.status[1] = step
    s.status[2] = vert
    return code


@kernel
def _first_nonfinite(pos, vel, fallback):
    """The first vertex with a non-finite coordinate, else `fallback` (the point
    that moved most: finite values whose kinetic energy overflowed)."""
    for i in range(pos.shape[0]):
        for a in range(3):
            if not (abs(pos[i, a]) < np.inf and abs(vel[i, a]) < np.inf):
                return i
    return fallback


@kernel
def run_membrane(m, s, nstep, step0):
    """nstep whole membrane steps; time advances as t0 + k h. Returns steps done."""
    t0 = s.scal[S_TIME]
    for k in range(nstep):
        t = t0 + k * m.dt
        membrane_forces(m, s, t)
        if membrane_advance(m, s, t, step0 + k) != OK:
            return k
        s.scal[S_TIME] = t0 + (k + 1) * m.dt
    return nstep


# the numbers captured at each frame by the frame kernels (Frames.scal columns)
F_TIME, F_VOLUME, F_PRESSURE, F_KE = range(4)


@kernel
def kinetic_energy_of(m, s):
    """0.5 sum m v^2 over the integrated points (J)."""
    ke = 0.0
    vel = s.vert_vel
    for i in range(vel.shape[0]):
        if m.vert_free[i] > 0:
            ke += m.vert_mass[i] * (vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2])
    return 0.5 * ke


@kernel
def capture_frame(m, s, pos_out, scal_out):
    """The state's positions and numbers (F_* columns) into one frame's rows."""
    pos = s.vert_pos
    for i in range(pos.shape[0]):
        for a in range(3):
            pos_out[i, a] = pos[i, a]
    scal_out[F_TIME] = s.scal[S_TIME]
    scal_out[F_VOLUME] = face_volume(m.face_vert, m.vol_ref, pos)
    scal_out[F_PRESSURE] = s.scal[S_PRESSURE]
    scal_out[F_KE] = kinetic_energy_of(m, s)


@kernel
def run_membrane_frames(m, s, stops, step0, frame_pos, frame_scal):
    """Step to each step index of stops, capturing a frame at each; returns the
    frames captured (fewer than stops when a step fails; its status is in s.status)."""
    done = step0
    for i in range(stops.shape[0]):
        n = stops[i] - done
        k = run_membrane(m, s, n, done)
        done += k
        if k < n:
            return i
        capture_frame(m, s, frame_pos[i], frame_scal[i])
    return stops.shape[0]


class Frames:
    """Frames captured in one compiled call (`Simulation.step_frames`): per frame,
    pos (nvert, 3) m, scal (F_TIME s, F_VOLUME m^3, F_PRESSURE Pa, F_KE J), and the
    rigid bodies' poses body_pos (nbody, 3) m, body_quat (nbody, 4) (w, x, y, z),
    world excluded. `count`: the frames of the last call, also when it raised."""

    def __init__(self, capacity: int, nvert: int, nbody: int = 0):
        self.pos = np.zeros((capacity, nvert, 3))
        self.scal = np.zeros((capacity, 4))
        self.body_pos = np.zeros((capacity, nbody, 3))
        self.body_quat = np.zeros((capacity, nbody, 4))
        self.count = 0

    @property
    def capacity(self) -> int:
        return len(self.pos)


class Simulation:
    """A run of a model: `step(n)`, and the state as read-only views.

    >>> sim = Simulation(compile_scene(scene)); sim.step(1000); sim.pressure
    """

    def __init__(self, model: Model):
        self.model = model
        self.rigid = None
        if model.rigid is not None:
            from .coupling import Coupling  # imports mujoco only for rigid scenes
            self.rigid = Coupling(model)
        self.reset()

    # ------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to rest at t = 0."""
        self.state = new_state(self.model.arrays)
        self.steps_done = 0
        self.failed: Exception | None = None
        if self.rigid is not None:
            self.rigid.reset(self.state)

    @property
    def mj_model(self):
        """MuJoCo's `MjModel` of the rigid part (None for a membrane-only scene)."""
        return None if self.rigid is None else self.rigid.mj_model

    @property
    def mj_data(self):
        """MuJoCo's `MjData` of this run (None for a membrane-only scene)."""
        return None if self.rigid is None else self.rigid.mj_data

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return float(self.state.scal[S_TIME])

    @property
    def vert_pos(self) -> np.ndarray:
        """(nvert, 3) m, a read-only view."""
        v = self.state.vert_pos.view()
        v.flags.writeable = False
        return v

    @property
    def vert_vel(self) -> np.ndarray:
        """(nvert, 3) m/s, a read-only view."""
        v = self.state.vert_vel.view()
        v.flags.writeable = False
        return v

    @property
    def volume(self) -> float:
        """Enclosed volume (m^3) of the current positions, measured face by face
        (independently of the projection)."""
        a = self.model.arrays
        return float(face_volume(a.face_vert, a.vol_ref, self.state.vert_pos))

    @property
    def volume_rel_error(self) -> float:
        """|V - V0| / V0 of the current positions (0 if the model keeps no volume)."""
        v0 = self.model.arrays.vol0
        return abs(self.volume - v0) / v0 if v0 else 0.0

    @property
    def pressure(self) -> float:
        """Gauge pressure inside the body (Pa) from the last projection, p = phi / h^2."""
        return float(self.state.scal[S_PRESSURE])

    @property
    def kinetic_energy(self) -> float:
        """Kinetic energy of the integrated points after the last step, constraints
        included (J). (The step's own figure, used by the divergence check, is
        taken before the projections and so counts velocity they remove.)"""
        return float(kinetic_energy_of(self.model.arrays, self.state))

    @property
    def term_calls(self) -> dict:
        """How many times each term's kernel ran: {term name: count}."""
        return {name: int(c) for name, c in zip(TERMS, self.state.term_calls)}

    # ------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance n steps. Raises SimulationDiverged or ConstraintError;
        the state then holds the failing step and further steps refuse."""
        if self.failed is not None:
            raise self.failed
        if not (isinstance(n, (int, np.integer)) and n >= 0):
            raise ValueError(f"n: expected an integer >= 0, received {n!r}")
        m, s = self.model.arrays, self.state
        if not self.model.python_schedules:
            if self.rigid is None:
                done = run_membrane(m, s, int(n), self.steps_done)
            else:  # the whole coupled loop in one compiled call (hybrid.coupling)
                done = self.rigid.run(s, int(n), self.steps_done)
            self.steps_done += done
            if done < n:
                self._raise()
            return
        for _ in range(int(n)):
            t = float(s.scal[S_TIME])
            self._python_schedules(t)
            if self.rigid is None:
                membrane_forces(m, s, t)
                code = membrane_advance(m, s, t, self.steps_done)
            else:
                code = self.rigid.step(s, t, self.steps_done)
            if code != OK:
                self._raise()
            s.scal[S_TIME] = t + m.dt
            self.steps_done += 1

    @property
    def can_step_frames(self) -> bool:
        """Whether `step_frames` runs in one compiled call (no Python schedules, no
        recorded wrench history)."""
        return not self.model.python_schedules and (self.rigid is None or not self.rigid.record_wrenches)

    def frames_buffer(self, capacity: int) -> Frames:
        """A `Frames` of `capacity` frames for this model."""
        nbody = self.mj_model.nbody - 1 if self.rigid is not None else 0
        return Frames(capacity, self.model.nvert, nbody)

    def step_frames(self, stops, frames: Frames) -> None:
        """Step to each step index of `stops` (increasing, after `steps_done`) and
        capture the state there into `frames` (`frames.count` of them), in one
        compiled call (`can_step_frames`). Raises as `step` does, the frames before
        the failing step captured."""
        stops = np.ascontiguousarray(stops, dtype=np.int64)
        frames.count = 0
        if self.failed is not None:
            raise self.failed
        if not self.can_step_frames:
            raise ValueError("step_frames: expected a model without Python schedules or wrench recording; "
                             "use step()")
        if len(stops) > frames.capacity:
            raise ValueError(f"stops: expected at most {frames.capacity} (the frames' capacity), "
                             f"received {len(stops)}")
        if len(stops) and (stops[0] < self.steps_done or np.any(np.diff(stops) < 0)):
            raise ValueError(f"stops: expected increasing step indices from {self.steps_done}, "
                             f"received {stops[:3].tolist()}...")
        m, s = self.model.arrays, self.state
        if self.rigid is None:
            count = run_membrane_frames(m, s, stops, self.steps_done, frames.pos, frames.scal)
        else:
            count = self.rigid.run_frames(s, stops, self.steps_done, frames)
        frames.count = int(count)
        if count < len(stops):
            self.steps_done = int(s.status[1])
            self._raise()
        self.steps_done = int(stops[-1]) if len(stops) else self.steps_done

    def _python_schedules(self, t: float) -> None:
        h = self.model.arrays.dt
        for row, fn in self.model.python_schedules:
            for out, tt in ((self.state.sched_val, t), (self.state.sched_next, t + h)):
                val = np.atleast_1d(np.asarray(fn(tt), dtype=float)).reshape(-1)
                if val.size not in (1, 3) or not np.all(np.isfinite(val)):
                    err = SimulationDiverged(
                        f"schedule function {getattr(fn, '__name__', fn)!r} returned {val.tolist()} at "
                        f"t = {tt:.6g} s; expected 1 or 3 finite numbers",
                        time_s=tt, step=self.steps_done, vert=0, dt_suggested_s=h)
                    self.failed = err
                    raise err
                out[row, :val.size] = val

    def _raise(self) -> None:
        s, model = self.state, self.model
        code, step, vert = int(s.status[0]), int(s.status[1]), int(s.status[2])
        h = model.arrays.dt
        t = step * h
        if code == VOLUME_FAILED:
            why = ("the volume gradient vanished on the free points" if s.status[3] == PROJ_NO_GRADIENT
                   else "the volume cubic has no real root")
            err: Exception = ConstraintError(
                f"volume projection failed at t = {t:.6g} s (step {step}): {why}; expected a closed surface "
                f"with free points to move")
        else:
            suggest = self.suggest_dt()
            disp = float(s.scal[S_MAXDISP])
            if code == DIVERGED_NONFINITE:
                what = "became non-finite"
            elif disp > model.arrays.runaway_disp:
                what = f"moved {disp:.3g} m in one step, more than the body's size {model.arrays.runaway_disp:.3g} m"
            else:
                what = f"reached {disp / h:.3g} m/s, above max_speed_m_s = {model.arrays.max_speed:.3g}"
            remedy = f"try dt_s <= {suggest:.3g} s"
            damping = self._damping_fraction()
            if h <= model.dt_stable_s and damping < SELF_EXCITATION_DAMPING:
                # the step is not the cause: the non-conservative shape memory excites itself
                remedy = (f"the step is within the stability bound {model.dt_stable_s:.3g} s but damping is "
                          f"{damping:.3g} of critical, below the {SELF_EXCITATION_DAMPING} where shape memory "
                          f"excites itself; add Damping(critical_fraction=0.3)")
            err = SimulationDiverged(
                f"simulation diverged at t = {t:.6g} s (step {step}): vertex {vert} {what}; "
                f"time step {h:.3g} s with {model.scene.integrator}; {remedy}",
                time_s=t, step=step, vert=vert, dt_suggested_s=suggest)
        self.failed = err
        raise err

    def _damping_fraction(self) -> float:
        """The smallest damping, as a fraction of critical, over the integrated
        shape-memory points (inf when the model has no shape memory)."""
        a = self.model.arrays
        if a.sm_vert.size == 0:
            return math.inf
        i = a.sm_vert[a.vert_free[a.sm_vert] > 0]
        k = self.model.vert_stiffness[i]
        return float(np.min(a.damp_coef[i] / (2.0 * np.sqrt(k * a.vert_mass[i])))) if i.size else math.inf

    def suggest_dt(self) -> float:
        """A time step (s) to try after a divergence: half the linear stability
        bound, and at most a quarter of the step that failed."""
        h = self.model.arrays.dt
        bound = self.model.dt_stable_s
        if bound == 0.0:  # explicit Euler without damping: no step is stable
            return h / 4.0
        return min(0.5 * bound, h / 4.0)
