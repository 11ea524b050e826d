"""What the membrane's step reads and writes, and how a simulation makes them: its state
(`MembraneState`, what a step advances), its work arrays (`StepWork`, scratch, with the addresses
of the kernels the step calls compiled apart) and its inputs (`ControlArrays`). The step itself
is `hybrid.step`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.core import types as nb_types

from .calls import kernel_address
from .implicit import ImplicitWork, implicit_start_forces, implicit_step
from .integrators import IMPLICIT_EULER_ID
from .kernel import chunk_count
from .model import MembraneArrays
from .switches import T_LUNGS, T_SOFT_VOLUME
from .terms import STEP_FORCES, TERMS
from .terms.lungs import NLUNG, P_RECOIL, P_V0, LungSlot, project_occluded
from .terms.soft_volume import soft_volume_step

__all__ = [
    "MembraneState",
    "StepWork",
    "ControlArrays",
    "NCALL",
    "CALL_IMPLICIT_START",
    "CALL_IMPLICIT_STEP",
    "CALL_OCCLUDED",
    "CALL_SOFT_VOLUME",
    "CALL_STEPS",
    "CALL_STEPS_PARALLEL",
    "CALL_RIGID",
    "CALL_WALL",
    "CALL_HOLD",
    "new_state",
    "new_work",
    "term_addresses",
    "new_control",
]


class MembraneState(NamedTuple):
    """What a step advances (a checkpoint's `hybrid.State` copies it). vert_pos (nvert, 3) m;
    vert_vel (nvert, 3) m/s; grad (nvert, 3) m^2: the volume gradient at the last
    projection (with a rigid part the next step sends p grad_i V to the ribs);
    scal: time s, pressure Pa, phi, kinetic energy J, largest step displacement m;
    status: code, failing step, worst vertex, projection status;
    term_calls (nterm,): how many times each term's kernel ran;
    lung (NLUNG,): the lungs' compartment at the last step's start (`hybrid.terms.lungs.LungSlot`);
    lung_wall_pos (nwall, 3) m, lung_wall_vel (nwall, 3) m/s: the cavity wall's points, which
    the rigid bodies carry."""

    vert_pos: np.ndarray
    vert_vel: np.ndarray
    grad: np.ndarray
    scal: np.ndarray
    status: np.ndarray
    term_calls: np.ndarray
    lung: np.ndarray
    lung_wall_pos: np.ndarray
    lung_wall_vel: np.ndarray


class StepWork(NamedTuple):
    """What a step writes before it reads: not state, never in a checkpoint. vert_force
    (nvert, 3) N: the step's forces before its constraints (`Simulation.vert_force`);
    face_force (nface_m, 6) N: the membrane triangles' forces (the multi-core build's);
    sm_sums (nsm, 9): the shape memory's ring sums; vert_acc (chunk_count(nvert), 4): the
    per-point passes' sums over each chunk of points (hybrid.kernel); dirn (nvert, 3), cubic
    (2,): the volume projection's; lung_wall_force (nwall, 3) N: the pleural load on the
    cavity wall (to its bodies); lung_grad (nvert + nwall, 3) m^2: the cavity's volume gradient
    at its points, by cavity index (`hybrid.terms.lung_cavity.cavity_volume_rate_gradient`: the
    lungs' step force writes it, the rigid phase reads the bodies' points); lung_scratch (5,
    nvert, 3): the occluded airway's projection (both empty without lungs); calls (NCALL,) int64: the addresses of the kernels
    the step calls compiled apart (`hybrid.calls.call_at`), by slot (`CALL_*`): implicit
    Euler's phases 1 and 2 (`implicit_start_forces`, `implicit_step`), the occluded airway's
    projection (`project_occluded`), the soft volume's force (`soft_volume_step`), the steps
    between two frames (`hybrid.loop.steps_between`: its serial-only build and the one with the
    multi-core passes, each a build of its own), the rigid phase (`rigid_between`) and, with lungs
    whose wall the bodies carry, MuJoCo's step with their load implicit
    (`hybrid.wall_coupling.wall_step_between`: these four filled at the first step of their build,
    `hybrid.loop_compile.loop_calls`), and their occluded airway's hold shared with the bodies
    (`hold_between`, at the first step of a run whose airway may close, `hold_call`), 0 where the
    model never calls it;
    force_calls (k, 2)
    int64: the registry's terms with their own step kernel that the model has, (id, address)
    (`hybrid.terms.STEP_FORCES`). Compiled apart, a kernel compiles only for a model that calls
    it, and the loop holds none of its code (numba links a callee into each caller and optimizes
    it again there). Implicit Euler's own arrays (`hybrid.implicit_work.ImplicitWork`: its warm
    start and carried pressure, which a checkpoint keeps, and its Newton work arrays) are an
    argument of their own, imp, beside this (an empty one for the explicit integrators,
    `no_implicit_work`: every solver steps through one loop build; inside this tuple every
    kernel given the step's work would take its hundreds of fields as arguments, 7 s more of a
    first run's compile)."""

    vert_force: np.ndarray
    face_force: np.ndarray
    sm_sums: np.ndarray
    vert_acc: np.ndarray
    dirn: np.ndarray
    cubic: np.ndarray
    lung_wall_force: np.ndarray
    lung_grad: np.ndarray
    lung_scratch: np.ndarray
    calls: np.ndarray
    force_calls: np.ndarray


#: the slots of `StepWork.calls`
NCALL = 9
(
    CALL_IMPLICIT_START,
    CALL_IMPLICIT_STEP,
    CALL_OCCLUDED,
    CALL_SOFT_VOLUME,
    CALL_STEPS,
    CALL_STEPS_PARALLEL,
    CALL_RIGID,
    CALL_WALL,
    CALL_HOLD,
) = range(NCALL)


def new_state(arrays: MembraneArrays) -> MembraneState:
    """The state before a first step: the points at rest, the lungs at rest."""
    n = arrays.vert_rest.shape[0]
    return MembraneState(
        vert_pos=arrays.vert_rest.copy(),
        vert_vel=np.zeros((n, 3)),
        grad=np.zeros((n, 3)),
        scal=np.zeros(8),
        status=np.zeros(4, np.int64),
        term_calls=np.zeros(len(TERMS), np.int64),
        lung=_lung_start(arrays),
        lung_wall_pos=arrays.lung_wall.copy(),
        lung_wall_vel=np.zeros_like(arrays.lung_wall),
    )


def new_work(
    arrays: MembraneArrays, state: MembraneState, imp: ImplicitWork | None = None, *, addresses: bool = True
) -> StepWork:
    """The step's work arrays for the model's arrays, with the addresses of the kernels its step
    calls compiled apart (`StepWork.calls`, `.force_calls`), each compiled (or loaded from the
    cache) now for the types the loop passes it (`term_addresses`; later when `addresses` is
    False); implicit Euler's with its arrays `imp` (`hybrid.solvers.Solver.new_work`, None for
    the explicit pair)."""
    n = arrays.vert_rest.shape[0]
    if (imp is not None) != (arrays.integrator == IMPLICIT_EULER_ID):
        raise ValueError(
            f"new_work: imp: expected implicit Euler's arrays exactly when the model steps with it "
            f"(integrator id {arrays.integrator}), received {'none' if imp is None else 'them'}"
        )
    forces = [(tid, step_force) for tid, step_force in STEP_FORCES if arrays.term_on[tid]]
    work = StepWork(
        vert_force=np.zeros((n, 3)),
        face_force=np.zeros((arrays.mem_vert.shape[0], 6)),
        sm_sums=np.zeros((arrays.sm_vert.shape[0], 9)),
        vert_acc=np.zeros((chunk_count(n), 4)),
        dirn=np.zeros((n, 3)),
        cubic=np.zeros(2),
        lung_wall_force=np.zeros_like(arrays.lung_wall),
        lung_grad=np.zeros((n + arrays.lung_wall.shape[0] if arrays.lung_face.shape[0] else 0, 3)),
        lung_scratch=np.zeros((5, n if arrays.lung_face.shape[0] else 0, 3)),
        calls=np.zeros(NCALL, np.int64),
        force_calls=np.zeros((len(forces), 2), np.int64),
    )
    if addresses:
        term_addresses(work, arrays, state, imp)
    return work


def term_addresses(work: StepWork, arrays: MembraneArrays, state: MembraneState, imp: ImplicitWork | None) -> None:
    """The addresses of the terms' kernels the step calls compiled apart into `work` (`new_work`)."""
    forces = [(tid, step_force) for tid, step_force in STEP_FORCES if arrays.term_on[tid]]
    # the example arguments: the types the loop passes (`membrane_forces`, `integrate`, `_after_integration`)
    control = new_control(arrays)
    for row, (tid, step_force) in enumerate(forces):
        work.force_calls[row] = tid, kernel_address(step_force, nb_types.none, arrays, state, work, control)
    if imp is not None:
        pos, vel = state.vert_pos, state.vert_vel
        work.calls[CALL_IMPLICIT_START] = kernel_address(
            implicit_start_forces, nb_types.none, arrays, control.value, pos, vel, state.lung, imp, work.vert_force
        )
        work.calls[CALL_IMPLICIT_STEP] = kernel_address(
            implicit_step, nb_types.int64, arrays, state, control.value, np.int64(0), imp, work.vert_acc
        )
    if arrays.term_on[T_SOFT_VOLUME]:
        work.calls[CALL_SOFT_VOLUME] = kernel_address(soft_volume_step, nb_types.float64, arrays, state, work)
    if arrays.term_on[T_LUNGS]:
        occluded = nb_types.Tuple((nb_types.float64, nb_types.float64, nb_types.boolean))
        work.calls[CALL_OCCLUDED] = kernel_address(project_occluded, occluded, arrays, state, work, 0.0, True)


def _lung_start(arrays: MembraneArrays) -> np.ndarray:
    """The lungs' slots before a first step: at rest (the first frame's flow is then 0)."""
    lung = np.zeros(NLUNG)
    lung[LungSlot.VOLUME] = arrays.lung_par[P_V0]
    lung[LungSlot.PLEURAL] = -arrays.lung_par[P_RECOIL]
    return lung


class ControlArrays(NamedTuple):
    """The inputs a step reads, one row per schedule of the model (`Model.control_names`):
    value (nsched, 3), each input at the step's time t (a tension N/m, a pressure Pa, a
    force N, ...: the unit of its key); value_next (nsched, 3), at t + h (prescribed motions
    read both ends of the step); user (nsched,) uint8: 1 where the user's program sets
    the row (`hybrid.Control`), which the step then leaves as it is, 0 where the step
    evaluates the scene's schedule."""

    value: np.ndarray
    value_next: np.ndarray
    user: np.ndarray


def new_control(arrays: MembraneArrays) -> ControlArrays:
    """Every input driven by its schedule, the values zero until the first step."""
    ns = arrays.sched.kind.shape[0]
    return ControlArrays(np.zeros((ns, 3)), np.zeros((ns, 3)), np.zeros(ns, np.uint8))
