"""Write runs of fixed-size messages into MCAP chunks in bulk.

The mcap library's :class:`mcap.writer.Writer` adds messages one Python call at a time
(~200 k messages/s here), which would make recording a 12 h log cost as much as the simulation
itself.  This writer builds each chunk's Message records and its MessageIndex as numpy arrays
(one structured array per chunk) and uses the mcap library's own record classes for everything
else (Header, Schema, Channel, Chunk, ChunkIndex, Metadata, Statistics, SummaryOffset, Footer), so
the file layout is exactly what ``Writer.finish()`` produces (MCAP spec, "Summary Section").

Every chunk is written, with its message index, and flushed to the OS as soon as it is complete,
so a writer killed with SIGKILL leaves every finished chunk readable by a linear scan.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import BinaryIO

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b"\x89MCAP0\r\n"
LIBRARY = "imupipe mcap_bulk"
_MESSAGE_HEADER = 2 + 4 + 8 + 8  # channel_id, sequence, log_time, publish_time


def _message_dtype(payload_size: int) -> np.dtype:
    """One Message record (opcode, length, fields, data) as a packed structured dtype."""
    return np.dtype(
        [
            ("opcode", "u1"),
            ("length", "<u8"),
            ("channel_id", "<u2"),
            ("sequence", "<u4"),
            ("log_time", "<u8"),
            ("publish_time", "<u8"),
            ("data", "u1", (payload_size,)),
        ]
    )


@dataclass
class _Totals:
    message_count: int = 0
    chunk_count: int = 0
    start: int | None = None
    end: int = 0
    per_channel: dict[int, int] = field(default_factory=dict)


class BulkWriter:
    """MCAP writer for fixed-size messages delivered in blocks.

    Args:
        stream: a binary stream opened for writing.
        compression: ``"zstd"`` (default), ``"lz4"`` or ``""`` (none).
        profile: MCAP profile string (``"ros2"`` for our CDR frames).
    """

    def __init__(self, stream: BinaryIO, compression: str = "zstd", profile: str = "") -> None:
        if compression not in ("zstd", "lz4", ""):
            raise ValueError(f"unsupported compression {compression!r}")
        self._stream = stream
        self._compression = compression
        self._zstd = zstandard.ZstdCompressor(level=3)
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._totals = _Totals()
        self._builder = RecordBuilder()
        self._stream.write(MAGIC)
        Header(profile=profile, library=LIBRARY).write(self._builder)
        self._flush()

    def _flush(self) -> None:
        self._stream.write(self._builder.end())

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        schema.write(self._builder)
        self._flush()
        return schema.id

    def register_channel(
        self,
        topic: str,
        message_encoding: str,
        schema_id: int,
        metadata: Mapping[str, str] | None = None,
    ) -> int:
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._channels.append(channel)
        channel.write(self._builder)
        self._flush()
        return channel.id

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        offset = self._stream.tell()
        Metadata(name=name, metadata=dict(data)).write(self._builder)
        self._metadata_indexes.append(
            MetadataIndex(offset=offset, length=self._builder.count, name=name)
        )
        self._flush()

    def write_chunk(
        self,
        channel_id: int,
        log_time: np.ndarray,
        payloads: np.ndarray,
        sequence: np.ndarray | None = None,
    ) -> None:
        """Write one chunk holding ``len(log_time)`` messages of one channel.

        Args:
            channel_id: a registered channel.
            log_time: ns since the epoch, one per message (uint64-compatible).
            payloads: ``(n, size)`` uint8 array, one encoded message per row.
            sequence: publisher sequence numbers (default 0).
        """
        n, size = payloads.shape
        if n == 0:
            return
        log_time = np.asarray(log_time, dtype=np.uint64)
        rec = np.empty(n, dtype=_message_dtype(size))
        rec["opcode"] = int(Opcode.MESSAGE)
        rec["length"] = _MESSAGE_HEADER + size
        rec["channel_id"] = channel_id
        rec["sequence"] = 0 if sequence is None else sequence
        rec["log_time"] = log_time
        rec["publish_time"] = log_time
        rec["data"] = payloads
        body = rec.tobytes()
        record_size = rec.dtype.itemsize

        if self._compression == "zstd":
            compressed = self._zstd.compress(body)
        elif self._compression == "lz4":
            compressed = lz4.frame.compress(body)
        else:
            compressed = body
        start, end = int(log_time.min()), int(log_time.max())
        chunk = Chunk(
            message_start_time=start,
            message_end_time=end,
            uncompressed_size=len(body),
            uncompressed_crc=zlib.crc32(body),
            compression=self._compression,
            data=compressed,
        )
        chunk_offset = self._stream.tell()
        chunk.write(self._builder)
        chunk_length = self._builder.count
        self._flush()

        # MessageIndex: channel_id u16, u32 byte length, then (log_time, offset) u64 pairs
        index_offset = self._stream.tell()
        pairs = np.empty((n, 2), dtype="<u8")
        pairs[:, 0] = log_time
        pairs[:, 1] = np.arange(n, dtype=np.uint64) * np.uint64(record_size)
        index_body = struct.pack("<HI", channel_id, pairs.nbytes) + pairs.tobytes()
        index_record = struct.pack("<BQ", int(Opcode.MESSAGE_INDEX), len(index_body)) + index_body
        self._stream.write(index_record)
        self._stream.flush()

        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_offset,
                chunk_length=chunk_length,
                message_index_offsets={channel_id: index_offset},
                message_index_length=len(index_record),
                compression=self._compression,
                compressed_size=len(compressed),
                uncompressed_size=len(body),
            )
        )
        totals = self._totals
        totals.message_count += n
        totals.chunk_count += 1
        totals.per_channel[channel_id] = totals.per_channel.get(channel_id, 0) + n
        totals.start = start if totals.start is None else min(totals.start, start)
        totals.end = max(totals.end, end)

    def count_messages(self, channel_id: int, messages: int) -> None:
        """Count in the summary's statistics ``messages`` Message records of ``channel_id``
        that the caller wrote into the stream itself (raw records)."""
        per_channel = self._totals.per_channel
        per_channel[channel_id] = per_channel.get(channel_id, 0) + messages
        self._totals.message_count += messages

    def finish(self) -> None:
        """Write DataEnd, the summary section (as ``mcap.writer.Writer.finish``) and the footer."""
        DataEnd(data_section_crc=0).write(self._builder)
        self._flush()
        summary_start = self._stream.tell()
        summary = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: list) -> None:
            begin = summary.count
            for record in records:
                record.write(summary)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + begin,
                    group_length=summary.count - begin,
                )
            )

        t = self._totals
        statistics = Statistics(
            message_count=t.message_count,
            schema_count=len(self._schemas),
            channel_count=len(self._channels),
            attachment_count=0,
            metadata_count=len(self._metadata_indexes),
            chunk_count=t.chunk_count,
            message_start_time=t.start or 0,
            message_end_time=t.end,
            channel_message_counts=dict(t.per_channel),
        )
        group(Opcode.SCHEMA, self._schemas)
        group(Opcode.CHANNEL, self._channels)
        group(Opcode.STATISTICS, [statistics])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        crc = zlib.crc32(data)
        crc = zlib.crc32(
            struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start),
            crc,
        )
        self._stream.write(data)
        Footer(
            summary_start=summary_start,
            summary_offset_start=summary_offset_start,
            summary_crc=crc,
        ).write(self._builder)
        self._flush()
        self._stream.write(MAGIC)
        self._stream.flush()
