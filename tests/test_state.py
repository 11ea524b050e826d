"""`hybrid.State`: a run split in two through a saved state is the run in one piece,
bit for bit, with every integrator, with and without MuJoCo (issue 26)."""

import dataclasses

import numpy as np
import pytest

import hybrid
from hybrid.simulation import Simulation


def _breathing(*sets, rigid=True):
    scene = hybrid.load_scene("breathing", overrides=["mesh.level=0", *sets])
    return scene if rigid else dataclasses.replace(scene, rigid=None)


CASES = {
    # (scene, steps in all)
    "paper formulation, explicit Euler, no MuJoCo": (
        lambda: hybrid.load_scene("membrane_demo", overrides=["integrator=explicit_euler"]),
        40,
    ),
    "symplectic Euler, no MuJoCo": (lambda: hybrid.load_scene("membrane_demo"), 40),
    "implicit Euler, no MuJoCo": (lambda: _breathing("integrator=implicit_euler", "dt_s=0.01", rigid=False), 12),
    "symplectic Euler, MuJoCo": (lambda: _breathing(), 40),
    "paper scene, MuJoCo": (lambda: hybrid.load_scene("breathing_paper"), 40),
    "symplectic Euler, MuJoCo, sliding links": (
        lambda: _breathing(*(f"rigid.links.{n}.slide_stiffness_n_per_m3=1e7" for n in ("rib_left", "rib_right"))),
        40,
    ),
    "implicit Euler, MuJoCo": (lambda: _breathing("integrator=implicit_euler", "dt_s=0.01"), 12),
    # the planes the solve holds its points to are placed by each step's rigid phase: no state
    "implicit Euler, MuJoCo, sliding links": (
        lambda: _breathing(
            *(f"rigid.links.{n}.slide_stiffness_n_per_m3=1e7" for n in ("rib_left", "rib_right")),
            "integrator=implicit_euler",
            "dt_s=0.004",
        ),
        12,
    ),
}


def _snapshot(sim):
    out = [np.array(sim.vert_pos), np.array(sim.vert_vel), np.array([sim.pressure, sim.time])]
    if sim.mj_data is not None:
        out += [np.array(sim.mj_data.qpos), np.array(sim.mj_data.qvel)]
    return out


@pytest.mark.parametrize("case", CASES)
def test_a_run_split_through_a_saved_state_is_the_run_in_one_piece(case):
    make, nstep = CASES[case]
    model = hybrid.compile_scene(make())
    whole = Simulation(model, build="serial")
    whole.step(nstep)
    for split in (1, nstep // 2 + 1):  # at the first step, and at an odd step mid-run
        first = Simulation(model, build="serial")
        first.step(split)
        saved = first.get_state()
        first.step(3)  # the saved copy does not follow the run it came from
        second = Simulation(model, build="serial")  # a fresh run of the same model
        second.set_state(saved)
        assert second.steps_done == split
        second.step(nstep - split)
        for a, b in zip(_snapshot(whole), _snapshot(second)):
            assert np.array_equal(a, b), (case, split)
        assert second.term_calls == whole.term_calls


def test_a_state_of_another_model_is_refused_in_one_line():
    demo = Simulation(hybrid.compile_scene(hybrid.load_scene("membrane_demo")))
    finer = Simulation(hybrid.compile_scene(_breathing("mesh.level=1", rigid=False)))
    with pytest.raises(
        ValueError, match=r"state\.vert_pos: expected shape \(\d+, 3\).*received an array of shape \(80, 3\)"
    ) as err:
        finer.set_state(demo.get_state())
    assert "\n" not in str(err.value)
    paper = Simulation(hybrid.compile_scene(hybrid.load_scene("breathing_paper")))  # 80 points and MuJoCo
    with pytest.raises(ValueError, match=r"state\.mj_state: expected shape"):
        paper.set_state(demo.get_state())
    with pytest.raises(ValueError, match="expected a hybrid.State"):
        demo.set_state({"vert_pos": 0})
    with pytest.raises(ValueError, match="a State or keyword parts, received both"):
        demo.set_state(demo.get_state(), time_s=0.0)


def test_stepping_by_frames_is_stepping_by_steps_bit_for_bit():
    """Step k runs from origin + k h whatever the calls: frames, pieces and one call agree."""
    model = hybrid.compile_scene(_breathing())
    whole = Simulation(model, build="serial")
    whole.step(30)
    framed = Simulation(model, build="serial")
    frames = framed.frames_buffer(3)
    framed.step_frames([7, 19, 30], frames)
    pieces = Simulation(model, build="serial")
    for n in (7, 12, 11):
        pieces.step(n)
    assert np.array_equal(frames.pos[2], whole.vert_pos)
    for a, b in zip(_snapshot(whole), _snapshot(pieces)):
        assert np.array_equal(a, b)
