"""Constraints on single points (hybrid.terms.local; paper 4): prescribed trajectories
followed exactly, keep-in regions that hold every point inside, alone and with the
volume constraint."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import EPS

from hybrid.model import compile_scene
from hybrid.regions import HalfSpace, Indices
from hybrid.scene import Damping, Gravity, KeepIn, Masses, MeshSpec, Nailed, Prescribed, Scene, ShapeMemory, Volume
from hybrid.schedule import Function, Table, evaluate
from hybrid.simulation import Simulation


@pytest.mark.parametrize("kind", ["table", "function"])
def test_prescribed_point_follows_its_schedule_exactly(kind):
    if kind == "table":
        sched = Table((0.0, 0.1, 0.3), ((0.0, 0.0, 0.0), (0.0, 0.0, 0.01), (0.005, -0.002, 0.0)))
    else:
        sched = Function(lambda t: (0.01 * math.sin(2 * math.pi * 5 * t), 0.0, 0.002 * t))
    vert = 7
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(total_kg=4.0),
        regions={"bottom": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0))},
        forces=(Gravity(), ShapeMemory(3000.0), Damping(critical_fraction=0.3)),
        constraints=(Nailed("bottom"), Prescribed(Indices((vert,)), sched), Volume()),
        dt_s=1e-3,
    )
    model = compile_scene(scene)
    assert model.arrays.vert_weight[vert] == 0.0  # the volume projection leaves it alone
    sim = Simulation(model)
    rest = model.mesh.vert_pos[vert]
    prev = rest.copy()
    for _ in range(400):
        sim.step(1)
        want = rest + evaluate(sched, sim.time)
        # position = rest + displacement(t), up to the roundoff of that sum
        assert np.abs(sim.vert_pos[vert] - want).max() <= 4 * EPS
        np.testing.assert_allclose(sim.vert_vel[vert], (sim.vert_pos[vert] - prev) / 1e-3, rtol=0, atol=1e-9)
        prev = np.array(sim.vert_pos[vert])
    assert sim.term_calls["prescribed"] == 400
    # it drags its neighbours along
    nbr = model.mesh.ring_vert[model.mesh.ring_ptr[vert]]
    assert np.linalg.norm(sim.vert_pos[nbr] - model.mesh.vert_pos[nbr]) > 1e-4


KEEP_IN = {
    # a floor 1 cm below the sphere: it falls on it
    "half_space": (
        KeepIn("all", "half_space", point_m=(0.0, 0.0, -0.13), normal=(0.0, 0.0, 1.0)),
        lambda x: x[:, 2] - (-0.13),
    ),
    # a ball smaller than the sphere: every point starts outside
    "ball": (
        KeepIn("all", "ball", center_m=(0.0, 0.0, 0.0), radius_m=0.115),
        lambda x: 0.115 - np.linalg.norm(x, axis=1),
    ),
    # a box squeezing x, with its floor 1 cm down
    "box": (
        KeepIn("all", "box", lo_m=(-0.11, -1.0, -0.13), hi_m=(0.11, 1.0, 1.0)),
        lambda x: np.minimum.reduce([x[:, 0] + 0.11, 0.11 - x[:, 0], x[:, 2] + 0.13]),
    ),
}


@pytest.mark.parametrize("shape", list(KEEP_IN))
def test_keep_in_region_keeps_points_inside(shape):
    """No volume constraint here: it projects after keep-in and may nudge a point
    out by its (small) correction; this tests the keep-in projection itself."""
    con, inside = KEEP_IN[shape]
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(total_kg=4.0),
        forces=(Gravity(), ShapeMemory(3000.0), Damping(critical_fraction=0.5)),
        constraints=(con,),
        dt_s=1e-3,
    )
    sim = Simulation(compile_scene(scene))
    worst = np.inf
    for _ in range(400):
        sim.step(1)
        worst = min(worst, inside(sim.vert_pos).min())
    # projected onto the boundary: inside up to the roundoff of coordinates ~0.1 m
    assert worst >= -4 * EPS * 0.13
    # the constraint is active: some points rest on the boundary
    assert (np.abs(inside(sim.vert_pos)) <= 1e-12).any()
    assert sim.term_calls["keep_in"] == 400
    # and without it the same points leave the region
    free = Simulation(compile_scene(scene.without("keep_in")))
    free.step(400)
    assert inside(free.vert_pos).min() < -1e-3


def test_keep_in_with_the_volume_constraint_keeps_the_volume_exact_and_the_overshoot_second_order():
    """Keep-in projects first, then the volume projection: the volume stays exact,
    and the volume projection gives back to the points on the floor part of what
    keep-in took, so they end each step slightly below it. That overshoot is one
    step's worth of the load's motion, a h^2: halving the step quarters it."""
    con = KeepIn("all", "half_space", point_m=(0.0, 0.0, -0.13), normal=(0.0, 0.0, 1.0))
    worst = {}
    for h in (1e-3, 5e-4):
        scene = Scene(
            formulation="paper",
            mesh=MeshSpec(),
            masses=Masses(total_kg=4.0),
            forces=(Gravity(), ShapeMemory(3000.0), Damping(critical_fraction=0.5)),
            constraints=(con, Volume()),
            dt_s=h,
        )
        sim = Simulation(compile_scene(scene))
        v0 = sim.model.arrays.vol0
        worst[h] = 0.0
        for k in range(int(round(2.0 / h))):
            sim.step(1)
            # exact: the projection's tolerance, ~EPS relative (measured: 1.7e-15)
            assert abs(sim.volume - v0) <= 100 * EPS * v0
            if k * h >= 1.0:  # resting on the floor (it lands at ~0.3 s)
                worst[h] = max(worst[h], -(sim.vert_pos[:, 2].min() + 0.13))
    assert 0.0 < worst[5e-4] < worst[1e-3] < 1e-4  # below the floor, by micrometres
    assert 3.0 < worst[1e-3] / worst[5e-4] < 5.0  # second order (measured 18.6 and 4.66 um: 4.00)
