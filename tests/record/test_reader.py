"""Reading a recording back (hybrid.record.reader): unfinished files up to their last
complete chunk; other encodings refused with a clear error."""

from __future__ import annotations

import numpy as np
import pytest

import hybrid
from hybrid.cli import main
from hybrid.demo import membrane_demo
from hybrid.record import Recorder, read
from hybrid.run import run


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
