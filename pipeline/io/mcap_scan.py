"""Tolerant linear scan of an MCAP file, yielding runs of messages as numpy arrays.

The mcap library's indexed reader needs an intact summary section and its per-message reader
runs ~100 k messages/s in Python.  This scanner walks the file record by record (MCAP spec:
``opcode u8, length u64, body``), parses Schema, Channel, Metadata and Chunk bodies with the mcap
library's own record classes, decompresses each chunk, and cuts its body into *runs* of
consecutive Message records of equal size, which become one ``(n, size)`` uint8 array each
(a strided view: no per-message Python).  Messages whose sizes vary still decode, one run per
message, just slower.

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
import os
import struct
import zlib
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Metadata, Schema

from imupipe.errors import InputError, NotMcapError

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = 9  # opcode u8 + length u64
_MESSAGE_FIXED = 2 + 4 + 8 + 8  # channel_id, sequence, log_time, publish_time
_MESSAGE_HEAD = _RECORD_HEAD + _MESSAGE_FIXED  # bytes of a Message record before its data
_CHUNK_FIXED = 8 + 8 + 8  # message_start_time, message_end_time, uncompressed_size
PREFETCH_RECORDS = 2
"""Records read ahead of the one being cut into runs; chunks among them are decompressed and
CRC-checked on a worker thread meanwhile (zstd, lz4 and crc32 release the GIL)."""
_PARSED = (Opcode.CHUNK, Opcode.MESSAGE, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA)
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
class MessageRun:
    """Consecutive messages of one channel with equal payload size.

    Attributes:
        channel_id: the MCAP channel.
        log_time: ns since the epoch (uint64, ``(n,)``).
        payloads: ``(n, size)`` uint8, the serialised messages.

    Both may be strided read-only views of the decompressed chunk (valid as long as the run is
    referenced).
    """

    channel_id: int
    log_time: np.ndarray
    payloads: np.ndarray


def _message_dtype(size: int) -> np.dtype:
    """A Message record of ``size`` bytes as a structured dtype (MCAP spec: opcode u8,
    length u64, channel_id u16, sequence u32, log_time u64, publish_time u64, data): read over a
    decompressed chunk, its fields are strided views of the bytes, not copies."""
    return np.dtype(
        {
            "names": ["opcode", "length", "channel_id", "log_time"],
            "formats": ["u1", "<u8", "<u2", "<u8"],
            "offsets": [0, 1, _RECORD_HEAD, _RECORD_HEAD + 2 + 4],
            "itemsize": size,
        }
    )


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
    messages: int = 0
    """Messages of wanted channels yielded."""
    message_records: int = 0
    message_record_bytes: int = 0
    """Message records read in chunks (all channels) and their total size: the mean record size
    converts a lost chunk's uncompressed size into an estimated message count."""

    max_chunk_bytes: int = MAX_CHUNK_BYTES
    """Chunks declaring more uncompressed bytes were skipped unread: their size is not trusted."""

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
        return out


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
        return zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=size)
    if chunk.compression == "lz4":
        inflater = lz4.frame.LZ4FrameDecompressor()
        data = inflater.decompress(chunk.data, max_length=size)
        if not inflater.eof:
            raise ValueError(f"it does not end within the {size} bytes its header declares")
        return data
    raise InputError(f"unsupported compression {chunk.compression!r}")


def _unpack(body: bytes) -> tuple[Chunk, bytes, str]:
    """Parse a Chunk record, decompress it and check its CRC: (chunk, records, reason), the
    reason why it cannot be read, empty if it can."""
    chunk = _parse(Chunk, body)
    try:
        data = _decompress(chunk)
    except Exception as exc:  # each codec raises its own error types
        return chunk, b"", f"decompression failed: {str(exc) or type(exc).__name__}"
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        return chunk, data, "CRC mismatch"
    return chunk, data, ""


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
        self._wanted_ids: set[int] = set()
        self._progress = progress or (lambda n: None)
        self._cut_head: bytes | None = None  # fixed fields of a chunk cut off by the file's end

    def _add_channel(self, channel: Channel) -> None:
        self.report.channels[channel.id] = channel
        if self._wanted(channel, self.report.schemas.get(channel.schema_id)):
            self._wanted_ids.add(channel.id)

    def runs(self) -> Iterator[MessageRun]:
        """The file's message runs in file order; chunks are unpacked a few records ahead."""
        with ThreadPoolExecutor(1, thread_name_prefix="mcap-unpack") as pool:
            pending: deque[tuple[int, bytes | Future, int]] = deque()
            for opcode, body, length in self._records():
                pending.append(
                    (opcode, pool.submit(_unpack, body) if opcode == Opcode.CHUNK else body, length)
                )
                if len(pending) > PREFETCH_RECORDS:
                    yield from self._record(*pending.popleft())
            while pending:
                yield from self._record(*pending.popleft())
        if self._cut_head is not None:
            self._cut_chunk(self._cut_head)

    def _records(self) -> Iterator[tuple[int, bytes, int]]:
        """(opcode, body, length) of each top-level record the scan parses, in file order;
        fills the report's truncation, footer and bytes-read fields."""
        report = self.report
        try:
            f = open(self.path, "rb")  # closed by the with below
        except OSError as exc:
            raise InputError(f"{self.path}: cannot be read ({exc.strerror or exc})") from None
        with f:
            if f.read(len(MAGIC)) != MAGIC:
                raise NotMcapError(f"{self.path} is not an MCAP file (bad magic)")
            pos = len(MAGIC)
            while True:
                head = f.read(_RECORD_HEAD)
                if len(head) == 0:
                    break
                if len(head) < _RECORD_HEAD:
                    report.truncated_bytes = report.file_bytes - pos
                    break
                opcode, length = struct.unpack("<BQ", head)
                if pos + _RECORD_HEAD + length > report.file_bytes:
                    report.truncated_bytes = report.file_bytes - pos
                    report.truncated_opcode = opcode
                    if opcode == Opcode.CHUNK:  # reported after the chunks before it
                        self._cut_head = f.read(_CHUNK_FIXED)
                    break
                if opcode == Opcode.CHUNK and length >= _CHUNK_FIXED:
                    head = f.read(_CHUNK_FIXED)
                    if self._too_large(head, length):
                        f.seek(length - _CHUNK_FIXED, os.SEEK_CUR)
                    else:
                        yield opcode, head + f.read(length - _CHUNK_FIXED), length
                elif opcode in _PARSED and length <= report.max_chunk_bytes:
                    yield opcode, f.read(length), length
                else:
                    if opcode in _PARSED:  # a record no budget can hold: counted, not read
                        self._bad_record(opcode)
                    f.seek(length, os.SEEK_CUR)
                pos += _RECORD_HEAD + length
                self._progress(pos)
                if opcode == Opcode.FOOTER:  # only the closing magic follows
                    report.has_footer = True
                    break

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
                f"{limit} a chunk may take under the memory budget; skipped unread",
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

    def _record(self, opcode: int, body: bytes | Future, length: int) -> Iterator[MessageRun]:
        """Parse one record (a chunk's body may be the :func:`_unpack` job already submitted);
        a record whose fields do not parse is counted and skipped."""
        try:
            yield from self._parsed_record(opcode, body, length)
        except _MALFORMED:
            self._bad_record(opcode)

    def _parsed_record(
        self, opcode: int, body: bytes | Future, length: int
    ) -> Iterator[MessageRun]:
        report = self.report
        if opcode == Opcode.SCHEMA:
            schema = _parse(Schema, body)
            report.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            self._add_channel(_parse(Channel, body))
        elif opcode == Opcode.METADATA:
            meta = _parse(Metadata, body)
            report.metadata[meta.name] = dict(meta.metadata)
        elif opcode == Opcode.MESSAGE:
            msg = _parse(Message, body, length)
            if msg.channel_id in self._wanted_ids:
                report.messages += 1
                yield MessageRun(
                    msg.channel_id,
                    np.array([msg.log_time], dtype=np.uint64),
                    np.frombuffer(msg.data, np.uint8).reshape(1, -1),
                )
        elif opcode == Opcode.CHUNK:
            report.chunks += 1
            chunk, data, reason = body.result() if isinstance(body, Future) else _unpack(body)
            if reason:
                report.bad_chunks.append(
                    LostChunk(
                        chunk.message_start_time,
                        chunk.message_end_time,
                        chunk.uncompressed_size,
                        reason,
                    )
                )
                return
            yield from self._chunk_runs(np.frombuffer(data, np.uint8), chunk)

    def _chunk_runs(self, buf: np.ndarray, chunk: Chunk) -> Iterator[MessageRun]:
        """Cut a decompressed chunk body into runs of equal-size Message records."""
        pos, end = 0, len(buf)
        while pos + _RECORD_HEAD <= end:
            opcode = int(buf[pos])
            length = int(buf[pos + 1 : pos + 9].view("<u8")[0])
            size = _RECORD_HEAD + length
            malformed = pos + size > end or (opcode == Opcode.MESSAGE and length < _MESSAGE_FIXED)
            if malformed:
                self.report.bad_chunks.append(
                    LostChunk(
                        chunk.message_start_time,
                        chunk.message_end_time,
                        chunk.uncompressed_size,
                        f"malformed record at byte {pos} of the chunk; the rest was skipped",
                    )
                )
                return
            if opcode != Opcode.MESSAGE:
                if opcode in _IN_CHUNK:
                    yield from self._record(
                        opcode, buf[pos + _RECORD_HEAD : pos + size].tobytes(), length
                    )
                elif opcode == Opcode.CHUNK:  # forbidden by the spec: never unpacked
                    bad = self.report.bad_records
                    bad[NESTED_CHUNK] = bad.get(NESTED_CHUNK, 0) + 1
                pos += size
                continue
            count = (end - pos) // size
            records = np.frombuffer(buf, _message_dtype(size), count, pos)
            same = (records["opcode"] == Opcode.MESSAGE) & (records["length"] == length)
            run = count if same.all() else int(np.argmin(same))
            records = records[:run]
            payloads = buf[pos : pos + run * size].reshape(run, size)[:, _MESSAGE_HEAD:]
            pos += run * size
            self.report.message_records += run
            self.report.message_record_bytes += run * size
            channel, log_time = records["channel_id"], records["log_time"]
            if (channel == channel[0]).all():  # the usual case: views, no copies
                if int(channel[0]) in self._wanted_ids:
                    self.report.messages += run
                    yield MessageRun(int(channel[0]), log_time, payloads)
                continue
            for cid in np.unique(channel):
                if int(cid) not in self._wanted_ids:
                    continue
                sel = channel == cid
                self.report.messages += int(sel.sum())
                yield MessageRun(int(cid), log_time[sel], payloads[sel])
