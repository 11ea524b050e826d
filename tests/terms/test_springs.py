"""Forces toward a target (hybrid.terms.springs): attraction to a moving target trails it
by the closed-form lag."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hybrid.model import compile_scene
from hybrid.scene import Attraction, Damping, Masses, MeshSpec, Scene
from hybrid.schedule import Function, Table
from hybrid.simulation import Simulation


@pytest.mark.parametrize("kind", ["table", "function"])
def test_attraction_follows_a_moving_target_with_the_closed_form_lag(kind):
    """Every point pulled (k) toward rest + offset(t), offset = u t, with damping c and
    no other force: the steady state trails the target by exactly c u / k, for
    the continuous equation m x'' + c x' + k (x - u t) = 0 and for both Euler
    schemes (x_n = u t_n - c u / k, v_n = u solves their update exactly)."""
    m, k = 0.05, 50.0
    c = 2 * math.sqrt(k * m)  # critical: the transient dies as exp(-31.6 t)
    u = np.array([0.01, -0.02, 0.005])  # m/s
    if kind == "table":
        offset = Table((0.0, 10.0), ((0.0, 0.0, 0.0), tuple(10.0 * u)))
    else:
        offset = Function(lambda t: tuple(u * t))
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(per_vertex_kg=(m,) * 80),
        forces=(Attraction("all", k, offset_m=offset), Damping(coef_n_s_per_m=c)),
        dt_s=1e-3,
    )
    sim = Simulation(compile_scene(scene))
    sim.step(1500)
    lag = sim.model.mesh.vert_pos + u * sim.time - sim.vert_pos
    # transient left after 1.5 s: ~(1 + omega t) exp(-omega t) x 1e-3 m ~ 1e-22 m; roundoff ~1e-17 m
    np.testing.assert_allclose(lag, np.broadcast_to(c * u / k, lag.shape), rtol=0, atol=1e-6 * np.abs(c * u / k).max())
    np.testing.assert_allclose(sim.vert_vel, np.broadcast_to(u, lag.shape), rtol=0, atol=1e-6 * np.abs(u).max())
