"""A recording's MCAP records read back and verified, chunk by chunk, on the `mcap` library.

mcap reads the summary and the header (`make_reader`), each record's fields (its
record classes) and a chunk's data, decompressed and its CRC checked
(`get_chunk_data_stream`). Kept here is what mcap does not do: the summary's CRC; each chunk
against the summary's index of it (mcap reads the data at the index's offset without
looking at its opcode, length, times or size), its times and size against its
messages, its message indexes (mcap never reads them); fields that fill their record
exactly; errors that name the chunk, its time range and byte offset (`RecordingError`,
or with `strict=False` a `RecordingWarning` and the chunk skipped); files without a
summary (a killed run) scanned up to their last complete chunk, with a warning; other
writers' files refused. `hybrid.record.reader` decodes what these yield.
"""

from __future__ import annotations

import io
import json
import struct
import warnings
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.reader import FOOTER_SIZE, make_reader
from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Header, MessageIndex, Metadata, Schema
from mcap.stream_reader import get_chunk_data_stream
from mcap.writer import MCAP0_MAGIC as MAGIC

from ..errors import HybridError

__all__ = ["RecordingError", "RecordingWarning"]

# what hybrid writes in a data section, and mcap's parser of each
_PARSE = {
    Opcode.HEADER: Header.read,
    Opcode.SCHEMA: Schema.read,
    Opcode.CHANNEL: Channel.read,
    Opcode.CHUNK: Chunk.read,
    Opcode.MESSAGE_INDEX: MessageIndex.read,
    Opcode.METADATA: Metadata.read,
    Opcode.DATA_END: DataEnd.read,
}
_PREFIX_MAX = 4096  # a chunk's fields before its data fit in this (hybrid's compression name is short)
_MSG = struct.Struct("<BQHIQQ")  # a message record's opcode, length, channel, sequence, log and publish times


class RecordingError(HybridError, ValueError):
    """A recording is unreadable: not an MCAP file, not hybrid's, or corrupt."""


class RecordingWarning(UserWarning):
    """A recording was read in part: it ends early (a killed run) or chunks were skipped."""


class _Bad(Exception):
    """Fields that disagree with each other."""


class _Cut(_Bad):
    """Fields that run past the bytes held."""


class _Exact(ReadDataStream):
    """mcap's field reader on bytes held, a field that runs past them an error."""

    def __init__(self, b: bytes):
        super().__init__(io.BytesIO(b))
        self.size = len(b)

    def read(self, length: int) -> bytes:
        if length > self.size - self.count:
            raise EndOfFile
        return super().read(length)


def _parse(op: int, body: bytes):
    """A record's body parsed by mcap, its fields filling exactly its length."""
    if op not in _PARSE:
        raise _Bad(f"opcode {op:#04x}, which hybrid does not write in a data section")
    s = _Exact(body)
    try:
        rec = _PARSE[op](s)
    except (McapError, struct.error):
        raise _Cut(f"its fields overrun its length of {len(body)} bytes") from None
    except UnicodeDecodeError:
        raise _Bad("a string field is not UTF-8") from None
    if s.count != len(body):
        raise _Bad(f"its length is {len(body)} bytes, its fields give {s.count}")
    return rec


def _read_record(fh, at: int, op: int, length: int):
    """The record at byte `at` of an index's opcode and length (with the opcode's and its own 9 bytes), by mcap."""
    fh.seek(at)
    got, n = struct.unpack("<BQ", fh.read(9).ljust(9, b"\0"))
    if got != op or n != length - 9:
        raise _Bad(f"its record has opcode {got:#04x} and length {n}, expected {op:#04x} and {length - 9}")
    return _parse(op, fh.read(n))


@dataclass
class _File:
    path: Path
    size: int
    finished: bool = False  # it ends with the magic
    chunks_indexed: bool = False  # its chunks come from its summary (else from a scan)
    library: str | None = None
    schemas: dict = field(default_factory=dict)  # id -> mcap Schema
    channels: dict = field(default_factory=dict)  # id -> mcap Channel
    meta: dict | None = None
    chunks: list = field(default_factory=list)  # mcap ChunkIndex records, by offset
    truncated: str | None = None  # where and in what the file ends early
    partial: int | None = None  # the offset of a chunk whose message indexes the file's end cuts

    def error(self, what: str) -> RecordingError:
        return RecordingError(f"recording {str(self.path)!r}: {what}")


def _description(rec: Metadata, f: _File, offset: int) -> dict:
    """The model's description of a "hybrid" metadata record, its CRC checked."""
    where = f"the model's description (metadata record at byte offset {offset})"
    text, crc = rec.metadata.get("description"), rec.metadata.get("description_crc32")
    if text is None:
        raise f.error(f"the metadata record at byte offset {offset} has no 'description'")
    if crc is not None and crc != f"{zlib.crc32(text.encode()):08x}":
        raise f.error(f"{where} is corrupt: its CRC is {zlib.crc32(text.encode()):08x}, the record gives {crc}")
    try:
        meta = json.loads(text)
        meta["face_vert"] = np.asarray(meta["face_vert"], np.int64).reshape(-1, 3)
        meta["vert_label"] = np.asarray(meta["vert_label"], int)
        meta["vert_rgba"] = np.asarray(meta["vert_rgba"], float)
        meta["link_vert"] = np.asarray(meta["link_vert"], int)
    except (ValueError, KeyError, TypeError) as exc:
        raise f.error(f"{where} is unreadable: {type(exc).__name__}: {exc}") from None
    return meta


def _open(fh, path: Path, strict: bool) -> _File:
    """The file's structure: its summary if it is finished, else a scan of its records."""
    size = fh.seek(0, 2)
    fh.seek(0)
    head = fh.read(8)
    if head != MAGIC:
        if MAGIC.startswith(head):  # empty, or ends inside the magic: nothing recorded yet
            msg = f"recording {str(path)!r}: the file ends at byte {size}, before its first record"
            warnings.warn(msg, RecordingWarning, stacklevel=3)
            return _File(path, size)
        raise _File(path, size).error(f"not an MCAP file: it starts with {head!r}, an MCAP file with {MAGIC!r}")
    fh.seek(max(8, size - 8 - FOOTER_SIZE))
    tail = fh.read()
    f = _File(path, size, finished=size >= 8 + FOOTER_SIZE + 8 and tail.endswith(MAGIC))
    try:
        if f.finished:
            _read_summary(fh, f)
        elif len(tail) == FOOTER_SIZE + 8 and tail.startswith(struct.pack("<BQ", Opcode.FOOTER, 20)):
            raise f.error(
                f"the end of the file after its footer at byte offset {size - 8 - FOOTER_SIZE} is corrupt: "
                f"expected the 8 bytes {MAGIC!r}"
            )
    except RecordingError as exc:
        if strict:
            raise
        warnings.warn(f"{exc}; reading its records one by one instead", RecordingWarning, stacklevel=3)
        f = _File(path, size, finished=f.finished)
    if not f.chunks_indexed:
        _scan(fh, f, strict)
    _check_foreign(f)
    if f.truncated is not None:
        msg = f"recording {str(path)!r}: {f.truncated}; read up to its last complete chunk"
        warnings.warn(msg, RecordingWarning, stacklevel=3)
    return f


def _check_foreign(f: _File) -> None:
    """Refuse what hybrid did not write (the encoding first: earlier hybrids wrote JSON)."""
    for c in f.channels.values():
        if c.message_encoding != "protobuf":
            raise f.error(
                f"channel {c.topic} is encoded in {c.message_encoding!r}; expected 'protobuf' (a recording of an "
                "earlier hybrid, which wrote JSON: run the scene again to record it anew)"
            )
    if f.library is not None and f.library != "hybrid":
        raise f.error(f"not a recording of hybrid: its header names the library {f.library!r}, expected 'hybrid'")


def _read_summary(fh, f: _File) -> None:
    """A finished file: its summary's CRC (against the footer), then mcap's reader of the
    summary and the header, then the model's description through the metadata index."""
    end = f.size - 8 - FOOTER_SIZE
    fh.seek(end)
    footer = fh.read(FOOTER_SIZE)
    op, n, summary_start, offset_start, crc = struct.unpack("<BQQQI", footer)
    if op != Opcode.FOOTER or n != 20 or not 8 < summary_start <= offset_start <= end:
        raise f.error(
            f"the footer at byte offset {end} is corrupt (opcode {op:#04x}, length {n}, summary at byte "
            f"{summary_start}, offsets at {offset_start}; expected 0x02, 20 and 8 < summary <= offsets <= {end})"
        )
    fh.seek(summary_start)
    actual = zlib.crc32(footer[:-4], zlib.crc32(fh.read(end - summary_start)))
    if actual != crc:
        raise f.error(
            f"the summary (bytes {summary_start} to {end}) is corrupt: its CRC is {actual:08x}, the footer gives {crc:08x}"
        )
    fh.seek(0)
    reader = make_reader(fh)
    try:
        summary = reader.get_summary()
        f.library = reader.get_header().library
    except (McapError, ValueError, struct.error) as exc:
        raise f.error(f"its summary or header does not read: {type(exc).__name__}: {exc}") from None
    f.schemas, f.channels = summary.schemas, summary.channels
    f.chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    f.chunks_indexed = True
    for m in summary.metadata_indexes:
        if m.name == "hybrid":
            try:
                f.meta = _description(_read_record(fh, m.offset, Opcode.METADATA, m.length), f, m.offset)
            except _Bad as exc:
                raise f.error(f"the metadata record at byte offset {m.offset} is corrupt: {exc}") from None
            break


def _scan(fh, f: _File, strict: bool) -> None:
    """An unfinished file (or one whose summary is damaged, in salvage): its records in
    order, parsed by mcap, chunks located from their headers and their data left unread.
    The file may end inside a record (a killed run); a record whose fields disagree is
    an error."""
    k, last = 8, None  # the last chunk, whose message indexes follow it
    while k < f.size:
        fh.seek(k)
        head, avail = fh.read(9), f.size - k - 9
        if avail < 0:
            f.truncated = f"the file ends at byte {f.size}, inside the opcode and length of a record at byte {k}"
            break
        op, n = struct.unpack("<BQ", head)
        body = fh.read(min(n, avail, _PREFIX_MAX if op == Opcode.CHUNK else n))
        try:
            if op == Opcode.CHUNK:  # its fields before its data
                s = _Exact(body)
                try:
                    t_lo, t_hi, usize, _ = s.read8(), s.read8(), s.read8(), s.read4()
                    compression, csize = s.read_prefixed_string(), s.read8()
                except (McapError, struct.error):
                    raise _Cut(f"its fields overrun its length of {n} bytes") from None
                except UnicodeDecodeError:
                    raise _Bad("its compression is not UTF-8") from None
                if s.count + csize != n:
                    raise _Bad(f"its length is {n} bytes, its fields give {s.count + csize}")
            else:
                rec = _parse(op, body)
                if len(body) < n:
                    raise _Bad(f"its length is {n} bytes, its fields give {len(body)}")
            if op == Opcode.MESSAGE_INDEX and (last is None or _end(last) != k):
                raise _Bad("a message index that follows no chunk")
        except _Bad as exc:
            if isinstance(exc, _Cut) and n > avail and len(body) == avail:
                f.truncated = f"the file ends at byte {f.size}, inside the record of opcode {op:#04x} at byte {k}"
                break
            what = f"the record at byte offset {k} is corrupt: {exc}"
            if last is not None:
                t_lo, t_hi = last.message_start_time * 1e-9, last.message_end_time * 1e-9
                what += f" (after chunk {len(f.chunks)}, t {t_lo:.6g} to {t_hi:.6g} s)"
            if strict:
                raise f.error(what + "; read with strict=False to keep the chunks before it") from None
            warnings.warn(
                f"recording {str(f.path)!r}: {what}; skipped the rest of the file", RecordingWarning, stacklevel=4
            )
            break
        if n > avail:
            f.truncated = f"the file ends at byte {f.size}, inside a chunk at byte {k} ({avail} of its {n} bytes)"
            break
        if op == Opcode.CHUNK:
            last = ChunkIndex(
                message_start_time=t_lo,
                message_end_time=t_hi,
                chunk_start_offset=k,
                chunk_length=9 + n,
                message_index_offsets={},
                message_index_length=0,
                compression=compression,
                compressed_size=csize,
                uncompressed_size=usize,
            )
            f.chunks.append(last)
        elif op == Opcode.MESSAGE_INDEX:
            last.message_index_offsets[rec.channel_id] = k
            last.message_index_length += 9 + n
        elif op == Opcode.DATA_END:
            if not f.finished:
                f.truncated = f"the file ends at byte {f.size}, inside its summary (the run was stopped finishing it)"
            return
        elif op == Opcode.HEADER:
            f.library = rec.library
            _check_foreign(f)
        elif op == Opcode.SCHEMA:
            f.schemas[rec.id] = rec
        elif op == Opcode.CHANNEL:
            f.channels[rec.id] = rec
        elif op == Opcode.METADATA and rec.name == "hybrid" and f.meta is None:
            f.meta = _description(rec, f, k)
        k += 9 + n
    else:
        f.truncated = f"the file ends at byte {f.size}, after a complete record but without its summary"
    if f.truncated is not None and last is not None and _end(last) == k:
        f.partial = last.chunk_start_offset  # the file ends in (or just before) its message indexes


def _end(c: ChunkIndex) -> int:
    """The byte after a chunk's message indexes."""
    return c.chunk_start_offset + c.chunk_length + c.message_index_length


def _load(fh, f: _File, c: ChunkIndex) -> tuple[bytes, list]:
    """A chunk's records (decompressed, their CRC checked, by mcap) and its messages as
    (channel, log time ns, start, end) in them, verified against the index of it and its
    message indexes. Raises _Bad on any disagreement."""
    chunk = _read_record(fh, c.chunk_start_offset, Opcode.CHUNK, c.chunk_length)
    head = (chunk.message_start_time, chunk.message_end_time, chunk.uncompressed_size, chunk.compression)
    want = (c.message_start_time, c.message_end_time, c.uncompressed_size, c.compression, c.compressed_size)
    if head + (len(chunk.data),) != want:
        said = "t {} to {} ns, {} bytes, {!r}, {} compressed".format
        raise _Bad(f"its header ({said(*head, len(chunk.data))}) differs from the index of it ({said(*want)})")
    if chunk.compression != "zstd":
        raise _Bad(f"its compression is {chunk.compression!r}, expected 'zstd'")
    try:
        stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    except (McapError, ValueError, zstandard.ZstdError, MemoryError, OverflowError) as exc:
        raise _Bad(f"its data does not read: {type(exc).__name__}: {exc}") from None
    raw = stream.read(size)
    if size != chunk.uncompressed_size:
        raise _Bad(f"its records are {size} bytes, its header says {chunk.uncompressed_size}")
    msgs, k = [], 0  # split here, not by mcap's breakup_chunk: a Message object a message reads 1.5 times slower
    while k < size:
        op, n, ch, _, t, _ = _MSG.unpack_from(raw.ljust(k + _MSG.size, b"\0"), k)
        if op != Opcode.MESSAGE or n < 22 or k + 9 + n > size:
            raise _Bad(f"the record at byte {k} of its records (opcode {op:#04x}, length {n}) is not a message in it")
        msgs.append((ch, t, k + _MSG.size, k + 9 + n))
        k += 9 + n
    if unknown := {m[0] for m in msgs} - set(f.channels):
        raise _Bad(f"messages are on channels {sorted(unknown)}, which the file does not declare")
    times = [m[1] for m in msgs]
    if msgs and (min(times), max(times)) != head[:2]:
        raise _Bad(f"its messages span t {min(times)} to {max(times)} ns, its header says {head[0]} to {head[1]}")
    # its message indexes list each of its messages: (log time, offset), by channel
    at = c.chunk_start_offset + c.chunk_length
    fh.seek(at)
    raw_index, k, indexed = fh.read(c.message_index_length), 0, {}
    while k < len(raw_index):
        op, n = struct.unpack_from("<BQ", raw_index.ljust(k + 9, b"\0"), k)
        if op != Opcode.MESSAGE_INDEX:
            raise _Bad(f"its message index at byte offset {at + k} has opcode {op:#04x}")
        ch, m = struct.unpack_from("<HI", raw_index.ljust(k + 15, b"\0"), k + 9)  # numpy, not mcap's entry by entry
        if m != n - 6 or m % 16 or k + 9 + n > len(raw_index):
            raise _Bad(f"its message index at byte offset {at + k} is malformed")
        if c.message_index_offsets.get(ch) != at + k:
            raise _Bad(
                f"its message index of channel {ch} is at byte offset {at + k}, the index of the chunk says "
                f"{c.message_index_offsets.get(ch)}"
            )
        indexed[ch] = np.frombuffer(raw_index, "<u8", m // 8, k + 15).reshape(-1, 2)
        k += 9 + n
    by_channel: dict[int, list] = {}
    for ch, t, start, _ in msgs:
        by_channel.setdefault(ch, []).append((t, start - _MSG.size))
    if f.partial != c.chunk_start_offset and set(indexed) != set(by_channel):
        raise _Bad(f"its message indexes are of channels {sorted(indexed)}, its messages of {sorted(by_channel)}")
    for ch, records in indexed.items():
        have = np.array(by_channel.get(ch, []), np.uint64).reshape(-1, 2)
        if not np.array_equal(records[np.argsort(records[:, 1], kind="stable")], have):
            raise _Bad(f"its message index of channel {ch} differs from its messages")
    return raw, msgs


def _chunks(fh, f: _File, lo_ns: int, hi_ns: int, strict: bool, decode) -> Iterator:
    """decode(records, messages) of each chunk overlapping [lo_ns, hi_ns], verified, in file
    order; in salvage, the corrupt ones skipped with a warning."""
    for i, c in enumerate(f.chunks):
        if c.message_end_time < lo_ns or c.message_start_time > hi_ns:
            continue
        try:
            out = decode(*_load(fh, f, c))
        except _Bad as exc:
            t_lo, t_hi, at = c.message_start_time * 1e-9, c.message_end_time * 1e-9, c.chunk_start_offset
            what = (
                f"chunk {i + 1} of {len(f.chunks)} (t {t_lo:.6g} to {t_hi:.6g} s, byte offset {at}) is corrupt: {exc}"
            )
            if strict:
                raise f.error(what + "; read with strict=False to skip it") from None
            warnings.warn(f"recording {str(f.path)!r}: {what}; skipped", RecordingWarning, stacklevel=3)
            continue
        yield out
