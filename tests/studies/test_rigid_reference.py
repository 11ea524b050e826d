"""The paper's rigid-body algorithm (hybrid.studies.rigid_reference): first order against
MuJoCo's RK4, and momentum conserved without force."""

from __future__ import annotations

import numpy as np
import pytest

from hybrid.studies import rigid_reference as ref


def test_paper_rigid_algorithm_converges_at_first_order_to_mujoco():
    body = ref.RigidBody(1.0, [0.01, 0.02, 0.03])
    state0 = ref.RigidState(vel=np.array([0.1, 0.0, 0.05]), omega=np.array([1.0, 2.0, 3.0]))
    point, force, duration = np.array([0.1, 0.05, 0.0]), np.array([0.0, 2.0, 1.0]), 1.0
    exact = ref.run_mujoco(body, state0, point, force, 1e-4, duration, integrator="RK4")
    check = ref.run_mujoco(body, state0, point, force, 2e-4, duration, integrator="RK4")
    assert max(ref.state_error(exact, check).values()) < 1e-10  # RK4 reference converged
    errors = [
        ref.state_error(ref.run_paper(body, state0, point, force, h, duration), exact) for h in (4e-3, 2e-3, 1e-3, 5e-4)
    ]
    for key in ("pos", "angle", "vel", "omega"):
        e = np.array([err[key] for err in errors])
        order = np.log2(e[:-1] / e[1:])
        assert np.all((order > 0.8) & (order < 1.2)), (key, e, order)


def test_paper_step_conserves_momentum_without_force():
    body = ref.RigidBody(2.0, [0.01, 0.02, 0.03])
    state = ref.RigidState(vel=np.array([0.3, 0.0, 0.0]), omega=np.array([0.0, 0.0, 0.5]))
    after = ref.paper_step(body, state, np.zeros(3), np.zeros(3), 1e-2)
    np.testing.assert_allclose(after.vel, state.vel)
    np.testing.assert_allclose(after.pos, [3e-3, 0.0, 0.0])
    # spin about a principal axis: no gyroscopic torque, omega unchanged
    np.testing.assert_allclose(after.omega, state.omega, atol=1e-15)
    assert np.linalg.norm(after.quat) == pytest.approx(1.0)
