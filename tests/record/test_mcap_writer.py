"""The MCAP file writer (hybrid.record.mcap_writer) and its schemas: a valid, indexed MCAP
in Foxglove's well-known schemas, read by mcap's own reader with its CRCs checked."""

from __future__ import annotations

import numpy as np
from helpers import decoded_messages

import hybrid
from hybrid.record import Recorder
from hybrid.run import run


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
    msgs = decoded_messages(tmp_path / "run.mcap", ["/membrane/mesh"])
    assert len(msgs) == 6
    log_ns, scene = msgs[-1]
    entity = scene.entities[0]
    assert entity.timestamp.seconds * 10**9 + entity.timestamp.nanos == log_ns
    tri = entity.triangles[0]
    assert len(tri.points) == sim.model.nvert
    assert len(tri.colors) == sim.model.nvert
    np.testing.assert_array_equal(np.reshape(tri.indices, (-1, 3)), sim.model.mesh.face_vert)
    np.testing.assert_array_equal([(p.x, p.y, p.z) for p in tri.points], sim.vert_pos)
    geoms = decoded_messages(tmp_path / "run.mcap", ["/rigid/geoms"])[0][1]
    assert {e.frame_id for e in geoms.entities} == {"spine", "rib_left", "rib_right"}
    assert sum(len(e.cylinders) + len(e.spheres) + len(e.cubes) for e in geoms.entities) > 0
    with open(tmp_path / "run.mcap", "rb") as f:  # the CRCs hold
        assert (
            sum(1 for _ in NonSeekingReader(f, validate_crcs=True).iter_messages()) == summary.statistics.message_count
        )
