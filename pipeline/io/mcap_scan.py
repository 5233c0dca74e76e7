"""Tolerant linear scan of an MCAP file, yielding each chunk's messages as index arrays.

The mcap library's indexed reader needs an intact summary section and its per-message reader
runs ~100 k messages/s in Python.  This scanner walks the file record by record (MCAP spec:
``opcode u8, length u64, body``), parses Schema, Channel and Metadata bodies with the mcap
library's own record classes (Chunk bodies into its :class:`Chunk`, without copying the
compressed records), decompresses each chunk and indexes its Message records with a
compiled walk (:mod:`imupipe.io.mcap_walk`), on a worker thread while the previous chunk is
decoded.  A chunk's messages of each wanted channel become one :class:`MessageBatch` (payload
offsets into the decompressed chunk), however the channels interleave.  Top-level Message
records (unchunked files) are read in blocks and indexed the same way.

Damage is survived and reported, never hidden: a file cut mid-record keeps every complete record
before the cut (and, when the cut falls inside a chunk, reads that chunk's header to tell what was
lost); a chunk whose CRC does not match (or that does not decompress) is skipped, with its time
range; a record whose fields do not parse is skipped and counted.  See :class:`ScanReport`.

Hostile files are refused piece by piece, never followed: a chunk nested inside a chunk (the
spec forbids it; unpacked, 15 KB of nested chunks became 10 M frames) is counted as a bad record
and not opened; a chunk whose header declares more than ``max_chunk_bytes`` uncompressed, or
any record longer than that, is skipped unread (its bytes are never copied) before anything is
inflated; and no chunk inflates beyond the size its header declares (zstd: the frame's own
content size must agree and the output is capped; lz4: streamed with a cap).
"""

from __future__ import annotations

import io
import itertools
import os
import struct
import threading
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import lz4.frame
import numpy as np
import zstandard
from isal.isal_zlib import crc32
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Metadata, Schema, Statistics

from imupipe.errors import InputError, NotMcapError
from imupipe.io.mcap_walk import (
    MESSAGE_HEAD,
    RECORD_HEAD,
    CdrLayout,
    CdrRows,
    CdrTable,
    MessageIndex,
    cdr_rows,
    gather,
    index_messages,
)

MAGIC = b"\x89MCAP0\r\n"
ROS1_BAG_MAGIC = b"#ROSBAG"
"""How a ROS 1 bag starts (ROS wiki, "Bags/Format/2.0": ``#ROSBAG V2.0`` and a newline)."""
CONVERT_ROS1 = "a ROS 1 bag converts to a ROS 2 one with `rosbags-convert --src BAG --dst DIR`"
"""How to read ROS 1 data: rosbags' converter writes a rosbag2 folder imupipe reads."""
_CHUNK_FIXED = 8 + 8 + 8  # message_start_time, message_end_time, uncompressed_size
UNPACK_THREADS = 2
PREFETCH_RECORDS = 4
"""Records read ahead of the one being decoded; chunks among them are decompressed, CRC-checked
and indexed on :data:`UNPACK_THREADS` worker threads meanwhile (zstd, lz4, crc32 and the walk
release the GIL): on a busy bag unpacking costs about twice the decoding."""
MESSAGE_BLOCK = (64 << 10, 4 << 20)
"""Least and most bytes read at once where top-level Message records follow each other (an
unchunked file): they are indexed by one compiled walk, not parsed one by one.  The block
doubles while the messages fill it and falls back to the least when they do not, so a file
that alternates messages with other records costs no more than reading it."""
_PARSED = (
    Opcode.CHUNK, Opcode.MESSAGE, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA,
    Opcode.STATISTICS,
)  # fmt: skip
_IN_CHUNK = (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA)
"""Records besides messages that a chunk may hold and the scan reads (MCAP spec: a chunk holds
Schema, Channel and Message records; anything else in it is skipped without a copy)."""
NESTED_CHUNK = "nested chunk"
"""The kind under which chunks found inside a chunk are counted in ``bad_records``."""
CHUNKS_IN_BUDGET = 16
"""A chunk may take at most 1/16 of the memory budget uncompressed: up to
``PREFETCH_RECORDS + 1`` chunks are held at once, each compressed and inflated, next to the
decoded columns."""
MAX_CHUNK_BYTES = 2_000_000_000 // CHUNKS_IN_BUDGET
"""Largest uncompressed chunk (bytes) read without a memory budget (``imupipe info``): that of
the default 2 GB budget of ``analyze``.  Writers use ~1 MB (rosbag2 768 KiB, ours ~1 s)."""


MIN_CHUNK_LIMIT = 64 << 20
"""A chunk of this size is always read, however small the budget: writers make ~1 MB chunks
(rosbag2 768 KiB, the mcap library 1 MiB), and a tiny budget asks for the low-memory path,
not for refusing the data."""


def chunk_limit(memory_budget_bytes: int) -> int:
    """Largest uncompressed chunk (bytes) the scan inflates under a memory budget: 1/16 of it,
    at least :data:`MIN_CHUNK_LIMIT`."""
    return max(memory_budget_bytes // CHUNKS_IN_BUDGET, MIN_CHUNK_LIMIT)


_MALFORMED = (McapError, UnicodeDecodeError, struct.error, ValueError, OverflowError)
"""What the mcap library's record parsers raise on bytes that are not a valid record."""


@dataclass(frozen=True)
class MessageBatch:
    """Messages of one channel from one chunk (or one block of top-level records), in file
    order, as offsets into the bytes that hold them.

    Attributes:
        channel_id: the MCAP channel.
        log_time: ns since the epoch (uint64, ``(n,)``).
        data: uint8, the decompressed chunk (or block) holding the payloads.
        offset: int64 ``(n,)``, where each payload (the serialised message) starts in ``data``.
        size: int64 ``(n,)``, payload bytes.
    """

    channel_id: int
    log_time: np.ndarray
    data: np.ndarray
    offset: np.ndarray
    size: np.ndarray

    def __len__(self) -> int:
        return len(self.offset)

    def runs(self) -> Iterator[MessageRun]:
        """The batch as runs of consecutive messages of equal size (payloads copied)."""
        cuts = [0, *(np.flatnonzero(np.diff(self.size)) + 1).tolist(), len(self)]
        for a, b in itertools.pairwise(cuts):
            payloads = gather(self.data, self.offset[a:b], int(self.size[a]))
            yield MessageRun(self.channel_id, self.log_time[a:b], payloads)


@dataclass(frozen=True)
class CdrBatch:
    """Messages of one channel from one chunk (or one block of top-level records), in file
    order, as rows of their CDR header and the fields of the channel's :class:`CdrLayout`
    (:func:`imupipe.io.mcap_walk.cdr_rows`).

    Attributes:
        channel_id: the MCAP channel.
        log_time: ns since the epoch (uint64, ``(n,)``) of the well-formed messages.
        rows: ``(n, layout.width)`` uint8, one per well-formed message.
        bad: messages of the batch that are not well-formed for the layout (not in ``rows``).
        first: the payload of the first well-formed message (None if there is none).
        source: the bytes and the :class:`MessageIndex` the rows were made from.
    """

    channel_id: int
    log_time: np.ndarray
    rows: np.ndarray
    bad: int
    first: np.ndarray | None
    source: tuple[np.ndarray, MessageIndex] | None = None

    def __len__(self) -> int:
        return len(self.rows)

    def payloads(self, count: int) -> list[np.ndarray]:
        """The payloads (views of the batch's bytes) of its channel's first ``count`` messages,
        well-formed or not."""
        if self.source is None:
            return []
        data, index = self.source
        at = np.flatnonzero(index.channel == self.channel_id)[:count].tolist()
        return [data[int(index.offset[i]) : int(index.offset[i] + index.size[i])] for i in at]


def cdr_batches_of(
    data: np.ndarray, index: MessageIndex, rows: CdrRows, channel_ids: list[int]
) -> Iterator[CdrBatch]:
    """The :class:`CdrBatch` of each slot with messages in ``rows`` (:func:`imupipe.io.
    mcap_walk.cdr_rows` of ``index`` over the bytes ``data``; ``channel_ids``: the channel of
    each slot), its first well-formed payload a view of ``data``."""
    for s in np.flatnonzero(rows.good + rows.bad).tolist():
        first = int(rows.first[s])
        payload = None
        if first >= 0:
            at = int(index.offset[first])
            payload = data[at : at + int(index.size[first])]
        yield CdrBatch(
            channel_ids[s], rows.log_time[s], rows.rows[s], int(rows.bad[s]), payload, (data, index)
        )


@dataclass(frozen=True)
class MessageRun:
    """Consecutive messages of one channel with equal payload size.

    Attributes:
        channel_id: the MCAP channel.
        log_time: ns since the epoch (uint64, ``(n,)``).
        payloads: ``(n, size)`` uint8, the serialised messages.
    """

    channel_id: int
    log_time: np.ndarray
    payloads: np.ndarray


@dataclass(frozen=True)
class _Block:
    """Top-level Message records read at once, and their index."""

    data: np.ndarray
    index: MessageIndex


def _opcode_name(opcode: int) -> str:
    """``"chunk"``, ``"message_index"``... or the hex value of an opcode the spec does not name."""
    try:
        return Opcode(opcode).name.lower()
    except ValueError:
        return f"0x{opcode:02x}"


@dataclass(frozen=True)
class LostChunk:
    """A chunk whose messages could not be read.

    Attributes:
        start_ns, end_ns: log time of its first and last message (ns), from the chunk header;
            None when the header itself was lost.
        uncompressed_bytes: size of its records, from the header (None when lost).
        reason: why it was skipped.
    """

    start_ns: int | None
    end_ns: int | None
    uncompressed_bytes: int | None
    reason: str


@dataclass
class ScanReport:
    """What the scan found besides messages, and what it could not read."""

    file_bytes: int = 0
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    has_footer: bool = False
    chunks: int = 0
    bad_chunks: list[LostChunk] = field(default_factory=list)
    """Every chunk skipped (damaged, or cut off by the end of the file)."""
    bad_records: dict[str, int] = field(default_factory=dict)
    """Records outside messages (schema, channel, metadata...) that did not parse, by kind."""
    truncated_bytes: int = 0
    """Bytes at the end of the file that did not form a complete record."""
    truncated_opcode: int | None = None
    """Opcode of the record cut by the end of the file (None if its header was cut too)."""
    read_counts: dict[int, int] = field(default_factory=dict)
    """Messages read per wanted channel id (malformed ones included; 0 for a wanted channel
    none of whose messages was read)."""
    stated_counts: dict[int, int] | None = None
    """Messages per channel id as the file's Statistics record (summary section) states them;
    None without one."""
    message_records: int = 0
    message_record_bytes: int = 0
    """Message records read in chunks (all channels) and their total size: the mean record size
    converts a lost chunk's uncompressed size into an estimated message count."""

    max_chunk_bytes: int = MAX_CHUNK_BYTES
    """Chunks declaring more uncompressed bytes were skipped unread: their size is not trusted."""

    @property
    def messages(self) -> int:
        """Messages of wanted channels yielded."""
        return sum(self.read_counts.values())

    def lost_messages_estimate(self, chunk: LostChunk) -> int | None:
        """Messages a lost chunk held ≈ its uncompressed size / the mean message record size
        seen in the readable chunks (exact for a chunk of equal-size messages only); None when
        unknown, also when its header claims more than a chunk may hold (a header's claim of
        1 TB is no count of anything)."""
        if chunk.uncompressed_bytes is None or self.message_records == 0:
            return None
        if chunk.uncompressed_bytes > self.max_chunk_bytes:
            return None
        mean_record = self.message_record_bytes / self.message_records
        return round(chunk.uncompressed_bytes / mean_record)

    def _describe_lost(self, chunk: LostChunk) -> str:
        if chunk.start_ns is None or chunk.end_ns is None:
            return f"a chunk was lost ({chunk.reason}); its size and time range are unknown"
        count = self.lost_messages_estimate(chunk)
        what = "an unknown number of messages" if count is None else f"about {count} messages"
        return (
            f"a chunk was lost ({chunk.reason}): {what} whose log times span "
            f"{(chunk.end_ns - chunk.start_ns) / 1e9:.3f} s"
        )

    def damage(self) -> list[str]:
        """One human sentence per kind of damage (empty for an intact file)."""
        out = [self._describe_lost(chunk) for chunk in self.bad_chunks]
        out.extend(
            f"skipped {count} unreadable {kind} record(s)"
            for kind, count in self.bad_records.items()
        )
        if self.truncated_bytes:
            cut = (
                "a record header"
                if self.truncated_opcode is None
                else f"a {_opcode_name(self.truncated_opcode)} record"
            )
            out.append(
                f"file ends mid-record (inside {cut}): the last {self.truncated_bytes} bytes "
                f"({100 * self.truncated_bytes / max(self.file_bytes, 1):.2f} % of the file) "
                "could not be read"
            )
        if not self.has_footer:
            out.append(
                "file has no footer/summary (the writer stopped before finishing): "
                "every complete chunk was read by a linear scan"
            )
        out.extend(self._count_mismatches())
        return out

    def _count_mismatches(self) -> list[str]:
        """One sentence per wanted channel whose messages read differ in number from what the
        file's Statistics record states: the only trace of damage that no other check sees (a
        record whose opcode was damaged is skipped as an unknown or unread record, a Message
        whose channel id was damaged belongs to no channel)."""
        if self.stated_counts is None:
            return []
        out = []
        for cid, read in sorted(self.read_counts.items()):
            stated = self.stated_counts.get(cid)
            if stated is None or stated == read:
                continue
            topic = self.channels[cid].topic  # counted channels are declared ones
            out.append(
                f"{topic}: {read} of the {stated} messages the file's summary counts were read "
                f"({stated - read} lost)"
                if read < stated
                else f"{topic}: {read} messages read, {read - stated} more than the file's "
                f"summary counts ({stated}): records repeated, or a summary written before the end"
            )
        return out


_THREAD = threading.local()


def _zstd() -> zstandard.ZstdDecompressor:
    """This thread's zstd decompressor (a decompressor is not shared between threads; making
    one per chunk cost ~20 % of the decompression)."""
    if not hasattr(_THREAD, "zstd"):
        _THREAD.zstd = zstandard.ZstdDecompressor()
    return _THREAD.zstd


def _decompress(chunk: Chunk) -> bytes:
    """The chunk's records, inflated to at most the ``uncompressed_size`` its header declares
    (a bomb cannot grow past the size checked against the budget before this is called).

    Raises:
        ValueError: the data would inflate beyond the declared size, or is cut short.
        InputError: a compression the MCAP spec does not name.
    """
    size = chunk.uncompressed_size
    if chunk.compression == "":
        return chunk.data
    if size == 0:  # no records; 0 would also mean "no limit" to zstandard
        return b""
    if chunk.compression == "zstd":
        framed = zstandard.frame_content_size(chunk.data)  # -1: not in the frame header
        if framed not in (-1, size):  # zstandard allocates the frame's size, not the cap
            raise ValueError(f"its zstd frame declares {framed} bytes, its header {size}")
        return _zstd().decompress(chunk.data, max_output_size=size)
    if chunk.compression == "lz4":
        inflater = lz4.frame.LZ4FrameDecompressor()
        data = inflater.decompress(chunk.data, max_length=size)
        if not inflater.eof:
            raise ValueError(f"it does not end within the {size} bytes its header declares")
        return data
    raise InputError(f"unsupported compression {chunk.compression!r}")


_CHUNK_HEAD = struct.Struct("<QQQII")
"""A Chunk record's fields before ``records`` (MCAP spec: message_start_time u64,
message_end_time u64, uncompressed_size u64, uncompressed_crc u32, compression string: u32
length + UTF-8)."""


def _parse_chunk(body: bytes) -> Chunk:
    """The mcap library's :class:`Chunk` of a record body, its ``data`` a view of ``body``:
    ``Chunk.read`` copies the compressed records (a camera bag's whole size once more)."""
    view = memoryview(body)
    start, end, size, crc, name_len = _CHUNK_HEAD.unpack_from(view)
    at = _CHUNK_HEAD.size + name_len
    compression = str(view[_CHUNK_HEAD.size : at], "utf-8")
    (records_len,) = struct.unpack_from("<Q", view, at)
    data = view[at + 8 : at + 8 + records_len]
    if len(data) != records_len:
        raise ValueError("chunk records run past the record's end")
    return Chunk(
        message_start_time=start,
        message_end_time=end,
        uncompressed_size=size,
        uncompressed_crc=crc,
        compression=compression,
        data=data,
    )


@dataclass(frozen=True)
class _Unpacked:
    """A Chunk record parsed, decompressed, CRC-checked and its leading Message records
    indexed (and, for :meth:`McapScanner.cdr_batches`, their rows made)."""

    chunk: Chunk
    data: np.ndarray
    reason: str
    """Why the chunk cannot be read (empty if it can; else no index)."""
    index: MessageIndex | None = None
    rows: CdrRows | None = None
    version: int = 0
    """:attr:`McapScanner._redefined` when the rows were made (a channel declared again since
    makes them stale)."""


def _unpack(body: bytes, table: CdrTable | None = None, version: int = 0) -> _Unpacked:
    """Parse a Chunk record, decompress it, check its CRC, index its leading Message records
    and, with a ``table``, make their rows."""
    chunk = _parse_chunk(body)
    try:
        data = _decompress(chunk)
    except Exception as exc:  # each codec raises its own error types
        reason = f"decompression failed: {str(exc) or type(exc).__name__}"
        return _Unpacked(chunk, np.empty(0, np.uint8), reason)
    if chunk.uncompressed_crc and crc32(data) != chunk.uncompressed_crc:
        return _Unpacked(chunk, np.empty(0, np.uint8), "CRC mismatch")
    buf = np.frombuffer(data, np.uint8)
    buf.flags.writeable = False  # an uncompressed chunk's bytes are writable: one compiled type
    index = index_messages(buf)
    rows = None if table is None else cdr_rows(buf, index, table, stop_at_unknown=True)
    return _Unpacked(chunk, buf, "", index, rows, version)


def _parse(record_type, body: bytes, length: int | None = None):
    stream = ReadDataStream(io.BytesIO(body))
    return record_type.read(stream) if length is None else record_type.read(stream, length)


class McapScanner:
    """Iterate over the message runs of an MCAP file; fills :attr:`report` as it goes.

    Args:
        path: the file.
        wanted: called with (channel, schema or None) when a channel is first seen; messages of
            channels for which it returns False are skipped without copying.
        progress: called with the number of bytes consumed so far.
        max_chunk_bytes: a chunk declaring more uncompressed bytes, or any record longer than
            this, is skipped unread (:func:`chunk_limit` of the memory budget).
    """

    def __init__(
        self,
        path: Path,
        wanted: Callable[[Channel, Schema | None], bool] = lambda c, s: True,
        progress: Callable[[int], None] | None = None,
        max_chunk_bytes: int = MAX_CHUNK_BYTES,
    ) -> None:
        self.path = Path(path)
        self.report = ScanReport(
            file_bytes=os.path.getsize(self.path), max_chunk_bytes=max_chunk_bytes
        )
        self._wanted = wanted
        self._wanted_ids = np.zeros(1 << 16, bool)  # by channel id (u16)
        self._progress = progress or (lambda n: None)
        self._cut_head: bytes | None = None  # fixed fields of a chunk cut off by the file's end
        self._block_bytes = MESSAGE_BLOCK[0]
        self._layout: Callable[[Channel, Schema | None], CdrLayout | None] | None = None
        self._table = CdrTable()
        self._ahead: CdrTable | None = None  # the table as chunks read ahead see it (a copy)
        self._redefined = 0  # channels declared again with another layout (or none)

    def _add_channel(self, channel: Channel) -> None:
        self.report.channels[channel.id] = channel
        schema = self.report.schemas.get(channel.schema_id)
        if self._layout is None:
            self._wanted_ids[channel.id] = bool(self._wanted(channel, schema))
        else:
            layout = self._layout(channel, schema)
            self._redefined += self._table.set(channel.id, layout)
            self._ahead = None
            self._wanted_ids[channel.id] = layout is not None
        if self._wanted_ids[channel.id]:
            self.report.read_counts.setdefault(channel.id, 0)

    def runs(self) -> Iterator[MessageRun]:
        """The file's messages as runs of equal payload size, in file order (the payloads are
        copied: :meth:`batches` is the fast way)."""
        for batch in self.batches():
            yield from batch.runs()

    def batches(self) -> Iterator[MessageBatch]:
        """The wanted channels' messages, one batch per channel and chunk, in file order;
        chunks are unpacked a few records ahead."""
        return self._scan()

    def cdr_batches(
        self, layout: Callable[[Channel, Schema | None], CdrLayout | None]
    ) -> Iterator[CdrBatch]:
        """The messages of the channels ``layout`` gives a :class:`CdrLayout` for (instead of
        ``wanted``), one batch of rows per channel and chunk, in file order.  A chunk's rows are
        made on the unpack thread with the channels known when it was read ahead; the messages
        of a channel declared after that are made when the chunk is reached."""
        self._layout = layout
        return self._scan()

    def _job(self, body: bytes) -> tuple:
        """The arguments of the :func:`_unpack` job of a chunk read ahead."""
        if self._layout is None:
            return (body,)
        if self._ahead is None:
            self._ahead = self._table.copy()
        return body, self._ahead, self._redefined

    def _scan(self) -> Iterator:
        with ThreadPoolExecutor(UNPACK_THREADS, thread_name_prefix="mcap-unpack") as pool:
            pending: deque[tuple[int, bytes | _Block | Future, int]] = deque()
            for opcode, body, length in self._records():
                if opcode == Opcode.CHUNK:
                    body = pool.submit(_unpack, *self._job(body))
                pending.append((opcode, body, length))
                if len(pending) > PREFETCH_RECORDS:
                    yield from self._record(*pending.popleft())
            while pending:
                yield from self._record(*pending.popleft())
        if self._cut_head is not None:
            self._cut_chunk(self._cut_head)

    def _records(self) -> Iterator[tuple[int, bytes | _Block, int]]:
        """(opcode, body, length) of each top-level record the scan parses, in file order (a
        :class:`_Block` for consecutive Message records); fills the report's truncation, footer
        and bytes-read fields."""
        report = self.report
        try:
            f = open(self.path, "rb")  # closed by the with below
        except OSError as exc:
            raise InputError(f"{self.path}: cannot be read ({exc.strerror or exc})") from None
        with f:
            magic = f.read(len(MAGIC))
            if magic.startswith(ROS1_BAG_MAGIC):
                raise NotMcapError(
                    f"{self.path} is a ROS 1 bag, not MCAP: imupipe reads ROS 2 bags "
                    f"(MCAP or SQLite); {CONVERT_ROS1}"
                )
            if magic != MAGIC:
                raise NotMcapError(f"{self.path} is not an MCAP file (bad magic)")
            pos = len(MAGIC)
            while True:
                head = f.read(RECORD_HEAD)
                if len(head) == 0:
                    break
                if len(head) < RECORD_HEAD:
                    report.truncated_bytes = report.file_bytes - pos
                    break
                opcode, length = struct.unpack("<BQ", head)
                if pos + RECORD_HEAD + length > report.file_bytes:
                    report.truncated_bytes = report.file_bytes - pos
                    report.truncated_opcode = opcode
                    if opcode == Opcode.CHUNK:  # reported after the chunks before it
                        self._cut_head = f.read(_CHUNK_FIXED)
                    break
                block = self._message_block(f, head, pos) if opcode == Opcode.MESSAGE else None
                if block is not None:
                    yield opcode, block, length
                    pos += block.index.stop
                    f.seek(pos)
                    self._progress(pos)
                    continue
                if opcode == Opcode.CHUNK and length >= _CHUNK_FIXED:
                    head = f.read(_CHUNK_FIXED)
                    if self._too_large(head, length):
                        f.seek(length - _CHUNK_FIXED, os.SEEK_CUR)
                    else:  # read whole: joining head and rest would copy the chunk again
                        f.seek(-_CHUNK_FIXED, os.SEEK_CUR)
                        yield opcode, f.read(length), length
                elif opcode in _PARSED and length <= report.max_chunk_bytes:
                    yield opcode, f.read(length), length
                else:
                    if opcode in _PARSED:  # a record no budget can hold: counted, not read
                        self._bad_record(opcode)
                    f.seek(length, os.SEEK_CUR)
                pos += RECORD_HEAD + length
                self._progress(pos)
                if opcode == Opcode.FOOTER:  # only the closing magic follows
                    report.has_footer = True
                    break

    def _message_block(self, f: BinaryIO, head: bytes, pos: int) -> _Block | None:
        """Read a block (:data:`MESSAGE_BLOCK`; at least the whole record) from the Message
        record at ``pos`` whose head was just read, and index the Message records that follow
        each other there; None, the file back after the head, if the first one is malformed."""
        length = struct.unpack_from("<Q", head, 1)[0]
        data = bytearray(
            min(max(self._block_bytes, RECORD_HEAD + length), self.report.file_bytes - pos)
        )
        data[:RECORD_HEAD] = head
        f.readinto(memoryview(data)[RECORD_HEAD:])
        buf = np.frombuffer(data, np.uint8)
        buf.flags.writeable = False  # as a chunk's bytes: one compiled walk for both
        index = index_messages(buf)
        filled = index.stop > len(buf) // 2
        self._block_bytes = (
            min(2 * self._block_bytes, MESSAGE_BLOCK[1]) if filled else MESSAGE_BLOCK[0]
        )
        if not len(index):
            f.seek(pos + RECORD_HEAD)
            return None
        return _Block(buf, index)

    def _too_large(self, head: bytes, length: int) -> bool:
        """Whether a chunk (its fixed fields ``head``, record ``length``) is over the limit; such
        a chunk is reported lost with the size it claims, and never read or inflated."""
        start, end, size = struct.unpack("<QQQ", head)
        limit = self.report.max_chunk_bytes
        if max(size, length) <= limit:
            return False
        self.report.chunks += 1
        self.report.bad_chunks.append(
            LostChunk(
                start,
                end,
                size,
                f"it declares {size} bytes uncompressed ({length} stored), more than the "
                f"{limit} a chunk may take under the memory budget (--memory-budget-gb); "
                "skipped unread",
            )
        )
        return True

    def _bad_record(self, opcode: int) -> None:
        kind = _opcode_name(opcode)
        self.report.bad_records[kind] = self.report.bad_records.get(kind, 0) + 1

    def _cut_chunk(self, head: bytes) -> None:
        """Record what a chunk cut by the end of the file held, from its fixed header fields."""
        if len(head) < _CHUNK_FIXED:
            lost = LostChunk(None, None, None, "cut off by the end of the file")
        else:
            lost = LostChunk(*struct.unpack("<QQQ", head), "cut off by the end of the file")
        self.report.bad_chunks.append(lost)

    def _record(self, opcode: int, body: bytes | _Block | Future, length: int) -> Iterator:
        """Parse one record (a chunk's body may be the :func:`_unpack` job already submitted);
        a record whose fields do not parse is counted and skipped."""
        try:
            yield from self._parsed_record(opcode, body, length)
        except _MALFORMED:
            self._bad_record(opcode)

    def _parsed_record(self, opcode: int, body: bytes | _Block | Future, length: int) -> Iterator:
        report = self.report
        if opcode == Opcode.SCHEMA:
            schema = _parse(Schema, body)
            report.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            self._add_channel(_parse(Channel, body))
        elif opcode == Opcode.METADATA:
            meta = _parse(Metadata, body)
            report.metadata[meta.name] = dict(meta.metadata)
        elif opcode == Opcode.STATISTICS:
            report.stated_counts = dict(_parse(Statistics, body).channel_message_counts)
        elif opcode == Opcode.MESSAGE:
            if isinstance(body, _Block):
                yield from self._batches(body.data, body.index)
                return
            msg = _parse(Message, body, length)
            data = np.frombuffer(msg.data, np.uint8)
            yield from self._batches(
                data,
                MessageIndex(
                    offset=np.zeros(1, np.int64),
                    size=np.array([len(data)], np.int64),
                    channel=np.array([msg.channel_id], np.uint16),
                    log_time=np.array([msg.log_time], np.uint64),
                    stop=len(data),
                ),
            )
        elif opcode == Opcode.CHUNK:
            report.chunks += 1
            job = body.result() if isinstance(body, Future) else _unpack(*self._job(body))
            chunk = job.chunk
            if job.reason:
                report.bad_chunks.append(
                    LostChunk(
                        chunk.message_start_time,
                        chunk.message_end_time,
                        chunk.uncompressed_size,
                        job.reason,
                    )
                )
                return
            rows = job.rows if job.version == self._redefined else None
            yield from self._chunk_batches(job.data, chunk, job.index, rows)

    def _batches(
        self, data: np.ndarray, index: MessageIndex, rows: CdrRows | None = None
    ) -> Iterator:
        """The indexed messages of wanted channels, one batch per channel: a
        :class:`MessageBatch`, or for :meth:`cdr_batches` a :class:`CdrBatch` (``rows``: those
        made ahead, if still valid)."""
        if self._layout is not None:
            yield from self._cdr_batches(data, index, rows)
            return
        channel = index.channel
        wanted = self._wanted_ids[channel]
        count = int(np.count_nonzero(wanted))
        if count == 0:
            return
        read = self.report.read_counts
        first = int(channel[0])
        if count == len(index) and (channel == first).all():  # one channel: no copies
            read[first] += count
            yield MessageBatch(first, index.log_time, data, index.offset, index.size)
            return
        for cid in np.unique(channel[wanted]).tolist():
            sel = channel == cid
            read[cid] += int(np.count_nonzero(sel))
            yield MessageBatch(cid, index.log_time[sel], data, index.offset[sel], index.size[sel])

    def _cdr_batches(
        self, data: np.ndarray, index: MessageIndex, rows: CdrRows | None
    ) -> Iterator[CdrBatch]:
        """The :class:`CdrBatch` of each slot with messages in ``index``; rows made ahead cover
        the index up to the first message of a channel then unknown, the rest is made now."""
        done = 0
        while done < len(index):
            part = index.since(done)
            if rows is None:
                rows = cdr_rows(data, part, self._table, stop_at_unknown=False)
            for batch in cdr_batches_of(data, part, rows, self._table.channel_ids):
                self.report.read_counts[batch.channel_id] += len(batch) + batch.bad
                yield batch
            done += rows.used
            rows = None

    def _chunk_batches(
        self, buf: np.ndarray, chunk: Chunk, index: MessageIndex, rows: CdrRows | None = None
    ) -> Iterator:
        """The batches of a decompressed chunk whose leading Message records are ``index``
        (``rows``: their rows made ahead, for :meth:`cdr_batches`); a Schema or Channel record
        among them is parsed where it stands and the walk resumes after it."""
        report, end = self.report, len(buf)
        while True:
            report.message_records += len(index)
            report.message_record_bytes += int(index.size.sum()) + MESSAGE_HEAD * len(index)
            yield from self._batches(buf, index, rows)
            rows = None
            pos = index.stop
            if end - pos < RECORD_HEAD:
                return
            opcode = int(buf[pos])
            size = RECORD_HEAD + int(buf[pos + 1 : pos + RECORD_HEAD].view("<u8")[0])
            if pos + size > end or opcode == Opcode.MESSAGE:  # the walk stops at no good Message
                report.bad_chunks.append(
                    LostChunk(
                        chunk.message_start_time,
                        chunk.message_end_time,
                        chunk.uncompressed_size,
                        f"malformed record at byte {pos} of the chunk; the rest was skipped",
                    )
                )
                return
            if opcode in _IN_CHUNK:
                yield from self._record(
                    opcode, buf[pos + RECORD_HEAD : pos + size].tobytes(), size - RECORD_HEAD
                )
            elif opcode == Opcode.CHUNK:  # forbidden by the spec: never unpacked
                bad = self.report.bad_records
                bad[NESTED_CHUNK] = bad.get(NESTED_CHUNK, 0) + 1
            index = index_messages(buf, pos + size)
