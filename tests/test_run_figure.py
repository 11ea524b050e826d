"""The run's figure drawn by a process of its own (`hybrid.pictures.run_figure`, issue 30's
warm start): `hybrid run` starts it first, it imports matplotlib while the run sets up,
and it returns the same picture the run would have drawn itself; when it fails, the run
draws the figure itself and loses nothing."""

from __future__ import annotations

import io

import numpy as np
import pytest

import hybrid
from hybrid.outputs import figure_series, plot_trace
from hybrid.pictures.run_figure import FigureProcess, png_bytes


def _pixels(png: bytes) -> np.ndarray:
    import matplotlib.image

    return matplotlib.image.imread(io.BytesIO(png), format="png")


@pytest.fixture(scope="module")
def series():
    """A short run of `breathing_lungs` at level 0: every panel and both diagrams."""
    sim = hybrid.load(hybrid.load_scene("breathing_lungs", overrides=["mesh.level=0"]))
    res = hybrid.run(sim, 0.05)
    s = figure_series(res["trace"])
    assert s["diagrams"] is not None and len(s["panels"]) >= 6  # premise: the whole figure
    return res["trace"], s


def test_the_figure_process_draws_the_picture_the_run_would_draw_itself(series):
    """Pixel for pixel: the same series and the same Agg renderer, in another process."""
    _, s = series
    with FigureProcess() as drawer:
        png = drawer.png(s, "breathing_lungs")
    assert png is not None and png.startswith(b"\x89PNG")
    here = png_bytes(s, title="breathing_lungs")
    a, b = _pixels(png), _pixels(here)
    assert a.shape == b.shape and a.shape[0] > 900  # the diagrams' row is there
    assert np.array_equal(a, b)


def test_a_failed_figure_process_leaves_the_figure_to_the_run(series, tmp_path):
    """A process that died (killed here) answers None, and plot_trace draws the figure
    itself: the same file as without a process."""
    trace, s = series
    drawer = FigureProcess()
    drawer._proc.kill()
    assert drawer.png(s, "x") is None
    drawer = FigureProcess()
    drawer._proc.kill()
    plot_trace(trace, tmp_path / "a.png", title="x", drawer=drawer)
    plot_trace(trace, tmp_path / "b.png", title="x")
    assert np.array_equal(_pixels((tmp_path / "a.png").read_bytes()), _pixels((tmp_path / "b.png").read_bytes()))
    assert drawer.png(s, "x") is None  # one figure a process: used, it answers None


def test_the_figure_process_ends_with_its_context_when_nothing_is_drawn():
    """A run refused after the process started closes it: nothing outlives the command."""
    with FigureProcess() as drawer:
        proc = drawer._proc
        assert proc is not None and proc.poll() is None
    assert proc.poll() is not None


def test_the_figure_process_exits_quietly_when_its_input_closes_first():
    """The pipe closed before any series (the run stopped): exit status 0, no output."""
    drawer = FigureProcess()
    proc = drawer._proc
    out, _ = proc.communicate(b"", timeout=120)
    assert (proc.returncode, out) == (0, b"")
    drawer._proc = None
