"""Muscle (hybrid.terms.muscle; paper 3.4): a region contracts along its fibres, with a
stiffness schedule given as a table or as a Python function."""

from __future__ import annotations

import numpy as np

from hybrid.model import compile_scene
from hybrid.regions import HalfSpace
from hybrid.scene import Damping, Masses, MeshSpec, Muscle, Nailed, Scene, ShapeMemory, Volume
from hybrid.schedule import Table
from hybrid.simulation import Simulation


def _muscle_scene(stiffness):
    # damping given as a coefficient (0.3 of critical for k = 3000 N/m, m = 0.05 kg):
    # a critical fraction would count the muscle's peak stiffness, which is
    # known for a table but not for a Python function
    return Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(total_kg=4.0),
        regions={
            "bottom": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0)),
            "top": HalfSpace((0.0, 0.0, 0.05), (0.0, 0.0, 1.0)),
        },
        forces=(
            ShapeMemory(3000.0),
            Damping(coef_n_s_per_m=7.3),
            Muscle("top", stiffness, toward_m=(0.0, 0.0, 0.12)),
        ),  # meridian fibres, toward the apex
        constraints=(Nailed("bottom"), Volume()),
        dt_s=1e-3,
    )


def test_muscle_contracts_its_region():
    table = Table((0.0, 0.2), (0.0, 200.0))  # N/m, ramped up in 0.2 s
    model = compile_scene(_muscle_scene(table))
    pv, pn = model.arrays.mus_vert, model.arrays.mus_nbr
    assert pv.size > 0 and set(pv.tolist()) <= set(model.regions["top"].tolist())
    rest = model.mesh.vert_pos
    d0 = np.linalg.norm(rest[pv] - rest[pn], axis=1)
    sim = Simulation(model)
    sim.step(500)
    d1 = np.linalg.norm(sim.vert_pos[pv] - sim.vert_pos[pn], axis=1)
    assert (d1 < d0).all()  # every contraction pair shortens
    assert d1.mean() < 0.9 * d0.mean()  # measured ~0.8
    assert sim.term_calls["muscle"] == 500
    # without the muscle nothing moves and the kernel never runs
    plain = Simulation(compile_scene(_muscle_scene(table).without("muscle")))
    plain.step(500)
    assert plain.term_calls["muscle"] == 0
    assert "muscle" not in plain.model.terms
    assert np.abs(plain.vert_pos - rest).max() < 1e-12


def test_python_function_schedule_equals_the_same_table():
    """A muscle stiffness given as a Python function (evaluated between steps)
    drives exactly the same run as the equivalent compiled table."""
    table = Table((0.0, 0.2), (0.0, 200.0))
    fn = lambda t: np.interp(t, [0.0, 0.2], [0.0, 200.0])  # noqa: E731
    a = Simulation(compile_scene(_muscle_scene(table)))
    b = Simulation(compile_scene(_muscle_scene(fn)))
    assert b.model.python_schedules and not a.model.python_schedules
    a.step(300)
    b.step(300)
    travel = np.abs(a.vert_pos - a.model.mesh.vert_pos).max()
    assert travel > 1e-3
    # the two interpolation formulas may differ in the last bit; damped, that stays ~eps
    assert np.abs(a.vert_pos - b.vert_pos).max() <= 1e-12 * travel + 1e-15
    assert b.term_calls["muscle"] == 300
