"""rosbag2's SQLite storage (``.db3``: the default storage of ROS 2 up to Humble), read through
the same interface as :class:`imupipe.io.mcap_scan.McapScanner`: a :class:`Db3Report` and the
wanted topics' messages as :class:`~imupipe.io.mcap_scan.CdrBatch` or
:class:`~imupipe.io.mcap_scan.MessageBatch` blocks, so everything after the scan is shared.

The rosbag2 SQLite schema (rosbag2_storage_default_plugins, ``sqlite_storage.cpp``): a table
``topics(id, name, type, serialization_format, ...)`` and a table ``messages(id, topic_id,
timestamp, data)`` whose ``data`` is the serialised message (CDR, as in an MCAP Message record)
and ``timestamp`` the receive time in ns (an MCAP log time).  Messages are read in ``id`` order —
the order the recorder wrote them (``id`` is the table's rowid), as an MCAP file's — a block of
:data:`BLOCK_ROWS` at a time, only the wanted topics' rows, and a message's CDR fields are copied
out by the same compiled kernel as a chunk's (:func:`imupipe.io.mcap_walk.cdr_rows`, over the
block's payloads joined).  Payloads compressed one by one (rosbag2's ``compression_mode:
message``) are inflated here; whole compressed files are inflated before
(:mod:`imupipe.io.rosbag2`).

The file is opened read-only; its strings (topic names, types) reach the outputs escaped like an
MCAP file's.  A payload longer than ``max_chunk_bytes``, or one that is no blob (SQLite's types
are the writer's choice) or does not inflate, is not read (counted as damage), and a database
damaged part way is read on both sides of the damage, with a warning naming the messages lost.
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zstandard
from mcap.records import Channel, Schema

from imupipe.errors import InputError
from imupipe.io.mcap_scan import MAX_CHUNK_BYTES, CdrBatch, MessageBatch, cdr_batches_of
from imupipe.io.mcap_walk import CdrLayout, CdrTable, MessageIndex, cdr_rows

SQLITE_MAGIC = b"SQLite format 3\x00"
"""The first 16 bytes of every SQLite 3 database file."""
BLOCK_ROWS = 1 << 16
"""Messages joined into one block (~25 MB of Imu payloads)."""
FETCH_ROWS = 1 << 12
"""Messages fetched from the database at a time: a database damaged part way loses at most
these beyond the damage."""


def is_db3(path: Path) -> bool:
    """Whether the file at ``path`` is an SQLite 3 database (by its header, not its name)."""
    with open(path, "rb") as f:
        return f.read(len(SQLITE_MAGIC)) == SQLITE_MAGIC


def message_count(path: Path) -> int:
    """Messages in the rosbag2 database at ``path`` (all topics; SQLite counts them on the
    smallest index, ``timestamp_idx``: milliseconds for a 158 MB bag).

    Raises:
        sqlite3.DatabaseError: not a readable rosbag2 database.
    """
    with contextlib.closing(_connect(path)) as db:
        return int(db.execute("SELECT count(*) FROM messages").fetchone()[0])


def _connect(path: Path) -> sqlite3.Connection:
    """The database at ``path``, opened read-only."""
    return sqlite3.connect(f"{Path(path).absolute().as_uri()}?mode=ro", uri=True)


@dataclass
class Db3Report:
    """What the scan of a ``.db3`` file found besides messages (the fields of
    :class:`imupipe.io.mcap_scan.ScanReport` that a rosbag2 database has), and what it could
    not read."""

    file_bytes: int = 0
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    chunks: int = 0
    messages: int = 0
    """Messages of wanted topics yielded."""
    skipped: int = 0
    """Messages of wanted topics not read: longer than ``max_chunk_bytes``, or whose payload is
    no blob (or, compressed per message, no zstd frame) or whose timestamp no integer."""
    lost: list[tuple[int, int | None, str]] = field(default_factory=list)
    """Stretches of messages the database failed to read: (the last message (rowid) read before,
    the last one lost (None: every one after it), SQLite's reason)."""
    last_row: int = 0
    """The database's last message (rowid; 0 if its last page cannot be read)."""

    def damage(self) -> list[str]:
        """One human sentence per kind of damage (empty for an intact database)."""
        out = []
        if self.skipped:
            out.append(
                f"{self.skipped} message(s) skipped unread (larger than the memory budget "
                "allows, or no readable binary payload with an integer timestamp)"
            )
        for before, until, reason in self.lost:
            out.append(f"database damaged ({reason}): " + self._stretch(before, until))
        return out

    def _stretch(self, before: int, until: int | None) -> str:
        """What a lost stretch of messages after ``before`` (up to ``until``) was."""
        if until is not None:
            of = (
                f" of {self.last_row} ({100 * (until - before) / self.last_row:.1f} %, all topics)"
                if self.last_row
                else " (all topics)"
            )
            return f"messages {before + 1}–{until}{of} could not be read; read on after them"
        lost = (
            f"the last {100 * (1 - before / self.last_row):.1f} % of the messages"
            if self.last_row >= before
            else "the messages after it (the last page cannot be read: how many is unknown)"
        )
        return f"read up to message {before}; {lost} could not be read"


class Db3Scanner:
    """The messages of a rosbag2 SQLite database (module docstring), with the interface of
    :class:`imupipe.io.mcap_scan.McapScanner`: :attr:`report` (topics as channels, their
    types as schemas), :meth:`batches` and :meth:`cdr_batches`.

    Raises:
        InputError: not a database, or not a rosbag2 one (no ``topics``/``messages`` tables).
    """

    def __init__(
        self,
        path: Path,
        wanted: Callable[[Channel, Schema | None], bool] = lambda c, s: True,
        progress: Callable[[int], None] | None = None,
        max_chunk_bytes: int = MAX_CHUNK_BYTES,
        message_compression: str = "",
    ) -> None:
        self.path = Path(path)
        self.report = Db3Report(file_bytes=os.path.getsize(self.path))
        self._inflate = (
            zstandard.ZstdDecompressor().decompress if message_compression == "zstd" else None
        )
        self._wanted = wanted
        self._progress = progress or (lambda n: None)
        self._max_bytes = max_chunk_bytes
        self._db = _connect(self.path)
        try:
            topics = self._db.execute(
                "SELECT id, name, type, serialization_format FROM topics ORDER BY id"
            ).fetchall()
            self._db.execute("SELECT 1 FROM messages LIMIT 1").fetchall()
        except sqlite3.DatabaseError as exc:
            self._db.close()
            raise InputError(f"{self.path}: not a readable rosbag2 database ({exc})") from exc
        with contextlib.suppress(sqlite3.DatabaseError):  # its last page cut off: unknown (0)
            last = self._db.execute("SELECT max(rowid) FROM messages").fetchone()[0]
            self.report.last_row = last or 0
        for topic_id, name, type_name, encoding in topics:
            if not isinstance(topic_id, int) or not 0 <= topic_id < 1 << 16:
                self._db.close()
                raise InputError(f"{self.path}: topic id {topic_id!r} is not a rosbag2 topic id")
            schema = Schema(id=topic_id, name=str(type_name), encoding="ros2msg", data=b"")
            self.report.schemas[topic_id] = schema
            self.report.channels[topic_id] = Channel(
                id=topic_id,
                topic=str(name),
                message_encoding=str(encoding),
                schema_id=topic_id,
                metadata={},
            )

    def batches(self) -> Iterator[MessageBatch]:
        """The wanted topics' messages, one batch per topic and block, in recording order."""
        ids = [
            i for i, c in self.report.channels.items() if self._wanted(c, self.report.schemas[i])
        ]
        for data, index in self._blocks(ids):
            for channel_id in np.unique(index.channel).tolist():
                mine = index.channel == channel_id
                yield MessageBatch(
                    channel_id, index.log_time[mine], data, index.offset[mine], index.size[mine]
                )

    def cdr_batches(
        self, layout: Callable[[Channel, Schema | None], CdrLayout | None]
    ) -> Iterator[CdrBatch]:
        """The messages of the CDR topics ``layout`` gives a :class:`CdrLayout` for, one batch of
        rows per topic and block, in recording order."""
        table = CdrTable()
        for i, channel in self.report.channels.items():
            wanted = channel.message_encoding == "cdr"
            table.set(i, layout(channel, self.report.schemas[i]) if wanted else None)
        for data, index in self._blocks(table.channel_ids):
            rows = cdr_rows(data, index, table, stop_at_unknown=False)
            for batch in cdr_batches_of(data, index, rows, table.channel_ids):
                self.report.messages += len(batch) + batch.bad
                yield batch

    def _blocks(self, ids: list[int]) -> Iterator[tuple[np.ndarray, MessageIndex]]:
        """The messages of topics ``ids`` as (their payloads joined, a :class:`MessageIndex`
        into them), :data:`BLOCK_ROWS` at a time in ``rowid`` order; the database is closed
        when the last block is read.  Where a fetch fails (a page SQLite cannot parse: a bad
        sector, a partial copy), the messages before the damage are read one at a time, reading
        resumes at the first readable message after it (:meth:`_next_readable`), and the
        stretch in between is reported lost.

        Raises:
            InputError: the database cannot be read at all."""
        readable = "typeof(data) = 'blob' AND length(data) <= ? AND typeof(timestamp) = 'integer'"
        query = (
            f"SELECT rowid, topic_id, timestamp, CASE WHEN {readable} THEN data END FROM messages "
            f"WHERE rowid > ? AND topic_id IN ({','.join(map(str, ids))}) ORDER BY rowid"
        )
        block: list[tuple] = []
        after = 0  # rowid of the last message read, or of the last one lost
        try:
            while ids:
                try:
                    cursor = self._db.execute(query, (self._max_bytes, after))
                    while rows := cursor.fetchmany(FETCH_ROWS):
                        block += rows
                        after = rows[-1][0]
                        if len(block) >= BLOCK_ROWS:
                            yield from self._kept(block)
                            block = []
                            self._progress(
                                int(self.report.file_bytes * after / max(self.report.last_row, 1))
                            )
                    break
                except sqlite3.DatabaseError as exc:
                    salvaged, failed = self._one_by_one(query, after)
                    block += salvaged
                    after = salvaged[-1][0] if salvaged else after
                    if not failed:  # the rows the failed fetch held all read: go on
                        continue
                    resume = self._next_readable(query, after)
                    if resume is None and not after:
                        raise InputError(
                            f"{self.path}: not a readable rosbag2 database ({exc})"
                        ) from exc
                    self.report.lost.append((after, resume, str(exc)))
                    if resume is None:
                        break
                    after = resume
        finally:
            self._db.close()
        yield from self._kept(block)

    def _first_rows(self, query: str, after: int) -> list[tuple] | None:
        """The first row of ``query`` after message ``after``, if any (None: SQLite failed)."""
        try:
            return self._db.execute(query, (self._max_bytes, after)).fetchmany(1)
        except sqlite3.DatabaseError:
            return None

    def _one_by_one(self, query: str, after: int) -> tuple[list[tuple], bool]:
        """The rows of ``query`` after message ``after`` up to the first that fails to read (at
        most :data:`FETCH_ROWS`: those a failed fetch held), and whether one failed."""
        rows: list[tuple] = []
        try:
            cursor = self._db.execute(query, (self._max_bytes, after))
            while len(rows) < FETCH_ROWS and (row := cursor.fetchone()) is not None:
                rows.append(row)
        except sqlite3.DatabaseError:
            return rows, True
        return rows, False

    def _next_readable(self, query: str, after: int) -> int | None:
        """The smallest rowid r > ``after`` from which ``query`` reads (its rows after r; the
        messages after ``after`` up to r are lost), found by doubling the distance and then
        bisecting; None when none up to 2⁶² does, or none is left after r (every message after
        ``after`` is lost)."""
        step, failed = 1, after
        while (first := self._first_rows(query, failed + step)) is None:
            failed += step
            step *= 2
            if failed + step > 1 << 62:
                return None
        ok = failed + step
        while ok - failed > 1:  # the first read beyond one damaged stretch
            mid = (failed + ok) // 2
            if (rows := self._first_rows(query, mid)) is None:
                failed = mid
            else:
                ok, first = mid, rows
        return ok if first else None  # no message after it: all lost

    def _inflated(
        self, kept: list[tuple], payloads: list[bytes]
    ) -> tuple[list[tuple], list[bytes]]:
        """The rows whose payload is a zstd frame that inflates to at most ``max_chunk_bytes``,
        and those payloads inflated."""
        rows, out = [], []
        for row, payload in zip(kept, payloads, strict=True):
            with contextlib.suppress(zstandard.ZstdError):
                out.append(self._inflate(payload, max_output_size=self._max_bytes))
                rows.append(row)
        return rows, out

    def _kept(self, block: list[tuple]) -> Iterator[tuple[np.ndarray, MessageIndex]]:
        """The readable messages of ``block`` (rows of rowid, topic, timestamp and payload or
        None) as their payloads joined and a :class:`MessageIndex` into them; the others
        counted as skipped."""
        kept = [row for row in block if row[3] is not None]
        payloads = [row[3] for row in kept]
        if self._inflate is not None:  # rosbag2's per-message compression
            kept, payloads = self._inflated(kept, payloads)
        self.report.skipped += len(block) - len(kept)
        if not kept:
            return
        size = np.fromiter(map(len, payloads), np.int64, len(kept))
        offset = np.zeros(len(kept), np.int64)
        np.cumsum(size[:-1], out=offset[1:])
        data = np.frombuffer(b"".join(payloads), np.uint8)
        channel = np.fromiter([row[1] for row in kept], np.uint16, len(kept))
        log_time = np.fromiter([row[2] for row in kept], np.int64, len(kept)).view(np.uint64)
        yield data, MessageIndex(offset, size, channel, log_time, len(data))
