"""The runner (hybrid.run.run): compiled frames give the same trace as stepping frame by frame."""

from __future__ import annotations

import numpy as np
import pytest

import hybrid
from hybrid.demo import membrane_demo
from hybrid.run import run


def _plain_observer(sim, trace):
    """A per-frame observer: the runner then steps frame by frame."""


@pytest.mark.parametrize("scene", ["breathing", "membrane_demo"])
def test_compiled_frames_give_the_trace_of_frame_by_frame_stepping(scene):
    make = (lambda: hybrid.load("breathing_paper")) if scene == "breathing" else (lambda: hybrid.load(membrane_demo()))
    duration = 5.0 if scene == "breathing" else 1.0  # the breathing: one whole cycle, so rest_return_mm
    batched = run(make(), duration)
    stepped = run(make(), duration, observers=[_plain_observer])
    a, b = batched["trace"].arrays(), stepped["trace"].arrays()
    assert len(a["t_s"]) == int(round(duration / 0.01)) + 1
    for key in a:  # the same kernels, the same order of sums: equal to the bit
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    sa, sb = dict(batched["summary"]), dict(stepped["summary"])
    for s in (sa, sb):
        del s["wall_s"], s["us_per_step"], s["provenance"]["started_utc"]
    assert sa == sb
    if scene == "breathing":
        assert sa["rest_return_mm"] is not None
