"""The Recorder (hybrid.record.recorder): what it writes reads back equal to the simulation
at the recorded times, stepped frame by frame or in compiled batches, and a run that
diverges, is interrupted or killed leaves a readable file with its frames."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import FrameCopies

import hybrid
from hybrid.demo import membrane_demo
from hybrid.record import SCALAR_CHANNELS, Recorder, read
from hybrid.run import RunFailed, run


def test_read_back_equals_the_simulation_at_the_recorded_times(tmp_path):
    sim = hybrid.load("breathing_paper")  # the coupled breathing trunk, 80 points
    copies = FrameCopies()
    with Recorder(tmp_path / "run.mcap", sim) as rec:
        result = run(sim, 0.3, observers=[copies, rec])
    data = read(tmp_path / "run.mcap")
    pts = data["membrane"]
    # a small mesh: the triangle list every frame, its points as the simulation's doubles
    assert "/membrane/points" not in data
    assert pts["pos"].dtype == np.float64
    assert pts["pos"].shape == (31, sim.model.nvert, 3)  # t = 0, 0.01, ..., 0.3
    np.testing.assert_allclose(pts["t"], copies.t, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(pts["pos"], np.asarray(copies.pos))
    tf = data["/rigid/transforms"]
    assert tf["bodies"] == ["spine", "rib_left", "rib_right"]
    np.testing.assert_array_equal(tf["pos"], np.asarray(copies.xpos))
    np.testing.assert_array_equal(tf["quat"], np.asarray(copies.xquat))
    # every scalar channel, one value a frame, equal to the runner's trace
    trace = result["trace"].arrays()
    for topic, key in SCALAR_CHANNELS.items():
        if topic.startswith("/lungs/"):  # the scene has no lungs: nothing claimed of them
            assert topic not in data, topic
            continue
        assert topic in data, topic
        np.testing.assert_array_equal(data[topic]["t"], pts["t"])
        np.testing.assert_array_equal(data[topic]["value"], trace[key])
    assert data["/rib_elevation"]["value"].max() > 0.0
    # the triangle list every frame for a small mesh; the model's description
    assert len(data["/membrane/mesh"]["t"]) == 31
    model = data["model"]
    np.testing.assert_array_equal(model["face_vert"], sim.model.mesh.face_vert)
    assert "dome" in model["regions"] and "abdomen" in model["regions"]
    assert {g["body"] for g in model["geoms"]} >= {"spine", "rib_left", "rib_right"}


def test_read_back_of_a_run_stepped_in_compiled_frames(tmp_path):
    """The recorder alone: the runner steps in compiled batches of frames and hands
    them over as blocks; equal to a twin run stepped frame by frame."""
    sim, twin = hybrid.load("breathing_paper"), hybrid.load("breathing_paper")
    copies = FrameCopies()
    with Recorder(tmp_path / "run.mcap", sim, every_s=0.02) as rec:
        result = run(sim, 2.5, observers=[rec])
    run(twin, 2.5, observers=[copies])
    data = read(tmp_path / "run.mcap")
    every = slice(None, None, 2)  # frames every 0.01 s, recorded every 0.02 s
    pts = data["membrane"]
    np.testing.assert_allclose(pts["t"], copies.t[every], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(pts["pos"], np.asarray(copies.pos[every]))
    np.testing.assert_array_equal(data["/rigid/transforms"]["pos"], np.asarray(copies.xpos[every]))
    np.testing.assert_array_equal(data["/rigid/transforms"]["quat"], np.asarray(copies.xquat[every]))
    trace = result["trace"].arrays()
    for topic, key in SCALAR_CHANNELS.items():
        if not topic.startswith("/lungs/"):  # no lungs in the scene
            np.testing.assert_array_equal(data[topic]["value"], trace[key][every])


def _diverging_scene():
    return dataclasses.replace(membrane_demo(), dt_s=0.006)  # diverges at step 11 (t = 0.066 s)


def test_a_run_that_diverges_leaves_every_frame_up_to_the_divergence(tmp_path):
    sim = hybrid.load(_diverging_scene())
    copies = FrameCopies()
    rec = Recorder(tmp_path / "run.mcap", sim)
    try:
        with pytest.raises(RunFailed) as failed:
            run(sim, 1.0, observers=[copies, rec])
    finally:
        rec.close()
    frames = failed.value.result["trace"].t_s
    assert len(frames) >= 5
    data = read(tmp_path / "run.mcap")
    pts = data["membrane"]
    np.testing.assert_allclose(pts["t"], frames, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(pts["pos"], np.asarray(copies.pos))
    for topic in SCALAR_CHANNELS:  # each but the ribs' and lungs': the scene has none, nothing says 0 for them
        if topic == "/rib_elevation" or topic.startswith("/lungs/"):
            assert topic not in data
        else:
            assert len(data[topic]["t"]) == len(frames)


def test_an_interrupted_run_leaves_a_finished_file_with_every_frame_before_the_interrupt(tmp_path):
    sim = hybrid.load(membrane_demo())
    seen = []

    def interrupt(s, trace):
        seen.append(s.time)
        if len(seen) == 37:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        with Recorder(tmp_path / "run.mcap", sim) as rec:
            run(sim, 1.0, observers=[rec, interrupt])
    t = read(tmp_path / "run.mcap")["membrane"]["t"]
    np.testing.assert_allclose(t, seen, atol=1e-9)


def test_a_killed_run_leaves_a_readable_file_with_its_frames(tmp_path):
    """SIGKILL: no finally runs; the frames flushed before the kill are readable."""
    import os
    import signal
    import subprocess
    import sys
    import time

    # the same recorded run here first, briefly: the child then loads its compiled
    # code from the cache instead of compiling it while the clock below runs
    warm = hybrid.load(membrane_demo(duration_s=0.05))
    with Recorder(tmp_path / "warm.mcap", warm) as rec:
        run(warm, 0.05, observers=[rec])
    path = tmp_path / "run.mcap"
    script = (
        "import hybrid\n"
        "from hybrid.demo import membrane_demo\n"
        "from hybrid.record import Recorder\n"
        "from hybrid.run import run\n"
        "sim = hybrid.load(membrane_demo(duration_s=1000.0))\n"
        f"rec = Recorder({str(path)!r}, sim, flush_s=0.05)\n"
        "run(sim, 1000.0, observers=[rec])\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 120
        n = 0
        while time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            if path.exists():
                n = len(read(path).get("membrane", {}).get("t", []))
                if n >= 100:
                    break
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert n >= 100
    t = read(path)["membrane"]["t"]
    assert len(t) >= n
    np.testing.assert_allclose(t, np.arange(len(t)) * 0.01, atol=1e-9)  # every frame, in order, from 0
