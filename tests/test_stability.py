"""The paper's stability analysis (6.1, Table 1) against OUR compiled step.

The three-point system: one free point P between fixed neighbours, an
elastic force and viscous damping kv (N s/m), one explicit Euler step (the
paper's eq. 4). We build it as a tiny scene, run `Simulation.step(1)` from
chosen states of P and take the Jacobian of (x, v) -> (x', v') by central
differences; its eigenvalues must equal `table1_eigenvalues` to 1e-12.

The paper's system is planar (a 4x4 Jacobian); ours is 3D (6x6):

- mass-spring: P at the origin between nailed N1 = (-L, 0, 0) and
  N2 = (+L, 0, 0), springs of stiffness k_ms = 2k/3 at rest length. Along the
  axis the two springs add up to 4k/3: the pair with 16/3 m h^2 k. Across
  it the springs are at rest length, so the force is of third order in the
  offset: stiffness 0, eigenvalues {1, 1 - h kv/m} for each of the two
  transverse directions. Table 1 lists them once (one transverse direction
  in the plane); we expect them twice.
- shape memory: with only two neighbours the ring frame is degenerate in 3D
  (its normal is undefined), so P is the apex of an icosahedron whose whole
  ring of 5 neighbours is nailed. The ideal position is then fixed and the
  force k (P_ideal - P) exactly affine: the pair with 4 m h^2 k, once per
  direction (Table 1 lists it for the plane's two).

Eigenvalues are compared as multisets (optimal matching). They are simple
and well conditioned for the parameters below (no defective double root),
so an error of ~eps in the Jacobian gives ~eps in the eigenvalues.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import hanging_sphere
from scipy.optimize import linear_sum_assignment

from hybrid.mesh import Mesh, icosahedron
from hybrid.model import compile_scene
from hybrid.regions import All, Difference, Indices
from hybrid.scene import Damping, Masses, MassSpring, Nailed, Scene, ShapeMemory
from hybrid.simulation import Simulation
from hybrid.stability import max_stable_dt, step_matrix, table1_eigenvalues

# (h s, k N/m, kv N s/m, m kg): underdamped and overdamped, stable and unstable
CASES = [
    (1e-3, 3000.0, 2.0, 0.05),  # complex pair, the trunk's shape memory at its usual step
    (4e-3, 100.0, 20.0, 0.05),  # real pair (strong damping)
    (2e-2, 50.0, 1.0, 0.2),  # complex pair, large step
    (1e-3, 1e4, 0.5, 0.01),  # |lambda| > 1: an unstable step, same formulas
]


def multiset_error(got, want) -> float:
    """Largest |got_i - want_pi(i)| over the best one-to-one matching pi."""
    got, want = np.asarray(got, complex), np.asarray(want, complex)
    assert got.shape == want.shape
    cost = np.abs(got[:, None] - want[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())


def step_jacobian(sim: Simulation, vert: int, x0, v0, dx: float, dv: float) -> np.ndarray:
    """(6, 6) Jacobian of one step of `sim` w.r.t. (x, v) of `vert`, by central differences."""
    jac = np.zeros((6, 6))
    for col in range(6):
        out = []
        for sign in (1.0, -1.0):
            sim.reset()
            x, v = np.array(x0, float), np.array(v0, float)
            if col < 3:
                x[col] += sign * dx
            else:
                v[col - 3] += sign * dv
            sim.state.vert_pos[vert] = x
            sim.state.vert_vel[vert] = v
            sim.step(1)
            out.append(np.concatenate([sim.vert_pos[vert], sim.vert_vel[vert]]))
        jac[:, col] = (out[0] - out[1]) / (2.0 * (dx if col < 3 else dv))
    return jac


@pytest.mark.parametrize("h,k,kv,m", CASES)
def test_table1_mass_spring(h, k, kv, m):
    # L and the position step are powers of two: L - dx and L + dx are exact,
    # and sqrt((L -+ dx)^2) returns |L -+ dx| exactly, so the axial spring force
    # k (len - L) is computed to ~eps relative. Across the axis dx / L = 2^-26
    # makes L^2 + dx^2 round to L^2: the spring length stays exactly L and the
    # third-order transverse force (~k dx^3 / L^2) vanishes exactly. (A step
    # like 1e-7 with L = 0.05 errs by ~1e-11: the length's roundoff eps L is
    # then 1e-10 of the step, and the cubic term adds (dx / L)^2 ~ 4e-12.)
    L = 2.0**-4  # m
    pos = np.array([[0, 0, 0], [-L, 0, 0], [L, 0, 0], [0, L, 0], [0, -L, 0]], float)
    face = np.array([[0, 2, 3], [0, 3, 1], [0, 1, 4], [0, 4, 2]])  # P's closed fan N2, A, N1, B
    mesh = Mesh.from_arrays(pos, face, name="three_points")
    scene = Scene(
        formulation="paper",
        mesh=mesh,
        masses=Masses(per_vertex_kg=(m,) * 5),
        # springs are the mesh edges with both ends in the region: P-N1, P-N2 (and N1-N2? not an edge)
        regions={"springs": Indices((0, 1, 2)), "fixed": Indices((1, 2, 3, 4))},
        forces=(MassSpring(2.0 * k / 3.0, region="springs"), Damping(coef_n_s_per_m=kv)),
        constraints=(Nailed("fixed"),),
        dt_s=h,
        integrator="explicit_euler",
    )
    model = compile_scene(scene)
    springs = {tuple(sorted(e)) for e in model.arrays.spring_vert.tolist()}
    assert {(0, 1), (0, 2)} <= springs and not any(0 in e and e not in {(0, 1), (0, 2)} for e in springs)
    sim = Simulation(model)
    jac = step_jacobian(sim, 0, np.zeros(3), np.zeros(3), dx=L * 2.0**-26, dv=2.0**-10)
    got = np.linalg.eigvals(jac)
    table = table1_eigenvalues("mass_spring", h, k, kv, m)
    want = np.concatenate([table, [1.0, 1.0 - h * kv / m]])  # the second transverse direction
    assert multiset_error(got, want) <= 1e-12
    # and the structure: the transverse blocks are exactly those of a free damped point
    assert jac[4, 1] == 0.0 and jac[5, 2] == 0.0


@pytest.mark.parametrize("h,k,kv,m", CASES)
def test_table1_shape_memory(h, k, kv, m):
    base = icosahedron(0.1)
    mesh = icosahedron(0.1, center=tuple(-base.vert_pos[0]))  # the free apex P at the origin
    scene = Scene(
        formulation="paper",
        mesh=mesh,
        masses=Masses(per_vertex_kg=(m,) * 12),
        regions={"P": Indices((0,)), "others": Difference(All(), Indices((0,)))},
        forces=(ShapeMemory(k, region="P"), Damping(coef_n_s_per_m=kv)),
        constraints=(Nailed("others"),),
        dt_s=h,
        integrator="explicit_euler",
    )
    sim = Simulation(compile_scene(scene))
    # the map is affine, so central differences are exact up to roundoff for any step
    jac = step_jacobian(sim, 0, mesh.vert_pos[0], np.zeros(3), dx=1e-4, dv=1e-3)
    got = np.linalg.eigvals(jac)
    table = table1_eigenvalues("shape_memory", h, k, kv, m)  # the pair, twice
    want = np.concatenate([table, table[:2]])  # and once more for the third direction
    assert multiset_error(got, want) <= 1e-12
    # the closed forms themselves: roots of l^2 - (2 - h kv/m) l + (1 - h kv/m + h^2 k/m)
    pair = table[:2]
    assert abs(pair.sum() - (2 - h * kv / m)) <= 1e-14
    assert abs(pair.prod() - (1 - h * kv / m + h * h * k / m)) <= 1e-13


# ---------------------------------------------------------------------------
# The largest stable step, closed forms (per point: mass m, stiffness k, damping c)
# ---------------------------------------------------------------------------


def h_max_explicit(m, k, c) -> float:
    """Explicit Euler, step matrix [[1, h], [-h k/m, 1 - h c/m]]: det = 1 - hc/m + h^2 k/m,
    tr = 2 - hc/m. Jury: |det| < 1 and |tr| < 1 + det. det < 1 <=> h < c/k.
    |tr| < 1 + det fails first where (k/m) h^2 - (2c/m) h + 4 = 0, which has real
    roots only if c^2 >= 4 m k; its smaller root 4m / (c + sqrt(c^2 - 4mk)) is
    below c/k. So h_max = c/k if c^2 < 4mk, else 4m / (c + sqrt(c^2 - 4mk))
    (-> the paper's 2m/kv as k -> 0); 0 without damping."""
    if c == 0.0:
        return 0.0
    if k == 0.0:
        return 2.0 * m / c
    if c * c < 4.0 * m * k:
        return c / k
    return 4.0 * m / (c + math.sqrt(c * c - 4.0 * m * k))


def h_max_symplectic(m, k, c) -> float:
    """Symplectic Euler: det = 1 - hc/m, tr = 2 - hc/m - h^2 k/m. Jury gives
    h < 2m/c and (k/m) h^2 + (2c/m) h < 4, whose root 4m / (c + sqrt(c^2 + 4mk))
    is the smaller: h_max = 4m / (c + sqrt(c^2 + 4mk)), i.e. 2/omega undamped
    and 2m/c without stiffness."""
    return 4.0 * m / (c + math.sqrt(c * c + 4.0 * m * k))


STEP_CASES = [  # (m kg, k N/m, c N s/m)
    (0.05, 3000.0, 0.0),  # undamped
    (0.05, 3000.0, 0.3 * 2 * math.sqrt(3000.0 * 0.05)),  # 0.3 of critical (the trunk's setting)
    (0.05, 3000.0, 1.5 * 2 * math.sqrt(3000.0 * 0.05)),  # overdamped
    (3.9e-4, 3000.0, 0.65),  # an icosphere(5) point
    (0.2, 50.0, 1.0),
    (0.05, 0.0, 2.0),  # damping only: the paper's 2m/kv
    (1.0, 1e-3, 5.0),  # nearly no stiffness
]


@pytest.mark.parametrize("m,k,c", STEP_CASES)
def test_max_stable_dt_matches_the_closed_forms(m, k, c):
    # Bisection on the spectral radius resolves the boundary to where rho - 1
    # is lost in roundoff: a relative error ~ eps / (h |d rho / dh|), below
    # 1e-12 for these cases; 1e-9 leaves margin.
    ex = float(max_stable_dt(m, k, c, "explicit_euler"))
    sy = float(max_stable_dt(m, k, c, "symplectic_euler"))
    want_ex, want_sy = h_max_explicit(m, k, c), h_max_symplectic(m, k, c)
    if want_ex == 0.0:
        assert ex == 0.0
    else:
        assert ex == pytest.approx(want_ex, rel=1e-9)
    assert sy == pytest.approx(want_sy, rel=1e-9)
    if c == 0.0:
        assert sy == pytest.approx(2.0 / math.sqrt(k / m), rel=1e-9)  # h < 2 / omega
    if k == 0.0:
        assert ex == pytest.approx(2.0 * m / c, rel=1e-9) and sy == pytest.approx(2.0 * m / c, rel=1e-9)
    # the bound separates bounded from growing powers of the step matrix
    for integ, hmax in (("explicit_euler", want_ex), ("symplectic_euler", want_sy)):
        if hmax == 0.0:
            continue
        for factor, grows in ((0.98, False), (1.02, True)):
            mat = step_matrix(factor * hmax, k, c, m, integ)
            rho = np.abs(np.linalg.eigvals(mat)).max()
            assert (rho > 1.0 + 1e-9) == grows, (integ, factor, rho)


def test_table2_bounds_from_table1():
    """Table 2's shape-memory row follows from Table 1: with little stiffness the
    largest stable explicit step tends to 2m/kv; at the bound |lambda| = 1."""
    m, kv = 0.05, 2.0
    h = h_max_explicit(m, 1e-6, kv)
    assert h == pytest.approx(2 * m / kv, rel=1e-6)
    lam = table1_eigenvalues("shape_memory", h, 1e-6, kv, m)
    assert np.abs(lam).max() == pytest.approx(1.0, abs=1e-6)


# ---------------------------------------------------------------------------
# The volume projection adds a mode of its own
# ---------------------------------------------------------------------------


def _damped_incompressible_sphere(integrator, dt, m=0.05, c=50.0, gravity=False):
    """The hanging sphere, or (gravity=False) the same sphere with damping alone."""
    scene = hanging_sphere(dt, integrator, kv=c, m=m)
    return scene if gravity else scene.without("gravity", "shape_memory")


@pytest.mark.parametrize("integrator", ["explicit_euler", "symplectic_euler"])
def test_velocity_along_the_volume_gradient_after_one_projected_step(integrator):
    """Start at rest shape with v = a D (D_i = grad_i V / m_i, the projection's
    direction) and damping c only. The free step moves X by h v along D, the
    projection takes it back (phi = -a h to first order) and adds phi D / h = -v
    to the velocity. Explicit Euler: v' = (1 - hc/m) v - v = -(hc/m) v, an
    eigenvalue -hc/m, stable only for h < m/c (the paper's mass-spring bound
    m/kv, here from the constraint). Symplectic Euler: x moves with the damped
    velocity, which the correction removes whole: v' = 0. Both to first order
    in the step: the gradient turns by ~h |v| / edge between X and X*, a
    relative error ~1e-5 at |v| = 1 mm/s (measured), ~1e-7 at the 10 um/s used
    here; the roundoff of phi (V - V0 ~ 1e-7 V0) adds ~eps / 1e-7 ~ 2e-9."""
    m, c, h = 0.05, 20.0, 1e-3
    model = compile_scene(_damped_incompressible_sphere(integrator, h, m, c))
    free = model.arrays.vert_free > 0
    d = model.mesh.volume_gradient() / m
    d[~free] = 0.0
    a = 1e-5 / np.abs(d).max()  # |v| <= 10 um/s
    sim = Simulation(model)
    sim.state.vert_vel[:] = a * d
    sim.step(1)
    want = -(h * c / m) * a * d if integrator == "explicit_euler" else np.zeros_like(d)
    assert np.abs(sim.vert_vel - want).max() <= 1e-6 * a * np.abs(d).max()


def test_explicit_euler_with_volume_is_stable_below_m_over_c_only():
    """The model's stable step for explicit Euler with the volume constraint
    includes the bound h < m/c of the projection's mode (here 1e-3 s, below the
    per-point bound 2.1e-3 s); just above it the run turns into bounded chaos
    (velocities of tens of m/s); just below it hangs quietly."""
    m, c = 0.05, 50.0
    model = compile_scene(_damped_incompressible_sphere("explicit_euler", 1e-3, m, c, gravity=True))
    assert model.dt_stable_s <= m / c * (1 + 1e-12)
    assert (
        compile_scene(
            _damped_incompressible_sphere("explicit_euler", 1e-3, m, c, gravity=True).without("volume")
        ).dt_stable_s
        > 2 * m / c
    )  # the per-point bound alone
    speeds = {}
    for factor in (0.95, 1.05):
        sim = Simulation(model.with_dt(factor * m / c))
        try:
            sim.step(2000)
            speeds[factor] = np.abs(sim.vert_vel).max()
        except Exception:  # SimulationDiverged: also a failure to stay stable
            speeds[factor] = np.inf
    assert speeds[0.95] < 0.05  # m/s (the resting velocity -phi D / h, ~7e-3)
    assert speeds[1.05] > 1.0
