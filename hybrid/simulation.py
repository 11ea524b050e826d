"""The changing state of a run: `Simulation`, which drives the compiled step
(`hybrid.step`, or `hybrid.coupling` for scenes with rigid parts).

The whole loop is compiled; `Simulation.step(n)` runs n steps in one call
unless the scene has Python schedules (evaluated between steps).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time

import numpy as np

from . import readouts
from .builds import BuildChoice
from .errors import ArgumentError, ConstraintError, SceneError, SimulationDiverged
from .implicit import IMPLICIT_NOT_CONVERGED, Info
from .model import TERMS, Model
from .step import (
    DIVERGED_NONFINITE,
    OK,
    S_MAXDISP,
    S_PHI,
    S_PRESSURE,
    S_TIME,
    VOLUME_FAILED,
    Frames,
    advance_switches,
    force_switches,
    kinetic_energy_of,
    membrane_advance,
    membrane_forces,
    new_state,
    run_membrane,
    run_membrane_frames,
    step_switches,
)
from .terms.volume import PROJ_NO_GRADIENT, face_volume

__all__ = ["Simulation"]

# below this fraction of critical damping the shape-memory force excites
# itself on the breathing membrane (measured by `hybrid study stability`)
SELF_EXCITATION_DAMPING = 0.15


def _read_only(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


class Simulation:
    """A run of a model: `step(n)`, and the state as read-only views.

    >>> sim = Simulation(compile_scene(scene)); sim.step(1000); sim.pressure

    `build`: "auto" times the serial and the parallel build of the step against
    each other as the run goes and runs the faster (`hybrid.builds.BuildChoice`,
    for models that may run in parallel); "serial" or "parallel" fixes it. The
    two agree to the bit. `sim.builds.summary()` says what ran.
    """

    def __init__(self, model: Model, build: str = "auto"):
        _check_model(model)
        self.model = model
        self.builds = BuildChoice(model.arrays.parallel, build)
        # the model's arrays with each build's flag: what the compiled calls take
        self._arrays = {p: model.arrays._replace(parallel=p) for p in (False, True)}
        self._piece_frame: Frames | None = None  # `_run_piece`'s scratch frame
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
        return _read_only(self.state.vert_pos)

    @property
    def vert_vel(self) -> np.ndarray:
        """(nvert, 3) m/s, a read-only view."""
        return _read_only(self.state.vert_vel)

    @property
    def vert_force(self) -> np.ndarray:
        """(nvert, 3) N, the forces of the last step before its constraints, a read-only view."""
        return _read_only(self.state.vert_force)

    @property
    def volume(self) -> float:
        """Enclosed volume (m^3) of the current positions, measured face by face
        (independently of the projection)."""
        a = self.model.arrays
        return float(face_volume(a.face_vert, self.state.vert_pos))

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
    def elastic_energy(self) -> float | None:
        """The membrane's elastic energy (J) at the current positions; None in the
        paper formulation, whose shape memory and muscle derive from no energy."""
        return readouts.elastic_energy(self.model.arrays, self.state.vert_pos)

    def internal_net(self) -> dict:
        """Net force (N) and moment about the centroid (N m) of the membrane's internal
        forces (elasticity, muscle, springs) at the current state, with the sums of |F|
        and |r x F|: zero to round-off in the continuum formulation, not in the
        paper's. {"net_force_n": (3,), "net_moment_n_m": (3,), "sum_abs_force_n",
        "sum_abs_moment_n_m"}."""
        f = readouts.internal_forces(self.model.arrays, self.state.vert_pos, self.state.sched_val)
        return readouts.net_internal(self.state.vert_pos, f)

    def swept_volume_m3(self, region: str) -> float:
        """Volume (m^3) swept by the faces of the named region (`Model.region_faces`)
        since rest, positive outward: for the diaphragm, minus
        its share of the tidal volume. Over every region of a closed surface the
        swept volumes add up to V - V0."""
        m = self.model
        if region not in m.regions:
            raise SceneError(
                f"region {region!r}: not a region of scene {m.scene.name!r}; expected one of {sorted(m.regions)}"
            )
        faces = m.region_faces(region)
        return readouts.swept_volume(m.mesh.face_vert[faces], m.arrays.vert_rest, self.state.vert_pos)

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
        if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 0):
            raise ArgumentError(f"n: expected an integer >= 0, received {_described(n)}")
        if n >= MAX_STEP_COUNT:  # the compiled loop counts in int64
            raise ArgumentError(f"n: expected fewer than 2^63 steps, received {n}")
        s = self.state
        if not self.model.python_schedules:
            left = int(n)
            while True:  # one compiled call, or pieces timed for the choice of build
                par, k = self.builds.chunk(left)
                t0 = time.perf_counter()
                done = self._run(self._arrays[par], k)
                self.builds.record(par, done, time.perf_counter() - t0)
                self.steps_done += done
                left -= done
                if done < k:
                    self._raise()
                if left <= 0:
                    return
        par = self.builds.parallel
        m = self._arrays[par]
        for _ in range(int(n)):
            t = float(s.scal[S_TIME])
            self._python_schedules(t)
            if self.rigid is None:
                membrane_forces(m, s, t, *force_switches(m))
                code = membrane_advance(m, s, t, self.steps_done, *advance_switches(m))
            else:
                code = self.rigid.step(s, t, self.steps_done, m)
            if code != OK:
                self._raise()
            s.scal[S_TIME] = t + m.dt
            self.steps_done += 1
            self.builds.steps[par] += 1

    def _run(self, arrays, nstep: int) -> int:
        """nstep steps in one compiled call with these arrays (the build their flag
        says); the steps done."""
        if self.rigid is None:
            return run_membrane(arrays, self.state, nstep, self.steps_done, *step_switches(arrays))
        return self.rigid.run(self.state, nstep, self.steps_done, arrays)  # the whole coupled loop (hybrid.coupling)

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
            raise ValueError("step_frames: expected a model without Python schedules or wrench recording; use step()")
        if len(stops) > frames.capacity:
            raise ValueError(f"stops: expected at most {frames.capacity} (the frames' capacity), received {len(stops)}")
        if len(stops) and (stops[0] < self.steps_done or np.any(np.diff(stops) < 0)):
            raise ValueError(
                f"stops: expected increasing step indices from {self.steps_done}, received {stops[:3].tolist()}..."
            )
        i, s = 0, self.state
        while i < len(stops):  # one compiled call, or pieces timed for the choice of build
            par, k = self.builds.chunk(int(stops[-1]) - self.steps_done)
            t0 = time.perf_counter()
            if k < int(stops[i]) - self.steps_done:  # a piece short of the next frame
                done = self._run_piece(self._arrays[par], k)
                self.builds.record(par, done, time.perf_counter() - t0)
                self.steps_done += done
                if done < k:
                    self._raise()
                continue
            j = max(i + 1, int(np.searchsorted(stops, self.steps_done + k, side="right")))
            count = self._run_frames(self._arrays[par], stops[i:j], frames, i)
            frames.count = i + count
            if count < j - i:
                self.steps_done = int(s.status[1])
                self._raise()
            self.builds.record(par, int(stops[j - 1]) - self.steps_done, time.perf_counter() - t0)
            self.steps_done = int(stops[j - 1])
            i = j

    def _run_piece(self, arrays, nstep: int) -> int:
        """nstep steps by the frames' compiled call (its frame into a scratch buffer), so
        that stepping by frames compiles that one loop; the steps done."""
        if self._piece_frame is None:
            self._piece_frame = self.frames_buffer(1)
        stop = np.array([self.steps_done + nstep], np.int64)
        if self._run_frames(arrays, stop, self._piece_frame, 0):
            return nstep
        return int(self.state.status[1]) - self.steps_done  # the failing step's index

    def _run_frames(self, arrays, stops: np.ndarray, frames: Frames, first: int) -> int:
        """Step to each of stops in one compiled call, capturing into frames from
        index `first` on; the frames captured."""
        if first:
            frames = copy.copy(frames)
            frames.pos, frames.scal = frames.pos[first:], frames.scal[first:]
            frames.body_pos, frames.body_quat = frames.body_pos[first:], frames.body_quat[first:]
        if self.rigid is None:
            return run_membrane_frames(
                arrays, self.state, stops, self.steps_done, frames.pos, frames.scal, *step_switches(arrays)
            )
        return self.rigid.run_frames(self.state, stops, self.steps_done, frames, arrays)

    def _python_schedules(self, t: float) -> None:
        h = self.model.arrays.dt
        for row, fn in self.model.python_schedules:
            for out, tt in ((self.state.sched_val, t), (self.state.sched_next, t + h)):
                val = np.atleast_1d(np.asarray(fn(tt), dtype=float)).reshape(-1)
                if val.size not in (1, 3) or not np.all(np.isfinite(val)):
                    err = SimulationDiverged(
                        f"schedule function {getattr(fn, '__name__', fn)!r} returned {val.tolist()} at "
                        f"t = {tt:.6g} s; expected 1 or 3 finite numbers",
                        time_s=tt,
                        step=self.steps_done,
                        vert=0,
                        dt_suggested_s=h,
                    )
                    self.failed = err
                    raise err
                out[row, : val.size] = val

    def _raise(self) -> None:
        s, model = self.state, self.model
        code, step, vert = int(s.status[0]), int(s.status[1]), int(s.status[2])
        h = model.arrays.dt
        t = step * h
        if code == IMPLICIT_NOT_CONVERGED:
            info = s.implicit.info
            a = model.arrays
            # the iterations ran out: more of them is what helps (a smaller step needs them too)
            capped = int(info[Info.NEWTON]) >= a.implicit_max_iter
            remedy = (
                f"raise implicit_max_iter (now {a.implicit_max_iter}, all used; the step can stay)"
                if capped
                else f"raise implicit_max_iter (now {a.implicit_max_iter}) or take dt_s <= {0.5 * h:.3g} s"
            )
            err: Exception = SimulationDiverged(
                f"implicit Euler did not converge at t = {t:.6g} s (step {step}): residual {info[Info.RESIDUAL]:.3g} "
                f"of the forces after {int(info[Info.NEWTON])} Newton iterations, above implicit_tol = "
                f"{a.implicit_tol:g} (largest at vertex {vert}); {remedy}",
                time_s=t,
                step=step,
                vert=vert,
                dt_suggested_s=h if capped else 0.5 * h,
            )
        elif code == VOLUME_FAILED:
            why = (
                "the volume gradient vanished on the free points"
                if s.status[3] == PROJ_NO_GRADIENT
                else "the volume cubic has no real root"
            )
            if step == 0:  # the first projection: the surface or its free points are at fault
                err = ConstraintError(
                    f"volume projection failed at t = {t:.6g} s (step {step}): {why}; expected a closed surface "
                    f"with free points to move"
                )
            else:  # projections that held until now: the surface has folded, the run diverged
                moved = float(np.sqrt(((s.vert_pos - model.arrays.vert_rest) ** 2).sum(axis=1)).max())
                remedy, suggest = self._advice()
                err = SimulationDiverged(
                    f"simulation diverged at t = {t:.6g} s (step {step}): the volume projection failed ({why}): "
                    f"the surface folded, a point {moved:.3g} m from rest; time step {h:.3g} s with "
                    f"{model.scene.integrator}; {remedy}",
                    time_s=t,
                    step=step,
                    vert=vert,
                    dt_suggested_s=suggest,
                )
        else:
            disp = float(s.scal[S_MAXDISP])
            if code == DIVERGED_NONFINITE:
                what = "became non-finite"
            else:
                what = f"reached {disp / h:.3g} m/s, above max_speed_m_s = {model.arrays.max_speed:.3g}"
            remedy, suggest = self._advice()
            err = SimulationDiverged(
                f"simulation diverged at t = {t:.6g} s (step {step}): vertex {vert} {what}; "
                f"time step {h:.3g} s with {model.scene.integrator}; {remedy}",
                time_s=t,
                step=step,
                vert=vert,
                dt_suggested_s=suggest,
            )
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
        bound, and at most a quarter of the step that failed; nan where no step
        is stable (explicit Euler on an undamped spring)."""
        return self._advice()[1]

    def _advice(self) -> tuple[str, float]:
        """What to try after a divergence, and the step it suggests (nan: none helps);
        a mesh far larger than a body is named first (a file in millimetres)."""
        remedy, suggest = self._step_advice()
        span = float(np.ptp(self.model.arrays.vert_rest, axis=0).max())
        if span > BODY_SPAN_MAX_M:
            remedy = (
                f"the mesh spans {span:.3g} m, no body's size: a mesh file in millimetres needs "
                f"mesh.unit_scale = 0.001 (a generator, radius_m in metres); if the size is meant, {remedy}"
            )
        return remedy, suggest

    def _step_advice(self) -> tuple[str, float]:
        """What to try after a divergence, and the step it suggests (nan: none helps)."""
        model, a = self.model, self.model.arrays
        h = a.dt
        k, c, m = model.vert_stiffness, a.damp_coef, a.vert_mass
        held = (a.vert_free > 0) & (k > 0)
        if a.integrator == 0 and np.any(held & (c == 0)):
            # one step of x'' = -k/m x multiplies the amplitude by sqrt(1 + h^2 k/m) > 1
            undamped = np.flatnonzero(held & (c == 0))
            i = int(undamped[0])
            # symplectic Euler keeps a conservative spring bounded, not shape memory
            # (it excites itself below SELF_EXCITATION_DAMPING): there only damping helps
            other = "" if np.isin(undamped, a.sm_vert).any() else " or use integrator = 'symplectic_euler'"
            return (
                f"explicit Euler grows every undamped oscillation whatever the step (vertex {i} has stiffness "
                f"{k[i]:.3g} N/m and no damping), so no smaller step helps; add Damping(critical_fraction=0.3)"
                f"{other}"
            ), math.nan
        bound = model.dt_stable_s
        if bound == 0.0:
            # below what the stability estimate resolves (1e-9 s): the tightest point's
            # bound in closed form: c/k for damped explicit Euler (|1 - h c/m + h^2 k/m| < 1),
            # 2 sqrt(m/k) for symplectic Euler, 2 m/c for the damping alone
            with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
                spring = np.where(k > 0, c / k if a.integrator == 0 else 2.0 * np.sqrt(m / k), np.inf)
                drag = np.where(c > 0, 2.0 * m / c, np.inf)
            per = np.where(a.vert_free > 0, np.minimum(spring, drag), np.inf)
            i = int(np.argmin(per))
            est = float(per[i])
            stiff = f"vertex {i}: stiffness {k[i]:.3g} N/m, damping {c[i]:.3g} N s/m, mass {m[i]:.3g} kg"
            if not est > 0:
                return f"no representable step is stable ({stiff}); lower the stiffness or damping", math.nan
            return (
                f"a stable step would be about {est:.3g} s ({stiff}), {1.0 / est:.3g} steps per simulated "
                f"second: lower the stiffness or damping (or raise the mass) rather than the step"
            ), 0.5 * est
        suggest = min(0.5 * bound, h / 4.0)
        damping = self._damping_fraction()
        if h <= bound and damping < SELF_EXCITATION_DAMPING:
            # the step is not the cause: the non-conservative shape memory excites itself
            return (
                f"the step is within the stability bound {bound:.3g} s but damping is {damping:.3g} of "
                f"critical, below the {SELF_EXCITATION_DAMPING} where shape memory excites itself; add "
                f"Damping(critical_fraction=0.3)"
            ), suggest
        return f"try dt_s <= {suggest:.3g} s", suggest

    # ------------------------------------------------------------ a state set by hand
    def set_state(self, *, vert_pos=None, vert_vel=None, time_s: float | None = None, qpos=None, qvel=None) -> None:
        """Start from another state; what is not given stays as it is.

        vert_pos (nvert, 3) m, vert_vel (nvert, 3) m/s: every point (the linked
        points then take their sites' positions and velocities, as at reset). New
        positions clear the last projection (`pressure` 0 and its volume gradient):
        it belonged to the old ones, and with a rigid part the first step then
        transmits no pressure to the ribs (implicit Euler also forgets its warm start);
        time_s: simulated time, >= 0 s (the step count follows, time_s / dt rounded);
        qpos (nq,), qvel (nv,): MuJoCo's generalized positions and velocities of the
        rigid part (`mj_model.nq`, `mj_model.nv`), only for a scene with one.

        Every value is checked (shape, finite) before any is set: ArgumentError (a
        HybridError and a ValueError) names
        the argument, what was expected and what was received. A run that failed
        steps again from the new state.
        """
        nvert = self.model.nvert
        pos = _checked_array("vert_pos", vert_pos, (nvert, 3), "positions (m)")
        vel = _checked_array("vert_vel", vert_vel, (nvert, 3), "velocities (m/s)")
        if vel is not None:  # a state the runaway guard stops at once: no step would help
            speed = np.hypot(np.hypot(vel[:, 0], vel[:, 1]), vel[:, 2])  # no overflow at 1e200
            fast = int(np.argmax(speed))
            if speed[fast] > self.model.arrays.max_speed:
                raise ArgumentError(
                    f"vert_vel: expected speeds at most max_speed_m_s = {self.model.arrays.max_speed:g} m/s "
                    f"(the runaway guard), received {speed[fast]:.3g} m/s at vertex {fast}"
                )
        if time_s is not None:
            ok = isinstance(time_s, (int, float, np.integer, np.floating)) and not isinstance(time_s, bool)
            if not (ok and math.isfinite(time_s) and time_s >= 0):
                raise ArgumentError(f"time_s: expected a finite time >= 0 s, received {time_s!r}")
        rigid = {}
        for name, value, size in (("qpos", qpos, "nq"), ("qvel", qvel, "nv")):
            if value is None:
                continue
            if self.rigid is None:
                raise ArgumentError(
                    f"{name}: expected None (scene {self.model.scene.name!r} has no rigid part), "
                    f"received {_described(value)}"
                )
            n = int(getattr(self.mj_model, size))
            rigid[name] = _checked_array(name, value, (n,), f"values (mj_model.{size} = {n})")
        s = self.state
        if pos is not None:
            s.vert_pos[:] = pos
            s.scal[S_PRESSURE] = s.scal[S_PHI] = 0.0
            s.grad[:] = 0.0
            if s.implicit is not None:  # implicit Euler's warm start and carried pressure: the old state's
                s.implicit.dv[:] = 0.0
                s.implicit.info[Info.PRESSURE] = 0.0
        if vel is not None:
            s.vert_vel[:] = vel
        if time_s is not None:
            s.scal[S_TIME] = float(time_s)
            self.steps_done = int(round(float(time_s) / self.model.arrays.dt))
        if self.rigid is not None:
            self.rigid.set_state(s, time_s=None if time_s is None else float(time_s), **rigid)
        self.failed = None


#: a mesh wider than this (m) is taken for one in the wrong units when a run diverges
BODY_SPAN_MAX_M = 5.0

#: step counts `step` takes: below 2^63, what the compiled loop's int64 holds
MAX_STEP_COUNT = 2**63


def _check_model(model) -> None:
    """`Simulation(model)`'s argument: a compiled Model (a Scene is compiled first), and
    breathing periods of at least two steps (a waveform shorter than a step is sampled
    at random phases, not breathed)."""
    if not isinstance(model, Model):
        raise ArgumentError(
            f"model: expected a hybrid.Model (hybrid.compile_scene(scene); or hybrid.load(scene) for a "
            f"Simulation at once), received {_described(model)}"
        )
    from .schedule import Breathing

    dt = model.dt_s
    for term in (*model.scene.forces, *model.scene.constraints):
        for field in dataclasses.fields(term) if dataclasses.is_dataclass(term) else ():
            value = getattr(term, field.name)
            if isinstance(value, Breathing) and not value.period_s >= 2 * dt:
                raise SceneError(
                    f"{getattr(term, 'name', type(term).__name__)}.{field.name}.period_s: expected at least "
                    f"two steps of dt_s = {dt:g} s, received {value.period_s:g} s"
                )


def _described(value) -> str:
    """What an argument was, for an error message: its shape and kind, or its type."""
    if isinstance(value, (np.ndarray, list, tuple)):
        try:
            arr = np.asarray(value)
        except ValueError:  # nested sequences of different lengths
            return f"a ragged {type(value).__name__}"
        kind = "numbers" if arr.dtype.kind in "biuf" else f"{arr.dtype.kind!r} values ({arr.dtype})"
        return f"an array of shape {arr.shape} of {kind}"
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 80 else text[:77] + '...'}"


def _checked_array(name: str, value, shape: tuple, what: str) -> np.ndarray | None:
    """`value` as a float array of `shape` with finite entries (None stays None), or ArgumentError."""
    if value is None:
        return None
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"{name}: expected finite {what} of shape {shape}, received {_described(value)}") from None
    if arr.shape != shape:
        raise ArgumentError(f"{name}: expected finite {what} of shape {shape}, received {_described(value)}")
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        raise ArgumentError(
            f"{name}: expected finite {what}, received {arr[tuple(bad[0])]} at index "
            f"{tuple(int(i) for i in bad[0])} ({len(bad)} non-finite)"
        )
    return arr
