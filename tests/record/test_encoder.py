"""The compiled protobuf encoder (hybrid.record.encoder): compiled once, before the run."""

from __future__ import annotations

import hybrid
from hybrid.demo import membrane_demo
from hybrid.record import Recorder
from hybrid.run import run


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
