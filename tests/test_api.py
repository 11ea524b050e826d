"""The public API for scripted experiments: hybrid.load and repeated runs."""

import dataclasses

import numpy as np
import pytest

import hybrid


def test_load_builtin_breathing_exposes_state_and_mujoco():
    sim = hybrid.load()
    assert sim.mj_model is not None and sim.mj_data is not None
    z_rib0 = sim.mj_data.site_xpos.copy()
    sim.step(800)  # 0.8 s into the first inspiration
    assert sim.time == pytest.approx(0.8)
    assert sim.vert_pos.shape == (80, 3)
    assert abs(sim.volume - sim.model.arrays.vol0) <= 1e-12 * sim.model.arrays.vol0
    assert sim.pressure > 0  # the contracting diaphragm pressurises the abdomen
    assert not np.array_equal(sim.mj_data.site_xpos, z_rib0)  # the ribs moved


def test_parameters_change_and_the_run_repeats(tmp_path):
    scene = hybrid.load_scene("breathing")
    runs = {}
    for dt in (1e-3, 5e-4):
        sim = hybrid.load(dataclasses.replace(scene, dt_s=dt))
        sim.step(int(round(0.5 / dt)))
        runs[dt] = sim.pressure
    # same physics at two steps: the pressures agree to the integrator's O(h) error
    assert runs[1e-3] == pytest.approx(runs[5e-4], rel=0.05)
    assert runs[1e-3] != runs[5e-4]


def test_membrane_only_scene_has_no_mujoco():
    from hybrid.demo import membrane_demo
    sim = hybrid.load(membrane_demo())
    assert sim.mj_model is None and sim.mj_data is None
