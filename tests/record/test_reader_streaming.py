"""Reading a long recording by window, by topic and frame by frame
(hybrid.record.read(t_s=..., topics=...), hybrid.record.frames): only the chunks
that overlap the window are read, and memory is the window's, not the file's."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import hybrid
import hybrid.record.mcap_reader as reader  # where the chunks are loaded
from hybrid.demo import membrane_demo
from hybrid.record import Recorder, RecordingWarning, frames, read
from hybrid.run import run

DURATION_S = 200.0  # 20,001 frames 10 ms apart, about 40 MB


@pytest.fixture(scope="module")
def long(tmp_path_factory):
    path = tmp_path_factory.mktemp("long") / "run.mcap"
    sim = hybrid.load(membrane_demo(duration_s=DURATION_S))
    with Recorder(path, sim, every_s=0.01) as rec:
        run(sim, DURATION_S, observers=[rec])
    return path


def _overlapping(path, a_s, b_s):
    """The chunks whose time range overlaps [a, b], and all of them, from mcap's own reader."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    near = [c for c in chunks if c.message_start_time <= b_s * 1e9 and c.message_end_time >= a_s * 1e9]
    return near, chunks


@pytest.fixture
def loads(monkeypatch):
    """The chunks the reader reads and decompresses, by byte offset."""
    seen = []
    load = reader._load

    def counting(fh, f, c):
        seen.append(c.chunk_start_offset)
        return load(fh, f, c)

    monkeypatch.setattr(reader, "_load", counting)
    return seen


def _peak_bytes(fn):
    tracemalloc.start()
    try:
        out = fn()
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_one_second_of_a_long_recording_reads_only_its_chunks_in_memory_bounded_by_the_window(long, loads):
    """Issue 16, item 5: read(path, t_s=(a, b)) seeks the chunks that overlap the
    window through the chunk index, and holds one chunk and the window's arrays."""
    near, chunks = _overlapping(long, 100.0, 101.0)
    assert long.stat().st_size > 20e6 and len(chunks) > 100 and len(near) <= 3
    data, peak = _peak_bytes(lambda: read(long, t_s=(100.0, 101.0)))
    assert sorted(loads) == sorted(c.chunk_start_offset for c in near)
    t = data["membrane"]["t"]
    np.testing.assert_allclose(t, 100.0 + 0.01 * np.arange(101), rtol=0, atol=1e-9)  # both ends included
    assert data["membrane"]["pos"].shape == (101, 80, 3)
    for topic in ("/volume", "/pressure"):
        np.testing.assert_array_equal(data[topic]["t"], t)
    window = sum(a.nbytes for topic in data.values() for a in topic.values() if isinstance(a, np.ndarray))
    chunk = max(c.uncompressed_size for c in near) + max(c.compressed_size for c in near)
    assert peak < 2 * chunk + 4 * window, (peak, chunk, window)
    assert peak < long.stat().st_size / 10


def test_topics_and_windows_select_what_a_full_read_holds(long):
    """Issue 16, item 5: a window and a choice of topics give the same values as the
    whole file's read, cut."""
    part = read(long, t_s=(37.005, 37.5), topics=["/volume", "membrane"])
    assert set(part) == {"/volume", "membrane", "model"}
    np.testing.assert_allclose(part["/volume"]["t"], 37.01 + 0.01 * np.arange(50), rtol=0, atol=1e-9)
    wide = read(long, t_s=(36.0, 38.0))
    keep = (wide["/volume"]["t"] >= 37.005) & (wide["/volume"]["t"] <= 37.5)
    np.testing.assert_array_equal(part["/volume"]["value"], wide["/volume"]["value"][keep])
    np.testing.assert_array_equal(part["membrane"]["pos"], wide["membrane"]["pos"][keep])
    assert read(long, t_s=(DURATION_S + 1, DURATION_S + 2)).keys() == {"model"}
    with pytest.raises(hybrid.HybridError, match="topics: expected names among .* received '/volumes'"):
        read(long, topics=["/volumes"])
    with pytest.raises(hybrid.HybridError, match=r"t_s: expected a window \(start, end\) .* received \(2, 1\)"):
        read(long, t_s=(2, 1))


def test_frames_yields_the_points_one_at_a_time_in_memory_independent_of_the_window(long):
    """Issue 16, item 5: frames() streams: 10 s of frames take about the memory of one chunk."""
    got, peak = _peak_bytes(lambda: [(t, p.sum()) for t, p in frames(long, t_s=(50.0, 60.0))])
    assert len(got) == 1001
    np.testing.assert_allclose([t for t, _ in got], 50.0 + 0.01 * np.arange(1001), rtol=0, atol=1e-9)
    near, _ = _overlapping(long, 50.0, 51.0)
    chunk = max(c.uncompressed_size for c in near) + max(c.compressed_size for c in near)
    assert peak < 3 * chunk
    first = next(frames(long, t_s=(50.0, 60.0)))
    np.testing.assert_array_equal(first[1], read(long, t_s=(50.0, 50.0))["membrane"]["pos"][0])


def test_an_unfinished_long_recording_is_read_by_window_without_decoding_the_rest(long, tmp_path, loads):
    """Issue 16, item 5: without a summary the chunks are found from their headers;
    only those in the window are decompressed."""
    near, chunks = _overlapping(long, 100.0, 101.0)
    cut = tmp_path / "cut.mcap"
    with open(long, "rb") as f:
        cut.write_bytes(f.read(chunks[len(chunks) * 3 // 4].chunk_start_offset + 1000))
    with pytest.warns(RecordingWarning, match="ends at byte"):
        data = read(cut, t_s=(100.0, 101.0))
    assert sorted(loads) == sorted(c.chunk_start_offset for c in near)
    np.testing.assert_array_equal(data["membrane"]["pos"], read(long, t_s=(100.0, 101.0))["membrane"]["pos"])
