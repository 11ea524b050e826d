"""The membrane's compiled step (hybrid.step) against closed forms, and its failures.

Free fall against the exact discrete and continuous solutions of both integrators;
divergence detection (runaway, non-finite forces and schedules, speed limit) with a
suggested step or the missing damping named."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from helpers import hanging_sphere

from hybrid.errors import SimulationDiverged
from hybrid.model import compile_scene
from hybrid.regions import Indices
from hybrid.scene import AppliedForce, Gravity, Masses, MeshSpec, Scene
from hybrid.schedule import Function
from hybrid.simulation import Simulation

G = np.array([0.0, 0.0, -9.81])


@pytest.mark.parametrize("integrator", ["explicit_euler", "symplectic_euler"])
def test_free_fall_matches_the_closed_form(integrator):
    """Gravity alone, initial velocity v0, n steps of h.

    Exact discrete solutions: v_n = v0 + g n h for both; explicit Euler moves
    with the old velocity, x_n = x0 + v0 n h + g h^2 n(n-1)/2; symplectic with
    the new one, x_n = x0 + v0 n h + g h^2 n(n+1)/2. Against the continuous
    x(t) = x0 + v0 t + g t^2 / 2 the error is therefore exactly -+ g h t / 2:
    first order in h, which the test checks by halving h.
    """
    v0 = np.array([0.3, -0.2, 1.5])  # m/s
    errors = {}
    for h in (1e-3, 5e-4):
        n = int(round(0.5 / h))  # 0.5 s
        scene = Scene(
            formulation="paper",
            mesh=MeshSpec(),
            masses=Masses(total_kg=4.0),
            forces=(Gravity(),),
            dt_s=h,
            integrator=integrator,
        )
        sim = Simulation(compile_scene(scene))
        x0 = np.array(sim.vert_pos)
        sim.state.vert_vel[:] = v0
        sim.step(n)
        t = n * h
        assert sim.time == pytest.approx(t, rel=1e-14)
        x = np.array(sim.vert_pos)
        steps = n * (n - 1) / 2 if integrator == "explicit_euler" else n * (n + 1) / 2
        discrete = x0 + v0 * n * h + G * h * h * steps
        # roundoff: n additions of h v to coordinates of ~1 m: ~n eps / 2 ~ 1e-13 of the motion
        travel = np.abs(x - x0).max()
        assert np.abs(x - discrete).max() <= 1e-12 * travel
        np.testing.assert_allclose(
            sim.vert_vel, np.broadcast_to(v0 + G * t, x.shape), rtol=0, atol=1e-12 * np.linalg.norm(v0 + G * t)
        )
        continuous = x0 + v0 * t + 0.5 * G * t * t
        err = x - continuous
        bound = np.linalg.norm(G) * h * t / 2  # |g| h t / 2
        sign = -1.0 if integrator == "explicit_euler" else 1.0
        # the whole error is the O(h) term, along g, of exactly this size
        np.testing.assert_allclose(err, np.broadcast_to(sign * G * h * t / 2, x.shape), rtol=0, atol=1e-9 * bound)
        assert np.abs(err).max() <= bound * (1 + 1e-9)
        errors[h] = np.abs(err).max()
    assert errors[5e-4] / errors[1e-3] == pytest.approx(0.5, rel=1e-6)


@pytest.mark.parametrize("integrator", ["explicit_euler", "symplectic_euler"])
def test_divergence_is_detected_with_a_suggested_step(integrator):
    """dt = 5 x the paper's bound 2m/kv: one step multiplies a velocity by
    |1 - h kv/m| = 9, so the run runs away from its first step; it must stop
    within 100 steps, never return non-finite positions from a step that
    succeeded, name a smaller time step, and refuse to go on."""
    m, kv = 0.05, 50.0
    dt = 5 * 2 * m / kv
    model = compile_scene(hanging_sphere(dt, integrator, kv, m))
    assert model.dt_stable_s < dt
    sim = Simulation(model)
    with pytest.raises(SimulationDiverged) as info:
        for _ in range(100):
            sim.step(1)
            assert np.isfinite(sim.vert_pos).all() and np.isfinite(sim.vert_vel).all()
    exc = info.value
    assert exc.step < 100
    assert exc.time_s == pytest.approx(exc.step * dt)
    assert 0 <= exc.vert < 80 and f"vertex {exc.vert}" in str(exc)
    assert f"step {exc.step}" in str(exc)
    suggested = re.search(r"try dt_s <= ([0-9.eE+-]+) s", str(exc))
    assert suggested is not None, str(exc)
    assert float(suggested.group(1)) == pytest.approx(exc.dt_suggested_s, rel=1e-2)
    assert 0 < exc.dt_suggested_s < dt
    assert exc.dt_suggested_s <= model.dt_stable_s
    # it stays failed: no silent continuation
    for n in (1, 10):
        with pytest.raises(SimulationDiverged):
            sim.step(n)
    # and the suggestion works
    retry = Simulation(model.with_dt(exc.dt_suggested_s))
    retry.step(2000)
    assert np.isfinite(retry.vert_pos).all()
    assert np.linalg.norm(retry.vert_pos - model.mesh.vert_pos, axis=1).max() < 0.02  # m: it just sags (6 mm)
    before = np.array(retry.vert_pos)
    retry.step(100)
    # and creeps (heavily damped) rather than oscillates: under 1 cm/s on average
    # (measured 1e-4 m in 100 steps; an unstable step gives tens of m/s). Positions,
    # not velocities: explicit Euler with the volume projection keeps a velocity
    # -phi D / h at rest, cancelled by the next step's projection (~6e-3 m/s here).
    assert np.linalg.norm(retry.vert_pos - before, axis=1).max() < 100 * exc.dt_suggested_s * 1e-2


def test_divergence_of_a_batch_stops_at_the_failing_step():
    """The same run in one call of step(1000): it stops at the failing step (time
    and step count are those of the last good step) instead of running on."""
    dt = 5 * 2 * 0.05 / 50.0
    sim = Simulation(compile_scene(hanging_sphere(dt, "explicit_euler")))
    with pytest.raises(SimulationDiverged) as info:
        sim.step(1000)
    assert info.value.step < 100
    assert sim.steps_done == info.value.step
    assert sim.time == pytest.approx(info.value.step * dt)


def test_non_finite_force_is_detected():
    """A force so large that the kinetic energy overflows: 'non-finite', not NaN positions."""
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(total_kg=4.0),
        forces=(AppliedForce(Indices((5,)), (1e308, 0.0, 0.0)),),
        dt_s=1e-3,
    )
    sim = Simulation(compile_scene(scene))
    with pytest.raises(SimulationDiverged, match="non-finite") as info:
        sim.step(10)
    assert info.value.step == 0 and info.value.vert == 5
    with pytest.raises(SimulationDiverged):
        sim.step(1)


def test_python_schedule_returning_nan_is_detected():
    def bad_force(t):
        return (0.0, 0.0, math.nan if t > 0.0095 else 1.0)

    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(total_kg=4.0),
        forces=(AppliedForce(Indices((3,)), Function(bad_force)),),
        dt_s=1e-3,
    )
    sim = Simulation(compile_scene(scene))
    with pytest.raises(SimulationDiverged, match="bad_force"):
        sim.step(100)
    assert np.isfinite(sim.vert_pos).all()
    with pytest.raises(SimulationDiverged):
        sim.step(1)


def test_runaway_speed_is_detected_and_the_limit_is_a_scene_setting():
    """A point driven past max_speed_m_s is a runaway even while each step stays
    shorter than the body (the volume projection can keep an unstable run
    bounded but fast); a scene meant to move fast raises the limit."""
    import dataclasses

    from hybrid.errors import SimulationDiverged
    from hybrid.model import compile_scene
    from hybrid.scene import AppliedForce, Masses, MeshSpec, Scene
    from hybrid.simulation import Simulation

    # 1 kg over 80 points, 100 N per point: the lightest point crosses 50 m/s
    # after a few ms, while one step of 1e-4 s moves it a few mm, far less
    # than the 0.24 m body
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(total_kg=1.0),
        forces=(AppliedForce("all", (100.0, 0.0, 0.0)),),
        dt_s=1e-4,
    )
    model = compile_scene(scene)
    sim = Simulation(model)
    with pytest.raises(SimulationDiverged, match="max_speed_m_s") as exc:
        sim.step(1000)
    # symplectic Euler: v_n = n h a exactly, so the first step above 50 m/s is known
    m_min = model.arrays.vert_mass.min()
    expected = math.ceil(50.0 / (1e-4 * 100.0 / m_min)) - 1  # 0-based index of that step
    assert abs(exc.value.step - expected) <= 1
    assert exc.value.vert == int(np.argmin(model.arrays.vert_mass))
    fast = Simulation(compile_scene(dataclasses.replace(scene, max_speed_m_s=1e3)))
    fast.step(300)  # the lightest point reaches about 370 m/s: allowed now
    assert np.all(np.isfinite(fast.vert_pos))


def test_divergence_without_damping_names_the_damping_not_the_step():
    """Undamped shape memory excites itself at a stable step: the message
    says so instead of suggesting a smaller step (found by `hybrid study extremes`)."""
    from hybrid.demo import membrane_demo

    sim = Simulation(compile_scene(membrane_demo().without("damping")))
    with pytest.raises(SimulationDiverged, match="critical_fraction=0.3") as exc:
        sim.step(20000)
    assert "0.15" in str(exc.value)
