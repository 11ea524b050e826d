"""The recording's channels (hybrid.record.channels): a large mesh as a point cloud every
frame and its triangles less often."""

from __future__ import annotations

import numpy as np
from helpers import FrameCopies, decoded_messages

import hybrid
from hybrid.demo import membrane_demo
from hybrid.record import Recorder, read
from hybrid.run import run


def test_a_large_mesh_records_a_point_cloud_every_frame_and_the_triangles_less_often(tmp_path):
    """`mesh_every` > 1 (the default above MESH_EVERY_FRAME_MAX points): the points as
    a float32 cloud every frame, the triangle list every mesh_every frames; the time
    stamps past one second carry their seconds."""
    sim = hybrid.load(membrane_demo())
    copies = FrameCopies()
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
    for log_ns, msg in decoded_messages(tmp_path / "run.mcap", ["/membrane/points", "/membrane/mesh"]):
        stamp = msg.timestamp if hasattr(msg, "data") else msg.entities[0].timestamp
        assert stamp.seconds * 10**9 + stamp.nanos == log_ns
