"""Headless pictures (hybrid.render): the three-panel figure 4 and the MP4."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import hybrid
from hybrid.cli import main
from hybrid.record import Recorder
from hybrid.render import draw_figure, frames_from_recording, key_frames, write_video
from hybrid.run import run


def _image(path):
    import matplotlib.image as mpimg
    img = mpimg.imread(path)[..., :3]
    h = img.shape[0]
    return img[int(0.12 * h):]  # below the titles


def _panels(img):
    w = img.shape[1] // 3
    return [img[:, i * w:(i + 1) * w] for i in range(3)]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """The breathing trunk through its first breath (4 s), recorded."""
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    sim = hybrid.load()
    with Recorder(path, sim) as rec:
        run(sim, 4.05, observers=[rec])
    return path


def test_render_a_recording_makes_three_different_panels_with_the_membrane_visible(recording, tmp_path, capsys):
    out = tmp_path / "fig"
    assert main(["render", str(recording), "--out", str(out)]) == 0
    assert "peak inspiration" in capsys.readouterr().out
    img = _image(out / "figure4.png")
    a, b, c = _panels(img)
    # below the titles: peak inspiration differs clearly from rest and from the end of
    # expiration; the end of expiration is back near rest, as in the paper's figure 4 c
    # ("the system returns to its original shape"), but not to the pixel
    assert np.abs(a - b).sum() > 1000.0 and np.abs(b - c).sum() > 1000.0
    assert 0.0 < np.abs(a - c).sum() < 0.1 * np.abs(a - b).sum()
    # the same frames without the membrane: the membrane's pixels are there
    fr = frames_from_recording(recording)
    rest, peak, end = key_frames(fr)
    assert fr.t[rest] == 0.0 and 1.0 < fr.t[peak] < 2.5 and fr.t[end] == pytest.approx(4.0, abs=0.011)
    draw_figure(fr, tmp_path / "empty.png", [rest, peak, end], membrane=False)
    bare = _image(tmp_path / "empty.png")
    membrane_px = np.abs(img - bare).max(axis=2) > 0.1
    assert membrane_px.mean() > 0.03
    # and a picture of neither membrane nor bones would be blank: the bones are drawn
    assert (np.abs(bare - 1.0).max(axis=2) > 0.1).mean() > 0.005


def test_render_a_scene_runs_it_first(tmp_path, capsys):
    out = tmp_path / "fig"
    # the membrane alone (no MuJoCo), still sagging under gravity through its first breath
    assert main(["render", "membrane_demo", "--out", str(out), "--duration", "4.2"]) == 0
    assert "peak inspiration t = 1.60 s, end of expiration t = 4.00 s" in capsys.readouterr().out
    a, b, c = _panels(_image(out / "figure4.png"))
    assert np.abs(a - b).sum() > 50.0 and np.abs(b - c).sum() > 50.0


def test_render_reports_a_missing_recording(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope.mcap"), "--out", str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err


@pytest.mark.skipif(importlib.util.find_spec("imageio_ffmpeg") is None, reason="needs the [video] extra")
def test_video(recording, tmp_path):
    fr = frames_from_recording(recording)
    n = write_video(fr, tmp_path / "run.mp4", every_s=0.5)
    assert n == 9
    data = (tmp_path / "run.mp4").read_bytes()
    assert len(data) > 1000 and data[4:8] == b"ftyp"


def test_view_without_a_display_says_so_in_one_line(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "membrane_demo"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no display" in err and "hybrid render" in err


def test_the_viewer_draws_the_membrane_edges_as_user_geoms():
    """The drawing the live viewer does each frame, on a plain (headless) MjvScene."""
    import mujoco

    from hybrid.render import draw_membrane, membrane_edges

    sim = hybrid.load()
    sim.step(100)
    edges, rgba = membrane_edges(sim.model)
    assert len(edges) == 80 + 156 - 2  # Euler: V - E + F = 2
    scn = mujoco.MjvScene(sim.mj_model, maxgeom=1000)  # the test reaches MuJoCo itself
    assert draw_membrane(scn, sim.vert_pos, edges, rgba) == len(edges)
    i, j = edges[0]
    np.testing.assert_allclose(scn.geoms[0].pos, 0.5 * (sim.vert_pos[i] + sim.vert_pos[j]), atol=1e-6)
    np.testing.assert_allclose(scn.geoms[0].rgba, rgba[0], atol=1e-6)


def test_view_runs_in_mujocos_viewer_on_a_virtual_display():
    """`hybrid view` on an X display (Xvfb, software OpenGL): the window opens, the
    membrane is drawn each frame, and the process ends cleanly (it crashed at exit,
    exit -11, while the viewer's thread still rendered)."""
    import os
    import re
    import shutil
    import subprocess
    import sys
    import time

    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("Xvfb is not installed (.ci/run installs it)")
    number = 100 + os.getpid() % 800
    server = subprocess.Popen([xvfb, f":{number}", "-screen", "0", "800x600x24", "-nolisten", "tcp"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 20
        while not os.path.exists(f"/tmp/.X11-unix/X{number}") and time.monotonic() < deadline:
            time.sleep(0.05)
        env = {**os.environ, "DISPLAY": f":{number}"}
        for scene in ([], ["membrane_demo"]):  # the coupled trunk, and a membrane alone
            done = subprocess.run([sys.executable, "-m", "hybrid", "view", *scene, "--duration", "0.3"],
                                  env=env, capture_output=True, text=True, timeout=300)
            assert done.returncode == 0, (scene, done.returncode, done.stderr[-2000:])
            shown = re.search(r"viewed (\d+) frames .* drawn as (\d+) of its (\d+) edges", done.stdout)
            assert shown, done.stdout
            frames, drawn, edges = (int(g) for g in shown.groups())
            assert frames >= 5 and drawn == edges > 0
    finally:
        server.terminate()
        server.wait()
