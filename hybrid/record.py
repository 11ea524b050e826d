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

Cost: the run's thread only copies each frame (positions, body poses, its row in
the runner's trace). A chunk's worth of frames (about 1 MiB) goes to a writer thread
that encodes every message of every frame in one compiled pass (numbers exact, with
17 significant digits at most; the triangle list's points to 1 um; the point cloud
in base64), then compresses (zstd) and writes the chunk. The encoder and the
compressor release the GIL, so the run goes on meanwhile on another core.
`hybrid bench` times the breathing run with and without the recording.

Crash safety: the frames held are handed to the writer at least every `flush_s`
seconds of wall time, each batch written as a whole chunk, so a killed process leaves
every frame but those of its last second or so; `close()` (called in a `finally` by `hybrid run`, or by
`with Recorder(...)`) encodes the rest and finishes the file on an error or an
interrupt. `read` accepts unfinished files (no summary, truncated last record).
"""

from __future__ import annotations

import base64
import json
import math
import queue
import struct
import threading
import time
from pathlib import Path

import numpy as np

from .kernel import jit
from .simulation import F_PRESSURE, F_TIME, F_VOLUME

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


# ------------------------------------------------------------------ compiled encoder
# A frame's messages are written by one compiled pass from small programs, one per
# channel: each op is (code, a, b), run in order into the chunk buffer.
OP_CONST = 0      # copy const[a:b]
OP_STAMP = 1      # the frame's time as {"sec":S,"nsec":N}
OP_NUMBER = 2     # number slot a of the frame (exact), null if not finite
OP_BASE64 = 3     # the frame's point cloud bytes, base64
OP_POINTS = 4     # the frame's points as JSON Point3 objects, 6 decimals (1 um)
OP_IF_FINITE = 5  # write the message only if number slot a is finite

_B64 = np.frombuffer(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/", np.uint8).copy()
RECORD_HEAD = 31  # MCAP message record: opcode 1, length 8, channel 2, sequence 4, log and publish time 8 + 8


@jit(nogil=True)
def _put_uint(out, k, value, nbyte):  # pragma: no cover - compiled
    """value as an nbyte little-endian unsigned integer at out[k]."""
    for i in range(nbyte):
        out[k + i] = (value >> (8 * i)) & 255


@jit(nogil=True)
def _put_decimal(out, k, value):  # pragma: no cover - compiled
    """A non-negative integer in decimal at out[k]; returns the new end."""
    nd = 1
    t = value // 10
    while t > 0:
        nd += 1
        t //= 10
    for d in range(nd - 1, -1, -1):
        out[k + d] = 48 + value % 10
        value //= 10
    return k + nd


def _pow10_table(lo: int, hi: int) -> np.ndarray:
    """10^k = (m_hi + m_lo) * 2^e as rows (m_hi, m_lo, e) for k in [lo, hi], m_hi in
    [0.5, 1): a double-double mantissa exact to ~2^-106, beyond the double range too."""
    from fractions import Fraction

    out = np.zeros((hi - lo + 1, 3))
    for i, k in enumerate(range(lo, hi + 1)):
        x = Fraction(10) ** k
        e = x.numerator.bit_length() - x.denominator.bit_length()
        while x / Fraction(2) ** e >= 1:
            e += 1
        while x / Fraction(2) ** e < Fraction(1, 2):
            e -= 1
        m = x / Fraction(2) ** e
        out[i] = float(m), float(m - Fraction(float(m))), e
    return out


_POW10_MIN, _POW10_MAX = -310, 345  # 10^(16 - e10) for every finite double
_POW10 = _pow10_table(_POW10_MIN, _POW10_MAX)


@jit(nogil=True)
def _scaled_round(a, k, pow10):  # pragma: no cover - compiled
    """round(a * 10^k) for a > 0 where the result lies in [1e15, 1e18]; exact but for
    ties within ~1e-30 relative: the product in double-double (Veltkamp's split and
    Dekker's exact product) of mantissas, scaled by powers of two (exact)."""
    am, ae = math.frexp(a)
    hm = pow10[k - _POW10_MIN, 0]
    lm = pow10[k - _POW10_MIN, 1]
    s = ae + int(pow10[k - _POW10_MIN, 2])
    p = am * hm
    split = 134217729.0  # 2^27 + 1
    t = split * am
    ah = t - (t - am)
    al = am - ah
    t = split * hm
    hh = t - (t - hm)
    hl = hm - hh
    e = ((ah * hh - p) + ah * hl + al * hh) + al * hl + am * lm  # am * (hm + lm) = p + e
    p = math.ldexp(p, s)
    e = math.ldexp(e, s)
    base = math.floor(p)
    return np.int64(base) + np.int64(math.floor((p - base) + e + 0.5))


@jit(nogil=True)
def _put_digits(out, k, value, width):  # pragma: no cover - compiled
    """value in decimal on exactly `width` digits (zero-padded) at out[k]; returns the new end."""
    for d in range(width - 1, -1, -1):
        out[k + d] = 48 + value % 10
        value //= 10
    return k + width


@jit(nogil=True)
def _put_float(out, k, v, pow10):  # pragma: no cover - compiled
    """v as a JSON number of 17 significant digits at most (trailing zeros dropped)
    that reads back as exactly v; "null" where v is not finite. Returns the new end."""
    if not np.isfinite(v):
        for c in b"null":
            out[k] = c
            k += 1
        return k
    if v == 0.0:
        out[k] = 48
        return k + 1
    if v < 0.0:
        out[k] = 45  # -
        k += 1
        v = -v
    e10 = int(math.floor(math.log10(v)))
    q = _scaled_round(v, 16 - e10, pow10)
    if q >= 100000000000000000:
        e10 += 1
        q = _scaled_round(v, 16 - e10, pow10)
    elif q < 10000000000000000:
        e10 -= 1
        q = _scaled_round(v, 16 - e10, pow10)
    nd = 17
    while nd > 1 and q % 10 == 0:
        q //= 10
        nd -= 1
    if 0 <= e10 < 17:  # positional: 123.456
        if nd <= e10 + 1:
            k = _put_digits(out, k, q, nd)
            for d in range(e10 + 1 - nd):
                out[k] = 48
                k += 1
        else:
            scale = np.int64(10) ** (nd - e10 - 1)
            k = _put_digits(out, k, q // scale, e10 + 1)
            out[k] = 46  # .
            k = _put_digits(out, k + 1, q % scale, nd - e10 - 1)
    elif -5 <= e10 < 0:  # 0.00123
        out[k] = 48
        out[k + 1] = 46
        k += 2
        for d in range(-e10 - 1):
            out[k] = 48
            k += 1
        k = _put_digits(out, k, q, nd)
    else:  # 1.23e-7
        scale = np.int64(10) ** (nd - 1)
        k = _put_digits(out, k, q // scale, 1)
        if nd > 1:
            out[k] = 46
            k = _put_digits(out, k + 1, q % scale, nd - 1)
        out[k] = 101  # e
        k += 1
        if e10 < 0:
            out[k] = 45
            k += 1
        k = _put_decimal(out, k, abs(e10))
    return k


@jit(nogil=True)
def _put_points(pos, out, k):  # pragma: no cover - compiled
    """pos (n, 3) m as JSON Point3 objects, '{"x":-0.012345,"y":...,"z":...},...', with
    6 decimals (1 um), at out[k]; returns the new end. Non-finite values and values
    beyond 1e9 are written as 0 (JSON has no NaN). ~50 times faster than '%.6g'."""
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
            if v < 0.0:
                v = -v
                out[k] = 45  # -
                k += 1
            q = np.uint64(v * 1e6 + 0.5)  # unsigned: division by a constant becomes a multiplication
            ip = q // np.uint64(1000000)
            if ip == 0:
                out[k] = 48
                k += 1
            else:
                k = _put_decimal(out, k, np.int64(ip))
            out[k] = 46  # .
            fp = q - ip * np.uint64(1000000)
            for d in range(6, 0, -1):
                out[k + d] = np.uint64(48) + fp % np.uint64(10)
                fp //= np.uint64(10)
            k += 7
        out[k] = 125  # }
        k += 1
    return k


@jit(nogil=True)
def _put_base64(src, out, k, table):  # pragma: no cover - compiled
    """src (uint8) in base64 (with padding) at out[k]; returns the new end."""
    n = src.shape[0]
    i = 0
    while i + 2 < n:
        v = (src[i] << 16) | (src[i + 1] << 8) | src[i + 2]
        out[k] = table[(v >> 18) & 63]
        out[k + 1] = table[(v >> 12) & 63]
        out[k + 2] = table[(v >> 6) & 63]
        out[k + 3] = table[v & 63]
        i += 3
        k += 4
    rest = n - i
    if rest:
        v = src[i] << 16
        if rest == 2:
            v |= src[i + 1] << 8
        out[k] = table[(v >> 18) & 63]
        out[k + 1] = table[(v >> 12) & 63]
        out[k + 2] = table[(v >> 6) & 63] if rest == 2 else 61  # =
        out[k + 3] = 61
        k += 4
    return k


@jit(nogil=True)
def _encode_frames(t_ns, number, cloud, pos, frame0, const, prog, channels, table, pow10, out,
                   index):  # pragma: no cover - compiled
    """The MCAP message records of nframe frames, written into out; index[m] =
    (channel, log time ns, offset in out) of each. Returns (bytes written, messages).

    t_ns (nframe,); number (nframe, nslot) the numeric slots; cloud (nframe, nbyte)
    the point cloud bytes; pos (nframe, nvert, 3); frame0 the run's index of the first frame;
    channels (nchannel, 4) = (channel id, first op, end op, every nth frame)."""
    k = 0
    m = 0
    for f in range(t_ns.shape[0]):
        t = t_ns[f]
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
            start = k
            k += RECORD_HEAD
            for p in range(p0, p1):
                op, a, b = prog[p, 0], prog[p, 1], prog[p, 2]
                if op == OP_CONST:
                    out[k:k + b - a] = const[a:b]
                    k += b - a
                elif op == OP_STAMP:
                    for c8 in b'{"sec":':
                        out[k] = c8
                        k += 1
                    k = _put_decimal(out, k, t // 1000000000)
                    for c8 in b',"nsec":':
                        out[k] = c8
                        k += 1
                    k = _put_decimal(out, k, t % 1000000000)
                    out[k] = 125  # }
                    k += 1
                elif op == OP_NUMBER:
                    k = _put_float(out, k, number[f, a], pow10)
                elif op == OP_BASE64:
                    k = _put_base64(cloud[f], out, k, table)
                elif op == OP_POINTS:
                    k = _put_points(pos[f], out, k)
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
            self._zstd = zstandard.ZstdCompressor(level=1)  # fast: the chunks are written during the run
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


class _FrameWriter:
    """Writes the file's head (metadata, schemas, channels, geoms) and then batches of
    frames, each batch encoded by one compiled pass into one chunk."""

    def __init__(self, path: Path, plan: dict, *, mesh_every: int, chunk_size: int):
        self._file = open(path, "wb")
        self._writer = w = _McapWriter(self._file, chunk_size=chunk_size)
        n, face, colours = plan["nvert"], plan["face_vert"], plan["colours"]
        bodies = [name for _, name in plan["bodies"]]
        w.metadata("hybrid", {"description": json.dumps({
            "scene": plan["scene"], "dt_s": plan["dt_s"], "every_s": plan["every_s"], "nvert": n,
            "face_vert": face.tolist(), "regions": plan["regions"], "vert_label": plan["vert_label"].tolist(),
            "vert_rgba": np.round(colours, 4).tolist(), "link_vert": plan["link_vert"].tolist(),
            "geoms": plan["geoms"], "bodies": bodies})})
        schemas = {name: w.schema(name, "jsonschema", json.dumps(s).encode())
                   for name, s in _foxglove_schemas().items()}

        def channel(topic, schema):
            return w.channel(topic, "json", schemas[schema])

        # number slots of a frame: t, the scalars, then each body's x, y, z and w, x, y, z
        self.nbody = len(bodies)
        self.nslot = 1 + len(SCALAR_CHANNELS) + 7 * self.nbody
        const = bytearray()
        prog: list[tuple[int, int, int]] = []
        programs: list[tuple[int, int, int, int]] = []  # (channel, first op, end op, every)

        def text(s: str) -> None:
            a = len(const)
            const.extend(s.encode())
            prog.append((OP_CONST, a, len(const)))

        def program(ch: int, every: int, *ops) -> None:
            p0 = len(prog)
            for op in ops:
                text(op) if isinstance(op, str) else prog.append(op)
            programs.append((ch, p0, len(prog), every))

        stamp, points, cloud = (OP_STAMP, 0, 0), (OP_POINTS, 0, 0), (OP_BASE64, 0, 0)

        def num(slot):
            return (OP_NUMBER, slot, 0)

        # point cloud: x, y, z float32 then r, g, b, a uint8 (16 bytes a point)
        self._cloud = np.zeros((0, n), dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
        self._rgba = np.round(colours * 255).astype(np.uint8)
        fields = [{"name": k, "offset": o, "type": _FLOAT32} for k, o in (("x", 0), ("y", 4), ("z", 8))]
        fields += [{"name": k, "offset": 12 + i, "type": _UINT8} for i, k in enumerate(("red", "green", "blue", "alpha"))]
        program(channel("/membrane/points", "foxglove.PointCloud"), 1,
                '{"frame_id":"world","pose":%s,"point_stride":16,"fields":%s,"timestamp":'
                % (_IDENTITY_POSE, json.dumps(fields)), stamp, ',"data":"', cloud, '"}')
        # triangle list: the points change, indices and colours do not
        rgba = np.round(colours, 3)
        program(channel("/membrane/mesh", "foxglove.SceneUpdate"), mesh_every,
                '{"deletions":[],"entities":[{"frame_id":"world","id":"membrane",'
                '"lifetime":{"sec":0,"nsec":0},"frame_locked":false,"timestamp":', stamp,
                ',"triangles":[{"pose":%s,"color":{"r":0.8,"g":0.8,"b":0.8,"a":1},"colors":%s,"indices":%s,"points":['
                % (_IDENTITY_POSE, json.dumps([dict(zip("rgba", c)) for c in rgba.tolist()], separators=(",", ":")),
                   json.dumps(face.ravel().tolist(), separators=(",", ":"))), points, "]}]}]}")
        for i, topic in enumerate(SCALAR_CHANNELS):
            program(channel(topic, "hybrid.Scalar"), 1, (OP_IF_FINITE, 1 + i, 0),
                    '{"t":', num(0), ',"value":', num(1 + i), "}")
        if bodies:
            ops: list = ['{"transforms":[']
            for b, name in enumerate(bodies):
                s = 1 + len(SCALAR_CHANNELS) + 7 * b  # x, y, z, qw, qx, qy, qz
                ops += ["," if b else "", '{"timestamp":', stamp,
                        ',"parent_frame_id":"world","child_frame_id":%s,"translation":{"x":' % json.dumps(name),
                        num(s), ',"y":', num(s + 1), ',"z":', num(s + 2), '},"rotation":{"x":', num(s + 4),
                        ',"y":', num(s + 5), ',"z":', num(s + 6), ',"w":', num(s + 3), "}}"]
            program(channel("/rigid/transforms", "foxglove.FrameTransforms"), 1, *ops, "]}")
            w.message(channel("/rigid/geoms", "foxglove.SceneUpdate"), 0, _geom_scene(plan["geoms"]).encode())
            w.flush_chunk()
        self._const = np.frombuffer(bytes(const), np.uint8)
        self._prog = np.array(prog, np.int64).reshape(-1, 3)
        self._programs = np.array(programs, np.int64)
        # bytes of a frame at most (a number at 24 characters, a coordinate at 23)
        cloud_b64 = 4 * ((16 * n + 2) // 3)
        self.frame_bytes = (len(const) + len(programs) * (RECORD_HEAD + 60) + 24 * self.nslot * 2
                            + cloud_b64 + (n * 3 * 24 + n) // mesh_every + 64)
        self._out = np.empty(0, np.uint8)
        self._index = np.empty((0, 3), np.int64)
        # compile (or load) the encoder before the run, for the (writable) arrays the run passes
        one = np.zeros((1, self.nslot))
        self.write(np.zeros(1), one, np.array(plan["rest"], float)[None], 0, dry=True)

    def write(self, t_s, number, pos, frame0: int, *, dry: bool = False) -> None:
        """Frames frame0, frame0 + 1, ...: t_s (nframe,) s, number (nframe, nslot), pos
        (nframe, nvert, 3) m, as one chunk."""
        nframe = len(t_s)
        t_ns = np.maximum(np.round(np.asarray(t_s) * 1e9), 0).astype(np.int64)
        if len(self._cloud) < nframe:
            self._cloud = np.zeros((nframe, pos.shape[1]), self._cloud.dtype)
            self._cloud["rgba"] = self._rgba
        cloud = self._cloud[:nframe]
        cloud["xyz"] = pos
        need = nframe * self.frame_bytes
        if len(self._out) < need:
            self._out = np.empty(2 * need, np.uint8)
        if len(self._index) < nframe * len(self._programs):
            self._index = np.empty((2 * nframe * len(self._programs), 3), np.int64)
        k, m = _encode_frames(t_ns, number, cloud.view(np.uint8).reshape(nframe, -1), pos, frame0, self._const,
                              self._prog, self._programs, _B64, _POW10, self._out, self._index)
        if not dry:
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
    `MESH_EVERY_FRAME_MAX` points, 10 above).
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
        self._fw = _FrameWriter(self.path, plan, chunk_size=chunk_size,
                                mesh_every=int(mesh_every) if mesh_every else (1 if n <= MESH_EVERY_FRAME_MAX else 10))
        batch = int(min(max(chunk_size // self._fw.frame_bytes, 1), 1000))
        nslot = self._fw.nslot
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
            self._thread = threading.Thread(target=self._work, name="hybrid-recorder", daemon=True)
            self._thread.start()

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
        """Record the frames a compiled call captured (`hybrid.simulation.Frames`,
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
        if time.perf_counter() - self._last_flush > self.flush_s:
            self._hand_over()

    def _take_trace(self, buf, nframe: int) -> None:
        """The scalar channels of the frames held, from the runner's trace rows."""
        rows = buf.trace_row[:nframe]
        have = rows >= 0
        if self._trace is None or not have.any():
            return
        lo, hi = int(rows[have].min()), int(rows[have].max())
        for i, key in enumerate(SCALAR_CHANNELS.values()):
            series = getattr(self._trace, key, None)
            col = buf.number[:nframe, 1 + i]
            if series and len(series) > hi:
                col[have] = np.asarray(series[lo:hi + 1], float)[rows[have] - lo]
            else:
                col[have] = np.nan

    def _hand_over(self) -> None:
        """Pass the frames held to the writer (the thread, or now)."""
        if self._held:
            self._take_trace(self._buf, self._held)
            item = (self._buf, self._held, self._first)
            self._first += self._held
            self._held = 0
            if self._todo is not None:
                self._todo.put(item)
                self._buf = self._free.get()  # waits while both buffers are being written
            else:
                self._write(item)
        self._last_flush = time.perf_counter()
        if self._error is not None:
            raise self._error

    def _write(self, item) -> None:
        buf, nframe, first = item
        try:
            if self._error is None:
                number = buf.numbers(nframe)
                self._fw.write(number[:, 0], number, buf.pos[:nframe], first)
        except BaseException as exc:  # raised again in the run's thread
            self._error = exc
        finally:
            if self._todo is not None:
                self._free.put(item[0])
            else:
                self._buf = item[0]

    def _work(self) -> None:
        while True:
            item = self._todo.get()
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
                self._hand_over()
            finally:
                if self._todo is not None:
                    self._todo.put(None)
                    self._thread.join()
        finally:
            self._fw.close()
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
            out[topic] = {"t": t, "bodies": names, "pos": np.array(pos, float), "quat": np.array(quat, float)}
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
