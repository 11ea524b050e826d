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


def test_progress_shows_in_a_notebook_and_stays_out_of_pipes(monkeypatch, capsys):
    """Issue 29, item 6: progress=True drew only on a terminal, so a Jupyter cell showed
    nothing. In a kernel (ipykernel loaded, stderr no terminal) it is an IPython display
    updated in place, or without IPython a plain line each tenth of the run; on a pipe
    it stays silent (logs and the command line's one-line messages are kept clean)."""
    import sys
    import types

    def quiet_run():
        run(hybrid.load(membrane_demo()), 0.2, progress=True, observers=[_plain_observer])  # 20 frames, 20 updates
        return capsys.readouterr().err

    monkeypatch.delitem(sys.modules, "ipykernel", raising=False)
    assert quiet_run() == ""  # a pipe (capsys): nothing, as before
    monkeypatch.setitem(sys.modules, "ipykernel", types.ModuleType("ipykernel"))
    monkeypatch.setitem(sys.modules, "IPython", None)  # a kernel without IPython's display
    lines = quiet_run().splitlines()
    assert 2 <= len(lines) <= 11 and lines[-1].startswith("[" + "#" * 30 + "] 100.0%"), lines
    shown = []

    class Handle:
        def update(self, obj):
            shown.append(obj.text)

    display = types.ModuleType("IPython.display")
    display.Pretty = type("Pretty", (), {"__init__": lambda self, text: setattr(self, "text", text)})
    display.display = lambda obj, display_id: (shown.append(obj.text), Handle())[1] if display_id else None
    monkeypatch.setitem(sys.modules, "IPython", types.ModuleType("IPython"))
    monkeypatch.setitem(sys.modules, "IPython.display", display)
    assert quiet_run() == ""  # drawn in the display, not on stderr
    assert shown[0].startswith("[" + "." * 30 + "]   0.0%") and "100.0%" in shown[-1], shown
