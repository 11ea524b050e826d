"""Implicit Euler coupled with MuJoCo: the packaged breathing scene (continuum, mesh
level 2, 318 points, its ribs in MuJoCo) breathes at several times the explicit
bound with the volume exact, and its metrics agree with symplectic Euler at a small
step within the first-order error measured (README, "Implicit Euler")."""

from __future__ import annotations

import dataclasses

import pytest

import hybrid
from hybrid.errors import SimulationDiverged
from hybrid.model import compile_scene
from hybrid.run import run

KEYS = ("apex_descent_mm", "rib_lift_mm", "pressure_max_pa")


@pytest.fixture(scope="module")
def scene():
    return hybrid.load_scene("breathing", overrides=["mesh.level=2"])


def breath(scene, h, integrator):
    sim = hybrid.Simulation(compile_scene(dataclasses.replace(scene, dt_s=h, integrator=integrator)))
    return run(sim, 4.0)["summary"]


def test_the_coupled_breathing_scene_at_seven_times_the_explicit_bound(scene):
    bound = compile_scene(dataclasses.replace(scene, dt_s=1e-3)).dt_stable_s  # 2.2 ms
    h = 0.016
    assert h >= 7 * bound
    with pytest.raises(SimulationDiverged):
        hybrid.Simulation(compile_scene(dataclasses.replace(scene, dt_s=h))).step(50)
    ref = breath(scene, 5e-4, "symplectic_euler")
    runs = {step: breath(scene, step, "implicit_euler") for step in (h, h / 4)}
    for step, s in runs.items():
        assert s["status"] == "ok" and s["volume_rel_error_max"] <= 1e-12, step
        for k in KEYS:
            # measured: relative errors <= 0.026 h/s (rib lift, 16 ms); first order
            assert abs(s[k] - ref[k]) <= 0.05 * step * abs(ref[k]), (step, k, s[k], ref[k])
    lift_err = [abs(runs[step]["rib_lift_mm"] - ref["rib_lift_mm"]) for step in (h, h / 4)]
    assert lift_err[1] <= lift_err[0] / 2  # the error falls with the step (measured 1.7e-3 -> 1.7e-4 mm)
    assert 2.0 <= ref["rib_lift_mm"] <= 8.0  # the ribs do rise: the coupling carries the breath


def test_a_residual_at_its_round_off_floor_ends_the_solve():
    """The breathing scene at level 6 starts at rest: its forces are about 5e-9 N, and
    positions rounded to their last place, times the stiffness, leave a residual of about
    3e-13 N (6e-5 of them), above the default implicit_tol = 1e-6. Corrections of a few
    units in the last place that no longer halve the residual end the solve there (before,
    Newton ran out of its 50 iterations at the first step)."""
    from hybrid.implicit import Info

    model = compile_scene(hybrid.load_scene("breathing", overrides=["mesh.level=6", "integrator=implicit_euler",
                                                                     "dt_s=0.01"]))
    assert model.arrays.implicit_tol == 1e-6
    sim = hybrid.Simulation(model, build="serial")
    sim.step(3)
    info = sim.state.implicit.info
    assert info[Info.NEWTON_TOTAL] < model.arrays.implicit_max_iter
    assert sim.volume_rel_error <= 1e-12
