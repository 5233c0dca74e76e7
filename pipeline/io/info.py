"""``imupipe info``: what a recording holds, read by the same tolerant scan the analyser uses.

Damage (a lost chunk with its estimated message count and log-time span, a cut tail, no footer)
is worded by :meth:`imupipe.io.mcap_scan.ScanReport.damage`, the same sentences ``analyze`` puts in
``report.json``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imupipe.device.frame_schema import SCHEMA_NAME
from imupipe.io.db3_scan import Db3Report
from imupipe.io.decode import IMU_SCHEMA, MESSAGE_ENCODING_READ
from imupipe.io.mcap_scan import ScanReport
from imupipe.io.rosbag2 import bag_files, message_compression, opened


@dataclass
class TopicInfo:
    topic: str
    schema: str
    encoding: str = MESSAGE_ENCODING_READ
    """The channel's message encoding (``cdr``: ROS 2's, the one imupipe reads)."""
    messages: int = 0
    start_ns: int | None = None
    end_ns: int | None = None

    @property
    def read(self) -> bool:
        """Messages in the encoding imupipe decodes."""
        return self.encoding == MESSAGE_ENCODING_READ

    @property
    def duration_s(self) -> float:
        if self.start_ns is None or self.end_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) / 1e9


METADATA_SHOWN = 80
"""Characters of a metadata value that ``imupipe info`` shows; a longer or multi-line one (the
``serialized_metadata`` of every rosbag2 bag: its whole metadata.yaml, ~1 KB) shows its first
line, cut there, and its length."""


def shown(value: str) -> str:
    """A metadata value as ``imupipe info`` shows it on one line (:data:`METADATA_SHOWN`)."""
    if len(value) <= METADATA_SHOWN and "\n" not in value:
        return value
    first = value.split("\n", 1)[0][:METADATA_SHOWN]
    return f"{first} … ({len(value)} characters)"


@dataclass
class RecordingInfo:
    path: Path
    file_bytes: int
    chunks: int
    """MCAP chunks (none in rosbag2's SQLite storage)."""
    topics: list[TopicInfo]
    metadata: dict[str, dict[str, str]]
    damage: list[str] = field(default_factory=list)
    sqlite: bool = False
    """Stored in rosbag2's SQLite storage (``.db3``) rather than MCAP."""

    def lines(self) -> list[str]:
        storage = "rosbag2 SQLite storage (.db3)" if self.sqlite else f"{self.chunks} chunks"
        out = [f"{self.path}: {self.file_bytes / 1e6:.1f} MB, {storage}"]
        for t in self.topics:
            rate = (t.messages - 1) / t.duration_s if t.duration_s > 0 else 0.0
            kind = t.schema if t.read else f"{t.schema}, {t.encoding!r} encoding: not read"
            timing = f"{t.duration_s:.1f} s, {rate:.2f} Hz"
            if t.messages > 1 and t.start_ns is not None and t.start_ns == t.end_ns:
                timing = f"every log time {t.start_ns} ns (not set by the file's writer?)"
            out.append(f"  {t.topic}  [{kind}]  {t.messages} messages, {timing}")
        for name, meta in self.metadata.items():
            out.append(
                f"  metadata {name}: " + ", ".join(f"{k}={shown(v)}" for k, v in meta.items())
            )
        out.extend(f"  warning: {d}" for d in self.damage)
        return out


def _topic(
    topics: dict[str, TopicInfo], report: ScanReport | Db3Report, channel_id: int
) -> TopicInfo:
    channel = report.channels[channel_id]
    schema = report.schemas.get(channel.schema_id)
    return topics.setdefault(
        channel.topic,
        TopicInfo(channel.topic, schema.name if schema else "", channel.message_encoding),
    )


def describe(path: Path) -> RecordingInfo:
    """Scan an MCAP file or a rosbag2 directory (its split files, as one recording) and count
    the messages and log-time span of every topic.

    Raises:
        InputError: not a file, empty, a directory without MCAP or .db3 files, not MCAP (nor
            a rosbag2 database).
    """
    path = Path(path)
    files, damage = bag_files(path)
    topics: dict[str, TopicInfo] = {}
    metadata: dict[str, dict[str, str]] = {}
    file_bytes = chunks = 0
    sqlite = False
    compression = message_compression(path)
    for file in files:
        with opened(file, compression) as scanner:
            report = scanner.report
            for batch in scanner.batches():
                info = _topic(topics, report, batch.channel_id)
                info.messages += len(batch)
                lo, hi = int(np.min(batch.log_time)), int(np.max(batch.log_time))
                info.start_ns = lo if info.start_ns is None else min(info.start_ns, lo)
                info.end_ns = hi if info.end_ns is None else max(info.end_ns, hi)
        for channel_id in report.channels:  # channels without readable messages too
            _topic(topics, report, channel_id)
        file_bytes += report.file_bytes
        chunks += report.chunks
        sqlite |= isinstance(report, Db3Report)
        metadata.update(report.metadata)
        prefix = f"{file.name}: " if len(files) > 1 else ""
        damage.extend(prefix + d for d in report.damage())
    return RecordingInfo(
        path=path,
        file_bytes=file_bytes,
        chunks=chunks,
        sqlite=sqlite,
        topics=sorted(topics.values(), key=lambda t: t.topic),
        metadata=metadata,
        damage=damage,
    )


def imu_topics(path: Path) -> list[str]:
    """The IMU topics (our ADIS16364 frames or ``sensor_msgs/msg/Imu``, in CDR) that hold
    messages."""
    return [
        t.topic
        for t in describe(path).topics
        if t.schema in (SCHEMA_NAME, IMU_SCHEMA) and t.read and t.messages > 0
    ]
