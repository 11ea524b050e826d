"""Reading a recording back, checked (hybrid.record.read): every chunk's CRC and
header, the file's structure, salvage, foreign files, and truncated ends."""

from __future__ import annotations

import shutil
import warnings

import numpy as np
import pytest

import hybrid
from hybrid.cli import main
from hybrid.demo import membrane_demo
from hybrid.record import Recorder, RecordingError, RecordingWarning, read
from hybrid.run import run

# a chunk record: opcode 1, length 8, message start and end times 8 + 8,
# uncompressed size 8, uncompressed CRC 4, compression (length 4, "zstd"), data length 8
CHUNK_FIELDS = {
    "opcode": (0, 1),
    "record length": (1, 8),
    "message start time": (9, 8),
    "message end time": (17, 8),
    "uncompressed size": (25, 8),
    "uncompressed crc": (33, 4),
    "compression length": (37, 4),
    "compression": (41, 4),
    "data length": (45, 8),
}
DATA_AT = 53


def _chunk_indexes(path):
    """The chunks as mcap's own reader finds them in the summary (not hybrid's reader)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset), summary


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """A finished recording of 0.3 s of membrane_demo in small chunks (a few frames each)."""
    path = tmp_path_factory.mktemp("short") / "run.mcap"
    sim = hybrid.load(membrane_demo())
    with Recorder(path, sim, chunk_size=1 << 14) as rec:
        run(sim, 0.3, observers=[rec])
    return path


def _flips(rec_offset, compressed_size):
    """(what, byte offset, bit) to flip in one chunk: a low and a high bit of each
    header field, and bits at the start, middle and end of its compressed data."""
    out = []
    for name, (at, n) in CHUNK_FIELDS.items():
        out.append((f"{name}, low bit", rec_offset + at, 0))
        out.append((f"{name}, high bit", rec_offset + at + n - 1, 7))
    for where, k in (("start", 0), ("middle", compressed_size // 2), ("end", compressed_size - 1)):
        out.append((f"data {where}", rec_offset + DATA_AT + k, 3))
    return out


def _flipped(whole: bytes, offset: int, bit: int) -> bytes:
    b = bytearray(whole)
    b[offset] ^= 1 << bit
    return bytes(b)


def test_a_bit_flipped_in_any_chunk_of_a_finished_file_raises_naming_the_chunk(short, tmp_path):
    """Issue 16, item 3: a bit flipped anywhere in a recording's chunks (each header
    field, the compressed data, the message indexes) makes read() raise, naming the
    chunk, its time range and its byte offset."""
    whole = short.read_bytes()
    chunks, _ = _chunk_indexes(short)
    assert len(chunks) >= 5
    bad = tmp_path / "bad.mcap"
    for i, c in enumerate(chunks):
        flips = _flips(c.chunk_start_offset, c.compressed_size)
        index_at = c.chunk_start_offset + c.chunk_length
        flips += [("message index", index_at + k, 0) for k in (0, 9, 11, c.message_index_length - 1)]
        for what, offset, bit in flips:
            bad.write_bytes(_flipped(whole, offset, bit))
            with pytest.raises(RecordingError) as exc:
                read(bad)
            msg = str(exc.value)
            assert "\n" not in msg
            assert (
                f"chunk {i + 1} of {len(chunks)} (t {c.message_start_time * 1e-9:.6g} to "
                f"{c.message_end_time * 1e-9:.6g} s, byte offset {c.chunk_start_offset})" in msg
            ), (what, msg)


def test_a_bit_flipped_in_any_chunk_of_an_unfinished_file_raises(short, tmp_path):
    """Issue 16, item 3: without a summary (a killed run) the chunks are found from
    their own headers; a flip in any of them is still an error, not a truncated end."""
    chunks, summary = _chunk_indexes(short)
    data_end = max(c.chunk_start_offset + c.chunk_length + c.message_index_length for c in chunks)
    whole = short.read_bytes()[:data_end]  # every chunk and its indexes, no data end, summary or footer
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(whole)
    with pytest.warns(RecordingWarning, match="ends at byte"):
        clean = read(bad)
    assert len(clean["membrane"]["t"]) == summary.statistics.channel_message_counts[1]
    for i, c in enumerate(chunks):
        for what, offset, bit in _flips(c.chunk_start_offset, c.compressed_size):
            bad.write_bytes(_flipped(whole, offset, bit))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RecordingWarning)
                with pytest.raises(RecordingError, match=r"corrupt") as exc:
                    read(bad)
            assert f"byte offset {c.chunk_start_offset}" in str(exc.value), (i, what, str(exc.value))


def test_a_file_cut_anywhere_in_its_last_chunk_reads_up_to_the_chunk_before_with_a_warning(short, tmp_path):
    """Issue 16, item 3: truncated at the end (a killed run) is allowed and reported;
    every complete chunk is read, the torn one left out."""
    chunks, _ = _chunk_indexes(short)
    whole = short.read_bytes()
    full = read(short)["membrane"]
    last = chunks[-1]
    before = int(np.sum(full["t"] * 1e9 < last.message_start_time - 1))
    cut = tmp_path / "cut.mcap"
    end = last.chunk_start_offset + last.chunk_length
    for n in list(range(last.chunk_start_offset, end, max(1, last.chunk_length // 40))) + [end - 1]:
        cut.write_bytes(whole[:n])
        with pytest.warns(RecordingWarning, match=f"ends at byte {n}"):
            got = read(cut)["membrane"]
        np.testing.assert_array_equal(got["t"], full["t"][:before])
        np.testing.assert_array_equal(got["pos"], full["pos"][:before])
    # cut inside its message indexes: the chunk itself is whole, and read
    cut.write_bytes(whole[: end + 5])
    with pytest.warns(RecordingWarning, match="ends at byte"):
        got = read(cut)["membrane"]
    np.testing.assert_array_equal(got["pos"], full["pos"])


def test_salvage_skips_the_corrupt_chunk_and_says_which(short, tmp_path):
    """Issue 16, item 3: strict=False reads every sound chunk and warns of the one skipped."""
    chunks, _ = _chunk_indexes(short)
    c = chunks[2]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(_flipped(short.read_bytes(), c.chunk_start_offset + DATA_AT + c.compressed_size // 2, 5))
    with pytest.warns(
        RecordingWarning, match=rf"chunk 3 of {len(chunks)} .*byte offset {c.chunk_start_offset}\).*skipped"
    ):
        got = read(bad, strict=False)["membrane"]
    full = read(short)["membrane"]
    keep = (full["t"] * 1e9 < c.message_start_time - 1) | (full["t"] * 1e9 > c.message_end_time + 1)
    assert 0 < keep.sum() < len(keep)
    np.testing.assert_array_equal(got["t"], full["t"][keep])
    np.testing.assert_array_equal(got["pos"], full["pos"][keep])


def test_a_damaged_summary_or_model_description_is_an_error(short, tmp_path):
    """Issue 16, item 3: the summary is checked by the footer's CRC, the model's
    description by its own."""
    chunks, _ = _chunk_indexes(short)
    whole = short.read_bytes()
    bad = tmp_path / "bad.mcap"
    summary_at = chunks[-1].chunk_start_offset + chunks[-1].chunk_length + chunks[-1].message_index_length + 13
    bad.write_bytes(_flipped(whole, summary_at + 40, 1))
    with pytest.raises(RecordingError, match="summary .* is corrupt: its CRC"):
        read(bad)
    at = whole.index(b'"face_vert": [[') + 20  # a digit of a face's point index
    bad.write_bytes(_flipped(whole, at, 0))
    with pytest.raises(RecordingError, match="model's description .* is corrupt"):
        read(bad)
    bad.write_bytes(whole[:-1] + b"X")  # the final magic
    with pytest.raises(RecordingError, match="after its footer .* is corrupt"):
        read(bad)


def test_a_png_or_a_text_is_not_an_mcap_and_an_mcap_of_another_writer_is_not_ours(tmp_path):
    """Issue 16, item 3: refused with one line (a PNG came back as {})."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    png = tmp_path / "figure.png"
    plt.imsave(png, np.zeros((4, 4)))
    with pytest.raises(RecordingError, match=r"not an MCAP file: it starts with b'\\x89PNG"):
        read(png)
    text = tmp_path / "notes.mcap"
    text.write_text("breathing\n" * 10)
    with pytest.raises(RecordingError, match="not an MCAP file"):
        read(text)
    from mcap.writer import Writer

    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start()
        ch = w.register_channel("/volume", "protobuf", w.register_schema("hybrid.Scalar", "protobuf", b""))
        w.add_message(ch, 0, b"", 0)
        w.finish()
    with pytest.raises(RecordingError, match="not a recording of hybrid: its header names the library 'mcap-python/"):
        read(other)


def test_render_of_a_corrupt_recording_prints_one_line_and_exits_2(short, tmp_path, capsys):
    """Issue 16, item 3: `hybrid render` on a corrupt file: one line, status 2, no traceback."""
    chunks, _ = _chunk_indexes(short)
    c = chunks[1]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(_flipped(short.read_bytes(), c.chunk_start_offset + DATA_AT + 7, 2))
    capsys.readouterr()
    assert main(["render", str(bad), "--out", str(tmp_path / "figs")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hybrid: error: recording ")
    assert f"chunk 2 of {len(chunks)}" in err and "Traceback" not in err
    png = tmp_path / "picture.mcap"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    assert main(["render", str(png), "--out", str(tmp_path / "figs")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not an MCAP file" in err


def test_render_of_a_truncated_recording_draws_it_and_says_so_in_one_line(short, tmp_path, capsys):
    """Issue 16, item 3: a killed run's recording is drawn from what it holds; the
    warning is one line."""
    chunks, _ = _chunk_indexes(short)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(short.read_bytes()[: chunks[-1].chunk_start_offset + 100])
    capsys.readouterr()
    assert main(["render", str(cut), "--out", str(tmp_path / "figs")]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hybrid: warning: recording ") and "ends at byte" in err


def test_an_empty_file_is_a_run_stopped_before_its_first_frame(tmp_path):
    """A run killed before its first frames leaves the file empty: nothing, with a warning."""
    empty = tmp_path / "run.mcap"
    empty.write_bytes(b"")
    with pytest.warns(RecordingWarning, match="before its first record"):
        assert read(empty) == {}


def test_a_copy_reads_the_same(short, tmp_path):
    """The checks accept every sound file: the recording, read twice, is the same."""
    copy = tmp_path / "copy.mcap"
    shutil.copy(short, copy)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a, b = read(short), read(copy)
    np.testing.assert_array_equal(a["membrane"]["pos"], b["membrane"]["pos"])
    assert set(a) == set(b)


def test_salvage_of_a_file_with_a_damaged_summary_reads_its_chunks(short, tmp_path):
    """Issue 16, item 3: strict=False reads the chunks from their own headers when the
    summary is corrupt, and says so."""
    chunks, _ = _chunk_indexes(short)
    whole = short.read_bytes()
    summary_at = chunks[-1].chunk_start_offset + chunks[-1].chunk_length + chunks[-1].message_index_length + 13
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(_flipped(whole, summary_at + 40, 1))
    with pytest.warns(RecordingWarning, match="summary .* is corrupt: its CRC .* one by one"):
        got = read(bad, strict=False)
    np.testing.assert_array_equal(got["membrane"]["pos"], read(short)["membrane"]["pos"])
