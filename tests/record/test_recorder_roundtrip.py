"""Property: what the recorder writes, the reader gives back exactly (positions
as the doubles they were, times, the volume channel), for any mesh size and any
sequence of states, with or without the writer thread."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hybrid
from hybrid.record import Recorder, read

# small meshes (a triangle list every frame) and one above the point-cloud
# threshold (float32 cloud every frame, the exact triangle list every 10th)
MESHES = {
    "icosahedron": hybrid.MeshSpec("icosahedron"),
    "uv_sphere": hybrid.MeshSpec("uv_sphere"),
    "icosphere_4": hybrid.MeshSpec("icosphere", subdivisions=4),
}
_SIMS: dict = {}


def _sim(mesh: str):
    if mesh not in _SIMS:  # one compiled model per mesh for every example
        scene = hybrid.Scene(
            mesh=MESHES[mesh], masses=hybrid.Masses(total_kg=1.0), forces=(), constraints=(hybrid.Volume(),), dt_s=1e-3
        )
        _SIMS[mesh] = hybrid.load(scene)
    return _SIMS[mesh]


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    mesh=st.sampled_from(sorted(MESHES)),
    nframe=st.integers(1, 25),
    seed=st.integers(0, 2**32 - 1),
    scale=st.floats(1e-3, 1e2),
    background=st.booleans(),
)
def test_what_is_recorded_reads_back_exactly(mesh, nframe, seed, scale, background):
    sim = _sim(mesh)
    rng = np.random.default_rng(seed)
    rest = sim.model.mesh.vert_pos
    # frames at whole numbers of recording intervals (10 steps of 1 ms), a random gap apart
    steps = 10 * np.cumsum(rng.integers(1, 50, nframe))
    times = steps * sim.model.dt_s
    poses = [rest * (1 + 0.1 * rng.standard_normal()) + scale * rng.standard_normal(rest.shape) for _ in range(nframe)]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.mcap"
        rec = Recorder(path, sim, every_s=0.01, background=background)
        volumes = []
        for t, pos in zip(times, poses):
            sim.set_state(vert_pos=pos, time_s=float(t))  # its step count follows: t / dt
            rec(sim)
            volumes.append(sim.volume)
        rec.close()
        data = read(path)
    got = data["membrane"]
    # MCAP's log times are whole nanoseconds
    assert np.allclose(got["t"], times, rtol=0.0, atol=1e-9) and len(got["t"]) == nframe
    if sim.model.nvert <= 2000:  # the triangle list: the doubles themselves
        assert np.array_equal(got["pos"], np.array(poses))
    else:  # the point cloud: float32 of them; the triangle list exact where written
        assert np.array_equal(got["pos"], np.array(poses, np.float32))
        mesh_frames = data["/membrane/mesh"]
        every = [int(np.argmin(abs(times - t))) for t in mesh_frames["t"]]
        assert np.array_equal(mesh_frames["pos"], np.array(poses)[every])
    assert np.allclose(data["/volume"]["value"], volumes, rtol=1e-12, atol=0.0)
