"""How the step loop's kernels are compiled and found (`hybrid.loop`): the addresses of the steps
between two frames (`steps_between`, a build for each `par`) and of the rigid phase in the step's work
(`loop_calls`), compiled on a first run by a helper process while this one compiles the rest
(`start_loop_compile`, `hybrid.calls`); which build a compile is, for the compile notice (`loop_build`).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types

from .calls import compile_callees, compile_elsewhere, kernel_address
from .loop import Frames, RigidPack, rigid_between, run_steps, steps_between
from .step import membrane_advance
from .step_work import CALL_HOLD, CALL_RIGID, CALL_STEPS, CALL_STEPS_PARALLEL, CALL_WALL
from .wall_coupling import hold_between, wall_step_between

__all__ = ["hold_call", "loop_build", "loop_calls", "start_loop_compile", "steps_slot"]


def loop_build(arg_types) -> str:
    """Which build of the step loop (`run_steps`, or the steps it calls, `steps_between`) its
    argument types make: "parallel" (the multi-core passes) or "serial" (every solver steps through
    either: implicit Euler's solve is compiled apart, `hybrid.step_work.StepWork`). For the compile
    notice's estimate (`hybrid.compile_estimate`)."""
    par = arg_types[9] if len(arg_types) == 10 else arg_types[4]  # `run_steps`'s, `steps_between`'s
    return "serial" if par == types.none else "parallel"


def _steps_args(work, arrays, state, imp, control, rig, par) -> tuple:
    """Example arguments of `steps_between` as `run_steps` calls it with these arrays."""
    return 0, 0, 0, 0, par, numba.typeof((arrays, state, work, imp, control, rig))


def _advance_of(m, s, w, imp, c, t, step, par):
    """Phases 2-5 as `steps_between` calls them (`membrane_advance`): typed, never compiled, so
    that this process compiles its callees while a helper compiles the steps (`start_loop_compile`)."""
    return membrane_advance(m, s, w, imp, c, t, step, par)


def start_loop_compile(work, arrays, state, imp, control, rig: RigidPack, par):
    """On a first run, the steps between two stops (`steps_between`, half of the step's compile)
    compiled for these types by a helper process meanwhile (`hybrid.calls.compile_elsewhere`),
    for `loop_calls` to wait for; else None."""
    steps_types = tuple(numba.typeof(a) for a in _steps_args(work, arrays, state, imp, control, rig, par))
    elsewhere = compile_elsewhere([(steps_between, steps_types)])
    if elsewhere is not None:  # meanwhile the second half's callees here, which the helper then loads
        advance_types = tuple(numba.typeof(a) for a in (arrays, state, work, imp, control, 0.0, 0, par))
        compile_callees(_advance_of, advance_types, like=steps_between)
    return elsewhere


def loop_calls(work, arrays, state, imp, control, rig: RigidPack, par, elsewhere=None) -> None:
    """The addresses of the steps between two stops (`steps_between`, its build for `par`) and, with a rigid part,
    of its phase (`rigid_between`, and the lungs' step it calls, `wall_step_between`) into `work.calls`, each compiled (or loaded from the cache)
    now for the types `run_steps` passes them with these arrays. `elsewhere`: the steps being
    compiled by a helper process (`start_loop_compile`), waited for after this process compiled
    the rigid phase and `run_steps` itself (which its first call would otherwise compile)."""
    if rig.coupled:
        rigid_args = numba.typeof((arrays, state, work, imp.planes, rig))
        work.calls[CALL_RIGID] = kernel_address(rigid_between, types.none, 0, 0.0, 0, rigid_args)
        if rig.wall.qfrc.shape[0]:  # lungs whose wall the bodies carry: their step, compiled apart
            work.calls[CALL_WALL] = kernel_address(wall_step_between, types.none, 0, rigid_args)
    if elsewhere is not None:
        stops, frames = np.zeros(1, np.int64), Frames(1, 1, 0).arrays()
        run_steps.compile(
            tuple(numba.typeof(a) for a in (arrays, state, work, imp, control, stops, 0, frames, rig, par))
        )
        elsewhere.wait()
    steps_args = _steps_args(work, arrays, state, imp, control, rig, par)
    work.calls[steps_slot(par)] = kernel_address(steps_between, types.int64, *steps_args)


def hold_call(work, arrays, state, imp, rig: RigidPack) -> None:
    """The occluded airway's hold shared with the bodies that carry the cavity (`hold_between`) into
    `work.calls`, compiled (or loaded from the cache) now: only for a run whose airway may close (its
    schedule, or the user's program through `hybrid.Control`: `Simulation._loop_ready`), since a
    lungs scene that breathes with its airway open never reaches it."""
    rigid_args = numba.typeof((arrays, state, work, imp.planes, rig))
    work.calls[CALL_HOLD] = kernel_address(hold_between, types.int64, 0, 0, 0, 0.0, rigid_args)


def steps_slot(par) -> int:
    """The slot of `StepWork.calls` holding `steps_between`'s build for `par` (`run_steps`)."""
    return CALL_STEPS if par is None else CALL_STEPS_PARALLEL
