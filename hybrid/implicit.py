"""Backward (implicit) Euler for the membrane: `integrator = "implicit_euler"`.

The step's free points take v+ = v + dv, x+ = x + h v+ with

    M dv = h (f_i(x+, v+) + f_e),

f_i the forces treated implicitly (the continuum membrane with its Kelvin-Voigt
viscosity, muscle fibres, passive fibres, resting tension, drag, the sliding links' planes
at the step's end: `hybrid.terms.slide_planes`) and f_e the others at the step's start
(gravity, applied loads, pressure loads, ...: the step's force pass minus f_i
there), plus, with a volume constraint, the last step's pressure on the
volume gradient (and with the lungs' airway occluded, the occlusion's last constraint
pressure on the cavity's). Nailed, prescribed and linked points keep their positions
and velocities during the solve (zero rows). The exact volume projection
follows as in the explicit steps and corrects the pressure carried: at rest the
correction vanishes and the pressure readout is the constraint's whole
multiplier (without the carried pressure a stiff membrane's solve would
collapse inward each step and the projection push it back along another
direction, reading a pressure too small by 1 + h^2 k/m).

Newton's method on dv, warm-started from the last step's dv. Each iteration
solves (M + h^2 K + h C) ddv = h r, r = f_i + f_e - M dv / h (N) the residual,
C the damping matrix and K the forces' exact Hessian (`hybrid.terms.tangents`),
by conjugate gradients with the matrix assembled once per Newton iteration from
the terms' per-triangle tangent caches (`hybrid.implicit_matrix`), preconditioned
with its symmetric over-relaxed Gauss-Seidel (SSOR) sweep whose diagonal blocks are those
of the matrix with K made positive semi-definite per element, in Eisenstat's implementation
(`hybrid.implicit_matrix.split_cg`: two triangular solves an iteration). Where the exact matrix has negative curvature
(a membrane under compression: it has no bending stiffness) the conjugate
gradients stop, and the solve is repeated with the Hessian projected element by element
(each triangle's compressive stress and each fibre's negative coefficients clamped at
zero), assembled as the exact one (projected Newton for that iteration). Taking the
truncated iterate instead (truncated Newton), as before 0.14, made the breathing
scene with lungs at level 8 (implicit Euler at 30 ms) take 677 Newton iterations
over 12 s where this takes 595 (and 496 -> 463 without lungs). Solving
with the projected Hessian throughout converged linearly and slowly on the
sagging trunk at 10x the explicit bound (no convergence in 200 iterations where
this needs at most 14): the projection drops the compressive stress that the
mass term nearly balances on out-of-plane modes. Each step is then halved until
the incremental potential (whose dv-gradient is -h r, the viscous part taken at
the iteration's start) falls by 1e-4 of the predicted decrease, or |r| halves
(at most 12 halvings). A step has converged when |r| <= implicit_tol max(F, F_mean),
F = |f_i| + |f_e| + |M dv / h| (2-norms over the free points) and F_mean the mean of
the step-start F over the run's solved steps, this one included (the time-averaged force
of Abaqus's residual criterion: at the end of expiration the breathing membrane's forces
fall 50-200 fold, and a tolerance of the instantaneous forces alone asked for a residual
that many times smaller in newtons there, at 2-3 Newton iterations a step, for no
change in the run's metrics), or when a Newton correction
moves no point by more than a few units in the last place of the positions, or
one of at most a few hundred such units no longer halves the residual (the
round-off floor: a coupled body at rest, its linked points placed by the rigid
model, has forces of 1e-10 N whose residual cannot fall below 1e-15 N; positions
rounded to their last place, times the stiffness, leave about 3e-13 N on the
breathing scene at level 6); one that has not after
implicit_max_iter iterations stops the run (`IMPLICIT_NOT_CONVERGED`), the
state left at the step's start.

`implicit_start_forces` and `implicit_step` are compiled apart from the step loop and called
at their addresses (`hybrid.calls.call_at`, `hybrid.step_work.StepWork.calls`): one loop
build serves every solver, and the solve compiles only for a scene that steps with it (the
explicit integrators hold an empty `ImplicitWork`, and no address).
"""

from __future__ import annotations

import math

import numpy as np

from .implicit_lungs import TO_POINTS, add_lung_forces, flow_by_rate, flow_by_volume, lung_potential, lung_rank_one
from .implicit_matrix import (
    assemble,
    gather,
    half_sweep,
    scatter_add,
    split_cg,
)
from .implicit_work import (
    I_CARRIED,
    I_CG,
    I_CG_TOTAL,
    I_FORCE,
    I_FORCE_SUM,
    I_NEWTON,
    I_NEWTON_TOTAL,
    I_PRESSURE,
    I_PROJECTED_TOTAL,
    I_RESIDUAL,
    I_SOLVED,
    I_WORST,
    IMPLICIT_NOT_CONVERGED,
    ImplicitWork,
    Info,
    NewtonRows,
    implicit_work,
    newton_rows,
)
from .integrators import IMPLICIT_EULER_ID
from .kernel import CHUNK_VERTS, kernel
from .switches import T_DAMPING, T_LUNGS, T_MEMBRANE, T_MUSCLE_FIBRES, T_PASSIVE_FIBRES, T_RESTING_TENSION, T_VOLUME
from .terms.fibres import add_muscle_fibres
from .terms.lung_cavity import add_cavity_pressure
from .terms.lungs import L_HOLD, L_OCCLUDED, L_RATE, L_VOLUME, P_REF
from .terms.membrane import add_membrane_serial, membrane_energy
from .terms.passive_fibres import add_passive_fibres
from .terms.resting_tension import add_resting_tension, resting_tension_energy, resting_tension_product
from .terms.slide_planes import add_plane_forces, plane_energy, plane_product
from .terms.tangents import (
    fibre_cached_product,
    fibre_energy,
    fibre_tangent_cache,
    kelvin_voigt_dissipation,
    membrane_tangent_cache,
    membrane_tangent_product,
    passive_fibres_cached_product,
    passive_fibres_energy_kernel,
    passive_fibres_tangent_cache,
)

__all__ = [
    "IMPLICIT_NOT_CONVERGED",
    "ImplicitWork",
    "Info",
    "implicit_work",
    "implicit_step",
    "implicit_pressure",
    "implicit_forces",
    "implicit_start_forces",
    "NewtonRows",
    "newton_rows",
    "newton_caches",
    "newton_product",
]

#: `assemble`'s `project`, the exact Hessian or projected element by element: numpy booleans, so
#: that numba compiles one build for both (a constant True or False is a literal type, each its own
#: build of `assemble`: 10-14 s more of implicit Euler's first compile)
EXACT, PROJECTED = np.bool_(False), np.bool_(True)

CG_MIN_ITER = 50  # the conjugate gradients' cap: 3 x the free coordinates, at least this
HALVINGS = 12
ARMIJO = 1e-4  # the fraction of the predicted decrease a step must achieve
EPS = 2.0**-52  # the doubles' relative spacing
ULPS = 4.0  # a Newton correction at most this many units in the last place of the positions ends the solve
STALL_ULPS = 256.0  # ... and one at most this many that did not halve the residual
FORCING = 0.5  # the linear solve: to this fraction of the residual, and of what convergence asks


@kernel
def implicit_forces(m, tri, sched_val, x, v, out, w, planes=None):
    """out = the forces implicit Euler treats implicitly at (x, v): membrane (with its
    viscosity), muscle fibres, passive fibres, resting tension, drag, the lungs' pleural load; of the
    triangles `tri` (m itself: all of them; `NewtonRows`: those with a free corner, whole on
    the free points); and the sliding links' planes when given (the solve's: the step's start
    has their force from the rigid phase, `hybrid.loop.slide_forces`).
    # Model: m, tri, planes (`SlidePlanes`) or None   # Data in: sched_val (schedules at t), x (m), v (m/s)
    # Data in: w.lung_wall_pos, w.lung_wall_vel, planes.origin, .normal   # Data out: out (N)   # Scratch: w.lung_wall_f
    """
    for i in range(out.shape[0]):
        for a in range(3):
            out[i, a] = 0.0
    on = m.term_on
    if on[T_MEMBRANE]:
        add_membrane_serial(tri.mem_vert, tri.mem_par, m.kv_on, x, v, out)
    if on[T_MUSCLE_FIBRES]:
        add_muscle_fibres(tri.fib_vert, tri.fib_par, tri.fib_sched, sched_val, x, out)
    if on[T_PASSIVE_FIBRES]:
        add_passive_fibres(tri.pf_vert, tri.pf_par, x, out)
    if on[T_RESTING_TENSION]:
        add_resting_tension(tri.rt_vert, tri.rt_par, x, out)
    if on[T_DAMPING]:
        for i in range(out.shape[0]):
            c = m.damp_coef[i]
            for a in range(3):
                out[i, a] -= c * v[i, a]
    if on[T_LUNGS]:
        add_lung_forces(
            m.lung_face,
            m.lung_par,
            m.lung_sched[0],
            m.dt,
            sched_val,
            x,
            v,
            out,
            w.lung_wall_pos,
            w.lung_wall_vel,
            w.lung_wall_f,
            w.info,
        )
    if planes is not None:
        add_plane_forces(planes, x, out)


@kernel
def implicit_start_forces(m, sched_val, x, v, lung, imp, vert_force):
    """Step phase 1's implicit part: imp.f = `implicit_forces` at the step's start, added to
    vert_force (which the force pass left without them, kept as the explicit forces in
    imp.f_expl). `implicit_step` reads imp.f_expl: the explicit forces at the step's start,
    before the linked points move to their new sites. The sliding planes' force at the start
    comes later, from the rigid phase (`hybrid.loop.slide_forces`), into vert_force alone. The
    lungs' airway flow is the last step's, as the wall's load took it (`lungs_step_force`, which
    set lung's VOLUME and RATE): all the cavity's points, the linked ones among them, see one load.
    # Model: m   # Data in: sched_val, x (m), v (m/s), lung (`LungSlot`)   # Data out: imp.f, imp.f_expl (N)
    # Data in/out: vert_force (N)
    """
    # the last step's start volume, V_n - h Q (within rounding of V_n's)
    flow_by_volume(m, lung, imp.info, lung[L_VOLUME] - m.dt * lung[L_RATE])
    implicit_forces(m, m, sched_val, x, v, imp.f, imp)
    flow_by_rate(imp.info)
    for i in range(vert_force.shape[0]):
        for a in range(3):
            imp.f_expl[i, a] = vert_force[i, a]  # the explicit forces, kept exact for the solve
            vert_force[i, a] += imp.f[i, a]


@kernel
def newton_caches(m, rows, sched_val, x, face, fib, pf):
    """The tangent caches of the triangles `rows` at x, what `newton_product` reads: once
    per Newton iteration, not once per conjugate-gradient iteration.
    # Model: m.term_on; rows (NewtonRows): mem_vert, mem_par, fib_vert, fib_par, fib_sched, pf_vert, pf_par
    # Data in: sched_val (the inputs at t), x (nvert, 3) m
    # Data out: face (nmem, NCACHE), fib (nfib, NFIB_CACHE), pf (npf, NPF_CACHE): the terms on (the others' kept)
    """
    on = m.term_on
    if on[T_MEMBRANE]:
        membrane_tangent_cache(rows.mem_vert, rows.mem_par, x, face)
    if on[T_MUSCLE_FIBRES]:
        fibre_tangent_cache(rows.fib_vert, rows.fib_par, rows.fib_sched, sched_val, x, fib)
    if on[T_PASSIVE_FIBRES]:
        passive_fibres_tangent_cache(rows.pf_vert, rows.pf_par, x, pf)


@kernel
def newton_product(m, rows, face, fib, pf, h, project, u, y, planes=None):
    """y = (M + h^2 K + h C) u on every point (no rows zeroed) with the triangles `rows`
    (all of the model's: the Newton matrix; `newton_rows`: its free points' rows): the
    matrix at the positions the caches face, fib, pf were taken at (`newton_caches`);
    the Hessian projected per element when `project`; with the sliding links' planes when given.
    # Model: m.vert_mass (nvert,) kg, m.damp_coef (nvert,) kg/s, m.term_on; rows: mem_vert, mem_par, fib_vert, pf_vert, rt_vert, rt_par
    # Data in: face, fib, pf (`newton_caches`), h (s), project, u (nvert, 3), planes (`SlidePlanes`) or None
    # Data out: y (nvert, 3), kg times u's unit
    """
    on = m.term_on
    for i in range(y.shape[0]):
        c = m.vert_mass[i] + (h * m.damp_coef[i] if on[T_DAMPING] else 0.0)
        for a in range(3):
            y[i, a] = c * u[i, a]
    if on[T_MEMBRANE]:
        membrane_tangent_product(rows.mem_vert, rows.mem_par, face, project, h * h, h, u, y)
    if on[T_MUSCLE_FIBRES]:
        fibre_cached_product(rows.fib_vert, fib, project, h * h, u, y)
    if on[T_PASSIVE_FIBRES]:
        passive_fibres_cached_product(rows.pf_vert, pf, project, h * h, u, y)
    if on[T_RESTING_TENSION]:  # positive semi-definite per triangle: the same projected or not
        resting_tension_product(rows.rt_vert, rows.rt_par, h * h, u, y)
    if planes is not None:  # positive semi-definite: the same projected or not
        plane_product(planes, h * h, u, y)


@kernel
def _trial(m, pos, vel, h, dv, w):
    """w.v_try = vel + dv, w.x_try = pos + h w.v_try on the free points; pos, vel on the others.
    # Model: m.vert_free (nvert,) uint8   # Data in: pos (nvert, 3) m, vel (nvert, 3) m/s, h (s), dv (nvert, 3) m/s
    # Data out: w.x_try (nvert, 3) m, w.v_try (nvert, 3) m/s
    """
    xt, vt = w.x_try, w.v_try
    free = m.vert_free
    for i in range(pos.shape[0]):
        for a in range(3):
            if free[i]:
                vt[i, a] = vel[i, a] + dv[i, a]
                xt[i, a] = pos[i, a] + h * vt[i, a]
            else:
                vt[i, a] = vel[i, a]
                xt[i, a] = pos[i, a]


@kernel
def _residual(m, sched_val, pos, vel, h, w):
    """At dv: x_try, v_try, f = f_i(x_try, v_try), res = f + f_expl - M dv / h (0 on fixed
    points). Returns (|res|, |f| + |f_expl| + |M dv / h|, the vertex of the largest residual).
    # Model: m (vert_free, vert_mass kg, term_on, kv_on, damp_coef kg/s), w.rows (the triangles of f_i), w.planes
    # Data in: sched_val (the inputs at t), pos (nvert, 3) m, vel (nvert, 3) m/s, h (s), w.dv m/s, w.f_expl N
    # Data out: w.x_try m, w.v_try m/s (`_trial`), w.f, w.res (nvert, 3) N; returns (N, N, a vertex)
    """
    dv, xt, vt, res = w.dv, w.x_try, w.v_try, w.res
    free = m.vert_free
    _trial(m, pos, vel, h, dv, w)
    implicit_forces(m, w.rows, sched_val, xt, vt, w.f, w, w.planes)
    rr = ff = ee = mm = 0.0
    worst, big = 0, -1.0
    for i in range(pos.shape[0]):
        if not free[i]:
            res[i, 0] = res[i, 1] = res[i, 2] = 0.0
            continue
        s = m.vert_mass[i] / h
        ri = 0.0
        for a in range(3):
            f, e, md = w.f[i, a], w.f_expl[i, a], s * dv[i, a]
            r = f + e - md
            res[i, a] = r
            ri += r * r
            ff += f * f
            ee += e * e
            mm += md * md
        rr += ri
        if ri > big:
            big, worst = ri, i
    return math.sqrt(rr), math.sqrt(ff) + math.sqrt(ee) + math.sqrt(mm), worst


@kernel
def _merit(m, sched_val, h, dv, w):
    """The incremental potential at dv (w.x_try, w.v_try taken there: `_trial`), whose
    dv-gradient is minus h res: 1/2 dv M dv - h f_e . dv + E(x_try) + h/2 sum c |v_try|^2
    + h R(x_kv, v_try), E the membrane's, fibres', resting tension's and sliding planes' energies, R the viscosity's
    dissipation function at the positions x_kv where the Newton iteration started (the
    gradient there exact).
    # Model: m (vert_free, vert_mass kg, damp_coef kg/s, term_on, kv_on), w.rows, w.planes
    # Data in: sched_val (the inputs at t), h (s), dv (nvert, 3) m/s, w.f_expl N, w.x_try m, w.v_try m/s, w.x_kv m
    # Data out: returns J
    """
    on = m.term_on
    total = 0.0
    for i in range(dv.shape[0]):
        if m.vert_free[i]:
            for a in range(3):
                total += dv[i, a] * (0.5 * m.vert_mass[i] * dv[i, a] - h * w.f_expl[i, a])
        if on[T_DAMPING]:
            total += 0.5 * h * m.damp_coef[i] * (w.v_try[i, 0] ** 2 + w.v_try[i, 1] ** 2 + w.v_try[i, 2] ** 2)
    # the triangles with a free corner (`NewtonRows`): the others' terms do not change in the solve
    tri = w.rows
    if on[T_MEMBRANE]:
        total += membrane_energy(tri.mem_vert, tri.mem_par, w.x_try)
        if m.kv_on:
            total += h * kelvin_voigt_dissipation(tri.mem_vert, tri.mem_par, w.x_kv, w.v_try)
    if on[T_MUSCLE_FIBRES]:
        total += fibre_energy(tri.fib_vert, tri.fib_par, tri.fib_sched, sched_val, w.x_try)
    if on[T_PASSIVE_FIBRES]:
        total += passive_fibres_energy_kernel(tri.pf_vert, tri.pf_par, w.x_try)
    if on[T_RESTING_TENSION]:
        total += resting_tension_energy(tri.rt_vert, tri.rt_par, w.x_try)
    if on[T_LUNGS]:
        total += lung_potential(
            m.lung_face,
            m.lung_par,
            m.lung_sched[0],
            sched_val,
            h,
            w.x_try,
            w.v_try,
            w.lung_wall_pos,
            w.lung_wall_vel,
            w.info,
        )
    if w.planes.vert.shape[0]:
        total += plane_energy(w.planes, w.x_try)
    return total


@kernel
def _volume_gradient(face_vert, pos, grad):
    """grad = grad V at pos (m^2), face by face: whole at the points all of whose faces
    face_vert lists (`NewtonRows.face_vert`: at the free points).
    # Model: face_vert (nface, 3) int32   # Data in: pos (nvert, 3) m   # Data out: grad (nvert, 3) m^2
    """
    for i in range(grad.shape[0]):
        grad[i, 0] = grad[i, 1] = grad[i, 2] = 0.0
    sixth = 1.0 / 6.0
    for k in range(face_vert.shape[0]):
        a, b, c = face_vert[k, 0], face_vert[k, 1], face_vert[k, 2]
        for i, j, l in ((a, b, c), (b, c, a), (c, a, b)):
            grad[i, 0] += sixth * (pos[j, 1] * pos[l, 2] - pos[j, 2] * pos[l, 1])
            grad[i, 1] += sixth * (pos[j, 2] * pos[l, 0] - pos[j, 0] * pos[l, 2])
            grad[i, 2] += sixth * (pos[j, 0] * pos[l, 1] - pos[j, 1] * pos[l, 0])


@kernel
def implicit_step(m, s, sched_val, step, imp, vert_acc):
    """Step phase 2 for implicit Euler: the free points' new velocities and positions,
    with the divergence check's sums per chunk of points into vert_acc (as
    `hybrid.step._integrate`). Returns 0 (done) or `IMPLICIT_NOT_CONVERGED` (status
    set, state unchanged). Called by `hybrid.step.integrate` at its address.
    # Model: m   # Data in: imp.f_expl (the explicit forces at the step's start), sched_val (the inputs at t)
    # Data in/out: s.vert_pos, s.vert_vel, imp   # Data out: vert_acc (chunk_count(nvert), 4), s.status on failure
    """
    h = m.dt
    pos, vel = s.vert_pos, s.vert_vel
    n = pos.shape[0]
    w = imp
    info = w.info
    flow_by_volume(m, s.lung, info, s.lung[L_VOLUME])  # the airway's flow: this step's volume change
    free = m.vert_free
    # the explicit part: the force pass's other terms (w.f_expl, `implicit_start_forces`, taken
    # before the linked points moved to their new sites; not the whole force less w.f, whose
    # rounding would set a floor under the residual), plus the carried pressure
    carried = info[I_PRESSURE] if m.term_on[T_VOLUME] else 0.0
    if carried != 0.0:
        _volume_gradient(w.rows.face_vert, pos, w.grad)
    for i in range(n):
        for a in range(3):
            if carried != 0.0:
                w.f_expl[i, a] += carried * w.grad[i, a]
            if not free[i]:
                w.dv[i, a] = 0.0
    info[I_CARRIED] = carried
    # the occluded airway's constraint pressure carried as the abdomen's: its last projection's,
    # on the cavity (`hybrid.terms.lungs`, L_HOLD). Without it the solve pulled the dome away
    # each step and the projection pushed it back: the held trunk settled where the hold was
    # too small by 1 + h^2 k/m (Pdi 29% low at 5 ms on `breathing_lungs`, level 0)
    if m.term_on[T_LUNGS] and s.lung[L_OCCLUDED] != 0.0 and s.lung[L_HOLD] != 0.0:
        ref = m.lung_par[P_REF:]
        add_cavity_pressure(m.lung_face, ref, s.lung[L_HOLD], pos, w.lung_wall_pos, w.f_expl, w.lung_wall_f, TO_POINTS)
    tol = m.implicit_tol
    rows_of = w.mat.free  # the free point of each row of the Newton matrix
    cg_max = max(CG_MIN_ITER, 9 * rows_of.shape[0])
    rn, scale, worst = _residual(m, sched_val, pos, vel, h, w)
    # the time-averaged force scale: the run's mean step-start scale, this step's included
    scale_start = scale
    scale_mean = (info[I_FORCE_SUM] + scale) / (info[I_SOLVED] + 1.0)
    it = 0
    cg_total = 0
    at_roundoff = False
    x_max = 0.0
    for i in range(n):
        for a in range(3):
            x_max = max(x_max, abs(pos[i, a]))
    ulp_x = ULPS * EPS * x_max
    while not (rn <= tol * max(scale, scale_mean)) and it < m.implicit_max_iter and rn < np.inf:
        for i in range(n):
            for a in range(3):
                w.x_kv[i, a] = w.x_try[i, a]
        newton_caches(m, w.rows, sched_val, w.x_try, w.face, w.fib, w.pf)
        assemble(m, w.rows, w.face, w.fib, w.pf, h, w.mat, w.planes, EXACT)
        # the exact Hessian; where it has negative curvature, the Hessian projected per element
        gather(rows_of, h, w.res, w.cg_r)
        # solve just accurately enough: FORCING of what convergence asks, at most FORCING of the residual
        eta = min(FORCING, FORCING * tol * max(scale, scale_mean) / rn)
        target = eta * h * rn
        # the lungs' rank-one stiffness in the product (`hybrid.implicit_lungs`)
        # (c = 0 without lungs: one build of the solves serves every scene, the term skipped at run time)
        c_lung = 0.0
        if m.term_on[T_LUNGS] != 0:
            c_lung = lung_rank_one(
                m.lung_face,
                m.lung_par,
                h,
                w.x_try,
                w.v_try,
                w.lung_wall_pos,
                w.lung_wall_vel,
                w.lung_wall_f,
                w.info,
                w.mat,
                (w.lung_g, w.lung_gf, w.lung_gh),
            )
        k = split_cg(w, target, cg_max, c_lung, w.lung_gf, w.lung_gh)
        if k < 0:  # negative curvature: solved again with the Hessian projected element by element
            cg_total += -1 - k
            assemble(m, w.rows, w.face, w.fib, w.pf, h, w.mat, w.planes, PROJECTED)
            if c_lung != 0.0:  # the rank-one term's C^-1 g, of the new matrix's sweep
                half_sweep(w.mat, w.lung_gf, w.lung_gh)
            gather(rows_of, h, w.res, w.cg_r)
            k = split_cg(w, target, cg_max, c_lung, w.lung_gf, w.lung_gh)
            info[I_PROJECTED_TOTAL] += 1
            if k < 0:  # rounding: the projected matrix has none
                k = -1 - k
        cg_total += k
        it += 1
        # a correction below the positions' rounding (ULPS units in the last place of the
        # body's largest coordinate) cannot move the state: the solve is at its round-off
        # floor (a body at rest whose forces are themselves round-off, as at a run's start)
        dx_max = 0.0
        slope = 0.0  # the potential's derivative along the step (< 0)
        for f in range(rows_of.shape[0]):
            i = rows_of[f]
            for a in range(3):
                dx_max = max(dx_max, abs(h * w.cg_x[f, a]))
                slope -= h * w.res[i, a] * w.cg_x[f, a]
        if dx_max <= ulp_x:
            at_roundoff = True
            break
        dv_start = w.dv_start  # the iteration's start
        for i in range(n):
            for a in range(3):
                dv_start[i, a] = w.dv[i, a]
        scatter_add(rows_of, 1.0, w.cg_x, w.dv)
        frac = 1.0  # of the step now applied
        phi = np.nan  # the potential at the start: taken only when a residual does not halve
        for k in range(HALVINGS + 1):
            rn_new, scale, worst = _residual(m, sched_val, pos, vel, h, w)
            # a residual that halved (near the root the potential's change is round-off),
            # else Armijo on the potential
            if rn_new <= 0.5 * rn or k == HALVINGS:
                break
            if phi != phi:
                _trial(m, pos, vel, h, dv_start, w)
                phi = _merit(m, sched_val, h, dv_start, w)
                _trial(m, pos, vel, h, w.dv, w)
            if _merit(m, sched_val, h, w.dv, w) <= phi + ARMIJO * frac * slope:
                break
            frac *= 0.5
            scatter_add(rows_of, -frac, w.cg_x, w.dv)
        # a residual that no longer falls under corrections of a few hundred units in the last
        # place of the positions: its floor is the positions' rounding times the stiffness
        # (about 3e-13 N on the breathing scene at rest at level 6), where no correction helps
        if rn_new > 0.5 * rn and frac * dx_max <= STALL_ULPS * EPS * x_max:
            rn = rn_new
            at_roundoff = True
            break
        rn = rn_new
    flow_by_rate(info)
    info[I_NEWTON] = it
    ref = max(scale, scale_mean)
    info[I_RESIDUAL] = rn / ref if ref > 0.0 else 0.0
    info[I_CG] = cg_total
    info[I_NEWTON_TOTAL] += it
    info[I_CG_TOTAL] += cg_total
    info[I_WORST] = worst
    if not (rn <= tol * ref or at_roundoff):
        for i in range(n):  # no warm start from a failed solve
            for a in range(3):
                w.dv[i, a] = 0.0
        s.status[0] = IMPLICIT_NOT_CONVERGED
        s.status[1] = step
        s.status[2] = worst
        return IMPLICIT_NOT_CONVERGED
    info[I_FORCE] = scale_start
    info[I_FORCE_SUM] += scale_start
    info[I_SOLVED] += 1.0
    acc = vert_acc
    for c in range(acc.shape[0]):
        dsum = ke = dmax = 0.0
        far = 0
        for i in range(c * CHUNK_VERTS, min((c + 1) * CHUNK_VERTS, n)):
            if not free[i]:
                continue
            d2 = 0.0
            for a in range(3):
                dx = w.x_try[i, a] - pos[i, a]
                pos[i, a] = w.x_try[i, a]
                vel[i, a] = w.v_try[i, a]
                d2 += dx * dx
            dsum += d2
            ke += m.vert_mass[i] * (vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2)
            if d2 > dmax:
                dmax = d2
                far = i
        acc[c, 0] = dsum
        acc[c, 1] = ke
        acc[c, 2] = dmax
        acc[c, 3] = far
    return 0


@kernel
def implicit_pressure(m, info, projected):
    """The step's pressure (Pa) from the volume projection's `projected` = phi / h^2:
    itself for the other integrators; for implicit Euler plus the pressure its solve
    carried (kept as the next step's).
    # Model: m.integrator   # Data in: projected (Pa), info[CARRIED] (Pa): `ImplicitWork.info`
    # Data out: info[PRESSURE] (Pa) for implicit Euler; returns Pa
    """
    if m.integrator != IMPLICIT_EULER_ID:
        return projected
    p = info[I_CARRIED] + projected
    info[I_PRESSURE] = p
    return p
