"""Record a run to MCAP, in Foxglove's well-known schemas (protobuf encoding), and read it back.

`hybrid run` writes `DIR/run.mcap` through a `Recorder`, an observer of the runner
(`hybrid.run.run(..., observers=[rec])`) called at each frame. Channels:

- `/membrane/mesh`     foxglove.SceneUpdate: the membrane as one TriangleListPrimitive
  with per-vertex region colours, its points as exact doubles; every frame for
  meshes up to `MESH_EVERY_FRAME_MAX` points, every `mesh_every` frames above;
- `/membrane/points`   foxglove.PointCloud, every frame, for the larger meshes only:
  the points as float32 x, y, z and their region colour (uint8 r, g, b, a);
- `/rigid/transforms`  foxglove.FrameTransforms: each MuJoCo body's pose (`xpos`,
  `xquat`) as the frame `world` -> body name (scenes with a rigid part);
- `/rigid/geoms`       foxglove.SceneUpdate, once: each body's geoms in its own frame
  (capsules and cylinders as cylinders, spheres, boxes), frame-locked;
- scalars, `hybrid.Scalar` {double t (s); double value}: `/volume` (m^3),
  `/volume_rel_error`, `/pressure` (Pa), `/rib_elevation` (mm), `/apex_descent` (mm),
  `/muscle_stiffness` (N/m), `/kinetic_energy` (J), as far as the observer is given them.

Log times are the simulated time in nanoseconds (t = 0 at the start). Each schema is
a protobuf FileDescriptorSet (foxglove's from `foxglove-schemas-protobuf`). The model's
description (faces, region of each point, colours, geoms) is an MCAP metadata record
named "hybrid", so that `hybrid render` needs nothing but the file.

Cost: the run's thread only copies each block of frames (positions, body poses,
their rows in the runner's trace). The frames go to a writer thread (at the end of
a block once half a chunk, about 0.5 MiB, is held) that writes the file's head with
the first ones, takes their scalars from the trace, encodes every message of every
frame in one compiled pass (protobuf: numbers are copied as their 8 bytes, the
fields that do not change are encoded once), then compresses (zstd at a fast level)
and writes the chunk. The encoder and the compressor release the GIL, as do the
run's compiled steps, so the two go on side by side. `hybrid bench` times the
breathing run with and without the recording.

Crash safety: the frames held are handed to the writer at least every `flush_s`
seconds of wall time, each batch written as a whole chunk, so a killed process leaves
every frame but those of its last second or so; `close()` (called in a `finally` by `hybrid run`, or by
`with Recorder(...)`) encodes the rest and finishes the file on an error or an
interrupt. `read` accepts unfinished files (no summary, truncated last record).
"""

from __future__ import annotations

import functools
import json
import math
import queue
import struct
import threading
import time
from pathlib import Path

import numpy as np

from .errors import HybridError
from .kernel import jit
from .step import F_PRESSURE, F_TIME, F_VOLUME

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
    table = np.array(_PALETTE + [_UNLABELLED])  # row -1: no region
    colours = np.ones((n, 4))
    colours[:, :3] = table[np.where(label >= 0, label % len(_PALETTE), -1)]
    return names, label, colours


# ------------------------------------------------------------------ compiled encoder
# A frame's messages are written in protobuf by one compiled pass from small programs,
# one per channel: each op is (code, a, b), run in order. A first pass over a program
# sizes its nested messages (protobuf puts a message's length before it); only the
# time stamps change size from frame to frame.
OP_CONST = 0      # bytes const[a:b] (fields encoded once, by protobuf)
OP_BEGIN = 1      # a nested message, field tag a, up to its OP_END
OP_END = 2
OP_STAMP = 3      # the frame's time as a google.protobuf.Timestamp, field tag a
OP_DOUBLE = 4     # number slot b of the frame as a double, field tag a
OP_POINTS = 5     # the frame's points as repeated foxglove.Point3, field tag a
OP_CLOUD = 6      # the frame's point cloud bytes, field tag a
OP_IF_FINITE = 7  # write the message only if number slot a is finite

RECORD_HEAD = 31  # MCAP message record: opcode 1, length 8, channel 2, sequence 4, log and publish time 8 + 8
POINT3_BYTES = 27  # foxglove.Point3: three doubles, each a one-byte tag and 8 bytes
MAX_DEPTH = 16


def _tag(field: int, wire: int) -> int:
    """A protobuf field key: wire type 1 (64-bit), 2 (length-delimited)."""
    return field << 3 | wire


@jit(nogil=True)
def _put_uint(out, k, value, nbyte):  # pragma: no cover - compiled
    """value as an nbyte little-endian unsigned integer at out[k]."""
    for i in range(nbyte):
        out[k + i] = (value >> (8 * i)) & 255


@jit(nogil=True)
def _varint_len(v):  # pragma: no cover - compiled
    n = 1
    while v >= 128:
        v >>= 7
        n += 1
    return n


@jit(nogil=True)
def _put_varint(out, k, v):  # pragma: no cover - compiled
    """v (>= 0) as a protobuf varint at out[k]; returns the new end."""
    while v >= 128:
        out[k] = (v & 127) | 128
        v >>= 7
        k += 1
    out[k] = v
    return k + 1


@jit(nogil=True)
def _put_bytes(out, k, src, a, b):  # pragma: no cover - compiled
    """src[a:b] at out[k]; returns the new end. With unsigned indices (no wraparound
    checks) LLVM makes the loop a copy, ~50 times faster than with signed ones or a
    slice assignment."""
    ku, au = np.uint64(k), np.uint64(a)
    for q in range(np.uint64(b - a)):
        out[ku + q] = src[au + q]
    return k + b - a


@jit(nogil=True)
def _put_bits(out, k, bits):  # pragma: no cover - compiled
    """A double's 8 bytes (its bits as uint64), little-endian, at out[k]; returns the
    new end. Unsigned indices: no wraparound checks in the encoder's longest loop."""
    ku = np.uint64(k)
    for q in range(np.uint64(8)):
        out[ku + q] = (bits >> (np.uint64(8) * q)) & np.uint64(255)
    return k + 8


@jit(nogil=True)
def _put_points(out, k, key, bits):  # pragma: no cover - compiled
    """Repeated foxglove.Point3 (field key `key`) of bits (3 nvert,) uint64, the
    doubles x, y, z of each point; returns the new end."""
    for i in range(bits.shape[0] // 3):
        k = _put_varint(out, k, key)
        out[k] = POINT3_BYTES
        k += 1
        for j in range(3):
            out[k] = 9 + 8 * j  # x, y, z: fields 1, 2, 3, 64-bit
            k = _put_bits(out, k + 1, bits[3 * i + j])
    return k


@jit(nogil=True)
def _stamp_body_len(sec, nsec):  # pragma: no cover - compiled
    """Bytes of a Timestamp's fields (proto3 leaves zeros out)."""
    n = 0
    if sec:
        n += 1 + _varint_len(sec)
    if nsec:
        n += 1 + _varint_len(nsec)
    return n


@jit(nogil=True)
def _leaf_len(op, a, nvert, ncloud, stamp_body):  # pragma: no cover - compiled
    """Bytes an op writes (but OP_CONST, OP_BEGIN, OP_END)."""
    if op == OP_STAMP:
        return _varint_len(a) + _varint_len(stamp_body) + stamp_body
    if op == OP_DOUBLE:
        return _varint_len(a) + 8
    if op == OP_POINTS:
        return nvert * (_varint_len(a) + 1 + POINT3_BYTES)
    if op == OP_CLOUD:
        return _varint_len(a) + _varint_len(ncloud) + ncloud
    return 0


@jit(nogil=True)
def _encode_frames(t_ns, number, cloud, pos, frame0, const, prog, channels, out, index,
                   size):  # pragma: no cover - compiled
    """The MCAP message records of nframe frames, written into out; index[m] =
    (channel, log time ns, offset in out) of each. Returns (bytes written, messages).

    t_ns (nframe,); number (nframe, nslot) the numeric slots; cloud (nframe, nbyte)
    the point cloud bytes; pos (nframe, 3 nvert) the points' x, y, z; frame0 the run's
    index of the first frame; channels (nchannel, 4) = (channel id, first op, end op,
    every nth frame); size (nop,) scratch for the nested messages' lengths. Doubles
    are written as their bits, little-endian, as protobuf does."""
    number_bits = number.view(np.uint64)
    pos_bits = pos.view(np.uint64)
    nvert = pos.shape[1] // 3
    ncloud = cloud.shape[1]
    acc = np.zeros(MAX_DEPTH, np.int64)
    opened = np.zeros(MAX_DEPTH, np.int64)
    k = 0
    m = 0
    for f in range(t_ns.shape[0]):
        t = t_ns[f]
        sec = t // 1000000000
        nsec = t % 1000000000
        stamp_body = _stamp_body_len(sec, nsec)
        for c in range(channels.shape[0]):
            ch, p0, p1, every = channels[c, 0], channels[c, 1], channels[c, 2], channels[c, 3]
            if (frame0 + f) % every != 0:
                continue
            write = True
            for p in range(p0, p1):
                if prog[p, 0] == OP_IF_FINITE and not np.isfinite(number[f, prog[p, 1]]):
                    write = False
            if not write:
                continue
            # sizes: each nested message's length, innermost first
            depth = 0
            acc[0] = 0
            for p in range(p0, p1):
                op, a = prog[p, 0], prog[p, 1]
                if op == OP_BEGIN:
                    depth += 1
                    acc[depth] = 0
                    opened[depth] = p
                elif op == OP_END:
                    inner = acc[depth]
                    size[opened[depth]] = inner
                    depth -= 1
                    acc[depth] += _varint_len(prog[opened[depth + 1], 1]) + _varint_len(inner) + inner
                elif op == OP_CONST:
                    acc[depth] += prog[p, 2] - a
                else:
                    acc[depth] += _leaf_len(op, a, nvert, ncloud, stamp_body)
            start = k
            k += RECORD_HEAD
            for p in range(p0, p1):
                op, a, b = prog[p, 0], prog[p, 1], prog[p, 2]
                if op == OP_CONST:
                    k = _put_bytes(out, k, const, a, b)
                elif op == OP_BEGIN:
                    k = _put_varint(out, k, a)
                    k = _put_varint(out, k, size[p])
                elif op == OP_STAMP:
                    k = _put_varint(out, k, a)
                    k = _put_varint(out, k, stamp_body)
                    if sec:
                        out[k] = 8  # seconds: field 1, varint
                        k = _put_varint(out, k + 1, sec)
                    if nsec:
                        out[k] = 16  # nanos: field 2, varint
                        k = _put_varint(out, k + 1, nsec)
                elif op == OP_DOUBLE:
                    k = _put_varint(out, k, a)
                    k = _put_bits(out, k, number_bits[f, b])
                elif op == OP_POINTS:
                    k = _put_points(out, k, a, pos_bits[f])
                elif op == OP_CLOUD:
                    k = _put_varint(out, k, a)
                    k = _put_varint(out, k, ncloud)
                    k = _put_bytes(out, k, cloud[f], 0, ncloud)
            if k - start - RECORD_HEAD != acc[0]:  # the sizing pass and the writing pass disagree
                raise RuntimeError("hybrid.record: a message's size differs from the size its fields were given")
            out[start] = 5  # opcode: message
            _put_uint(out, start + 1, k - start - 9, 8)
            _put_uint(out, start + 9, ch, 2)
            _put_uint(out, start + 11, 0, 4)  # sequence
            _put_uint(out, start + 15, t, 8)  # log time
            _put_uint(out, start + 23, t, 8)  # publish time
            index[m, 0] = ch
            index[m, 1] = t
            index[m, 2] = start
            m += 1
    return k, m


def _load_encoder() -> None:
    """Compile the encoder, or load it from the cache, once a process, in the calling
    thread (the recorder's constructor: before the run, not in the writer thread while
    the run waits for it), with the argument types `_FrameWriter.write` passes."""
    if _encode_frames.signatures:
        return
    _encode_frames(np.zeros(1, np.int64), np.zeros((1, 1)), np.zeros((1, 16), np.uint8), np.zeros((1, 3)), 0,
                   np.frombuffer(b"\0", np.uint8), np.zeros((0, 3), np.int64), np.zeros((0, 4), np.int64),
                   np.zeros(1, np.uint8), np.zeros((0, 3), np.int64), np.zeros(0, np.int64))


# ------------------------------------------------------------------ schemas
SCALAR_PROTO = "hybrid/Scalar.proto"


def _scalar_file():
    """hybrid.Scalar {double t = 1 (simulated time, s); double value = 2;} as a
    protobuf file descriptor."""
    from google.protobuf import descriptor_pb2

    f = descriptor_pb2.FileDescriptorProto(name=SCALAR_PROTO, package="hybrid", syntax="proto3")
    msg = f.message_type.add(name="Scalar")
    for number, name in ((1, "t"), (2, "value")):
        msg.field.add(name=name, number=number, type=descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE,
                      label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL, json_name=name)
    return f


def _descriptor_set(file_descriptor) -> bytes:
    """A FileDescriptorSet of a .proto file and everything it imports (an MCAP
    protobuf schema)."""
    from google.protobuf import descriptor_pb2

    out = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(fd) -> None:
        for dep in fd.dependencies:
            if dep.name not in seen:
                seen.add(dep.name)
                add(dep)
        fd.CopyToProto(out.file.add())

    add(file_descriptor)
    return out.SerializeToString()


@functools.lru_cache(maxsize=1)
def _schemas() -> dict[str, bytes]:
    """The schemas written here, by name: foxglove's (from foxglove-schemas-protobuf) and hybrid.Scalar."""
    from google.protobuf import descriptor_pb2
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    out = {m.DESCRIPTOR.full_name: _descriptor_set(m.DESCRIPTOR.file)
           for m in (SceneUpdate, FrameTransforms, PointCloud)}
    out["hybrid.Scalar"] = descriptor_pb2.FileDescriptorSet(file=[_scalar_file()]).SerializeToString()
    return out


def _message_classes(schemas: dict[str, bytes]) -> dict:
    """Message classes, by name, built from the schemas a file holds."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    out = {}
    for name, data in schemas.items():
        fds = descriptor_pb2.FileDescriptorSet.FromString(data)
        for fd in fds.file:
            try:
                pool.Add(fd)
            except (TypeError, ValueError):
                pass  # already in the pool (shared imports)
        out[name] = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
    return out


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


def _geom_scene(geoms: list[dict]) -> bytes:
    """A foxglove.SceneUpdate with one frame-locked entity per body holding its geoms."""
    from foxglove_schemas_protobuf.Color_pb2 import Color
    from foxglove_schemas_protobuf.Pose_pb2 import Pose
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from foxglove_schemas_protobuf.Vector3_pb2 import Vector3

    scene = SceneUpdate()
    by_body: dict[str, object] = {}
    for g in geoms:
        if g["body_id"] == 0:
            continue  # world geoms (floors) are not drawn
        e = by_body.get(g["body"])
        if e is None:
            e = by_body[g["body"]] = scene.entities.add(frame_id=g["body"], id="geoms_" + g["body"], frame_locked=True)
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = g["pos"]
        q = pose.orientation
        q.w, q.x, q.y, q.z = g["quat"]
        colour = Color(r=g["rgba"][0], g=g["rgba"][1], b=g["rgba"][2], a=g["rgba"][3])
        s = g["size"]
        if g["type"] in (GEOM_CAPSULE, GEOM_CYLINDER):
            length = 2 * s[1] + (2 * s[0] if g["type"] == GEOM_CAPSULE else 0.0)
            e.cylinders.add(pose=pose, size=Vector3(x=2 * s[0], y=2 * s[0], z=length), bottom_scale=1.0,
                            top_scale=1.0, color=colour)
        elif g["type"] == GEOM_SPHERE:
            e.spheres.add(pose=pose, size=Vector3(x=2 * s[0], y=2 * s[0], z=2 * s[0]), color=colour)
        elif g["type"] == GEOM_ELLIPSOID:
            e.spheres.add(pose=pose, size=Vector3(x=2 * s[0], y=2 * s[1], z=2 * s[2]), color=colour)
        elif g["type"] == GEOM_BOX:
            e.cubes.add(pose=pose, size=Vector3(x=2 * s[0], y=2 * s[1], z=2 * s[2]), color=colour)
    return scene.SerializeToString()


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
        """Write the chunk of single messages in progress."""
        if not self.chunk:
            return
        index = {ch: np.asarray(rec, "<u8") for ch, rec in self.index.items()}
        self._write_chunk(bytes(self.chunk), index, self.t_lo, self.t_hi)
        self.chunk = bytearray()
        self.index = {}
        self.t_lo = self.t_hi = None

    def add_chunk(self, raw: np.ndarray, index: np.ndarray) -> None:
        """A chunk of ready message records: raw (uint8), index (nmsg, 3) = (channel,
        log time ns, offset in raw) in log-time order."""
        if not len(index):
            return
        self.flush_chunk()
        ch = index[:, 0]
        per_channel = {int(c): np.ascontiguousarray(index[ch == c, 1:], "<u8") for c in np.unique(ch)}
        for c, rec in per_channel.items():
            self.counts[c] += len(rec)
        self._write_chunk(raw, per_channel, int(index[:, 1].min()), int(index[:, 1].max()))

    def _write_chunk(self, raw, index: dict, t_lo: int, t_hi: int) -> None:
        """A chunk (zstd) and its message indexes ({channel: (n, 2) (log time, offset)}); flush the file."""
        import zlib

        import zstandard
        from mcap.opcode import Opcode
        from mcap.records import Chunk, ChunkIndex

        if self._zstd is None:
            self._zstd = zstandard.ZstdCompressor(level=-3)  # fast: the chunks are written during the run
        data = self._zstd.compress(raw)
        chunk = Chunk(compression="zstd", data=data, message_start_time=t_lo, message_end_time=t_hi,
                      uncompressed_crc=zlib.crc32(raw), uncompressed_size=len(raw))
        start = self.f.tell()
        chunk.write(self.b)
        length = self.b.count
        self._out()
        index_start = self.f.tell()
        offsets = {}
        parts = []
        count = 0
        for ch, records in index.items():  # MessageIndex records, packed at once
            body = records.tobytes()
            rec = struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 2 + 4 + len(body), ch, len(body)) + body
            offsets[ch] = index_start + count
            parts.append(rec)
            count += len(rec)
        self.f.write(b"".join(parts))
        self.chunk_indexes.append(ChunkIndex(
            message_start_time=t_lo, message_end_time=t_hi, chunk_start_offset=start,
            chunk_length=length, message_index_offsets=offsets, message_index_length=count,
            compression="zstd", compressed_size=len(data), uncompressed_size=len(raw)))
        self.nmsg += sum(len(r) for r in index.values())
        self.t_first = t_lo if self.t_first is None else min(self.t_first, t_lo)
        self.t_last = t_hi if self.t_last is None else max(self.t_last, t_hi)
        self.nchunk += 1
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
    """What the writer needs to know of the model, as plain data."""
    model = sim.model
    names, label, colours = region_colours(model)
    mj_model = sim.mj_model
    bodies = ([(b, mj_model.body(b).name or f"body{b}") for b in range(1, mj_model.nbody)]
              if mj_model is not None else [])
    return {"scene": model.scene.name, "dt_s": model.dt_s, "every_s": every_s, "nvert": model.mesh.nvert,
            "face_vert": np.asarray(model.mesh.face_vert, np.int64), "regions": names, "vert_label": label,
            "colours": colours, "link_vert": np.asarray(model.link_vert), "rest": np.array(model.mesh.vert_pos, float),
            "geoms": _geoms(mj_model) if mj_model is not None else [], "bodies": bodies}


def _nslot(nbody: int) -> int:
    """Number slots of a frame: t, the scalars, then each body's x, y, z and w, x, y, z."""
    return 1 + len(SCALAR_CHANNELS) + 7 * nbody


def _frame_bytes_estimate(plan: dict, mesh_every: int) -> int:
    """About the bytes of a frame's messages (to size a chunk's batch of frames)."""
    n, nface, nbody = plan["nvert"], len(plan["face_vert"]), len(plan["bodies"])
    mesh = 30 * n + 38 * n + 12 * nface + 200
    cloud = 16 * n + 200 if mesh_every > 1 else 0
    return mesh // mesh_every + cloud + 130 * nbody + 50 * len(SCALAR_CHANNELS) + 100


class _FrameWriter:
    """Writes the file's head (metadata, schemas, channels, geoms) and then batches of
    frames, each batch encoded by one compiled pass into one chunk."""

    def __init__(self, file, plan: dict, *, mesh_every: int, chunk_size: int):
        from foxglove_schemas_protobuf.Color_pb2 import Color
        from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
        from foxglove_schemas_protobuf.Pose_pb2 import Pose
        from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
        from foxglove_schemas_protobuf.TriangleListPrimitive_pb2 import TriangleListPrimitive
        from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform

        self._file = file
        self._writer = w = _McapWriter(file, chunk_size=chunk_size)
        n, face, colours = plan["nvert"], plan["face_vert"], plan["colours"]
        bodies = [name for _, name in plan["bodies"]]
        w.metadata("hybrid", {"description": json.dumps({
            "scene": plan["scene"], "dt_s": plan["dt_s"], "every_s": plan["every_s"], "nvert": n,
            "face_vert": face.tolist(), "regions": plan["regions"], "vert_label": plan["vert_label"].tolist(),
            "vert_rgba": np.round(colours, 4).tolist(), "link_vert": plan["link_vert"].tolist(),
            "geoms": plan["geoms"], "bodies": bodies})})
        schemas = {name: w.schema(name, "protobuf", data) for name, data in _schemas().items()}

        def channel(topic, schema):
            return w.channel(topic, "protobuf", schemas[schema])

        const = bytearray()
        prog: list[tuple[int, int, int]] = []
        programs: list[tuple[int, int, int, int]] = []  # (channel, first op, end op, every)

        def fields(message) -> None:
            """Fields encoded once by protobuf (concatenated fields are a valid message)."""
            a = len(const)
            const.extend(message.SerializeToString())
            prog.append((OP_CONST, a, len(const)))

        def program(ch: int, every: int, ops) -> None:
            p0 = len(prog)
            for op in ops:
                fields(op) if hasattr(op, "SerializeToString") else prog.append(op)
            depth = np.cumsum([(op == OP_BEGIN) - (op == OP_END) for op, _, _ in prog[p0:]])
            # the encoder sizes nested messages on a stack of MAX_DEPTH, unchecked
            assert depth[-1] == 0 and depth.min() >= 0 and depth.max() < MAX_DEPTH, "unbalanced program"
            programs.append((ch, p0, len(prog), every))

        def begin(field):
            return (OP_BEGIN, _tag(field, 2), 0)

        def stamp(field):
            return (OP_STAMP, _tag(field, 2), 0)

        def double(field, slot):
            return (OP_DOUBLE, _tag(field, 1), slot)

        end = (OP_END, 0, 0)
        identity = Pose()
        identity.orientation.w = 1.0
        # small meshes: the triangle list every frame; large ones: the point cloud every
        # frame (x, y, z float32, r, g, b, a uint8: 16 bytes a point), the triangles less often
        self.has_cloud = mesh_every > 1
        self._cloud = np.zeros((0, n), dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
        self._rgba = np.round(colours * 255).astype(np.uint8)
        if self.has_cloud:
            T = PackedElementField
            cloud_fields = [PackedElementField(name=k, offset=o, type=T.FLOAT32) for k, o in (("x", 0), ("y", 4), ("z", 8))]
            cloud_fields += [PackedElementField(name=k, offset=12 + i, type=T.UINT8)
                             for i, k in enumerate(("red", "green", "blue", "alpha"))]
            program(channel("/membrane/points", "foxglove.PointCloud"), 1, [
                stamp(1), PointCloud(frame_id="world", pose=identity, point_stride=16, fields=cloud_fields),
                (OP_CLOUD, _tag(6, 2), 0)])
        # triangle list (SceneUpdate.entities = 2, SceneEntity.triangles = 12): the
        # points change, indices and colours do not
        entity = SceneEntity(frame_id="world", id="membrane", frame_locked=False)
        entity.lifetime.SetInParent()
        tri = TriangleListPrimitive(pose=identity, color=Color(r=0.8, g=0.8, b=0.8, a=1.0),
                                    colors=[Color(r=r, g=g, b=b, a=a) for r, g, b, a in colours.tolist()],
                                    indices=face.ravel().tolist())
        program(channel("/membrane/mesh", "foxglove.SceneUpdate"), mesh_every, [
            begin(2), stamp(1), entity, begin(12), tri, (OP_POINTS, _tag(2, 2), 0), end, end])
        for i, topic in enumerate(SCALAR_CHANNELS):
            program(channel(topic, "hybrid.Scalar"), 1, [(OP_IF_FINITE, 1 + i, 0), double(1, 0), double(2, 1 + i)])
        if bodies:
            ops: list = []
            for b, name in enumerate(bodies):  # FrameTransforms.transforms = 1
                s = 1 + len(SCALAR_CHANNELS) + 7 * b  # x, y, z, qw, qx, qy, qz
                ops += [begin(1), stamp(1), FrameTransform(parent_frame_id="world", child_frame_id=name),
                        begin(4), double(1, s), double(2, s + 1), double(3, s + 2), end,
                        begin(5), double(1, s + 4), double(2, s + 5), double(3, s + 6), double(4, s + 3), end, end]
            program(channel("/rigid/transforms", "foxglove.FrameTransforms"), 1, ops)
            w.message(channel("/rigid/geoms", "foxglove.SceneUpdate"), 0, _geom_scene(plan["geoms"]))
            w.flush_chunk()
        self._const = np.frombuffer(bytes(const), np.uint8)
        self._prog = np.array(prog, np.int64).reshape(-1, 3)
        self._programs = np.array(programs, np.int64)
        self._size = np.zeros(len(prog), np.int64)
        # bytes of a frame at most: a nested message's key and length 8 at most, a time stamp 20
        leaf = {OP_POINTS: n * (2 + 1 + POINT3_BYTES), OP_CLOUD: 16 * n + 12}
        self.frame_bytes = len(const) + len(programs) * RECORD_HEAD + sum(
            leaf.get(op, 20) for op, _, _ in prog)
        self._out = np.empty(0, np.uint8)
        self._index = np.empty((0, 3), np.int64)
        _load_encoder()

    def write(self, t_s, number, pos, frame0: int) -> None:
        """Frames frame0, frame0 + 1, ...: t_s (nframe,) s, number (nframe, nslot), pos
        (nframe, nvert, 3) m, as one chunk."""
        nframe = len(t_s)
        t_ns = np.maximum(np.round(np.asarray(t_s) * 1e9), 0).astype(np.int64)
        if len(self._cloud) < nframe:
            self._cloud = np.zeros((nframe, pos.shape[1]), self._cloud.dtype)
            self._cloud["rgba"] = self._rgba
        cloud = self._cloud[:nframe]
        if self.has_cloud:
            cloud["xyz"] = pos
        need = nframe * self.frame_bytes
        if len(self._out) < need:
            self._out = np.empty(2 * need, np.uint8)
        if len(self._index) < nframe * len(self._programs):
            self._index = np.empty((2 * nframe * len(self._programs), 3), np.int64)
        number = np.ascontiguousarray(number, "<f8")
        pos = np.ascontiguousarray(pos, "<f8")
        k, m = _encode_frames(t_ns, number, cloud.view(np.uint8).reshape(nframe, -1), pos.reshape(nframe, -1),
                              frame0, self._const, self._prog, self._programs, self._out, self._index, self._size)
        self._writer.add_chunk(self._out[:k], self._index[:m])

    def close(self) -> None:
        try:
            self._writer.finish()
        finally:
            self._file.close()


class _Frames:
    """Frames held until they are written: number (batch, nslot) = t, the scalars and
    each body's pose (copied there from xpos, xquat when written), pos (batch, nvert, 3),
    and each frame's row in the runner's trace (-1: none)."""

    def __init__(self, batch: int, nvert: int, nbody: int, nslot: int):
        self.number = np.full((batch, nslot), np.nan)
        self.pos = np.empty((batch, nvert, 3))
        self.xpos = np.zeros((batch, nbody, 3))
        self.xquat = np.zeros((batch, nbody, 4))
        self.trace_row = np.full(batch, -1, np.int64)

    def numbers(self, nframe: int) -> np.ndarray:
        """The number slots of the first nframe frames, the bodies' poses filled in."""
        nbody = self.xpos.shape[1]
        if nbody:
            body = self.number[:nframe, self.number.shape[1] - 7 * nbody:].reshape(nframe, nbody, 7)
            body[:, :, :3] = self.xpos[:nframe]
            body[:, :, 3:] = self.xquat[:nframe]
        return self.number[:nframe]


class Recorder:
    """Write a run's frames to an MCAP file; an observer for `hybrid.run.run`.

    >>> with Recorder("run.mcap", sim) as rec:
    ...     run(sim, 12.0, observers=[rec])

    `every_s`: the recording interval in simulated time (default 10 ms); frames the
    runner offers closer than that to the last recorded one are skipped.
    `mesh_every`: the triangle list every that many recorded frames (default: 1 up to
    `MESH_EVERY_FRAME_MAX` points, 10 above); above 1, a point cloud every frame.
    `chunk_size`: bytes of an MCAP chunk, about; frames are copied as they come and
    encoded a chunk at a time, and at least every `flush_s` seconds of wall time.
    `background`: encode, compress and write on a thread of their own (the compiled
    encoder and the compressor release the GIL), so that the run goes on meanwhile.
    `flush()` writes what is held; `close()` writes the rest and finishes the file.
    """

    def __init__(self, path: str | Path, sim, *, every_s: float = 0.01, mesh_every: int | None = None,
                 chunk_size: int = 1 << 20, flush_s: float = 1.0, background: bool = True):
        if not every_s > 0:
            raise ValueError(f"every_s: expected a time > 0 s, received {every_s!r}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.every_s = float(every_s)
        plan = _plan(sim, self.every_s)
        n = plan["nvert"]
        self.nbody = len(plan["bodies"])
        self.flush_s = flush_s
        self.frames_recorded = 0  # frames taken so far
        self._next_t = -math.inf
        self._closed = False
        mesh_every = int(mesh_every) if mesh_every else (1 if n <= MESH_EVERY_FRAME_MAX else 10)
        _load_encoder()
        self._file = open(self.path, "wb")  # a path that cannot be written fails here, at once
        self._fw: _FrameWriter | None = None

        def make_writer() -> _FrameWriter:  # the file's head, and the encoder loaded
            return _FrameWriter(self._file, plan, chunk_size=chunk_size, mesh_every=mesh_every)

        batch = int(min(max(chunk_size // _frame_bytes_estimate(plan, mesh_every), 1), 1000))
        nslot = _nslot(self.nbody)
        # frames are held in one buffer while the other is written (double buffering)
        self._free: queue.Queue = queue.Queue()
        for _ in range(2 if background else 1):
            self._free.put(_Frames(batch, n, self.nbody, nslot))
        self._buf = self._free.get()
        self._trace = None
        self._sim = self._body_src = None
        self._held = 0
        self._first = 0  # the run's index of the first frame held
        self._last_flush = time.perf_counter()
        self._error: BaseException | None = None
        self._todo: queue.Queue | None = None
        if background:
            self._todo = queue.Queue()
            self._thread = threading.Thread(target=self._work, args=(make_writer,), name="hybrid-recorder",
                                            daemon=True)
            self._thread.start()
        else:
            self._fw = make_writer()

    # ------------------------------------------------------------ observer
    def __call__(self, sim, trace=None) -> None:
        """Record the current frame of `sim` (if `every_s` has elapsed since the last one).
        `trace`: the runner's `Trace`, whose last values feed the scalar channels (read
        when the frames are handed over: a frame costs the run three copies)."""
        t = sim.time
        if t < self._next_t - 1e-9 * self.every_s or self._closed:
            return
        self._next_t = t + self.every_s
        k = self._held
        buf = self._buf
        buf.number[k, 0] = t
        buf.pos[k] = sim.state.vert_pos
        if self.nbody:
            if sim is not self._sim:
                self._sim, d = sim, sim.mj_data
                self._body_src = d.xpos[1:], d.xquat[1:]  # views of the MjData's memory
            buf.xpos[k] = self._body_src[0]
            buf.xquat[k] = self._body_src[1]
        if trace is not None:
            self._trace = trace
            buf.trace_row[k] = len(trace.t_s) - 1
        else:
            buf.trace_row[k] = -1
            row = buf.number[k]
            row[1:1 + len(SCALAR_CHANNELS)] = np.nan
            row[1], row[2], row[3] = sim.volume, sim.volume_rel_error, sim.pressure
        self._held = k + 1
        self.frames_recorded += 1
        if self._held == len(buf.pos) or time.perf_counter() - self._last_flush > self.flush_s:
            self._hand_over()

    frame = __call__

    def frames(self, sim, frames, trace=None) -> None:
        """Record the frames a compiled call captured (`hybrid.step.Frames`,
        `frames.count` of them; the trace's last rows are theirs), those `every_s`
        apart: copied in blocks, handed over as the buffer fills."""
        k = frames.count
        if self._closed or not k:
            return
        t = frames.scal[:k, F_TIME]
        pick = []
        for j, tj in enumerate(t.tolist()):
            if tj >= self._next_t - 1e-9 * self.every_s:
                pick.append(j)
                self._next_t = tj + self.every_s
        pick = np.asarray(pick, np.int64)
        row0 = len(trace.t_s) - k if trace is not None else 0
        if trace is not None:
            self._trace = trace
        while len(pick):
            buf, held = self._buf, self._held
            part, pick = pick[:len(buf.pos) - held], pick[len(buf.pos) - held:]
            end = held + len(part)
            buf.number[held:end, 0] = t[part]
            buf.pos[held:end] = frames.pos[part]
            if self.nbody:
                buf.xpos[held:end] = frames.body_pos[part]
                buf.xquat[held:end] = frames.body_quat[part]
            if trace is not None:
                buf.trace_row[held:end] = row0 + part
            else:
                buf.trace_row[held:end] = -1
                vol, v0 = frames.scal[part, F_VOLUME], sim.model.arrays.vol0
                buf.number[held:end, 1:1 + len(SCALAR_CHANNELS)] = np.nan
                buf.number[held:end, 1] = vol
                buf.number[held:end, 2] = np.abs(vol - v0) / v0 if v0 else 0.0
                buf.number[held:end, 3] = frames.scal[part, F_PRESSURE]
            self._held = end
            self.frames_recorded += len(part)
            if end == len(buf.pos):
                self._hand_over()
        # a buffer at least half full goes now, so that the writer works while the run
        # goes on rather than after its last call
        if 2 * self._held >= len(self._buf.pos) or time.perf_counter() - self._last_flush > self.flush_s:
            self._hand_over()

    @staticmethod
    def _take_trace(buf, nframe: int, trace) -> None:
        """The scalar channels of the frames held, from the runner's trace rows (rows
        already written: the writer thread may read them while the run appends)."""
        rows = buf.trace_row[:nframe]
        have = rows >= 0
        if trace is None or not have.any():
            return
        lo, hi = int(rows[have].min()), int(rows[have].max())
        for i, key in enumerate(SCALAR_CHANNELS.values()):
            series = getattr(trace, key, None)
            col = buf.number[:nframe, 1 + i]
            if series and len(series) > hi:
                col[have] = np.asarray(series[lo:hi + 1], float)[rows[have] - lo]
            else:
                col[have] = np.nan

    def _hand_over(self, last: bool = False) -> None:
        """Pass the frames held to the writer (the thread, or now); `last`: no frames follow."""
        if self._held:
            item = (self._buf, self._held, self._first, self._trace)
            self._first += self._held
            self._held = 0
            if self._todo is not None:
                self._todo.put(item)
                if not last:
                    self._buf = self._free.get()  # waits while both buffers are being written
            else:
                self._write(item)
        self._last_flush = time.perf_counter()
        if self._error is not None:
            raise self._error

    def _write(self, item) -> None:
        buf, nframe, first, trace = item
        try:
            if self._error is None:
                self._take_trace(buf, nframe, trace)
                number = buf.numbers(nframe)
                self._fw.write(number[:, 0], number, buf.pos[:nframe], first)
        except BaseException as exc:  # raised again in the run's thread
            self._error = exc
        finally:
            if self._todo is not None:
                self._free.put(item[0])
            else:
                self._buf = item[0]

    def _work(self, make_writer) -> None:
        while True:
            item = self._todo.get()
            if self._fw is None and self._error is None:
                # the file's head, once the first frames come: the run is then in its
                # compiled steps (which release the GIL), so this costs it nothing
                try:
                    self._fw = make_writer()
                except BaseException as exc:  # raised again in the run's thread
                    self._error = exc
            try:
                if item is None:
                    return
                self._write(item)
            finally:
                self._todo.task_done()

    def flush(self) -> None:
        """Write the frames held, and wait until they are in the file."""
        self._hand_over()
        if self._todo is not None:
            self._todo.join()
        if self._error is not None:
            raise self._error

    # ------------------------------------------------------------ closing
    def close(self) -> None:
        """Finish the file: the frames held, then summary and footer. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            try:
                self._hand_over(last=True)
            finally:
                if self._todo is not None:
                    self._todo.put(None)
                    self._thread.join()
        finally:
            if self._fw is not None:
                self._fw.close()
            else:
                self._file.close()
        if self._error is not None:
            raise self._error

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
