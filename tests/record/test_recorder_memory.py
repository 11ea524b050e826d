"""The recorder's memory is flat (issue 31, item 9): what it keeps is per chunk (the
summary's chunk index, serialized as each chunk is written), not per message or frame.

The recorder alone, fed synthetic frames of the 80-point membrane at the default
interval (10 steps a frame): 10^7 steps would be 10^6 frames, about a minute here, so
the growth is measured at two sizes ten times apart and extrapolated."""

from __future__ import annotations

import tracemalloc

import numpy as np

import hybrid
from hybrid.record import Recorder
from hybrid.step import F_TIME

#: frames offered a call (as the runner's compiled calls do)
PER_CALL = 1000


def _growth_bytes(sim, nframe: int) -> tuple[float, int]:
    """Traced memory the recorder holds after nframe frames more than after its first call."""
    rec = Recorder("/dev/null", sim)  # a device is written as it is, never replaced
    every = rec.every_steps
    frames = sim.frames_buffer(PER_CALL)
    frames.pos[:] = sim.vert_pos
    tracemalloc.start()
    try:
        done, base = 0, None
        while done < nframe:
            k = min(PER_CALL, nframe - done)
            frames.count = k
            frames.scal[:k, F_TIME] = (np.arange(done, done + k) + 1) * every * sim.model.dt_s
            rec.frames(sim, frames)
            done += k
            if base is None:
                rec.flush()
                base = tracemalloc.get_traced_memory()[0]
        rec.flush()  # everything written: what is left is what the recorder keeps
        grown = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
        rec.close()
    return grown, every


def test_recording_memory_grows_per_chunk_not_per_frame():
    sim = hybrid.load("membrane_demo")
    small, every = _growth_bytes(sim, 20_000)
    large, _ = _growth_bytes(sim, 200_000)
    per_frame = (large - small) / 180_000
    # 10^7 steps against 10^6: 9 x 10^5 more frames at 10 steps a frame
    extra_mb = per_frame * (10**7 - 10**6) / every / 1e6
    print(f"{per_frame:.2f} bytes a frame; 10^7 steps hold {extra_mb:.2f} MB more than 10^6")
    assert extra_mb <= 5.0
    # a chunk of this membrane holds about 260 frames and its index record about 250 bytes
    assert per_frame <= 2.0
