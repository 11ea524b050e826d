"""What went wrong when a step failed, and what to change: the error a failed step's
status stands for (`failure`), with advice that works when followed (`advice`): the
implicit iteration cap, the mesh's units, damping below the shape memory's
self-excitation, or the step the linear stability bound allows.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ConstraintError, SimulationDiverged
from .implicit import IMPLICIT_NOT_CONVERGED, Info
from .integrators import EXPLICIT_EULER_ID
from .step import DIVERGED_NONFINITE, S_MAXDISP, VOLUME_FAILED
from .terms.lungs import L_OCCLUDED
from .terms.volume import PROJ_NO_GRADIENT

__all__ = ["failure", "advice", "damping_fraction", "SELF_EXCITATION_DAMPING"]

# below this fraction of critical damping the shape-memory force excites
# itself on the breathing membrane (measured by `hybrid study stability`)
SELF_EXCITATION_DAMPING = 0.15
#: a mesh wider than this (m) is taken for one in the wrong units when a run diverges
BODY_SPAN_MAX_M = 5.0


def failure(model, s, solver=None) -> Exception:
    """The error a failed step's status in state `s` (a `MembraneState`) stands for, with
    the advice that helps (`advice`); solver: implicit Euler's arrays (`hybrid.implicit_work.ImplicitWork`), None for the explicit pair."""
    code, step, vert = int(s.status[0]), int(s.status[1]), int(s.status[2])
    h = model.arrays.dt
    t = step * h
    if code == IMPLICIT_NOT_CONVERGED:
        assert solver is not None  # the code only implicit Euler's step sets
        info = solver.info
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
            remedy, suggest = advice(model)
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
        remedy, suggest = advice(model)
        held = _held_volumes_remedy(model, s)
        if held is not None:
            remedy, suggest = held, math.nan
        err = SimulationDiverged(
            f"simulation diverged at t = {t:.6g} s (step {step}): vertex {vert} {what}; "
            f"time step {h:.3g} s with {model.scene.integrator}; {remedy}",
            time_s=t,
            step=step,
            vert=vert,
            dt_suggested_s=suggest,
        )
    return err


def _held_volumes_remedy(model, s) -> str | None:
    """The advice when the held volumes' pressures on the rigid bodies grow step by step
    (`hybrid.rigid.held_volumes`: a gain of 1 or more, with the airway as it was): no step helps."""
    if model.rigid is None:
        return None
    from .rigid.held_volumes import held_volumes_gain

    gain = held_volumes_gain(model)
    if gain is None:
        return None
    occluded = gain.occluded is not None and s.lung.shape[0] > 0 and s.lung[L_OCCLUDED] != 0.0
    rho = gain.occluded if occluded else gain.open
    if rho is None or rho < 1.0:
        return None
    return (
        f"the {gain.line()}: the volumes' pressures on the bodies grow {rho:.3g}-fold a step, and a smaller "
        "step will not help; make the bodies that carry the volumes heavier, or damp their joints"
    )


def damping_fraction(model) -> float:
    """The smallest damping, as a fraction of critical, over the integrated
    shape-memory points (inf when the model has no shape memory)."""
    a = model.arrays
    if a.sm_vert.size == 0:
        return math.inf
    i = a.sm_vert[a.vert_free[a.sm_vert] > 0]
    k = model.vert_stiffness[i]
    return float(np.min(a.damp_coef[i] / (2.0 * np.sqrt(k * a.vert_mass[i])))) if i.size else math.inf


def advice(model) -> tuple[str, float]:
    """What to try after a divergence, and the step it suggests (nan: none helps);
    a mesh far larger than a body is named first (a file in millimetres)."""
    remedy, suggest = _step_advice(model)
    span = float(np.ptp(model.arrays.vert_rest, axis=0).max())
    if span > BODY_SPAN_MAX_M:
        remedy = (
            f"the mesh spans {span:.3g} m, no body's size: a mesh file in millimetres needs "
            f"mesh.unit_scale = 0.001 (a generator, radius_m in metres); if the size is meant, {remedy}"
        )
    return remedy, suggest


def _step_advice(model) -> tuple[str, float]:
    """What to try after a divergence, and the step it suggests (nan: none helps)."""
    a = model.arrays
    h = a.dt
    k, c, m = model.vert_stiffness, a.damp_coef, a.vert_mass
    held = (a.vert_free > 0) & (k > 0)
    if a.integrator == EXPLICIT_EULER_ID and np.any(held & (c == 0)):
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
            spring = np.where(k > 0, c / k if a.integrator == EXPLICIT_EULER_ID else 2.0 * np.sqrt(m / k), np.inf)
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
    damping = damping_fraction(model)
    if h <= bound and damping < SELF_EXCITATION_DAMPING:
        # the step is not the cause: the non-conservative shape memory excites itself
        return (
            f"the step is within the stability bound {bound:.3g} s but damping is {damping:.3g} of "
            f"critical, below the {SELF_EXCITATION_DAMPING} where shape memory excites itself; add "
            f"Damping(critical_fraction=0.3)"
        ), suggest
    return f"try dt_s <= {suggest:.3g} s", suggest


# ------------------------------------------------------------ a state set by hand
