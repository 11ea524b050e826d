"""Implicit Euler's data (`hybrid.implicit`): its integrator id and status codes, the slots
of its run information, the triangles its Newton matrix reads, and its work arrays."""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numpy as np

from .implicit_matrix import NewtonMatrix, newton_matrix
from .integrators import IMPLICIT_EULER_ID
from .terms.slide_planes import SlidePlanes, slide_planes
from .terms.tangents import NCACHE, NFIB_CACHE, NPF_CACHE

__all__ = [
    "IMPLICIT_NOT_CONVERGED",
    "Info",
    "NewtonRows",
    "newton_rows",
    "ImplicitWork",
    "implicit_work",
    "no_implicit_work",
]

#: the step status of a Newton solve that did not converge (beside hybrid.step.StepStatus)
IMPLICIT_NOT_CONVERGED = 4


class Info(IntEnum):
    """The slots of `ImplicitWork.info`."""

    NEWTON = 0  # Newton iterations of the last step
    RESIDUAL = 1  # its relative residual |r| / max(F, F_mean) (the module's docstring)
    CG = 2  # conjugate-gradient iterations of the last step
    CARRIED = 3  # Pa, the pressure the last solve carried
    PRESSURE = 4  # Pa, the last step's pressure (carried + the projection's)
    NEWTON_TOTAL = 5  # over the run
    CG_TOTAL = 6
    WORST = 7  # the vertex of the largest residual
    PROJECTED_TOTAL = 8  # Newton iterations over the run solved again with the projected Hessian (negative curvature)
    FORCE_SUM = 9  # N, the step-start force scale F summed over the run's solved steps
    SOLVED = 10  # the run's solved steps
    FORCE = 11  # N, the last step's step-start force scale F
    # the airway's flow in the lungs' kernels (`hybrid.implicit_lungs.flow_by_volume`): 1 while it is
    # a volume change over a step, (V - LUNG_FLOW_FROM) / h (the step's start: the last step's; the
    # Newton solve: this step's), else 0 (the rate g . v)
    LUNG_FLOW_BY_VOLUME = 12
    LUNG_FLOW_FROM = 13  # m^3, the cavity's volume the flow is measured from


(
    I_NEWTON,
    I_RESIDUAL,
    I_CG,
    I_CARRIED,
    I_PRESSURE,
    I_NEWTON_TOTAL,
    I_CG_TOTAL,
    I_WORST,
    I_PROJECTED_TOTAL,
    I_FORCE_SUM,
    I_SOLVED,
    I_FORCE,
    I_LUNG_FLOW_BY_VOLUME,
    I_LUNG_FLOW_FROM,
) = (int(k) for k in Info)


class NewtonRows(NamedTuple):
    """The membrane's, muscle fibres', passive fibres' and resting tension's rows (`MembraneArrays`) and the
    surface's faces (face_vert) of the triangles with a free corner: the others add only
    to fixed points, whose rows the solve leaves out, so its residuals, products, blocks
    and volume gradient skip them (at level 8 of the breathing scene a fifth of the
    membrane's triangles and half of the muscle's)."""

    mem_vert: np.ndarray
    mem_par: np.ndarray
    fib_vert: np.ndarray
    fib_par: np.ndarray
    fib_sched: np.ndarray
    pf_vert: np.ndarray
    pf_par: np.ndarray
    rt_vert: np.ndarray
    rt_par: np.ndarray
    face_vert: np.ndarray


def newton_rows(arrays) -> NewtonRows:
    """The `NewtonRows` of a model's arrays (in their order)."""
    free = np.asarray(arrays.vert_free) != 0
    out = []
    for tri, *more in (
        (arrays.mem_vert, arrays.mem_par),
        (arrays.fib_vert, arrays.fib_par, arrays.fib_sched),
        (arrays.pf_vert, arrays.pf_par),
        (arrays.rt_vert, arrays.rt_par),
    ):
        keep = free[tri.reshape(-1, 3)].any(axis=1)
        out += [np.ascontiguousarray(a[keep]) for a in (tri, *more)]
    faces = np.asarray(arrays.face_vert)
    out.append(np.ascontiguousarray(faces[free[faces.reshape(-1, 3)].any(axis=1)]))
    for a in out:  # read-only as the model's: the terms' kernels compile once for both (`implicit_forces`)
        a.flags.writeable = False
    return NewtonRows(*out)


class ImplicitWork(NamedTuple):
    """The implicit step's arrays: dv (nvert, 3) m/s, the last step's velocity change
    (warm start); x_try, v_try, f, f_expl, res, x_kv (the positions the line search's
    viscous dissipation is taken at), dv_start (the Newton iteration's dv) (nvert, 3) and
    the conjugate gradients' cg_* (nfree,
    3, in the Newton matrix's numbering of the free points): scratch; grad (nvert, 3)
    m^2: the volume gradient at the step's start; rows: the
    triangles the Newton matrix reads (`newton_rows`); face (NCACHE), fib (NFIB_CACHE),
    pf (NPF_CACHE) per row of rows: the membrane's, muscle fibres' and passive fibres'
    tangent caches (`newton_caches`); mat: the assembled Newton matrix
    (`hybrid.implicit_matrix`); info (len(Info),): the `Info` slots; the lungs' (empty
    without them): lung_wall_pos, lung_wall_vel, the state's own wall arrays (not copies),
    which the solve holds fixed; lung_wall_f (nwall, 3), lung_g (nvert, 3), lung_gf, lung_gh
    (nfree, 3): the compartment's rank-one term (`hybrid.implicit_lungs.lung_rank_one`); planes:
    the sliding links' planes (`hybrid.terms.slide_planes`, empty without them), which the
    rigid phase places each step."""

    dv: np.ndarray
    x_try: np.ndarray
    v_try: np.ndarray
    f: np.ndarray
    f_expl: np.ndarray
    res: np.ndarray
    x_kv: np.ndarray
    grad: np.ndarray
    dv_start: np.ndarray
    cg_x: np.ndarray
    cg_r: np.ndarray
    cg_z: np.ndarray
    cg_p: np.ndarray
    cg_q: np.ndarray
    cg_t: np.ndarray
    cg_b: np.ndarray
    rows: NewtonRows
    face: np.ndarray
    fib: np.ndarray
    pf: np.ndarray
    mat: NewtonMatrix
    info: np.ndarray
    lung_wall_pos: np.ndarray
    lung_wall_vel: np.ndarray
    lung_wall_f: np.ndarray
    lung_g: np.ndarray
    lung_gf: np.ndarray
    lung_gh: np.ndarray
    planes: SlidePlanes


def implicit_work(
    arrays, wall_pos=None, wall_vel=None, slide_vert=None, slide_stiffness_n_per_m=None
) -> ImplicitWork | None:
    """The work arrays of a model that steps with implicit Euler, else None (`no_implicit_work`). wall_pos,
    wall_vel: the state's lungs' wall (`MembraneState.lung_wall_pos`, `lung_wall_vel`), the
    same arrays (the solve reads the wall where the rigid phase put it); slide_vert (ns,),
    slide_stiffness_n_per_m (ns,) N/m: the sliding points (`Model.slide_vert`), in the rigid
    part's order."""
    if arrays.integrator != IMPLICIT_EULER_ID:
        return None
    n = arrays.vert_rest.shape[0]
    nfree = int(np.count_nonzero(np.asarray(arrays.vert_free)))
    vec = [np.zeros((n, 3)) for _ in range(9)] + [np.zeros((nfree, 3)) for _ in range(7)]
    rows = newton_rows(arrays)
    return ImplicitWork(
        *vec,
        rows=rows,
        face=np.zeros((rows.mem_vert.shape[0], NCACHE)),
        fib=np.zeros((rows.fib_vert.shape[0], NFIB_CACHE)),
        pf=np.zeros((rows.pf_vert.shape[0], NPF_CACHE)),
        mat=newton_matrix(n, arrays.vert_free, rows.mem_vert, rows.fib_vert, rows.pf_vert, rows.rt_vert),
        info=np.zeros(len(Info)),
        lung_wall_pos=arrays.lung_wall.copy() if wall_pos is None else wall_pos,
        lung_wall_vel=np.zeros_like(arrays.lung_wall) if wall_vel is None else wall_vel,
        lung_wall_f=np.zeros_like(arrays.lung_wall),
        lung_g=np.zeros((n, 3)),
        lung_gf=np.zeros((nfree, 3)),
        lung_gh=np.zeros((nfree, 3)),
        planes=slide_planes(arrays.vert_free, slide_vert, slide_stiffness_n_per_m),
    )


def no_implicit_work(arrays) -> ImplicitWork:
    """The `ImplicitWork` of a model that steps with an explicit integrator: every array empty, of
    the types a model's own would have (`implicit_work`), so that every solver's step loop is one
    compiled build (`hybrid.loop.run_steps`'s imp); the loop never reads it."""
    return implicit_work(_emptied(arrays)._replace(integrator=IMPLICIT_EULER_ID))


def _emptied(value):
    """value with each array made empty (its dtype, dimensions and writability kept), through
    named tuples; any other value as it is."""
    if isinstance(value, np.ndarray):
        empty = np.zeros((0,) * value.ndim, value.dtype)
        empty.flags.writeable = value.flags.writeable
        return empty
    if isinstance(value, tuple) and hasattr(value, "_fields"):
        return type(value)(*(_emptied(v) for v in value))
    return value
