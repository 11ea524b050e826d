"""Reading a recording back, checked (`hybrid.record.mcap_reader`): `read()` decodes each channel with the schemas
the file holds, into numpy arrays by topic, for a time window and a choice of
topics; `frames()` yields the membrane's frames one at a time.

Integrity: every chunk read has its CRC, its header (against the summary's chunk
index, and its start and end times against its messages) and its message indexes
verified; the summary is verified by the footer's CRC and the model's description
by its own. A file whose bytes disagree with themselves is an error
(`RecordingError`) naming the chunk, its time range and its byte offset, unless
read with `strict=False`, which skips the chunk and says so (`RecordingWarning`).
A file that ends inside a record (a killed run) is read up to its last complete
chunk, with a warning; a file that is not an MCAP, or not hybrid's, is refused.

Streaming: a finished file is read through its summary's chunk index, so that only
the chunks whose time range overlaps the window are read and decoded, one at a
time; an unfinished one (no summary) is scanned record by record, chunks outside
the window skipped unread. Memory is that of the window's arrays and one chunk.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import HybridError
from .mcap_reader import RecordingError, RecordingWarning, _Bad, _chunks, _File, _open
from .schemas import SCALAR_CHANNELS, _message_classes

__all__ = ["read", "frames", "RecordingError", "RecordingWarning", "TOPICS"]

#: the topics a hybrid recording may hold ("membrane": the frames' points, from the
#: point cloud where there is one, else from the triangle list)
TOPICS = ("membrane", "/membrane/mesh", "/membrane/points", "/rigid/transforms", "/rigid/geoms", *SCALAR_CHANNELS)


def _window(t_s) -> tuple[int, int]:
    if t_s is None:
        return 0, 2**64 - 1
    try:
        a, b = t_s
        ok = all(not isinstance(v, bool) and isinstance(v, (int, float)) and not math.isnan(v) for v in (a, b))
    except (TypeError, ValueError):
        ok = False
    if not ok or a > b:
        raise HybridError(f"t_s: expected a window (start, end) in s with start <= end, received {t_s!r}")
    lo = 0 if a <= 0 else min(math.ceil(a * 1e9 - 0.5), 2**64 - 1)
    hi = -1 if b < 0 else min(math.floor(b * 1e9 + 0.5), 2**64 - 1)
    return lo, hi


def _topics(topics) -> set | None:
    if topics is None:
        return None
    names = [topics] if isinstance(topics, str) else list(topics)
    unknown = [t for t in names if t not in TOPICS and not str(t).startswith("/loads/")]
    if unknown:
        raise HybridError(f"topics: expected names among {', '.join(TOPICS)} or /loads/...; received {unknown[0]!r}")
    return set(names)


class _Decoder:
    """A chunk's messages decoded into arrays, by topic, and the arrays gathered."""

    def __init__(self, f: _File, wanted: set | None):
        schemas = {s.name: s.data for s in f.schemas.values()}
        try:
            self.classes = _message_classes(schemas)
        except Exception as exc:  # protobuf refuses a schema: name its error
            raise f.error(f"its schemas do not load: {type(exc).__name__}: {exc}") from None
        self.topic = {cid: c.topic for cid, c in f.channels.items()}
        self.schema = {cid: f.schemas[c.schema_id].name for cid, c in f.channels.items() if c.schema_id in f.schemas}
        has_points = "/membrane/points" in self.topic.values()
        if wanted is not None and "membrane" in wanted:
            wanted = wanted | {"/membrane/points" if has_points else "/membrane/mesh"}
        self.wanted = wanted
        self.parts: dict[str, dict[str, list]] = {}
        self.rgba: dict[str, np.ndarray] = {}
        self.bodies: list[str] | None = None

    def chunk(self, raw: bytes, msgs: list, lo: int, hi: int) -> dict[str, dict]:
        """The chunk's messages in [lo, hi] of the wanted topics, as arrays by topic."""
        view = memoryview(raw)
        picked: dict[int, list] = {}
        for ch, t, a, b in msgs:
            if lo <= t <= hi:
                picked.setdefault(ch, []).append((t, a, b))
        out = {}
        for ch, rows in picked.items():
            topic = self.topic[ch]
            if self.wanted is not None and topic not in self.wanted:
                continue
            if ch not in self.schema:
                raise _Bad(f"channel {ch} ({topic}) has no schema")
            decode = self.classes[self.schema[ch]].FromString
            t = np.array([r[0] for r in rows], np.int64) * 1e-9
            try:
                out[topic] = self._decode(topic, decode, [view[a:b] for _, a, b in rows], t)
            except Exception as exc:  # protobuf's DecodeError, or shapes that differ from frame to frame
                raise _Bad(f"its messages of {topic} do not decode: {type(exc).__name__}: {exc}") from None
        return out

    def _decode(self, topic: str, decode, datas: list, t: np.ndarray) -> dict:
        if topic == "/membrane/points":
            xyz = []
            for data in datas:
                arr = np.frombuffer(decode(data).data, dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
                xyz.append(arr["xyz"])
                self.rgba[topic] = arr["rgba"]
            return {"t": t, "pos": np.stack(xyz)}
        if topic == "/membrane/mesh":
            pos = np.empty((len(datas), 0, 3))
            for i, data in enumerate(datas):
                tri = decode(data).entities[0].triangles[0]
                pts = np.array([(p.x, p.y, p.z) for p in tri.points], float).reshape(-1, 3)
                if i == 0:
                    pos = np.empty((len(datas),) + pts.shape)
                pos[i] = pts
                if topic not in self.rgba:
                    self.rgba[topic] = np.array([(c.r, c.g, c.b, c.a) for c in tri.colors], float)
            return {"t": t, "pos": pos}
        if topic == "/rigid/transforms":
            trans, quat = [], []
            for data in datas:
                tfs = decode(data).transforms
                self.bodies = self.bodies or [tf.child_frame_id for tf in tfs]
                trans.append([(tf.translation.x, tf.translation.y, tf.translation.z) for tf in tfs])
                quat.append([(tf.rotation.w, tf.rotation.x, tf.rotation.y, tf.rotation.z) for tf in tfs])
            return {"t": t, "pos": np.array(trans, float), "quat": np.array(quat, float)}
        if topic in SCALAR_CHANNELS or topic.startswith("/loads/"):
            return {"t": t, "value": np.array([decode(d).value for d in datas], float)}
        return {"t": t}

    def add(self, decoded: dict) -> None:
        for topic, arrays in decoded.items():
            parts = self.parts.setdefault(topic, {})
            for key, arr in arrays.items():
                parts.setdefault(key, []).append(arr)

    def result(self) -> dict[str, dict]:
        out: dict[str, dict] = {}
        for topic, parts in self.parts.items():
            out[topic] = {key: np.concatenate(arrs) for key, arrs in parts.items()}
            if topic in self.rgba:
                out[topic]["rgba"] = self.rgba[topic]
            if topic == "/rigid/transforms":
                out[topic] = {
                    "t": out[topic]["t"],
                    "bodies": self.bodies,
                    "pos": out[topic]["pos"],
                    "quat": out[topic]["quat"],
                }
        return out


def read(
    path: str | Path, *, t_s: tuple[float, float] | None = None, topics=None, strict: bool = True
) -> dict[str, dict]:
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

    `t_s` = (start, end) s: only the messages logged in that window (ends included),
    reading only the chunks that overlap it; `topics`: only those (names of `TOPICS`;
    "model" always comes). Every chunk read is verified: a corrupt one raises
    `RecordingError` naming it, its time range and byte offset; `strict=False` skips
    it with a `RecordingWarning`. Unfinished files (a killed run) are read up to their
    last complete chunk, with a `RecordingWarning` saying where they end.
    """
    path = Path(path)
    lo, hi = _window(t_s)
    wanted = _topics(topics)
    with open(path, "rb") as fh:
        f = _open(fh, path, strict)
        dec = _Decoder(f, wanted)
        for decoded in _chunks(fh, f, lo, hi, strict, lambda raw, msgs: dec.chunk(raw, msgs, lo, hi)):
            dec.add(decoded)
    out = dec.result()
    every = out.get("/membrane/points") or out.get("/membrane/mesh")
    if every is not None and (wanted is None or "membrane" in wanted):
        out["membrane"] = {"t": every["t"], "pos": every["pos"]}
        if wanted is not None:
            for topic in ("/membrane/points", "/membrane/mesh"):
                if topic not in wanted:
                    out.pop(topic, None)
    if f.meta is not None:
        out["model"] = f.meta
    return out


def frames(
    path: str | Path, *, t_s: tuple[float, float] | None = None, strict: bool = True
) -> Iterator[tuple[float, np.ndarray]]:
    """The membrane's recorded frames as (t s, points (nvert, 3) m), one at a time,
    in order: memory is one chunk's, whatever the file's length. `t_s` and `strict`
    as for `read`."""
    path = Path(path)
    lo, hi = _window(t_s)
    with open(path, "rb") as fh:
        f = _open(fh, path, strict)
        dec = _Decoder(f, {"membrane"})
        topic = "/membrane/points" if "/membrane/points" in dec.topic.values() else "/membrane/mesh"
        dec.wanted = {topic}
        for decoded in _chunks(fh, f, lo, hi, strict, lambda raw, msgs: dec.chunk(raw, msgs, lo, hi)):
            part = decoded.get(topic)
            if part is not None:
                yield from zip(part["t"].tolist(), part["pos"])
