"""The compiled protobuf encoder: a frame's messages written as MCAP message records
by one compiled pass (numba) from small programs, one per channel. The only module
of the recording that compiles code."""

from __future__ import annotations

import numpy as np

from ..kernel import jit

# A frame's messages are written in protobuf by one compiled pass from small programs,
# one per channel: each op is (code, a, b), run in order. A first pass over a program
# sizes its nested messages (protobuf puts a message's length before it); only the
# time stamps change size from frame to frame.
OP_CONST = 0  # bytes const[a:b] (fields encoded once, by protobuf)
OP_BEGIN = 1  # a nested message, field tag a, up to its OP_END
OP_END = 2
OP_STAMP = 3  # the frame's time as a google.protobuf.Timestamp, field tag a
OP_DOUBLE = 4  # number slot b of the frame as a double, field tag a
OP_POINTS = 5  # the frame's points as repeated foxglove.Point3, field tag a
OP_CLOUD = 6  # the frame's point cloud bytes, field tag a
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
def _encode_frames(
    t_ns, number, number_bits, cloud, pos_bits, frame0, const, prog, channels, out, index, size, nest
):  # pragma: no cover - compiled
    """The MCAP message records of nframe frames, written into out; index[m] =
    (channel, log time ns, offset in out) of each. Returns (bytes written, messages).

    t_ns (nframe,); number (nframe, nslot) the numeric slots, number_bits the same
    as uint64 (their bits); cloud (nframe, nbyte) the point cloud bytes; pos_bits
    (nframe, 3 nvert) the bits of the points' x, y, z; frame0 the run's index of the
    first frame; channels (nchannel, 4) = (channel id, first op, end op, every nth
    frame); size (nop,) and nest (2, MAX_DEPTH) int64 scratch for the nested messages'
    lengths. Doubles are written as their bits, little-endian, as protobuf does. (The
    views and the scratch come from the caller: viewing and allocating here would
    compile numba's own functions for them, about a third of the encoder's compiling.)"""
    nvert = pos_bits.shape[1] // 3
    ncloud = cloud.shape[1]
    acc, opened = nest[0], nest[1]
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
                    k = _put_bytes(out, k, cloud[f], np.int64(0), ncloud)  # one compiled _put_bytes
            if k - start - RECORD_HEAD != acc[0]:  # the sizing pass and the writing pass disagree
                raise RuntimeError("hybrid.record: a message's size differs from the size its fields were given")
            out[start] = 5  # opcode: message
            # sizes as int64, not literal constants: one compiled _put_uint, not one per size
            _put_uint(out, start + 1, k - start - 9, np.int64(8))
            _put_uint(out, start + 9, ch, np.int64(2))
            _put_uint(out, start + 11, np.int64(0), np.int64(4))  # sequence
            _put_uint(out, start + 15, t, np.int64(8))  # log time
            _put_uint(out, start + 23, t, np.int64(8))  # publish time
            index[m, 0] = ch
            index[m, 1] = t
            index[m, 2] = start
            m += 1
    return k, m


def encode_frames(t_ns, number, cloud, pos, frame0, const, prog, channels, out, index, size):
    """`_encode_frames` of float64 C-contiguous number (nframe, nslot) and pos
    (nframe, 3 nvert): their bits viewed, the nesting scratch made, here. Returns
    (bytes written, messages)."""
    return _encode_frames(
        t_ns,
        number,
        number.view(np.uint64),
        cloud,
        pos.view(np.uint64),
        frame0,
        const,
        prog,
        channels,
        out,
        index,
        size,
        np.zeros((2, MAX_DEPTH), np.int64),
    )


def _load_encoder() -> None:
    """Compile the encoder, or load it from the cache, once a process, in the calling
    thread (the recorder's constructor: before the run, not in the writer thread while
    the run waits for it), with the argument types `_FrameWriter.write` passes."""
    if _encode_frames.signatures:
        return
    encode_frames(
        np.zeros(1, np.int64),
        np.zeros((1, 1)),
        np.zeros((1, 16), np.uint8),
        np.zeros((1, 3)),
        0,
        np.zeros(1, np.uint8),
        np.zeros((0, 3), np.int64),
        np.zeros((0, 4), np.int64),
        np.zeros(1, np.uint8),
        np.zeros((0, 3), np.int64),
        np.zeros(0, np.int64),
    )
