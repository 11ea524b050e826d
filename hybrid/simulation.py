"""The changing state of a run: `Simulation`, which drives the compiled step
(`hybrid.step`, or `hybrid.coupling` for scenes with rigid parts).

The whole loop is compiled; `Simulation.step(n)` runs n steps in one call
unless the scene has Python schedules (evaluated between steps).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from . import readouts
from .builds import BuildChoice
from .control import Control
from .diagnosis import advice, failure
from .errors import ArgumentError, SceneError, SimulationDiverged
from .implicit import Info
from .implicit_work import no_implicit_work
from .loop import Frames, kinetic_energy_of, membrane_only, run_steps
from .loop_compile import hold_call, loop_calls, start_loop_compile, steps_slot
from .model import TERMS, Model
from .solvers import SOLVERS, Solver, solver_of
from .state import State
from .step import (
    S_ORIGIN,
    S_PHI,
    S_PRESSURE,
    S_TIME,
    step_par,
)
from .step_work import CALL_HOLD, new_control, new_state, new_work, term_addresses
from .terms.volume import face_volume

__all__ = ["Simulation"]

_MEMBRANE_ONLY = membrane_only()  # the loop's rigid pack for a scene without a rigid part


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

    `solver`: the membrane's solver (`hybrid.solvers`: `SymplecticEuler()`,
    `ExplicitEuler()`, `ImplicitEuler(tol, max_iter)`), None for the scene's own
    (`integrator` and its settings). `sim.model` is then the model stepping with it, and
    `sim.solver` says which runs. Every solver steps through the one compiled loop
    (implicit Euler's solve compiles once, apart from it, for the first model that uses it).
    """

    def __init__(self, model: Model, build: str = "auto", solver: Solver | None = None):
        _check_model(model)
        if solver is not None:
            if not isinstance(solver, Solver):
                raise ArgumentError(
                    f"solver: expected a hybrid solver ({', '.join(c.__name__ + '()' for c in SOLVERS.values())}) "
                    f"or None, received {_described(solver)}"
                )
            model = solver.model_for(model)
        self.model = model
        self.solver = solver_of(model)
        self.builds = BuildChoice(model.arrays.parallel, build)
        # the model's arrays with each build's flag: what the compiled calls take
        self._arrays = {p: model.arrays._replace(parallel=p) for p in (False, True)}
        self._piece_frame: Frames | None = None  # `_run_piece`'s scratch frame
        self.rigid = None
        if model.rigid is not None:
            from .coupling import Coupling  # imports mujoco only for rigid scenes

            self.rigid = Coupling(model)
        self.control = self._new_control()
        self.reset()

    def _new_control(self) -> Control:
        """The run's inputs (`hybrid.Control`): the schedules' rows, then the driven actuators'."""
        arrays = new_control(self.model.arrays)
        if self.rigid is None:
            return Control(self.model.control_keys, arrays)
        system = self.rigid.system
        return Control(
            self.model.control_keys,
            arrays,
            system.controls.ctrl_actuators,
            self.rigid.ctrl_user,
            lambda: (self.rigid.mj_data.ctrl, system.ctrl_act),
        )

    # ------------------------------------------------------------ state
    def __getstate__(self) -> dict:
        """Pickled without the helper process compiling its loop, if any (a process of this one)."""
        state = dict(self.__dict__)
        state.pop("_loop_elsewhere", None)
        return state

    def __setstate__(self, state: dict) -> None:
        """Unpickled (a Simulation sent to another process): its step work made anew, since it holds
        the addresses of kernels compiled apart (`hybrid.step_work.StepWork.calls`), which are this
        process's, not the sender's. The work is scratch; the state and the solver's arrays are kept."""
        self.__dict__.update(state)
        self.work = new_work(self.model.arrays, self.state, self._implicit_work)

    def reset(self) -> None:
        """Back to rest at t = 0."""
        self.state = new_state(self.model.arrays)
        # the solver's own arrays (an empty set for the explicit pair: one loop build), the step's scratch
        imp = self.solver.new_work(self.model, self.state)
        self.solver_work = no_implicit_work(self.model.arrays) if imp is None else imp
        self.work = new_work(self.model.arrays, self.state, imp, addresses=False)
        self.steps_done = 0
        self.failed: Exception | None = None
        if self.rigid is not None:
            self.rigid.reset(self.state)
        if not hasattr(self, "_loop_elsewhere"):  # made: a first run's loop compiles meanwhile elsewhere
            work, arrays, state, imp_, control, rig, par = self._loop_types(self.model.arrays)
            self._loop_elsewhere = start_loop_compile(work, arrays, state, imp_, control, rig, par)
        term_addresses(self.work, self.model.arrays, self.state, imp)

    def _loop_types(self, arrays):
        """What the loop's kernels are compiled for (`hybrid.loop_compile.loop_calls`): these arrays, the
        state, work, solver's work and inputs, the rigid pack's types and the build's `par`."""
        rig = _MEMBRANE_ONLY if self.rigid is None else self.rigid.pack(0)
        return self.work, arrays, self.state, self.solver_work, self.control.arrays, rig, step_par(arrays)

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
        return _read_only(self.work.vert_force)

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
        f = readouts.internal_forces(self.model.arrays, self.state.vert_pos, self.control.arrays.value)
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
        if not self.model.python_schedules:
            left = int(n)
            while True:  # one compiled call, or pieces timed for the choice of build
                par, k = self.builds.chunk(left)
                self._loop_ready(self._arrays[par])
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
        for _ in range(int(n)):  # Python schedules: evaluated between steps
            self._python_schedules(float(self.state.scal[S_TIME]))
            done = self._run(self._arrays[par], 1)
            self.steps_done += done
            self.builds.steps[par] += done
            if done < 1:
                self._raise()

    def _run(self, arrays, nstep: int) -> int:
        """nstep steps in one compiled call with these arrays (the build their flag
        says), their frame into a scratch buffer; the steps done."""
        if self._piece_frame is None:
            self._piece_frame = self.frames_buffer(1)
        stop = np.array([self.steps_done + nstep], np.int64)
        if self._loop(arrays, stop, self._piece_frame, 0):
            return nstep
        return int(self.state.status[1]) - self.steps_done  # the failing step's index

    def _loop_ready(self, arrays) -> None:
        """The loop's kernels for these arrays' build compiled or loaded (`hybrid.loop_compile.loop_calls`), at
        its first step: before a timed piece of the run (`hybrid.builds`), which would count loading
        them. The helper's compile (`start_loop_compile`) is the model's own build's."""
        par = step_par(arrays)
        if not self.work.calls[steps_slot(par)]:  # checked at each piece: the rest once a build
            work, typed, state, imp, control, rig0, par = self._loop_types(arrays)
            elsewhere = getattr(self, "_loop_elsewhere", None) if par == step_par(self.model.arrays) else None
            loop_calls(work, typed, state, imp, control, rig0, par, elsewhere)
            if elsewhere is not None:
                self._loop_elsewhere = None
        if not self.work.calls[CALL_HOLD] and self._may_occlude():  # the airway may close: the hold's step
            work, typed, state, imp, control, rig0, par = self._loop_types(arrays)
            hold_call(work, typed, state, imp, rig0)

    def _may_occlude(self) -> bool:
        """Whether the next steps may close the airway of lungs whose cavity the bodies carry: the
        scene's schedule closes it at some time, or the user's program sets it (`Control`)."""
        a = self.model.arrays
        if self.rigid is None or not a.lung_face.shape[0]:
            return False
        scheduled = getattr(self, "_occlusion_scheduled", None)
        if scheduled is None:
            from .rigid.held_volumes import may_occlude  # a rigid part: MuJoCo is loaded

            scheduled = self._occlusion_scheduled = may_occlude(self.model.scene)
        return scheduled or bool(self.control.arrays.user[a.lung_sched[1]])

    def _loop(self, arrays, stops: np.ndarray, frames: Frames, first: int) -> int:
        """Step to each of stops in one call of the compiled step loop
        (`hybrid.loop.run_steps`), capturing into frames from index `first` on; the
        frames captured."""
        step0 = self.steps_done
        rig = _MEMBRANE_ONLY if self.rigid is None else self.rigid.pack(int(stops[-1]) - step0)
        self._loop_ready(arrays)
        count = run_steps(
            arrays,
            self.state,
            self.work,
            self.solver_work,
            self.control.arrays,
            stops,
            step0,
            frames.arrays(first),
            rig,
            step_par(arrays),
        )
        if self.rigid is not None:
            done = (int(stops[-1]) if count == len(stops) else int(self.state.status[1])) - step0
            self.rigid.finish(rig, self.state, step0, done)
        return count

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
            self._loop_ready(self._arrays[par])
            t0 = time.perf_counter()
            if k < int(stops[i]) - self.steps_done:  # a piece short of the next frame
                done = self._run(self._arrays[par], k)
                self.builds.record(par, done, time.perf_counter() - t0)
                self.steps_done += done
                if done < k:
                    self._raise()
                continue
            j = max(i + 1, int(np.searchsorted(stops, self.steps_done + k, side="right")))
            count = self._loop(self._arrays[par], stops[i:j], frames, i)
            frames.count = i + count
            if count < j - i:
                self.steps_done = int(s.status[1])
                self._raise()
            self.builds.record(par, int(stops[j - 1]) - self.steps_done, time.perf_counter() - t0)
            self.steps_done = int(stops[j - 1])
            i = j

    def _python_schedules(self, t: float) -> None:
        h = self.model.arrays.dt
        c = self.control.arrays
        for row, fn in self.model.python_schedules:
            if c.user[row]:  # the user's program sets this input
                continue
            for out, tt in ((c.value, t), (c.value_next, t + h)):
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
        """Raise the failure the state records (`hybrid.diagnosis.failure`); further steps refuse."""
        self.failed = failure(self.model, self.state, self._implicit_work)
        raise self.failed

    @property
    def _implicit_work(self):
        """Implicit Euler's work arrays (`hybrid.implicit_work.ImplicitWork`), None for the
        explicit integrators (whose step work holds an empty one)."""
        return self.solver_work if self.solver.implicit else None

    def suggest_dt(self) -> float:
        """A time step (s) to try after a divergence: half the linear stability
        bound, and at most a quarter of the step that failed; nan where no step
        is stable (explicit Euler on an undamped spring)."""
        return advice(self.model)[1]

    def get_state(self) -> State:
        """A copy of the run's state (`hybrid.State`): `set_state(state)` restarts from it
        bit for bit, in this `Simulation` or another of the same model."""
        s = self.state
        imp = self._implicit_work
        return State(
            steps_done=int(self.steps_done),
            vert_pos=s.vert_pos.copy(),
            vert_vel=s.vert_vel.copy(),
            scal=s.scal.copy(),
            vert_grad=s.grad.copy(),
            term_calls=s.term_calls.copy(),
            lung=s.lung.copy(),
            lung_wall_pos=s.lung_wall_pos.copy(),
            lung_wall_vel=s.lung_wall_vel.copy(),
            implicit_dv=None if imp is None else imp.dv.copy(),
            implicit_info=None if imp is None else imp.info.copy(),
            mj_state=None if self.rigid is None else self.rigid.mj_state(),
        )

    def _restore(self, state: State) -> None:
        """`set_state(state)`: every part checked against this model before any is set."""
        s, model = self.state, self.model
        want = {
            "vert_pos": s.vert_pos.shape,
            "implicit_dv": None if self._implicit_work is None else self._implicit_work.dv.shape,
            "mj_state": None if self.rigid is None else self.rigid.mj_state().shape,
        }
        for name, shape in want.items():
            got = getattr(state, name)
            if (None if got is None else np.shape(got)) != shape:
                raise ArgumentError(
                    f"state.{name}: expected {'None' if shape is None else f'shape {shape}'} (scene "
                    f"{model.scene.name!r}, integrator {model.scene.integrator}), received {_described(got)}"
                )
        s.vert_pos[:] = state.vert_pos
        s.vert_vel[:] = state.vert_vel
        s.scal[:] = state.scal
        s.grad[:] = state.vert_grad
        s.term_calls[:] = state.term_calls
        if state.lung is not None:
            s.lung[:] = state.lung
        if state.lung_wall_pos is not None and state.lung_wall_vel is not None:
            s.lung_wall_pos[:] = state.lung_wall_pos
            s.lung_wall_vel[:] = state.lung_wall_vel
        if self._implicit_work is not None:
            self._implicit_work.dv[:] = state.implicit_dv
            self._implicit_work.info[:] = state.implicit_info
        if self.rigid is not None:
            assert state.mj_state is not None  # its shape checked above
            self.rigid.set_mj_state(state.mj_state)
        self.steps_done = int(state.steps_done)
        self.failed = None

    def set_state(
        self,
        state: State | None = None,
        *,
        vert_pos=None,
        vert_vel=None,
        time_s: float | None = None,
        qpos=None,
        qvel=None,
    ) -> None:
        """Start from another state: a `State` (`get_state`), restored whole, or the parts
        given by keyword, what is not given staying as it is.

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
        if state is not None:
            if not isinstance(state, State):
                raise ArgumentError(
                    f"state: expected a hybrid.State (Simulation.get_state()), received {_described(state)}"
                )
            if any(v is not None for v in (vert_pos, vert_vel, time_s, qpos, qvel)):
                raise ArgumentError("set_state: expected a State or keyword parts, received both")
            return self._restore(state)
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
            if self._implicit_work is not None:  # implicit Euler's warm start and carried pressure: the old state's
                self._implicit_work.dv[:] = 0.0
                self._implicit_work.info[Info.PRESSURE] = 0.0
        if vel is not None:
            s.vert_vel[:] = vel
        if time_s is not None:
            s.scal[S_TIME] = float(time_s)
            s.scal[S_ORIGIN] = float(time_s) - round(float(time_s) / self.model.arrays.dt) * self.model.arrays.dt
            self.steps_done = int(round(float(time_s) / self.model.arrays.dt))
        if self.rigid is not None:
            self.rigid.set_state(s, time_s=None if time_s is None else float(time_s), **rigid)
        self.failed = None


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
