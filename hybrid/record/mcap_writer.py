"""The MCAP file writer: header, schemas, channels, metadata, chunks (zstd) with
their message indexes, then the summary, its offsets and the footer with its CRC."""

from __future__ import annotations

import struct

import numpy as np


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
        # the summary's ChunkIndex records, written as each chunk is (bytes, about 100 + 10
        # a channel per chunk): memory per chunk, not a Python object per chunk
        self.chunk_indexes = bytearray()
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

        c = Channel(id=len(self.channels) + 1, topic=topic, message_encoding=encoding, schema_id=schema_id, metadata={})
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
        from mcap.data_stream import RecordBuilder
        from mcap.opcode import Opcode
        from mcap.records import Chunk, ChunkIndex

        if self._zstd is None:
            self._zstd = zstandard.ZstdCompressor(level=-3)  # fast: the chunks are written during the run
        data = self._zstd.compress(raw)
        chunk = Chunk(
            compression="zstd",
            data=data,
            message_start_time=t_lo,
            message_end_time=t_hi,
            uncompressed_crc=zlib.crc32(raw),
            uncompressed_size=len(raw),
        )
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
        cb = RecordBuilder()
        ChunkIndex(
            message_start_time=t_lo,
            message_end_time=t_hi,
            chunk_start_offset=start,
            chunk_length=length,
            message_index_offsets=offsets,
            message_index_length=count,
            compression="zstd",
            compressed_size=len(data),
            uncompressed_size=len(raw),
        ).write(cb)
        self.chunk_indexes += cb.end()
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
        stats = Statistics(
            attachment_count=0,
            channel_count=len(self.channels),
            channel_message_counts=dict(self.counts),
            chunk_count=self.nchunk,
            message_count=self.nmsg,
            message_end_time=self.t_last or 0,
            message_start_time=self.t_first or 0,
            metadata_count=len(self.meta_indexes),
            schema_count=len(self.schemas),
        )
        for opcode, records in (
            (Opcode.SCHEMA, self.schemas),
            (Opcode.CHANNEL, self.channels),
            (Opcode.STATISTICS, [stats]),
            (Opcode.CHUNK_INDEX, [_Raw(self.chunk_indexes)] if self.chunk_indexes else []),
            (Opcode.METADATA_INDEX, self.meta_indexes),
        ):
            if not records:
                continue
            g = sb.count
            for r in records:
                r.write(sb)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + g, group_length=sb.count - g))
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


class _Raw:
    """Records already serialized, written as they are."""

    def __init__(self, data: bytes):
        self.data = data

    def write(self, b) -> None:
        b.write(self.data)
