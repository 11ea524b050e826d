"""Record a run to MCAP, in Foxglove's well-known schemas (JSON encoding), and read it back.

`hybrid run` writes `DIR/run.mcap` through a `Recorder`, an observer of the runner
(`hybrid.run.run(..., observers=[rec])`) called at each frame. Channels:

- `/membrane/points`   foxglove.PointCloud, every frame: the membrane's points as
  float32 x, y, z (exact to float32) and their region colour (uint8 r, g, b, a);
- `/membrane/mesh`     foxglove.SceneUpdate: the membrane as one TriangleListPrimitive
  with per-vertex region colours; every frame for meshes up to `MESH_EVERY_FRAME_MAX`
  points, every `mesh_every` frames above (the points channel carries every frame);
- `/rigid/transforms`  foxglove.FrameTransforms: each MuJoCo body's pose (`xpos`,
  `xquat`) as the frame `world` -> body name (scenes with a rigid part);
- `/rigid/geoms`       foxglove.SceneUpdate, once: each body's geoms in its own frame
  (capsules and cylinders as cylinders, spheres, boxes), frame-locked;
- scalars, `hybrid.Scalar` {"t": s, "value": v}: `/volume` (m^3), `/volume_rel_error`,
  `/pressure` (Pa), `/rib_elevation` (mm), `/apex_descent` (mm), `/muscle_stiffness`
  (N/m), `/kinetic_energy` (J), as far as the observer is given them.

Log times are the simulated time in nanoseconds (t = 0 at the start). The model's
description (faces, region of each point, colours, geoms) is an MCAP metadata record
named "hybrid", so that `hybrid render` needs nothing but the file.

Cost: a frame is copied when it comes and encoded with up to 199 others in one pass
(`batch`), the triangle list's points by a compiled formatter, the messages packed
straight into the chunk (`_McapWriter`): about 0.15 s for the 1201 frames of the
12 s breathing run.

Crash safety: the frames held are encoded and the chunk in progress written at least
every `flush_s` seconds of wall time, so a killed process leaves every frame but
those of its last second; `close()` (called in a `finally` by `hybrid run`, or by
`with Recorder(...)`) encodes the rest and finishes the file on an error or an
interrupt. `read` accepts unfinished files (no summary, truncated last record).
"""

from __future__ import annotations

import base64
import json
import math
import struct
import time
from pathlib import Path

import numpy as np

from .kernel import jit

__all__ = ["Recorder", "read", "region_colours", "SCALAR_CHANNELS", "MESH_EVERY_FRAME_MAX"]

#: the scalar channels, and the runner's trace key each one takes its value from
SCALAR_CHANNELS = {
    "/volume": "volume_m3",
    "/volume_rel_error": "volume_rel_error",
    "/pressure": "pressure_pa",
    "/rib_elevation": "rib_lift_mm",
    "/apex_descent": "apex_descent_mm",
    "/muscle_stiffness": "muscle_n_per_m",
    "/kinetic_energy": "kinetic_energy_j",
}

#: meshes with at most this many points get the triangle list every frame
MESH_EVERY_FRAME_MAX = 2000

# a qualitative palette (r, g, b) in 0..1, one colour per region in order
_PALETTE = [(0.84, 0.37, 0.30), (0.30, 0.52, 0.78), (0.45, 0.70, 0.35), (0.93, 0.66, 0.22),
            (0.58, 0.40, 0.74), (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.50, 0.50, 0.50),
            (0.74, 0.74, 0.13), (0.09, 0.75, 0.81)]
_UNLABELLED = (0.80, 0.80, 0.80)

_FLOAT32, _UINT8 = 7, 1  # foxglove.NumericType


def region_colours(model) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Each point's region for display: the smallest region that holds it (the most
    specific: "dome" rather than "diaphragm", "spine" rather than "fixed").
    Returns (names, vert_label (nvert,) int, -1 where no region; colours (nvert, 4) rgba 0..1)."""
    n = model.mesh.nvert
    regions = {k: np.asarray(v, int) for k, v in model.regions.items() if 0 < len(v) < n}
    order = sorted(regions, key=lambda k: (-len(regions[k]), k))  # largest first: the smallest wins
    label = np.full(n, -1)
    for i, name in enumerate(order):
        label[regions[name]] = i
    present = sorted(set(label[label >= 0].tolist()))
    names = [order[i] for i in present]
    remap = np.full(len(order) + 1, -1)
    remap[present] = np.arange(len(present))
    label = remap[label]  # -1 stays -1 (remap[-1])
    colours = np.ones((n, 4))
    for i in range(n):
        colours[i, :3] = _PALETTE[label[i] % len(_PALETTE)] if label[i] >= 0 else _UNLABELLED
    return names, label, colours


@jit
def _format_points(pos, out):  # pragma: no cover - compiled
    """Write pos (n, 3) m as JSON Point3 objects, '{"x":-0.012345,"y":...,"z":...},...',
    with 6 decimals (1 um), into the uint8 buffer out; returns the length. Non-finite
    values are written as 0 (JSON has no NaN). ~50 times faster than '%.6g' formatting."""
    k = 0
    for i in range(pos.shape[0]):
        if i:
            out[k] = 44  # ,
            k += 1
        for a in range(3):
            out[k] = 123 if a == 0 else 44  # { or ,
            out[k + 1] = 34
            out[k + 2] = 120 + a  # x y z
            out[k + 3] = 34
            out[k + 4] = 58  # :
            k += 5
            v = pos[i, a]
            if not (abs(v) < 1e9):
                v = 0.0
            q = int(round(v * 1e6))
            if q < 0:
                out[k] = 45  # -
                k += 1
                q = -q
            ip = q // 1000000
            fp = q - ip * 1000000
            nd = 1
            t = ip // 10
            while t > 0:
                nd += 1
                t //= 10
            t = ip
            for d in range(nd - 1, -1, -1):
                out[k + d] = 48 + t % 10
                t //= 10
            k += nd
            out[k] = 46  # .
            k += 1
            for d in range(5, -1, -1):
                out[k + d] = 48 + fp % 10
                fp //= 10
            k += 6
        out[k] = 125  # }
        k += 1
    return k


def _stamp(t_s: float) -> tuple[int, str]:
    ns = max(0, int(round(t_s * 1e9)))
    return ns, '{"sec":%d,"nsec":%d}' % divmod(ns, 1_000_000_000)


_SCALAR_SCHEMA = {"title": "hybrid.Scalar", "type": "object",
                  "properties": {"t": {"type": "number", "description": "simulated time (s)"},
                                 "value": {"type": "number"}}}


def _foxglove_schemas() -> dict:
    """Minimal JSON schemas of the foxglove messages written here (Foxglove picks the
    decoder by schema name; these list the fields used)."""
    num = {"type": "number"}
    vec = {"type": "object", "properties": {k: num for k in "xyz"}}
    quat = {"type": "object", "properties": {k: num for k in "xyzw"}}
    colour = {"type": "object", "properties": {k: num for k in "rgba"}}
    time_ = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
    pose = {"type": "object", "properties": {"position": vec, "orientation": quat}}
    sized = {"type": "object", "properties": {"pose": pose, "size": vec, "color": colour}}
    cyl = {"type": "object", "properties": {"pose": pose, "size": vec, "bottom_scale": num, "top_scale": num,
                                             "color": colour}}
    tri = {"type": "object", "properties": {"pose": pose, "points": {"type": "array", "items": vec},
                                             "color": colour, "colors": {"type": "array", "items": colour},
                                             "indices": {"type": "array", "items": {"type": "integer"}}}}
    entity = {"type": "object", "properties": {
        "timestamp": time_, "frame_id": {"type": "string"}, "id": {"type": "string"},
        "lifetime": time_, "frame_locked": {"type": "boolean"},
        "cubes": {"type": "array", "items": sized}, "spheres": {"type": "array", "items": sized},
        "cylinders": {"type": "array", "items": cyl}, "triangles": {"type": "array", "items": tri}}}
    field = {"type": "object", "properties": {"name": {"type": "string"}, "offset": {"type": "integer"},
                                               "type": {"type": "integer"}}}
    return {
        "foxglove.SceneUpdate": {"title": "foxglove.SceneUpdate", "type": "object", "properties": {
            "deletions": {"type": "array", "items": {"type": "object"}},
            "entities": {"type": "array", "items": entity}}},
        "foxglove.FrameTransforms": {"title": "foxglove.FrameTransforms", "type": "object", "properties": {
            "transforms": {"type": "array", "items": {"type": "object", "properties": {
                "timestamp": time_, "parent_frame_id": {"type": "string"}, "child_frame_id": {"type": "string"},
                "translation": vec, "rotation": quat}}}}},
        "foxglove.PointCloud": {"title": "foxglove.PointCloud", "type": "object", "properties": {
            "timestamp": time_, "frame_id": {"type": "string"}, "pose": pose,
            "point_stride": {"type": "integer"}, "fields": {"type": "array", "items": field},
            "data": {"type": "string", "contentEncoding": "base64"}}},
        "hybrid.Scalar": _SCALAR_SCHEMA,
    }


_IDENTITY_POSE = '{"position":{"x":0,"y":0,"z":0},"orientation":{"x":0,"y":0,"z":0,"w":1}}'


def _geoms(mj_model) -> list[dict]:
    """Each geom of a body (world geoms too) in its body's frame, for display."""
    out = []
    for g in range(mj_model.ngeom):
        body = int(mj_model.geom_bodyid[g])
        out.append({"body": mj_model.body(body).name or f"body{body}", "body_id": body,
                    "type": int(mj_model.geom_type[g]), "size": mj_model.geom_size[g].tolist(),
                    "pos": mj_model.geom_pos[g].tolist(), "quat": mj_model.geom_quat[g].tolist(),
                    "rgba": mj_model.geom_rgba[g].tolist(), "name": mj_model.geom(g).name})
    return out


# mjtGeom values (stable in MuJoCo's C API): plane 0, hfield 1, sphere 2, capsule 3,
# ellipsoid 4, cylinder 5, box 6, mesh 7
GEOM_SPHERE, GEOM_CAPSULE, GEOM_ELLIPSOID, GEOM_CYLINDER, GEOM_BOX = 2, 3, 4, 5, 6


def _geom_scene(geoms: list[dict]) -> str:
    """A SceneUpdate with one frame-locked entity per body holding its geoms."""
    by_body: dict[str, dict] = {}
    for g in geoms:
        if g["body_id"] == 0:
            continue  # world geoms (floors) are not drawn
        e = by_body.setdefault(g["body"], {"timestamp": {"sec": 0, "nsec": 0}, "frame_id": g["body"],
                                           "id": "geoms_" + g["body"], "lifetime": {"sec": 0, "nsec": 0},
                                           "frame_locked": True, "cylinders": [], "spheres": [], "cubes": []})
        w, x, y, z = g["quat"]
        pose = {"position": dict(zip("xyz", g["pos"])), "orientation": {"x": x, "y": y, "z": z, "w": w}}
        colour = dict(zip("rgba", g["rgba"]))
        s = g["size"]
        if g["type"] in (GEOM_CAPSULE, GEOM_CYLINDER):
            length = 2 * s[1] + (2 * s[0] if g["type"] == GEOM_CAPSULE else 0.0)
            e["cylinders"].append({"pose": pose, "size": {"x": 2 * s[0], "y": 2 * s[0], "z": length},
                                   "bottom_scale": 1, "top_scale": 1, "color": colour})
        elif g["type"] == GEOM_SPHERE:
            e["spheres"].append({"pose": pose, "size": {"x": 2 * s[0], "y": 2 * s[0], "z": 2 * s[0]}, "color": colour})
        elif g["type"] == GEOM_ELLIPSOID:
            e["spheres"].append({"pose": pose, "size": dict(zip("xyz", (2 * v for v in s))), "color": colour})
        elif g["type"] == GEOM_BOX:
            e["cubes"].append({"pose": pose, "size": dict(zip("xyz", (2 * v for v in s))), "color": colour})
    return json.dumps({"deletions": [], "entities": list(by_body.values())})


class _McapWriter:
    """A chunked, indexed MCAP writer with a fast message path.

    Structure records (header, schemas, channels, metadata, chunks, indexes, summary,
    footer) are mcap's own; a message is packed with one `struct` call into the chunk
    in progress (mcap's `Writer.add_message` costs about 9 us a message, this about
    0.5 us). Schemas, channels and metadata go straight to the data section, so that
    every chunk written is readable on its own. `finish()` writes the summary.
    """

    _MSG = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log time, publish time

    def __init__(self, f, *, chunk_size: int, library: str = "hybrid"):
        from mcap.data_stream import RecordBuilder
        from mcap.records import Header
        from mcap.writer import MCAP0_MAGIC

        self.f = f
        self.chunk_size = chunk_size
        self.b = RecordBuilder()
        self.schemas: list = []
        self.channels: list = []
        self.chunk = bytearray()
        self.index: dict[int, list] = {}
        self.t_lo = self.t_hi = None
        self.chunk_indexes: list = []
        self.meta_indexes: list = []
        self.counts: dict[int, int] = {}
        self.nmsg = 0
        self.t_first = self.t_last = None
        self.nchunk = 0
        self._zstd = None
        f.write(MCAP0_MAGIC)
        Header(profile="", library=library).write(self.b)
        self._out()

    def _out(self) -> None:
        self.f.write(self.b.end())

    def schema(self, name: str, encoding: str, data: bytes) -> int:
        from mcap.records import Schema
        s = Schema(id=len(self.schemas) + 1, name=name, encoding=encoding, data=data)
        self.schemas.append(s)
        s.write(self.b)
        self._out()
        return s.id

    def channel(self, topic: str, encoding: str, schema_id: int) -> int:
        from mcap.records import Channel
        c = Channel(id=len(self.channels) + 1, topic=topic, message_encoding=encoding, schema_id=schema_id,
                    metadata={})
        self.channels.append(c)
        self.counts[c.id] = 0
        c.write(self.b)
        self._out()
        return c.id

    def metadata(self, name: str, data: dict) -> None:
        from mcap.records import Metadata, MetadataIndex
        self.flush_chunk()
        offset = self.f.tell()
        Metadata(name=name, metadata=data).write(self.b)
        self.meta_indexes.append(MetadataIndex(offset=offset, length=self.b.count, name=name))
        self._out()

    def message(self, channel: int, t_ns: int, data: bytes) -> None:
        chunk = self.chunk
        idx = self.index.get(channel)
        if idx is None:
            idx = self.index[channel] = []
        idx.append((t_ns, len(chunk)))
        chunk += self._MSG.pack(5, 22 + len(data), channel, 0, t_ns, t_ns)
        chunk += data
        self.counts[channel] += 1
        if self.t_lo is None:
            self.t_lo = self.t_hi = t_ns
        elif t_ns > self.t_hi:
            self.t_hi = t_ns
        elif t_ns < self.t_lo:
            self.t_lo = t_ns
        if len(chunk) > self.chunk_size:
            self.flush_chunk()

    def flush_chunk(self) -> None:
        """Write the chunk in progress (zstd) and its message indexes; flush the file."""
        if not self.chunk:
            return
        import zlib

        import zstandard
        from mcap.opcode import Opcode
        from mcap.records import Chunk, ChunkIndex

        raw = bytes(self.chunk)
        if self._zstd is None:
            self._zstd = zstandard.ZstdCompressor(level=1)  # fast: the chunks are written during the run
        data = self._zstd.compress(raw)
        chunk = Chunk(compression="zstd", data=data, message_start_time=self.t_lo, message_end_time=self.t_hi,
                      uncompressed_crc=zlib.crc32(raw), uncompressed_size=len(raw))
        start = self.f.tell()
        chunk.write(self.b)
        length = self.b.count
        self._out()
        index_start = self.f.tell()
        offsets = {}
        parts = []
        count = 0
        for ch, records in self.index.items():  # MessageIndex records, packed at once
            body = np.asarray(records, dtype="<u8").tobytes()
            rec = struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 2 + 4 + len(body), ch, len(body)) + body
            offsets[ch] = index_start + count
            parts.append(rec)
            count += len(rec)
        index_length = count
        self.f.write(b"".join(parts))
        self.chunk_indexes.append(ChunkIndex(
            message_start_time=self.t_lo, message_end_time=self.t_hi, chunk_start_offset=start,
            chunk_length=length, message_index_offsets=offsets, message_index_length=index_length,
            compression="zstd", compressed_size=len(data), uncompressed_size=len(raw)))
        self.nmsg += sum(len(r) for r in self.index.values())
        self.t_first = self.t_lo if self.t_first is None else min(self.t_first, self.t_lo)
        self.t_last = self.t_hi if self.t_last is None else max(self.t_last, self.t_hi)
        self.nchunk += 1
        self.chunk = bytearray()
        self.index = {}
        self.t_lo = self.t_hi = None
        self.f.flush()

    def finish(self) -> None:
        """The last chunk, then the summary (schemas, channels, statistics, indexes,
        offsets) and the footer, laid out as mcap's own writer does."""
        import zlib

        from mcap.data_stream import RecordBuilder
        from mcap.opcode import Opcode
        from mcap.records import DataEnd, Footer, Statistics, SummaryOffset
        from mcap.writer import MCAP0_MAGIC

        self.flush_chunk()
        DataEnd(data_section_crc=0).write(self.b)
        self._out()
        summary_start = self.f.tell()
        sb = RecordBuilder()
        offsets = []
        stats = Statistics(attachment_count=0, channel_count=len(self.channels),
                           channel_message_counts=dict(self.counts), chunk_count=self.nchunk,
                           message_count=self.nmsg, message_end_time=self.t_last or 0,
                           message_start_time=self.t_first or 0, metadata_count=len(self.meta_indexes),
                           schema_count=len(self.schemas))
        for opcode, records in ((Opcode.SCHEMA, self.schemas), (Opcode.CHANNEL, self.channels),
                                (Opcode.STATISTICS, [stats]), (Opcode.CHUNK_INDEX, self.chunk_indexes),
                                (Opcode.METADATA_INDEX, self.meta_indexes)):
            if not records:
                continue
            g = sb.count
            for r in records:
                r.write(sb)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + g,
                                         group_length=sb.count - g))
        offset_start = summary_start + sb.count
        for o in offsets:
            o.write(sb)
        summary = sb.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start), crc)
        self.f.write(summary)
        Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc).write(self.b)
        self._out()
        self.f.write(MCAP0_MAGIC)
        self.f.flush()


def _plan(sim, every_s: float) -> dict:
    """What the writer needs to know of the model, as plain data (it may go to another process)."""
    model = sim.model
    names, label, colours = region_colours(model)
    mj_model = sim.mj_model
    bodies = ([(b, mj_model.body(b).name or f"body{b}") for b in range(1, mj_model.nbody)]
              if mj_model is not None else [])
    return {"scene": model.scene.name, "dt_s": model.dt_s, "every_s": every_s, "nvert": model.mesh.nvert,
            "face_vert": np.asarray(model.mesh.face_vert, np.int64), "regions": names, "vert_label": label,
            "colours": colours, "link_vert": np.asarray(model.link_vert), "rest": np.asarray(model.mesh.vert_pos, float),
            "geoms": _geoms(mj_model) if mj_model is not None else [], "bodies": bodies}


class _FrameWriter:
    """Encodes frames into the MCAP channels (in the recording process, or the run's)."""

    def __init__(self, path: Path, plan: dict, *, mesh_every: int, chunk_size: int, flush_s: float):
        self.mesh_every = mesh_every
        self.flush_s = flush_s
        self.frames = 0
        self._last_flush = time.perf_counter()
        self._file = open(path, "wb")
        self._writer = w = _McapWriter(self._file, chunk_size=chunk_size)
        n, face, colours = plan["nvert"], plan["face_vert"], plan["colours"]
        self._bodies = plan["bodies"]
        w.metadata("hybrid", {"description": json.dumps({
            "scene": plan["scene"], "dt_s": plan["dt_s"], "every_s": plan["every_s"], "nvert": n,
            "face_vert": face.tolist(), "regions": plan["regions"], "vert_label": plan["vert_label"].tolist(),
            "vert_rgba": np.round(colours, 4).tolist(), "link_vert": plan["link_vert"].tolist(),
            "geoms": plan["geoms"], "bodies": [name for _, name in self._bodies]})})
        schemas = {name: w.schema(name, "jsonschema", json.dumps(s).encode())
                   for name, s in _foxglove_schemas().items()}

        def channel(topic, schema):
            return w.channel(topic, "json", schemas[schema])

        self._ch_points = channel("/membrane/points", "foxglove.PointCloud")
        self._ch_mesh = channel("/membrane/mesh", "foxglove.SceneUpdate")
        self._ch_scalar = [channel(topic, "hybrid.Scalar") for topic in SCALAR_CHANNELS]
        self._ch_tf = channel("/rigid/transforms", "foxglove.FrameTransforms") if self._bodies else None
        if self._bodies:
            ch_geoms = channel("/rigid/geoms", "foxglove.SceneUpdate")
            w.message(ch_geoms, 0, _geom_scene(plan["geoms"]).encode())
        # point cloud: x, y, z float32 then r, g, b, a uint8 (16 bytes a point)
        self._cloud = np.zeros(n, dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
        self._cloud["rgba"] = np.round(colours * 255).astype(np.uint8)
        fields = [{"name": k, "offset": o, "type": _FLOAT32} for k, o in (("x", 0), ("y", 4), ("z", 8))]
        fields += [{"name": k, "offset": 12 + i, "type": _UINT8} for i, k in enumerate(("red", "green", "blue", "alpha"))]
        self._cloud_head = '{"frame_id":"world","pose":%s,"point_stride":16,"fields":%s,"timestamp":' % (
            _IDENTITY_POSE, json.dumps(fields))
        # triangle list: the points change, indices and colours do not
        rgba = np.round(colours, 3)
        self._mesh_head = ('{"deletions":[],"entities":[{"frame_id":"world","id":"membrane",'
                           '"lifetime":{"sec":0,"nsec":0},"frame_locked":false,"timestamp":')
        self._mesh_mid = (',"triangles":[{"pose":%s,"color":{"r":0.8,"g":0.8,"b":0.8,"a":1},"colors":%s,"indices":%s,"points":[' % (
            _IDENTITY_POSE, json.dumps([dict(zip("rgba", c)) for c in rgba.tolist()], separators=(",", ":")),
            json.dumps(face.ravel().tolist(), separators=(",", ":")))).encode()
        self._mesh_buf = np.empty(n * 3 * 40, np.uint8)  # room for '"x":-123456789.123456,' a coordinate
        self._mesh_tail = b"]}]}]}"
        _format_points(plan["rest"], self._mesh_buf)  # compile (or load) before the run

    def write(self, t: float, pos, xpos, xquat, scalars) -> None:
        """One frame: t s, pos (nvert, 3), xpos (nbody, 3) and xquat (nbody, 4) of the bodies
        (world excluded; None without), scalars (len(SCALAR_CHANNELS),) with NaN where absent."""
        ns, stamp = _stamp(t)
        w = self._writer
        cloud = self._cloud
        cloud["xyz"] = pos
        w.message(self._ch_points, ns, (self._cloud_head + stamp + ',"data":"'
                                        + base64.b64encode(cloud.tobytes()).decode("ascii") + '"}').encode())
        if self.frames % self.mesh_every == 0:
            buf = self._mesh_buf
            k = _format_points(pos, buf)
            w.message(self._ch_mesh, ns, b"".join(((self._mesh_head + stamp).encode(), self._mesh_mid,
                                                    buf[:k].tobytes(), self._mesh_tail)))
        if self._ch_tf is not None and xpos is not None:
            xp, xq = xpos.tolist(), xquat.tolist()
            parts = []
            for (_, name), p, q in zip(self._bodies, xp, xq):
                parts.append('{"timestamp":%s,"parent_frame_id":"world","child_frame_id":"%s",'
                             '"translation":{"x":%r,"y":%r,"z":%r},"rotation":{"x":%r,"y":%r,"z":%r,"w":%r}}'
                             % (stamp, name, p[0], p[1], p[2], q[1], q[2], q[3], q[0]))
            w.message(self._ch_tf, ns, ('{"transforms":[' + ",".join(parts) + "]}").encode())
        for ch, value in zip(self._ch_scalar, scalars.tolist()):
            if value == value:  # not NaN: present
                w.message(ch, ns, b'{"t":%r,"value":%r}' % (t, value))
        self.frames += 1
        now = time.perf_counter()
        if now - self._last_flush > self.flush_s:
            w.flush_chunk()
            self._last_flush = now

    def flush(self) -> None:
        self._writer.flush_chunk()

    def close(self) -> None:
        try:
            self._writer.finish()
        finally:
            self._file.close()


class Recorder:
    """Write a run's frames to an MCAP file; an observer for `hybrid.run.run`.

    >>> with Recorder("run.mcap", sim) as rec:
    ...     run(sim, 12.0, observers=[rec])

    `every_s`: the recording interval in simulated time (default 10 ms); frames the
    runner offers closer than that to the last recorded one are skipped.
    `mesh_every`: the triangle list every that many recorded frames (default: 1 up to
    `MESH_EVERY_FRAME_MAX` points, 10 above).
    `batch`: frames are copied as they come and encoded `batch` at a time (in one warm
    pass, about three times cheaper than one at a time between steps), and at least
    every `flush_s` seconds of wall time; `close()` encodes what is left and finishes the file.
    """

    def __init__(self, path: str | Path, sim, *, every_s: float = 0.01, mesh_every: int | None = None,
                 chunk_size: int = 256 * 1024, flush_s: float = 1.0, batch: int = 200):
        if not every_s > 0:
            raise ValueError(f"every_s: expected a time > 0 s, received {every_s!r}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.every_s = float(every_s)
        plan = _plan(sim, self.every_s)
        n = plan["nvert"]
        self.nbody = len(plan["bodies"])
        self.flush_s = flush_s
        self.frames = 0
        self._next_t = -math.inf
        self._closed = False
        self._fw = _FrameWriter(self.path, plan, chunk_size=chunk_size, flush_s=flush_s,
                                mesh_every=int(mesh_every) if mesh_every else (1 if n <= MESH_EVERY_FRAME_MAX else 10))
        self._writer, self._file = self._fw._writer, self._fw._file
        b = max(1, int(batch))
        nb = max(self.nbody, 1)
        self._scal = np.empty((b, 1 + len(SCALAR_CHANNELS)))
        self._pos = np.empty((b, n, 3))
        self._xpos = np.empty((b, nb, 3))
        self._xquat = np.empty((b, nb, 4))
        self._held = 0
        self._last_drain = time.perf_counter()

    # ------------------------------------------------------------ observer
    def __call__(self, sim, trace=None) -> None:
        """Record the current frame of `sim` (if `every_s` has elapsed since the last one).
        `trace`: the runner's `Trace`, whose last values feed the scalar channels."""
        t = sim.time
        if t < self._next_t - 1e-9 * self.every_s or self._closed:
            return
        self._next_t = t + self.every_s
        k = self._held
        scal = self._scal[k]
        scal[0] = t
        if trace is not None:
            for i, key in enumerate(SCALAR_CHANNELS.values()):
                series = getattr(trace, key, None)
                scal[1 + i] = series[-1] if series else np.nan
        else:
            scal[1:] = np.nan
            scal[1], scal[2], scal[3] = sim.volume, sim.volume_rel_error, sim.pressure
        self._pos[k] = sim.vert_pos
        if self.nbody:
            d = sim.mj_data
            self._xpos[k] = d.xpos[1:]
            self._xquat[k] = d.xquat[1:]
        self._held = k + 1
        self.frames += 1
        if self._held == len(self._scal) or time.perf_counter() - self._last_drain > self.flush_s:
            self._drain()

    frame = __call__

    def _drain(self) -> None:
        """Encode and write the frames held."""
        fw, bodies = self._fw, self.nbody > 0
        for k in range(self._held):
            scal = self._scal[k]
            fw.write(float(scal[0]), self._pos[k], self._xpos[k] if bodies else None,
                     self._xquat[k] if bodies else None, scal[1:])
        self._held = 0
        self._last_drain = time.perf_counter()

    # ------------------------------------------------------------ closing
    def close(self) -> None:
        """Finish the file: the frames held, then summary and footer. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._drain()
        finally:
            self._fw.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


# ---------------------------------------------------------------- reading
def _records(path: Path):
    """Every record of an MCAP file in order; stops quietly at a truncated end."""
    from mcap.exceptions import McapError
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        it = iter(StreamReader(f).records)
        while True:
            try:
                rec = next(it)
            except StopIteration:
                return
            except (McapError, EOFError, ValueError, IndexError, OSError, Exception) as exc:  # truncated tail
                if isinstance(exc, KeyboardInterrupt):
                    raise
                return
            yield rec


def read(path: str | Path) -> dict[str, dict]:
    """The recorded channels of `path` as numpy arrays, by topic.

    - scalar topics ("/volume", ...): {"t": (n,) s, "value": (n,)};
    - "/membrane/points": {"t": (nframe,) s, "pos": (nframe, nvert, 3) float32 m,
      "rgba": (nvert, 4) uint8};
    - "/rigid/transforms": {"t": (nframe,), "bodies": [names], "pos": (nframe, nbody, 3),
      "quat": (nframe, nbody, 4) (w, x, y, z as MuJoCo)};
    - "/membrane/mesh": {"t": (n,) s} (when the triangle list was written);
    - "model": the recorded description (faces as an (nface, 3) array, regions,
      per-point labels and colours, geoms).

    Unfinished files (a killed run) are read up to their last complete record.
    """
    from mcap.records import Channel, Message, Metadata

    path = Path(path)
    topics: dict[int, str] = {}
    raw: dict[str, list] = {}
    meta = None
    for rec in _records(path):
        if isinstance(rec, Message):
            topic = topics.get(rec.channel_id)
            if topic is not None:
                raw.setdefault(topic, []).append((rec.log_time, rec.data))
        elif isinstance(rec, Channel):
            topics[rec.id] = rec.topic
        elif isinstance(rec, Metadata) and rec.name == "hybrid" and meta is None:
            meta = json.loads(rec.metadata["description"])
    out: dict[str, dict] = {}
    for topic, msgs in raw.items():
        t = np.array([lt for lt, _ in msgs], np.int64) * 1e-9
        if topic == "/membrane/points":
            frames, rgba = [], None
            for _, data in msgs:
                m = json.loads(data)
                arr = np.frombuffer(base64.b64decode(m["data"]), dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
                frames.append(arr["xyz"])
                rgba = arr["rgba"]
            out[topic] = {"t": t, "pos": np.stack(frames).astype(np.float32), "rgba": rgba}
        elif topic == "/rigid/transforms":
            names = None
            pos, quat = [], []
            for _, data in msgs:
                tfs = json.loads(data)["transforms"]
                names = names or [tf["child_frame_id"] for tf in tfs]
                pos.append([[tf["translation"][k] for k in "xyz"] for tf in tfs])
                quat.append([[tf["rotation"][k] for k in "wxyz"] for tf in tfs])
            out[topic] = {"t": t, "bodies": names, "pos": np.array(pos), "quat": np.array(quat)}
        elif topic in SCALAR_CHANNELS:
            out[topic] = {"t": t, "value": np.array([json.loads(d)["value"] for _, d in msgs], float)}
        else:
            out[topic] = {"t": t}
    if meta is not None:
        meta["face_vert"] = np.asarray(meta["face_vert"], np.int64).reshape(-1, 3)
        meta["vert_label"] = np.asarray(meta["vert_label"], int)
        meta["vert_rgba"] = np.asarray(meta["vert_rgba"], float)
        meta["link_vert"] = np.asarray(meta["link_vert"], int)
        out["model"] = meta
    return out
