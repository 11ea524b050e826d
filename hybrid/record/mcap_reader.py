"""A recording's MCAP records read back and verified, chunk by chunk.

`_open` reads a file's structure (magic, header, footer, summary, chunk index)
or, for a file without a summary (a run killed before it closed it), scans its
records one by one; `_chunks` yields the chunks that overlap a time window,
each checked: its CRC, its header against the summary's chunk index, its start
and end times against its messages, its message indexes. A disagreement is a
`RecordingError` naming the chunk, its time range and its byte offset (with
`strict=False` the chunk is skipped and a `RecordingWarning` says so); a file
that ends inside a record is read up to its last complete chunk, with a warning.
`hybrid.record.reader` decodes what these yield.
"""

from __future__ import annotations

import json
import struct
import warnings
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import HybridError

__all__ = ["RecordingError", "RecordingWarning"]

MAGIC = b"\x89MCAP0\r\n"
# opcodes (MCAP spec)
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = 1, 2, 3, 4, 5, 6, 7, 8
ATTACHMENT_INDEX, STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = 10, 11, 12, 13, 14, 15
_DATA_OPS = {HEADER, SCHEMA, CHANNEL, CHUNK, MESSAGE_INDEX, METADATA, DATA_END}  # what hybrid writes
_SUMMARY_OPS = {SCHEMA, CHANNEL, STATISTICS, CHUNK_INDEX, METADATA_INDEX, ATTACHMENT_INDEX, SUMMARY_OFFSET}
_FOOTER_BYTES = 1 + 8 + 20
_PREFIX_MAX = 4096  # the fields that give a record's length fit in this (hybrid's names are short)
_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, length, channel, sequence, log time, publish time


class RecordingError(HybridError, ValueError):
    """A recording is unreadable: not an MCAP file, not hybrid's, or corrupt."""


class RecordingWarning(UserWarning):
    """A recording was read in part: it ends early (a killed run) or chunks were skipped."""


class _Cut(Exception):
    """The bytes end inside a field."""


class _Bad(Exception):
    """Fields that disagree with each other."""


class _Cursor:
    """Little-endian fields read off a bytes-like object from offset k."""

    __slots__ = ("b", "k")

    def __init__(self, b, k: int = 0):
        self.b, self.k = b, k

    def take(self, n: int):
        if n < 0 or self.k + n > len(self.b):
            raise _Cut
        v = self.b[self.k : self.k + n]
        self.k += n
        return v

    def skip(self, n: int) -> None:
        """Past n bytes, which may lie beyond the ones held."""
        self.k += n

    def _int(self, fmt: str, n: int) -> int:
        return struct.unpack(fmt, self.take(n))[0]

    def u8(self) -> int:
        return self._int("<B", 1)

    def u16(self) -> int:
        return self._int("<H", 2)

    def u32(self) -> int:
        return self._int("<I", 4)

    def u64(self) -> int:
        return self._int("<Q", 8)

    def str(self) -> str:
        raw = bytes(self.take(self.u32()))
        try:
            return raw.decode()
        except UnicodeDecodeError:
            raise _Bad(f"a string field is not UTF-8 ({raw[:20]!r})") from None

    def map(self, key, value) -> dict:
        n = self.u32()
        end = self.k + n
        out = {}
        while self.k < end:
            k = key(self)
            out[k] = value(self)
        if self.k != end:
            raise _Bad("a map's entries overrun its length")
        return out


def _implied_length(op: int, prefix) -> int:
    """A record's body length as its leading fields give it (raises _Cut if the
    prefix is too short to tell)."""
    c = _Cursor(prefix)
    if op == HEADER:
        c.take(c.u32())
        c.take(c.u32())
    elif op == SCHEMA:
        c.u16()
        c.take(c.u32())
        c.take(c.u32())
        c.skip(c.u32())
    elif op == CHANNEL:
        c.take(4)
        c.take(c.u32())
        c.take(c.u32())
        c.skip(c.u32())
    elif op == CHUNK:
        c.take(28)
        c.take(c.u32())
        c.skip(c.u64())
    elif op == MESSAGE_INDEX:
        c.u16()
        c.skip(c.u32())
    elif op == METADATA:
        c.take(c.u32())
        c.skip(c.u32())
    elif op == DATA_END:
        c.skip(4)
    else:
        raise _Bad(f"opcode {op:#04x}, which hybrid does not write")
    return c.k


@dataclass
class _Chunk:
    """Where a chunk is, and what its header (or the summary's index of it) says."""

    offset: int
    length: int  # the whole record, opcode and length included
    t_lo: int
    t_hi: int
    usize: int
    compression: str
    csize: int
    index_at: int = 0  # its message indexes: where they start, and their bytes
    index_len: int = 0
    index_offsets: dict | None = None  # channel -> the offset of its message index (from the summary)
    index_partial: bool = False  # the file ends inside its message indexes


@dataclass
class _File:
    path: Path
    size: int
    library: str | None = None
    schemas: dict = field(default_factory=dict)  # id -> (name, encoding, data)
    channels: dict = field(default_factory=dict)  # id -> (topic, encoding, schema id)
    meta: dict | None = None
    chunks: list = field(default_factory=list)
    truncated: str | None = None  # where and in what the file ends early

    def error(self, what: str) -> RecordingError:
        return RecordingError(f"recording {str(self.path)!r}: {what}")


def _chunk_header(c: _Cursor):
    t_lo, t_hi, usize, crc = c.u64(), c.u64(), c.u64(), c.u32()
    compression = c.str()
    return t_lo, t_hi, usize, crc, compression, c.u64()


def _parse_body(op: int, body, f: _File, offset: int) -> None:
    """A record of the data section (but chunks and message indexes) into f."""
    c = _Cursor(body)
    if op == HEADER:
        c.str()
        f.library = c.str()
    elif op == SCHEMA:
        sid, name, encoding = c.u16(), c.str(), c.str()
        f.schemas[sid] = (name, encoding, bytes(c.take(c.u32())))
    elif op == CHANNEL:
        cid, sid, topic, encoding = c.u16(), c.u16(), c.str(), c.str()
        c.map(_Cursor.str, _Cursor.str)
        f.channels[cid] = (topic, encoding, sid)
    elif op == METADATA:
        name = c.str()
        data = c.map(_Cursor.str, _Cursor.str)
        if name == "hybrid" and f.meta is None:
            f.meta = _description(data, f, offset)


def _description(data: dict, f: _File, offset: int) -> dict:
    """The model's description of a "hybrid" metadata record, its CRC checked."""
    text = data.get("description")
    if text is None:
        raise f.error(f"the metadata record at byte offset {offset} has no 'description'")
    crc = data.get("description_crc32")
    if crc is not None and crc != f"{zlib.crc32(text.encode()):08x}":
        raise f.error(
            f"the model's description (metadata record at byte offset {offset}) is corrupt: its CRC "
            f"is {zlib.crc32(text.encode()):08x}, the record gives {crc}"
        )
    try:
        meta = json.loads(text)
        meta["face_vert"] = np.asarray(meta["face_vert"], np.int64).reshape(-1, 3)
        meta["vert_label"] = np.asarray(meta["vert_label"], int)
        meta["vert_rgba"] = np.asarray(meta["vert_rgba"], float)
        meta["link_vert"] = np.asarray(meta["link_vert"], int)
    except (ValueError, KeyError, TypeError) as exc:
        raise f.error(
            f"the model's description (metadata record at byte offset {offset}) is unreadable: "
            f"{type(exc).__name__}: {exc}"
        ) from None
    return meta


def _open(fh, path: Path, strict: bool) -> _File:
    """The file's structure: its summary if it is finished, else a scan of its records."""
    fh.seek(0, 2)
    f = _File(path=path, size=fh.tell())
    fh.seek(0)
    head = fh.read(8)
    if head != MAGIC:
        if MAGIC.startswith(head):  # empty, or ends inside the magic: nothing recorded yet
            f.truncated = f"the file ends at byte {f.size}, before its first record"
            return f
        raise f.error(f"not an MCAP file: it starts with {head!r}, an MCAP file with {MAGIC!r}")
    if f.size >= 8 + _FOOTER_BYTES + 8:
        fh.seek(f.size - 8)
        if fh.read(8) == MAGIC:
            try:
                _read_summary(fh, f)
                _check_foreign(f)
                return f
            except RecordingError as exc:
                if strict:
                    raise
                warnings.warn(f"{exc}; reading its records one by one instead", RecordingWarning, stacklevel=3)
                f = _File(path=path, size=f.size)
    _scan(fh, f, strict)
    _check_foreign(f)
    return f


def _check_foreign(f: _File) -> None:
    """Refuse what hybrid did not write (the encoding first: earlier hybrids wrote JSON)."""
    for topic, encoding, _ in f.channels.values():
        if encoding != "protobuf":
            raise f.error(
                f"channel {topic} is encoded in {encoding!r}; expected 'protobuf' (a recording of an "
                "earlier hybrid, which wrote JSON: run the scene again to record it anew)"
            )
    if f.library is not None and f.library != "hybrid":
        raise f.error(f"not a recording of hybrid: its header names the library {f.library!r}, expected 'hybrid'")


def _read_summary(fh, f: _File) -> None:
    """A finished file: footer, summary (its CRC), header, chunk index, metadata."""
    end = f.size - 8 - _FOOTER_BYTES
    fh.seek(end)
    footer = fh.read(_FOOTER_BYTES)
    op, n, summary_start, offset_start, crc = struct.unpack("<BQQQI", footer)
    if op != FOOTER or n != 20:
        raise f.error(
            f"the footer at byte offset {end} is corrupt (opcode {op:#04x}, length {n}; expected 0x02 and 20)"
        )
    if not 8 < summary_start <= offset_start <= end:
        raise f.error(
            f"the footer at byte offset {end} is corrupt: its summary starts at byte {summary_start} "
            f"and its offsets at {offset_start}, expected 8 < start <= offsets <= {end}"
        )
    fh.seek(summary_start)
    summary = fh.read(end - summary_start)
    actual = zlib.crc32(footer[:-4], zlib.crc32(summary))
    if actual != crc:
        raise f.error(
            f"the summary (bytes {summary_start} to {end}) is corrupt: its CRC is {actual:08x}, the "
            f"footer gives {crc:08x}"
        )
    index, meta_at, nchunk = [], [], None
    c = _Cursor(summary)
    try:
        while c.k < len(summary):
            at = summary_start + c.k
            op, n = c.u8(), c.u64()
            body = _Cursor(c.take(n))
            if op == SCHEMA:
                sid, name, encoding = body.u16(), body.str(), body.str()
                f.schemas[sid] = (name, encoding, bytes(body.take(body.u32())))
            elif op == CHANNEL:
                cid, sid, topic, encoding = body.u16(), body.u16(), body.str(), body.str()
                f.channels[cid] = (topic, encoding, sid)
            elif op == STATISTICS:
                body.take(8 + 2 + 4 + 4 + 4)
                nchunk = body.u32()
            elif op == CHUNK_INDEX:
                t_lo, t_hi, start, length = body.u64(), body.u64(), body.u64(), body.u64()
                offsets = body.map(_Cursor.u16, _Cursor.u64)
                index_len, compression, csize, usize = body.u64(), body.str(), body.u64(), body.u64()
                index.append(
                    _Chunk(
                        offset=start,
                        length=length,
                        t_lo=t_lo,
                        t_hi=t_hi,
                        usize=usize,
                        compression=compression,
                        csize=csize,
                        index_at=start + length,
                        index_len=index_len,
                        index_offsets=offsets,
                    )
                )
            elif op == METADATA_INDEX:
                meta_at.append((body.u64(), body.u64(), body.str()))
            elif op not in _SUMMARY_OPS:
                raise _Bad(f"a record of opcode {op:#04x} at byte offset {at}, which a summary does not hold")
    except (_Cut, _Bad) as exc:
        raise f.error(
            f"the summary (bytes {summary_start} to {end}) is malformed: {exc or 'a record overruns it'}"
        ) from None
    # the header, and the data section's end
    fh.seek(8)
    prefix = fh.read(_PREFIX_MAX)
    try:
        c = _Cursor(prefix)
        if c.u8() != HEADER:
            raise _Bad("the first record is not a header")
        n = c.u64()
        _parse_body(HEADER, c.take(n), f, 8)
    except (_Cut, _Bad) as exc:
        raise f.error(f"the header at byte offset 8 is corrupt: {exc or 'it overruns its length'}") from None
    data_start, data_end = 8 + 9 + n, summary_start - 13
    fh.seek(data_end)
    if fh.read(9) != struct.pack("<BQ", DATA_END, 4):
        raise f.error(f"no data-end record at byte offset {data_end}, before the summary")
    if nchunk is not None and nchunk != len(index):
        raise f.error(f"the summary counts {nchunk} chunks but indexes {len(index)}")
    index.sort(key=lambda ch: ch.offset)
    k = data_start
    for i, ch in enumerate(index):
        if ch.offset < k or ch.offset + ch.length + ch.index_len > data_end:
            raise f.error(
                f"the chunk index's entry {i + 1} of {len(index)} (t {ch.t_lo * 1e-9:.6g} to "
                f"{ch.t_hi * 1e-9:.6g} s) puts it at bytes {ch.offset} to {ch.offset + ch.length}, "
                f"outside the data section's free bytes {k} to {data_end}"
            )
        k = ch.offset + ch.length + ch.index_len
    f.chunks = index
    for offset, length, name in meta_at:
        if name != "hybrid":
            continue
        fh.seek(offset)
        rec = fh.read(length)
        try:
            c = _Cursor(rec)
            if c.u8() != METADATA or c.u64() != length - 9:
                raise _Bad("its opcode or length differs from the summary's index of it")
            _parse_body(METADATA, c.take(length - 9), f, offset)
        except (_Cut, _Bad) as exc:
            raise f.error(
                f"the metadata record at byte offset {offset} is corrupt: {exc or 'it overruns its length'}"
            ) from None
        break


def _scan(fh, f: _File, strict: bool) -> None:
    """An unfinished file (or one whose summary is damaged, in salvage): its records
    in order, chunks located from their headers and left unread. The file may end
    inside a record (a killed run); a record whose fields disagree is an error."""
    k = 8
    last = None  # the last chunk, whose message indexes follow it
    while k < f.size:
        avail = f.size - k - 9
        if avail < 0:
            f.truncated = f"the file ends at byte {f.size}, inside the opcode and length of a record at byte {k}"
            break
        fh.seek(k)
        op, n = struct.unpack("<BQ", fh.read(9))
        want = min(n, avail)
        prefix = fh.read(min(want, _PREFIX_MAX))
        try:
            if op not in _DATA_OPS:
                raise _Bad(f"opcode {op:#04x}, which hybrid does not write in a data section")
            try:
                implied = _implied_length(op, prefix)
                head = _chunk_header(_Cursor(prefix)) if op == CHUNK else None
            except _Cut:
                if len(prefix) == want < n:
                    f.truncated = (
                        f"the file ends at byte {f.size}, inside the fields of a record of opcode {op:#04x} at byte {k}"
                    )
                    break
                raise _Bad(f"its fields overrun its length of {n} bytes") from None
            if implied != n:
                raise _Bad(f"its length is {n} bytes, its fields give {implied}")
            if op == MESSAGE_INDEX and (last is None or last.index_at + last.index_len != k):
                raise _Bad("a message index that follows no chunk")
        except _Bad as exc:
            what = f"the record at byte offset {k} is corrupt: {exc}"
            if last is not None:
                what += f" (after chunk {len(f.chunks)}, t {last.t_lo * 1e-9:.6g} to {last.t_hi * 1e-9:.6g} s)"
            if strict:
                raise f.error(what + "; read with strict=False to keep the chunks before it") from None
            warnings.warn(
                f"recording {str(f.path)!r}: {what}; skipped the rest of the file", RecordingWarning, stacklevel=4
            )
            break
        if n > avail:
            kind = {CHUNK: "a chunk", MESSAGE_INDEX: "a chunk's message index"}.get(op, f"a record ({op:#04x})")
            f.truncated = f"the file ends at byte {f.size}, inside {kind} at byte {k} ({avail} of its {n} bytes)"
            break
        if op == CHUNK:
            t_lo, t_hi, usize, _, compression, csize = head
            last = _Chunk(
                offset=k,
                length=9 + n,
                t_lo=t_lo,
                t_hi=t_hi,
                usize=usize,
                compression=compression,
                csize=csize,
                index_at=k + 9 + n,
            )
            f.chunks.append(last)
        elif op == MESSAGE_INDEX:
            last.index_len += 9 + n
        elif op == DATA_END:
            try:
                _scan_summary(fh, f, k + 9 + n)
            except RecordingError as exc:
                if strict:
                    raise
                warnings.warn(f"{exc}; read its data section", RecordingWarning, stacklevel=4)
            return
        else:
            if len(prefix) < n:
                fh.seek(k + 9)
                prefix = fh.read(n)
            try:
                _parse_body(op, prefix, f, k)
            except (_Cut, _Bad) as exc:
                raise f.error(
                    f"the record of opcode {op:#04x} at byte offset {k} is corrupt: {exc or 'it overruns its length'}"
                ) from None
            if op == HEADER:
                _check_foreign(f)
        k += 9 + n
    else:
        f.truncated = f"the file ends at byte {f.size}, after a complete record but without its summary"
    if f.truncated is not None and last is not None and last.index_at + last.index_len == k:
        last.index_partial = True  # the file ends in (or just before) its message indexes


def _scan_summary(fh, f: _File, k: int) -> None:
    """After the data section of a file without its final magic: the file ends in
    its summary (a process killed while finishing it), or its end is damaged."""
    while k < f.size:
        if f.size - k < 9:
            break
        fh.seek(k)
        op, n = struct.unpack("<BQ", fh.read(9))
        if op not in _SUMMARY_OPS | {FOOTER}:
            raise f.error(f"the record at byte offset {k}, in the summary, is corrupt: opcode {op:#04x}")
        if op == FOOTER:
            fh.seek(k + 9 + n)
            tail = fh.read(8)
            if n == 20 and len(tail) < 8 and MAGIC.startswith(tail):
                break
            raise f.error(
                f"the end of the file after its footer at byte offset {k} is corrupt: expected the 8 bytes {MAGIC!r}"
            )
        k += 9 + n
    f.truncated = f"the file ends at byte {f.size}, inside its summary (the run was stopped while finishing it)"


def _where(f: _File, i: int, c: _Chunk) -> str:
    return f"chunk {i + 1} of {len(f.chunks)} (t {c.t_lo * 1e-9:.6g} to {c.t_hi * 1e-9:.6g} s, byte offset {c.offset})"


def _load(fh, f: _File, c: _Chunk) -> tuple[bytes, list]:
    """A chunk's records, verified; returns them and their messages as (channel,
    log time ns, start, end) in the records. Raises _Bad on any disagreement."""
    import zstandard

    fh.seek(c.offset)
    rec = fh.read(c.length)
    cur = _Cursor(rec)
    op, n = cur.u8(), cur.u64()
    if op != CHUNK or n != c.length - 9:
        raise _Bad(f"its record has opcode {op:#04x} and length {n}, expected 0x06 and {c.length - 9}")
    t_lo, t_hi, usize, crc, compression, csize = _chunk_header(cur)
    head = (t_lo, t_hi, usize, compression, csize)
    if head != (c.t_lo, c.t_hi, c.usize, c.compression, c.csize):
        raise _Bad(
            f"its header (t {t_lo} to {t_hi} ns, {usize} bytes, {compression!r}, {csize} compressed) "
            f"differs from the summary's index of it (t {c.t_lo} to {c.t_hi} ns, {c.usize} bytes, "
            f"{c.compression!r}, {c.csize} compressed)"
        )
    if cur.k + csize != len(rec):
        raise _Bad(f"its data ({csize} bytes) overruns the record")
    data = rec[cur.k :]
    if compression == "zstd":
        try:
            raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
        except (zstandard.ZstdError, OverflowError, MemoryError) as exc:  # a size no chunk can have
            raise _Bad(f"its data does not decompress: {exc}") from None
    elif compression == "":
        raw = data
    else:
        raise _Bad(f"its compression is {compression!r}, expected 'zstd'")
    if len(raw) != usize:
        raise _Bad(f"its records are {len(raw)} bytes, its header says {usize}")
    actual = zlib.crc32(raw)
    if actual != crc:
        raise _Bad(f"the CRC of its records is {actual:08x}, its header gives {crc:08x}")
    msgs = []
    k = 0
    while k < len(raw):
        if len(raw) - k < _MSG_HEAD.size:
            raise _Bad(f"it ends inside a message's head at byte {k} of its records")
        op, n, ch, _, t, _ = _MSG_HEAD.unpack_from(raw, k)
        if op != MESSAGE or n < 22 or k + 9 + n > len(raw):
            raise _Bad(
                f"the record at byte {k} of its records (opcode {op:#04x}, length {n}) is not a message "
                "within the chunk"
            )
        if ch not in f.channels:
            raise _Bad(f"the message at byte {k} of its records is on channel {ch}, which the file does not declare")
        msgs.append((ch, t, k + _MSG_HEAD.size, k + 9 + n))
        k += 9 + n
    if msgs:
        times = [m[1] for m in msgs]
        if (min(times), max(times)) != (t_lo, t_hi):
            raise _Bad(f"its messages span t {min(times)} to {max(times)} ns, its header says {t_lo} to {t_hi}")
    _check_message_index(fh, c, msgs)
    return raw, msgs


def _check_message_index(fh, c: _Chunk, msgs: list) -> None:
    """The chunk's message indexes list each of its messages: (log time, offset), by channel."""
    fh.seek(c.index_at)
    raw = fh.read(c.index_len)
    indexed = {}
    cur = _Cursor(raw)
    while cur.k < len(raw):
        at = c.index_at + cur.k
        op, n = cur.u8(), cur.u64()
        body = _Cursor(cur.take(n))
        ch = body.u16()
        records = bytes(body.take(body.u32()))
        if op != MESSAGE_INDEX or body.k != n or len(records) % 16:
            raise _Bad(f"its message index at byte offset {at} is malformed")
        if c.index_offsets is not None and c.index_offsets.get(ch) != at:
            raise _Bad(
                f"its message index of channel {ch} is at byte offset {at}, the summary says {c.index_offsets.get(ch)}"
            )
        indexed[ch] = np.frombuffer(records, "<u8").reshape(-1, 2)
    by_channel: dict[int, list] = {}
    for ch, t, start, _ in msgs:
        by_channel.setdefault(ch, []).append((t, start - _MSG_HEAD.size))
    if not c.index_partial and set(indexed) != set(by_channel):
        raise _Bad(f"its message indexes are of channels {sorted(indexed)}, its messages of {sorted(by_channel)}")
    for ch, records in indexed.items():
        have = np.array(by_channel.get(ch, []), np.uint64).reshape(-1, 2)
        listed = records[np.argsort(records[:, 1], kind="stable")]
        if not np.array_equal(listed, have):
            raise _Bad(f"its message index of channel {ch} differs from its messages")


def _chunks(fh, f: _File, lo_ns: int, hi_ns: int, strict: bool, decode) -> Iterator:
    """decode(records, messages) of each chunk overlapping [lo_ns, hi_ns], verified,
    in file order; in salvage, the corrupt ones skipped with a warning."""
    for i, c in enumerate(f.chunks):
        if c.t_hi < lo_ns or c.t_lo > hi_ns:
            continue
        try:
            out = decode(*_load(fh, f, c))
        except (_Bad, _Cut) as exc:
            what = f"{_where(f, i, c)} is corrupt: {exc or 'a record overruns it'}"
            if strict:
                raise f.error(what + "; read with strict=False to skip it") from None
            warnings.warn(f"recording {str(f.path)!r}: {what}; skipped", RecordingWarning, stacklevel=3)
            continue
        yield out


def _warn_truncated(f: _File) -> None:
    if f.truncated is not None:
        warnings.warn(
            f"recording {str(f.path)!r}: {f.truncated}; read up to its last complete chunk",
            RecordingWarning,
            stacklevel=3,
        )
