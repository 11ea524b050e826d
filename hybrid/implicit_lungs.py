"""The lungs in implicit Euler's Newton solve (`hybrid.implicit`): their pleural load on the
dome among the forces the solve treats implicitly, their energy and the airway's dissipation
in the line search's potential (the airway's flow in the solve the volume's change over the
step, `_flow`: the force is then the potential's gradient), and their stiffness c g g^T
(c = h^2 dP_L/dV + h dR/dQ, g the cavity's volume gradient on the free points) in the Newton
matrix.

The stiffness is rank one, which the sparse matrix cannot hold; staggered a step behind, an
enclosed compartment is the unstable case of partitioned coupling. It joins the conjugate
gradients' product instead (`hybrid.implicit_matrix.split_cg`): a rank-one change of the
matrix adds at most one iteration in exact arithmetic. The first version applied it by
Sherman-Morrison with A^-1 g from a second solve each Newton iteration: on the breathing
scene at level 8 (implicit Euler at 30 ms, 200 steps) that solve took 18.5 iterations
against the first's 8 (g is smooth over the whole dome, the slowest kind of vector for a
Gauss-Seidel preconditioner) and 7.2 of the run's 13.4 s.
"""

from __future__ import annotations

import numpy as np

from .implicit_matrix import gather, half_sweep
from .implicit_work import I_LUNG_FLOW_BY_VOLUME, I_LUNG_FLOW_FROM
from .kernel import kernel
from .switches import T_LUNGS
from .terms.lung_cavity import add_cavity_pressure, cavity_volume_rate
from .terms.lungs import CMH2O_PA, L_OCCLUDED, P_K1, P_K2, P_REF, lung_load, lung_recoil

__all__ = ["add_lung_forces", "flow_by_rate", "flow_by_volume", "lung_potential", "lung_rank_one"]

#: `add_cavity_pressure`'s `to_points`, a numpy boolean: a constant True is a literal type, a build
#: of its own beside the step's (which passes a boolean it computes)
TO_POINTS = np.bool_(True)


@kernel(inline="always")
def flow_by_volume(m, lung, info, from_volume):
    """From here until `flow_by_rate`, the airway's flow in the kernels below is a volume change
    over a step from `from_volume` (m^3), if the scene has lungs and its airway is open: in the
    Newton solve this step's, from the step's start volume (the force is then the gradient of the
    line search's potential: the rate g . v at the trial puts h^2 K1 Q H v more in it, H the
    volume's Hessian, which stalled the line search at high airway resistance, 20 cmH2O s/L at 20
    ms, `hybrid study extremes`); at the step's start the last step's, the flow the ribs' load takes
    (`hybrid.terms.lungs.lungs_step_force`).
    # Model: m.term_on   # Data in: lung (`LungSlot`: OCCLUDED), from_volume m^3   # Data out: info
    """
    if m.term_on[T_LUNGS] != 0 and lung[L_OCCLUDED] == 0.0:
        info[I_LUNG_FLOW_FROM] = from_volume
        info[I_LUNG_FLOW_BY_VOLUME] = 1.0


@kernel(inline="always")
def flow_by_rate(info):
    """The airway's flow in the kernels below the rate g . v again (`flow_by_volume`).
    # Model: none   # Data in: none   # Data out: info
    """
    info[I_LUNG_FLOW_BY_VOLUME] = 0.0


@kernel(inline="always")
def _flow(info, vol, rate, h):
    """The airway's flow (m^3/s) at the cavity's volume vol: (vol - from) / h while
    `flow_by_volume` holds, else the rate g . v given.
    # Model: none   # Data in: info (LUNG_FLOW_BY_VOLUME, LUNG_FLOW_FROM), vol m^3, rate m^3/s, h s
    # Data out: returns m^3/s
    """
    if info[I_LUNG_FLOW_BY_VOLUME] != 0.0:
        return (vol - info[I_LUNG_FLOW_FROM]) / h
    return rate


# The kernels below take the arrays they read, not the model's and the solve's tuples: numba makes
# each field of an argument's tuple an argument of the compiled function, and compiles a kernel
# again for each tuple type it is given (the start's and the Newton iteration's work differ)


@kernel
def add_lung_forces(face, par, pao_row, dt, sched_val, x, v, out, wall_pos, wall_vel, wall_f, info):
    """out += the pleural load on the dome's free points at (x, v): (P_pl + P_L0) grad_i V
    (`hybrid.terms.lungs`), the wall held where the rigid phase put it.
    # Model: face (m.lung_face), par (m.lung_par), pao_row (m.lung_sched[0]), dt (s)
    # Data in: sched_val, x (m), v (m/s), wall_pos (m), wall_vel (m/s), info (`_flow`)
    # Data in/out: out (N)   # Scratch: wall_f
    """
    ref = par[P_REF:]
    vol, rate = cavity_volume_rate(face, ref, x, v, wall_pos, wall_vel)
    _, load = lung_load(par, sched_val[pao_row, 0] * CMH2O_PA, vol, _flow(info, vol, rate, dt))
    add_cavity_pressure(face, ref, load, x, wall_pos, out, wall_f, TO_POINTS)


@kernel
def lung_potential(face, par, pao_row, sched_val, h, x, v, wall_pos, wall_vel, info):
    """The lungs' part of the incremental potential at the trial x, v (J): E (V - V0)^2 / 2
    (the recoil's energy) - P_ao V, and h times the airway's dissipation K1 Q^2 / 2 + K2 |Q|^3 / 3.
    # Model: face, par, pao_row (as `add_lung_forces`)   # Data in: sched_val, h (s), x (m), v (m/s),
    #        wall_pos, wall_vel, info   # Data out: returns J
    """
    vol, rate = cavity_volume_rate(face, par[P_REF:], x, v, wall_pos, wall_vel)
    rate = _flow(info, vol, rate, h)
    pao = sched_val[pao_row, 0] * CMH2O_PA
    total = lung_recoil(par, vol)[2] - pao * vol
    return total + h * (0.5 * par[P_K1] * rate * rate + par[P_K2] * abs(rate) ** 3 / 3.0)


@kernel
def lung_rank_one(face, par, h, x, v, wall_pos, wall_vel, wall_f, info, mat, rank_one):
    """The lungs' stiffness c g g^T at the Newton iteration's start (the trial x, v): returns
    c = h^2 dP_L/dV + h dR/dQ (kg/m^4; R(Q) Q the airway's pressure drop); with rank_one = (g, gf,
    gh) (the solve's lung_g, lung_gf, lung_gh): gf = g on the free points (the matrix's numbering)
    and gh = C^-1 g (`half_sweep`, of the matrix `assemble` left in mat), what `split_cg` adds to
    its product.
    # Model: face, par (as `add_lung_forces`), mat (pattern, free)   # Data in: x (m), v (m/s),
    #        wall_pos, wall_vel, mat (assembled), info
    # Data out: gf (nfree, 3) m^2, gh (nfree, 3); returns kg/m^4
    # Scratch: g (nvert, 3), wall_f, mat.acc
    """
    ref = par[P_REF:]
    vol, rate = cavity_volume_rate(face, ref, x, v, wall_pos, wall_vel)
    rate = _flow(info, vol, rate, h)
    c = h * h * lung_recoil(par, vol)[1] + h * (par[P_K1] + 2.0 * par[P_K2] * abs(rate))
    g, gf, gh = rank_one
    for i in range(g.shape[0]):
        g[i, 0] = g[i, 1] = g[i, 2] = 0.0
    add_cavity_pressure(face, ref, 1.0, x, wall_pos, g, wall_f, TO_POINTS)
    gather(mat.free, 1.0, g, gf)
    half_sweep(mat, gf, gh)
    return c
