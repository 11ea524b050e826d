"""The MCAP recording (hybrid.record): read-back, crash safety, channels, the CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import hybrid
from hybrid.cli import main
from hybrid.demo import membrane_demo
from hybrid.record import SCALAR_CHANNELS, Recorder, read
from hybrid.run import RunFailed, run


class _Copies:
    """An observer keeping what the simulation holds at each frame."""

    def __init__(self):
        self.t, self.pos, self.xpos, self.xquat = [], [], [], []

    def __call__(self, sim, trace):
        self.t.append(sim.time)
        self.pos.append(np.array(sim.vert_pos))
        if sim.mj_data is not None:
            self.xpos.append(np.array(sim.mj_data.xpos[1:]))
            self.xquat.append(np.array(sim.mj_data.xquat[1:]))


def test_read_back_equals_the_simulation_at_the_recorded_times(tmp_path):
    sim = hybrid.load()  # the coupled breathing trunk
    copies = _Copies()
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
    sim, twin = hybrid.load(), hybrid.load()
    copies = _Copies()
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
        np.testing.assert_array_equal(data[topic]["value"], trace[key][every])


def _decoded(path, topics):
    """(log time, message) of each message on `topics`, decoded by mcap's own protobuf
    decoder from the schemas the file holds."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(m.log_time, msg) for _, _, m, msg in reader.iter_decoded_messages(topics=topics)]


def test_the_file_is_a_valid_indexed_mcap_in_foxglove_schemas(tmp_path):
    from mcap.reader import NonSeekingReader, make_reader

    sim = hybrid.load()
    with Recorder(tmp_path / "run.mcap", sim) as rec:
        run(sim, 0.05, observers=[rec])
    with open(tmp_path / "run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        assert {c.message_encoding for c in summary.channels.values()} == {"protobuf"}
        assert {s.encoding for s in schemas.values()} == {"protobuf"}
        assert schemas["/membrane/mesh"].name == "foxglove.SceneUpdate"
        assert schemas["/rigid/geoms"].name == "foxglove.SceneUpdate"
        assert schemas["/rigid/transforms"].name == "foxglove.FrameTransforms"
        assert schemas["/volume"].name == "hybrid.Scalar"
        assert "/membrane/points" not in schemas  # a small mesh: the triangle list every frame
        assert summary.statistics.message_count == sum(summary.statistics.channel_message_counts.values())
    msgs = _decoded(tmp_path / "run.mcap", ["/membrane/mesh"])
    assert len(msgs) == 6
    log_ns, scene = msgs[-1]
    entity = scene.entities[0]
    assert entity.timestamp.seconds * 10**9 + entity.timestamp.nanos == log_ns
    tri = entity.triangles[0]
    assert len(tri.points) == sim.model.nvert
    assert len(tri.colors) == sim.model.nvert
    np.testing.assert_array_equal(np.reshape(tri.indices, (-1, 3)), sim.model.mesh.face_vert)
    np.testing.assert_array_equal([(p.x, p.y, p.z) for p in tri.points], sim.vert_pos)
    geoms = _decoded(tmp_path / "run.mcap", ["/rigid/geoms"])[0][1]
    assert {e.frame_id for e in geoms.entities} == {"spine", "rib_left", "rib_right"}
    assert sum(len(e.cylinders) + len(e.spheres) + len(e.cubes) for e in geoms.entities) > 0
    with open(tmp_path / "run.mcap", "rb") as f:  # the CRCs hold
        assert sum(1 for _ in NonSeekingReader(f, validate_crcs=True).iter_messages()) == summary.statistics.message_count


def test_a_large_mesh_records_a_point_cloud_every_frame_and_the_triangles_less_often(tmp_path):
    """`mesh_every` > 1 (the default above MESH_EVERY_FRAME_MAX points): the points as
    a float32 cloud every frame, the triangle list every mesh_every frames; the time
    stamps past one second carry their seconds."""
    sim = hybrid.load(membrane_demo())
    copies = _Copies()
    with Recorder(tmp_path / "run.mcap", sim, every_s=0.05, mesh_every=4) as rec:
        run(sim, 1.2, observers=[copies, rec])
    data = read(tmp_path / "run.mcap")
    cloud, mesh = data["/membrane/points"], data["/membrane/mesh"]
    assert data["membrane"]["pos"] is cloud["pos"]
    np.testing.assert_allclose(cloud["t"], np.arange(25) * 0.05, atol=1e-9)
    np.testing.assert_array_equal(cloud["pos"], np.asarray(copies.pos[::5]).astype(np.float32))
    np.testing.assert_array_equal(cloud["rgba"], np.round(data["model"]["vert_rgba"] * 255))
    np.testing.assert_allclose(mesh["t"], np.arange(0, 25, 4) * 0.05, atol=1e-9)
    np.testing.assert_array_equal(mesh["pos"], np.asarray(copies.pos[::20]))
    for log_ns, msg in _decoded(tmp_path / "run.mcap", ["/membrane/points", "/membrane/mesh"]):
        stamp = msg.timestamp if hasattr(msg, "data") else msg.entities[0].timestamp
        assert stamp.seconds * 10**9 + stamp.nanos == log_ns


def test_the_encoder_is_compiled_once_before_the_run_for_the_types_the_run_passes(tmp_path):
    """Recorder() compiles (or loads) the encoder; the writer thread, small meshes and
    large, then finds it ready rather than compiling again while the run waits."""
    from hybrid.record.encoder import _encode_frames

    for mesh_every in (1, 4):
        sim = hybrid.load(membrane_demo())
        with Recorder(tmp_path / f"run{mesh_every}.mcap", sim, mesh_every=mesh_every) as rec:
            assert len(_encode_frames.signatures) == 1
            run(sim, 0.2, observers=[rec])
    assert len(_encode_frames.signatures) == 1


def _diverging_scene():
    return dataclasses.replace(membrane_demo(), dt_s=0.006)  # diverges at step 11 (t = 0.066 s)


def test_a_run_that_diverges_leaves_every_frame_up_to_the_divergence(tmp_path):
    sim = hybrid.load(_diverging_scene())
    copies = _Copies()
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
    for topic in SCALAR_CHANNELS:
        assert len(data[topic]["t"]) == len(frames)


def test_the_cli_run_that_diverges_still_writes_a_readable_recording(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "membrane_demo", "--dt", "0.006", "--duration", "1", "--out", str(out)]) == 2
    assert "diverged" in capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    data = read(out / "run.mcap")
    t = data["membrane"]["t"]
    # frames every 2 steps (0.012 s) up to the last complete one before the failing step
    expected = np.arange(0, summary["steps"] + 1, 2) * 0.006
    np.testing.assert_allclose(t, expected, rtol=0, atol=1e-9)


def test_an_unfinished_file_reads_up_to_its_last_complete_chunk(tmp_path):
    """A killed process leaves no summary: the reader takes what is there."""
    sim = hybrid.load(membrane_demo())
    path = tmp_path / "run.mcap"
    rec = Recorder(path, sim, chunk_size=4096)
    run(sim, 0.5, observers=[rec])
    rec.flush()  # as the periodic flush does; then the process "dies" (no close)
    whole = path.read_bytes()
    path.write_bytes(whole[: len(whole) - 1000])  # and a torn last record
    data = read(path)
    t = data["membrane"]["t"]
    assert 10 < len(t) < 51
    np.testing.assert_allclose(t, np.arange(len(t)) * 0.01, atol=1e-9)
    rec._fw._file.close()


def test_no_record_and_record_every(tmp_path):
    assert main(["run", "membrane_demo", "--duration", "0.1", "--out", str(tmp_path / "a"), "--no-record"]) == 0
    assert not (tmp_path / "a" / "run.mcap").exists()
    assert main(["run", "membrane_demo", "--duration", "0.1", "--out", str(tmp_path / "b"),
                 "--record-every", "0.05"]) == 0
    np.testing.assert_allclose(read(tmp_path / "b" / "run.mcap")["/pressure"]["t"], [0.0, 0.05, 0.1], atol=1e-9)


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

    path = tmp_path / "run.mcap"
    script = ("import hybrid\n"
              "from hybrid.demo import membrane_demo\n"
              "from hybrid.record import Recorder\n"
              "from hybrid.run import run\n"
              "sim = hybrid.load(membrane_demo(duration_s=1000.0))\n"
              f"rec = Recorder({str(path)!r}, sim, flush_s=0.05)\n"
              "run(sim, 1000.0, observers=[rec])\n")
    proc = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 60
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


def test_a_recording_in_another_encoding_is_refused_with_a_clear_error(tmp_path):
    """Earlier versions of hybrid wrote JSON messages: read() names the channel and its encoding."""
    from mcap.writer import Writer

    path = tmp_path / "old.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("hybrid.Scalar", "jsonschema", b"{}")
        ch = w.register_channel("/volume", "json", schema)
        w.add_message(ch, 0, b'{"t":0,"value":1}', 0)
        w.finish()
    with pytest.raises(hybrid.HybridError, match=r"/volume is encoded in 'json'; expected 'protobuf'"):
        read(path)
    assert main(["render", str(path), "--out", str(tmp_path / "figs")]) == 2
