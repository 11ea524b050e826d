"""The runner (hybrid.run.run) and the compiled frame capture it uses
(Simulation.step_frames): the same trace as stepping frame by frame."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import hybrid
from hybrid.demo import membrane_demo
from hybrid.errors import SimulationDiverged
from hybrid.run import run


def _plain_observer(sim, trace):
    """A per-frame observer: the runner then steps frame by frame."""


@pytest.mark.parametrize("scene", ["breathing", "membrane_demo"])
def test_compiled_frames_give_the_trace_of_frame_by_frame_stepping(scene):
    make = (lambda: hybrid.load()) if scene == "breathing" else (lambda: hybrid.load(membrane_demo()))
    duration = 5.0 if scene == "breathing" else 1.0  # the breathing: one whole cycle, so rest_return_mm
    batched = run(make(), duration)
    stepped = run(make(), duration, observers=[_plain_observer])
    a, b = batched["trace"].arrays(), stepped["trace"].arrays()
    assert len(a["t_s"]) == int(round(duration / 0.01)) + 1
    for key in a:  # the same kernels, the same order of sums: equal to the bit
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    sa, sb = dict(batched["summary"]), dict(stepped["summary"])
    for s in (sa, sb):
        del s["wall_s"], s["us_per_step"]
    assert sa == sb
    if scene == "breathing":
        assert sa["rest_return_mm"] is not None


def test_step_frames_captures_the_state_at_each_stop():
    stops = [3, 10, 10, 17]
    sim, ref = hybrid.load(), hybrid.load()
    frames = sim.frames_buffer(8)
    sim.step_frames(stops, frames)
    assert frames.count == 4 and sim.steps_done == 17
    for i, stop in enumerate(stops):
        ref.step(stop - ref.steps_done)
        np.testing.assert_array_equal(frames.pos[i], ref.vert_pos)
        np.testing.assert_array_equal(frames.body_pos[i], ref.mj_data.xpos[1:])
        np.testing.assert_array_equal(frames.body_quat[i], ref.mj_data.xquat[1:])
        assert frames.scal[i, 0] == ref.time
        assert frames.scal[i, 1] == ref.volume
        assert frames.scal[i, 2] == ref.pressure
        assert frames.scal[i, 3] == ref.kinetic_energy


def test_step_frames_keeps_the_frames_before_a_divergence():
    scene = dataclasses.replace(membrane_demo(), dt_s=0.006)  # diverges at step 11
    sim, ref = hybrid.load(scene), hybrid.load(scene)
    frames = sim.frames_buffer(10)
    with pytest.raises(SimulationDiverged) as caught:
        sim.step_frames(np.arange(2, 21, 2), frames)
    with pytest.raises(SimulationDiverged) as expected:
        ref.step(20)
    assert caught.value.step == expected.value.step == 11
    assert frames.count == 5  # steps 2, 4, ..., 10
    assert sim.steps_done == ref.steps_done == 11
    with pytest.raises(SimulationDiverged):  # a failed simulation refuses to go on
        sim.step_frames([12], frames)
    assert frames.count == 0


@pytest.mark.parametrize("stops, expected", [([5, 3], "increasing"), ([-1], "increasing"),
                                             (list(range(1, 12)), "capacity")])
def test_step_frames_refuses_bad_stops(stops, expected):
    sim = hybrid.load(membrane_demo())
    with pytest.raises(ValueError, match=expected):
        sim.step_frames(stops, sim.frames_buffer(10))
