"""Headless pictures (hybrid.render): the three-panel figure 4 and the MP4."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import hybrid
from hybrid.cli import main
from hybrid.record import Recorder
from hybrid.render import (
    STILL_TITLES,
    build_figure,
    draw_figure,
    frames_from_recording,
    frames_from_scene,
    key_frames,
    sagittal_section,
    write_video,
)
from hybrid.run import run


def _image(path):
    import matplotlib.image as mpimg

    img = mpimg.imread(path)[..., :3]
    h = img.shape[0]
    return img[int(0.12 * h) : int(0.92 * h)]  # below the titles, above the legend (which spans the panels)


def _panels(img):
    w = img.shape[1] // 3
    return [img[:, i * w : (i + 1) * w] for i in range(3)]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """The paper's breathing trunk through its first breath (4 s), recorded."""
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    sim = hybrid.load("breathing_paper")
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


def _dashed(collection) -> bool:
    return any(offset is not None and dashes for offset, dashes in collection.get_linestyle())


def test_the_figure_overlays_the_rest_outline_and_has_a_scale_and_a_legend(recording):
    from matplotlib.collections import LineCollection
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    fr = frames_from_recording(recording)
    fig, frames = build_figure(fr)
    try:
        views = [ax for ax in fig.axes if ax.name == "3d"]
        sections = [ax for ax in fig.axes if ax.name != "3d"]
        assert len(views) == len(sections) == 3
        y0 = fr.pos[0][:, 1].mean()
        rest_cut, _ = sagittal_section(fr.pos[0], fr.face_vert, y0)
        for view, section, k in zip(views, sections, frames):
            # the rest outline: dashed, on the 3D view and in the section, where the rest shape is cut
            assert any(_dashed(c) for c in view.collections if isinstance(c, Line3DCollection))
            rest = [c for c in section.collections if isinstance(c, LineCollection) and _dashed(c)]
            assert len(rest) == 1
            np.testing.assert_allclose(np.asarray(rest[0].get_segments()), rest_cut)
            # the deformed section: the frame's own cut
            deformed = [c for c in section.collections if c.get_label() == "deformed"]
            np.testing.assert_allclose(
                np.asarray(deformed[0].get_segments()), sagittal_section(fr.pos[k], fr.face_vert, y0)[0]
            )
            # a scale bar of the length it says, on an equal-aspect section
            bar = [line for line in section.lines if line.get_label() == "scale bar"][0]
            assert section.get_aspect() == 1.0
            assert np.ptp(bar.get_xdata()) == pytest.approx(0.05) and "5 cm" in [t.get_text() for t in section.texts]
        # the peak's section lies below the rest outline at the apex: the dome descended
        peak_cut = sagittal_section(fr.pos[frames[1]], fr.face_vert, y0)[0]
        assert rest_cut[:, :, 1].max() - peak_cut[:, :, 1].max() > 0.01
        legend = [t.get_text() for t in fig.legends[0].get_texts()]
        assert set(fr.regions) <= set(legend) and "rest outline" in legend and "ribs and spine" in legend
        assert [ax.get_title().split("  ")[0] for ax in views] == [
            "a. rest",
            "b. peak inspiration",
            "c. end of expiration",
        ]
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_a_sagittal_section_of_the_sphere_is_a_closed_polygon_inside_it():
    sim = hybrid.load("membrane_demo")
    pos, face = np.asarray(sim.vert_pos), np.asarray(sim.model.mesh.face_vert)
    segs, faces = sagittal_section(pos, face, 0.0)
    r = np.linalg.norm(segs, axis=2)
    assert len(segs) >= 13 and np.all(r <= 0.12 + 1e-12) and np.all(r > 0.12 * np.cos(np.pi / 7))
    ends, count = np.unique(np.round(segs.reshape(-1, 2), 12), axis=0, return_counts=True)
    assert np.all(count == 2)  # every end shared by two segments: one closed outline


def test_render_takes_set_and_without_like_run(tmp_path, capsys):
    out = tmp_path / "fig"
    # no muscle: the scene does not breathe, and the panels are not called inspiration and expiration
    args = [
        "render",
        "membrane_demo",
        "--without",
        "muscle",
        "--set",
        "forces.gravity.accel_m_s2=[0, 0, -30]",
        "--duration",
        "0.3",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    said = capsys.readouterr().out
    assert "largest displacement t =" in said and "last frame" in said and "inspiration" not in said
    assert (out / "figure4.png").is_file()
    heavy = frames_from_scene(
        "membrane_demo", 0.3, without=["muscle"], overrides=["forces.gravity.accel_m_s2=[0, 0, -30]"]
    )
    plain = frames_from_scene("membrane_demo", 0.3, without=["muscle"])
    assert not np.any(heavy.muscle) and heavy.apex_descent[-1] > 2 * plain.apex_descent[-1] > 0
    fig, _ = build_figure(heavy)
    assert [ax.get_title().split("  ")[0] for ax in fig.axes if ax.name == "3d"] == list(STILL_TITLES)
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_render_refuses_set_and_without_for_a_recording_and_unknown_names(recording, tmp_path, capsys):
    assert main(["render", str(recording), "--set", "dt_s=5e-4", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--set" in err and "recording" in err
    assert main(["render", "membrane_demo", "--without", "nothing", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'nothing'" in err


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

    sim = hybrid.load("breathing_paper")
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
    server = subprocess.Popen(
        [xvfb, f":{number}", "-screen", "0", "800x600x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 20
        while not os.path.exists(f"/tmp/.X11-unix/X{number}") and time.monotonic() < deadline:
            time.sleep(0.05)
        env = {**os.environ, "DISPLAY": f":{number}"}
        for scene in ([], ["membrane_demo"]):  # the coupled trunk, and a membrane alone
            done = subprocess.run(
                [sys.executable, "-m", "hybrid", "view", *scene, "--duration", "0.3"],
                env=env,
                capture_output=True,
                text=True,
                timeout=300,
            )
            assert done.returncode == 0, (scene, done.returncode, done.stderr[-2000:])
            shown = re.search(r"viewed (\d+) frames .* drawn as (\d+) of its (\d+) edges", done.stdout)
            assert shown, done.stdout
            frames, drawn, edges = (int(g) for g in shown.groups())
            assert frames >= 5 and drawn == edges > 0
    finally:
        server.terminate()
        server.wait()


def test_the_muscle_channel_says_what_it_holds_and_older_recordings_still_draw(recording, monkeypatch):
    # /muscle (named /muscle_stiffness before 0.20, whatever the muscle was) carries the trace's
    # muscle_n_per_m; the description says what that is: the paper's per-point muscle, a stiffness
    import hybrid.record as record

    data = hybrid.read(recording)
    assert "/muscle" in data and "/muscle_stiffness" not in data
    assert data["model"]["muscle"] == "muscle stiffness (N/m)"
    new = frames_from_recording(recording)
    assert new.muscle is not None and np.ptp(new.muscle) > 0  # the breath's drive, from the channel

    read = record.read

    def as_before(path, *args, **kw):  # the same file as 0.19 wrote it: the channel's old name
        d = read(path, *args, **kw)
        d["/muscle_stiffness"] = d.pop("/muscle")
        return d

    monkeypatch.setattr(record, "read", as_before)
    old = frames_from_recording(recording)
    np.testing.assert_array_equal(old.muscle, new.muscle)
