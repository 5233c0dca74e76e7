"""Structurally hostile MCAP pieces for tests: nested chunks, chunks that lie about their size,
decompression bombs (built in pieces, never held whole), raw records.

Record layout from the MCAP spec: ``opcode u8, length u64, body``; a Chunk body is
``message_start_time u64, message_end_time u64, uncompressed_size u64, uncompressed_crc u32,
compression (u32 length + bytes), records (u64 length + bytes)``.
"""

from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Chunk

from imupipe.io.decode import IMU_SCHEMA
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.testing.ros_cdr import imu_payloads

T0_NS = 1_700_000_000_000_000_000
_PIECE = 16 << 20


def record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def message(channel_id: int, log_time: int, data: bytes) -> bytes:
    return record(Opcode.MESSAGE, struct.pack("<HIQQ", channel_id, 0, log_time, log_time) + data)


def chunk(
    records: bytes,
    compression: str = "zstd",
    declared_size: int | None = None,
    start_ns: int = T0_NS,
    end_ns: int = T0_NS,
) -> bytes:
    """A Chunk record holding ``records``; ``declared_size`` overrides the true size."""
    if compression == "zstd":
        data = zstandard.ZstdCompressor().compress(records)
    elif compression == "lz4":
        data = lz4.frame.compress(records)
    else:
        data = records
    size = len(records) if declared_size is None else declared_size
    return _chunk_record(start_ns, end_ns, size, zlib.crc32(records), compression, data)


def _chunk_record(start: int, end: int, size: int, crc: int, compression: str, data: bytes):
    body = struct.pack("<QQQI", start, end, size, crc)
    body += struct.pack("<I", len(compression)) + compression.encode()
    body += struct.pack("<Q", len(data)) + data
    return record(Opcode.CHUNK, body)


def nested_chunk(records: bytes, depth: int, compression: str = "zstd") -> bytes:
    """``records`` inside ``depth`` chunks, each inside the next (the spec forbids it)."""
    out = records
    for _ in range(depth):
        out = chunk(out, compression)
    return out


def bomb_chunk(
    inflated_bytes: int,
    compression: str = "zstd",
    declared_size: int | None = None,
    content_size: bool = True,
) -> bytes:
    """A chunk whose records inflate to ``inflated_bytes``: one Message record of an unknown
    channel (id 999) as long as that, its data all zeros, compressed piece by piece (the
    inflated bytes are never held).  ``declared_size`` (default: the truth) is what the chunk
    header claims; ``content_size``: whether a zstd frame states its size too."""
    head = struct.pack("<BQHIQQ", Opcode.MESSAGE, inflated_bytes - 9, 999, 0, T0_NS, T0_NS)
    zeros = bytes(_PIECE)
    crc = zlib.crc32(head)
    left = inflated_bytes - len(head)
    if compression == "zstd":
        cctx = zstandard.ZstdCompressor(write_content_size=content_size)
        inflater = cctx.compressobj(size=inflated_bytes if content_size else -1)
        parts = [inflater.compress(head)]
    else:
        inflater = lz4.frame.LZ4FrameCompressor()
        parts = [inflater.begin(), inflater.compress(head)]
    while left > 0:
        piece = zeros[: min(left, _PIECE)]
        parts.append(inflater.compress(piece))
        crc = zlib.crc32(piece, crc)
        left -= len(piece)
    parts.append(inflater.flush())
    size = inflated_bytes if declared_size is None else declared_size
    return _chunk_record(T0_NS, T0_NS + 10**9, size, crc, compression, b"".join(parts))


def imu_file(
    path: Path,
    n: int = 3000,
    topics: tuple[str, ...] = ("/imu/data",),
    extra: tuple[bytes, ...] = (),
    rate_hz: float = 100.0,
) -> Path:
    """A ROS 2 ``sensor_msgs/msg/Imu`` MCAP of ``n`` white-noise messages per topic (one chunk
    each), followed by the raw records ``extra`` and then the summary and footer."""
    rng = np.random.default_rng(11)
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        sid = w.register_schema(IMU_SCHEMA, "ros2msg", b"")
        log = T0_NS + np.round(np.arange(n) * 1e9 / rate_hz).astype(np.int64)
        for topic in topics:
            cid = w.register_channel(topic, "cdr", sid)
            gyro = rng.normal(0, 1e-3, (n, 3))
            accel = rng.normal(0, 1e-2, (n, 3)) + np.array([0.0, 0.0, 9.81])
            w.write_chunk(cid, log, imu_payloads(log, gyro, accel))
        for rec in extra:
            f.write(rec)
        for cid, count in message_counts(b"".join(extra)).items():
            w.count_messages(cid, count)  # the summary counts them, as a writer's would
        w.finish()
    return path


def message_counts(records: bytes, in_chunk: bool = False) -> dict[int, int]:
    """Message records per channel id among raw ``records``: top-level ones and those in
    top-level chunks (not in chunks nested in them, which the spec forbids and readers skip);
    the walk stops at a record that runs past the end."""
    counts: dict[int, int] = {}
    at = 0
    while at + 9 <= len(records):
        opcode, length = struct.unpack_from("<BQ", records, at)
        body = records[at + 9 : at + 9 + length]
        if len(body) < length:
            break
        if opcode == Opcode.MESSAGE and length >= 2:
            cid = struct.unpack_from("<H", body)[0]
            counts[cid] = counts.get(cid, 0) + 1
        elif opcode == Opcode.CHUNK and not in_chunk:
            for cid, n in message_counts(_chunk_records(body), in_chunk=True).items():
                counts[cid] = counts.get(cid, 0) + n
        at += 9 + length
    return counts


def _chunk_records(body: bytes) -> bytes:
    """The records a Chunk record's ``body`` holds, decompressed (b"" if it cannot be)."""
    chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
    try:
        if chunk.compression == "zstd":
            return zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=1 << 26)
        if chunk.compression == "lz4":
            return lz4.frame.decompress(chunk.data)
    except (zstandard.ZstdError, RuntimeError):
        return b""
    return chunk.data if chunk.compression == "" else b""


def imu_message_records(
    channel_id: int, n: int, rate_hz: float = 100.0, first: int = 3000
) -> bytes:
    """``n`` Imu Message records of ``channel_id`` (zeros, stamps set), uncompressed, stamped
    and logged from sample ``first`` on (default: after the messages of :func:`imu_file`; a
    restart from 0 would read as a reset of the stamping clock)."""
    log = T0_NS + np.round(np.arange(first, first + n) * 1e9 / rate_hz).astype(np.int64)
    payloads = imu_payloads(log, np.zeros((n, 3)), np.zeros((n, 3)))
    pairs = zip(log, payloads, strict=True)
    return b"".join(message(channel_id, int(t), p.tobytes()) for t, p in pairs)
