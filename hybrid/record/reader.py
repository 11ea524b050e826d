"""Reading a recording back: `read()` decodes each channel with the schemas the
file holds, into numpy arrays by topic; unfinished files are read up to their last
complete record."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import HybridError
from .schemas import SCALAR_CHANNELS, _message_classes


def _records(path: Path):
    """Every record of an MCAP file in order; stops quietly at a truncated end."""
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        it = iter(StreamReader(f).records)
        while True:
            try:
                rec = next(it)
            except StopIteration:
                return
            except Exception:  # a truncated tail (McapError, EOFError, struct and index errors, ...)
                return
            yield rec


def read(path: str | Path) -> dict[str, dict]:
    """The recorded channels of `path` as numpy arrays, by topic.

    - "membrane": every recorded frame's points, {"t": (nframe,) s, "pos": (nframe,
      nvert, 3) m}, from "/membrane/mesh" or, where the triangle list was written less
      often (large meshes), from "/membrane/points";
    - "/membrane/mesh": {"t": (n,) s, "pos": (n, nvert, 3) float64 m (exact), "rgba":
      (nvert, 4) 0..1} from the triangle list;
    - "/membrane/points" (large meshes): {"t", "pos": float32 m, "rgba": (nvert, 4) uint8};
    - scalar topics ("/volume", ...): {"t": (n,) s, "value": (n,)};
    - "/rigid/transforms": {"t": (nframe,), "bodies": [names], "pos": (nframe, nbody, 3),
      "quat": (nframe, nbody, 4) (w, x, y, z as MuJoCo)};
    - "model": the recorded description (faces as an (nface, 3) array, regions,
      per-point labels and colours, geoms).

    Messages are decoded with the schemas the file holds. Unfinished files (a killed
    run) are read up to their last complete record.
    """
    from mcap.records import Channel, Message, Metadata, Schema

    path = Path(path)
    schemas: dict[int, tuple[str, bytes]] = {}
    topics: dict[int, tuple[str, int]] = {}
    raw: dict[str, list] = {}
    meta = None
    for rec in _records(path):
        if isinstance(rec, Message):
            topic = topics.get(rec.channel_id)
            if topic is not None:
                raw.setdefault(topic[0], []).append((rec.log_time, rec.data))
        elif isinstance(rec, Channel):
            if rec.message_encoding != "protobuf":
                raise HybridError(f"recording {str(path)!r}: channel {rec.topic} is encoded in "
                                  f"{rec.message_encoding!r}; expected 'protobuf' (a recording of an earlier "
                                  "hybrid, which wrote JSON: run the scene again to record it anew)")
            topics[rec.id] = (rec.topic, rec.schema_id)
        elif isinstance(rec, Schema):
            schemas[rec.id] = (rec.name, rec.data)
        elif isinstance(rec, Metadata) and rec.name == "hybrid" and meta is None:
            meta = json.loads(rec.metadata["description"])
    classes = _message_classes({name: data for name, data in schemas.values()})
    schema_of = {topic: schemas[sid][0] for topic, sid in topics.values() if sid in schemas}
    out: dict[str, dict] = {}
    for topic, msgs in raw.items():
        t = np.array([lt for lt, _ in msgs], np.int64) * 1e-9
        decode = classes[schema_of[topic]].FromString
        if topic == "/membrane/points":
            frames, rgba = [], None
            for _, data in msgs:
                arr = np.frombuffer(decode(data).data, dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
                frames.append(arr["xyz"])
                rgba = arr["rgba"]
            out[topic] = {"t": t, "pos": np.stack(frames), "rgba": rgba}
        elif topic == "/membrane/mesh":
            pos, rgba = [], None
            for _, data in msgs:
                tri = decode(data).entities[0].triangles[0]
                pos.append([(p.x, p.y, p.z) for p in tri.points])
                if rgba is None:
                    rgba = np.array([(c.r, c.g, c.b, c.a) for c in tri.colors], float)
            out[topic] = {"t": t, "pos": np.array(pos, float), "rgba": rgba}
        elif topic == "/rigid/transforms":
            names = None
            pos, quat = [], []
            for _, data in msgs:
                tfs = decode(data).transforms
                names = names or [tf.child_frame_id for tf in tfs]
                pos.append([(tf.translation.x, tf.translation.y, tf.translation.z) for tf in tfs])
                quat.append([(tf.rotation.w, tf.rotation.x, tf.rotation.y, tf.rotation.z) for tf in tfs])
            out[topic] = {"t": t, "bodies": names, "pos": np.array(pos, float), "quat": np.array(quat, float)}
        elif topic in SCALAR_CHANNELS:
            out[topic] = {"t": t, "value": np.array([decode(d).value for _, d in msgs], float)}
        else:
            out[topic] = {"t": t}
    every = out.get("/membrane/points") or out.get("/membrane/mesh")
    if every is not None:
        out["membrane"] = {"t": every["t"], "pos": every["pos"]}
    if meta is not None:
        meta["face_vert"] = np.asarray(meta["face_vert"], np.int64).reshape(-1, 3)
        meta["vert_label"] = np.asarray(meta["vert_label"], int)
        meta["vert_rgba"] = np.asarray(meta["vert_rgba"], float)
        meta["link_vert"] = np.asarray(meta["link_vert"], int)
        out["model"] = meta
    return out
