"""ROS 2 bags in rosbag2's SQLite storage (``.db3``: the default of ROS 2 up to Humble), written by
rosbags' rosbag2 writer, not our code: the decoded values equal rosbags' own reader's bit for bit
(NaN payloads, -0.0 and subnormals included), and the same messages stored as MCAP decode to the
same frame; hostile databases give one clear error or what can be recovered, with a warning.
"""

from __future__ import annotations

import re
import shutil
import sqlite3
import tempfile
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2 import Writer as Rosbag2Writer

from imupipe.errors import InputError
from imupipe.io import db3_scan, rosbag2
from imupipe.io.columns import message_count
from imupipe.io.decode import decode
from imupipe.io.info import describe
from imupipe.testing.busy_bag import (
    TWO_IMU_TOPICS,
    TYPESTORE,
    Stream,
    imu_stream,
    rosbags_imu_values,
    two_imu_streams,
    write_rosbag2,
    write_rosbag2_db3,
)
from imupipe.vocab import AXES

TOPICS = TWO_IMU_TOPICS
SECONDS = 1.5


def rosbags_imu(bag: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """(stamps ns int64, (n, 6) gyro+accel float64) of ``topic`` as rosbags' reader gives them."""
    with Rosbag2Reader(bag) as reader:
        wanted = [c for c in reader.connections if c.topic == topic]
        return rosbags_imu_values(raw for _, _, raw in reader.messages(connections=wanted))


@pytest.fixture(scope="module")
def streams():
    return two_imu_streams(SECONDS)


@pytest.fixture(scope="module")
def db3_bag(tmp_path_factory, streams) -> Path:
    bag = tmp_path_factory.mktemp("db3") / "bag"
    write_rosbag2_db3(bag, streams)
    return bag


def test_db3_bag_equals_rosbags_reader_bit_for_bit(db3_bag: Path) -> None:
    """Two Imu topics at 200 and 300 Hz interleaved message by message with /tf, /odom, a
    temperature topic and 20 kB camera images; frame_ids of 0-30 characters."""
    for topic in TOPICS:
        rec = decode(db3_bag, topic=topic)
        stamps, axes = rosbags_imu(db3_bag, topic)
        assert rec.frames.height == len(stamps) == int(SECONDS * (200 + 100 * TOPICS.index(topic)))
        np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps)
        ours = rec.frames.select(AXES).to_numpy()
        np.testing.assert_array_equal(ours.view(np.uint64), axes.view(np.uint64))
        assert rec.warnings == []
        assert rec.topics == list(TOPICS)  # the IMU topics


def test_db3_and_mcap_storage_of_the_same_messages_decode_alike(
    tmp_path: Path, db3_bag: Path, streams
) -> None:
    """The same streams stored as MCAP (the mcap library's writer) and as SQLite (rosbags):
    every column of the decoded frame equal, log-time columns included; the .db3 file given
    alone reads as its directory."""
    write_rosbag2(tmp_path / "mcap_bag", streams)
    for topic in TOPICS:
        from_mcap = decode(tmp_path / "mcap_bag", topic=topic).frames
        assert decode(db3_bag, topic=topic).frames.equals(from_mcap)
        assert decode(next(db3_bag.glob("*.db3")), topic=topic).frames.equals(from_mcap)


def test_describe_counts_every_topic_of_a_db3_bag(db3_bag: Path, streams) -> None:
    info = describe(db3_bag)
    counts = {t.topic: (t.schema, t.messages, t.start_ns, t.end_ns) for t in info.topics}
    assert counts == {
        s.topic: (s.msgtype, len(s.log_time), int(s.log_time[0]), int(s.log_time[-1]))
        for s in streams
    }
    assert info.damage == []
    # the memory budget's estimate counts the database's rows (not file bytes / 40: 10x more)
    assert message_count(next(db3_bag.glob("*.db3"))) == sum(len(s.log_time) for s in streams)
    assert (
        info.lines()[0]
        == f"{db3_bag}: {info.file_bytes / 1e6:.1f} MB, rosbag2 SQLite storage (.db3)"
    )


def _copy(bag: Path, tmp_path: Path) -> Path:
    """A copy of the bag's .db3 file to tamper with."""
    target = tmp_path / "tampered.db3"
    shutil.copyfile(next(bag.glob("*.db3")), target)
    return target


def test_unreadable_rows_are_skipped_and_counted(tmp_path: Path, db3_bag: Path) -> None:
    """SQLite stores whatever type a writer gives: a text payload, a text timestamp and a
    payload over the chunk limit are skipped unread and counted in one warning, the other
    messages decode as before."""
    db3 = _copy(db3_bag, tmp_path)
    with sqlite3.connect(db3) as db:
        imu0 = db.execute("SELECT id FROM topics WHERE name = ?", (TOPICS[0],)).fetchone()[0]
        rows = [r for (r,) in db.execute(
            "SELECT id FROM messages WHERE topic_id = ? ORDER BY id LIMIT 3", (imu0,)
        )]  # fmt: skip
        db.execute("UPDATE messages SET data = 'text' WHERE id = ?", (rows[0],))
        db.execute("UPDATE messages SET timestamp = 'noon' WHERE id = ?", (rows[1],))
        db.execute("UPDATE messages SET data = zeroblob(2000000) WHERE id = ?", (rows[2],))
    rec = decode(db3, topic=TOPICS[0], max_chunk_bytes=1_000_000)
    stamps, axes = rosbags_imu(db3_bag, TOPICS[0])
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps[3:])
    np.testing.assert_array_equal(rec.frames["gyro_y"].to_numpy()[-5:], axes[-5:, 1])
    assert rec.warnings == [
        "3 message(s) skipped unread (larger than the memory budget allows, or no readable "
        "binary payload with an integer timestamp)"
    ]


def test_a_database_that_is_not_a_bag_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "other.db3"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE things (x)")
    with pytest.raises(InputError, match=r"other\.db3: not a readable rosbag2 database \(no such"):
        decode(path)


def test_a_topic_id_beyond_the_channel_ids_is_refused(tmp_path: Path, db3_bag: Path) -> None:
    db3 = _copy(db3_bag, tmp_path)
    with sqlite3.connect(db3) as db:
        db.execute("UPDATE topics SET id = 70000 WHERE name = '/tf'")
    with pytest.raises(InputError, match="topic id 70000 is not a rosbag2 topic id"):
        decode(db3)


def test_a_directory_without_storage_files_says_which_it_looked_for(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match=r"a directory without MCAP or \.db3 files"):
        decode(tmp_path)


def test_a_database_damaged_part_way_is_read_on_both_sides_of_the_damage(
    tmp_path: Path, monkeypatch
) -> None:
    """Pages overwritten half way through (a bad sector, a partial copy): the messages before
    them decode, those before the damage in the fetch that failed included, reading resumes at
    the first readable message after them, and the warning names the messages lost.  (Until
    session 35 everything after the damage was lost: here half the recording.)  A file cut
    short is refused whole: SQLite opens no table of it."""
    monkeypatch.setattr(db3_scan, "FETCH_ROWS", 64)
    monkeypatch.setattr(db3_scan, "BLOCK_ROWS", 256)
    db3 = write_rosbag2_db3(tmp_path / "bag", [imu_stream(TOPICS[0], 10.0, 200, seed=4)])
    stamps, _ = rosbags_imu(tmp_path / "bag", TOPICS[0])
    size = db3.stat().st_size
    with open(db3, "r+b") as f:
        f.seek(size // 2 // 4096 * 4096)
        f.write(np.random.default_rng(0).integers(0, 256, 4 * 4096, np.uint8).tobytes())
    rec = decode(db3)
    read = rec.frames["stamp_ns"].to_numpy()
    (warning,) = rec.warnings
    first, last = (int(m) for m in re.search(r"messages (\d+)–(\d+) of 2000", warning).groups())
    assert (first, last) == (968, 1002)  # four pages of ~9 messages
    assert warning == (
        "database damaged (database disk image is malformed): messages 968–1002 of 2000 (1.8 %, "
        "all topics) could not be read; read on after them"
    )
    np.testing.assert_array_equal(read, np.concatenate([stamps[: first - 1], stamps[last:]]))
    cut = tmp_path / "cut.db3"
    cut.write_bytes(db3.read_bytes()[: size // 2])
    with pytest.raises(InputError, match=r"cut\.db3: not a readable rosbag2 database \(database"):
        decode(cut)


def test_a_database_whose_last_pages_are_damaged_keeps_what_precedes_them(
    tmp_path: Path, monkeypatch
) -> None:
    """Damage that reaches the last message leaves nothing to resume at: the messages before it
    decode and the warning says which share of the database is lost."""
    monkeypatch.setattr(db3_scan, "FETCH_ROWS", 64)
    db3 = write_rosbag2_db3(tmp_path / "bag", [imu_stream(TOPICS[0], 10.0, 200, seed=4)])
    stamps, _ = rosbags_imu(tmp_path / "bag", TOPICS[0])
    with sqlite3.connect(db3) as db:  # the messages' table's pages, in order
        pages = [p for (p,) in db.execute("SELECT pageno FROM dbstat WHERE name = 'messages'")]
    page_size = 4096
    with open(db3, "r+b") as f:
        for page in pages[-len(pages) // 4 :]:  # its last quarter
            f.seek((page - 1) * page_size)
            f.write(bytes([0xFF]) * page_size)
    monkeypatch.setattr(db3_scan, "BLOCK_ROWS", 256)
    seen: list[int] = []  # the total unknown: progress against 1 row, never a division by 0
    rec = decode(db3, progress=seen.append)
    n = rec.frames.height
    assert 1000 < n < 2000
    assert seen and all(v > 0 for v in seen)
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps[:n])
    assert rec.warnings == [
        f"database damaged (database disk image is malformed): read up to message {n}; the "
        "messages after it (the last page cannot be read: how many is unknown) could not be read"
    ]


def _compressed_bag(bag: Path, storage: str, mode: str) -> tuple[Stream, Path]:
    """An Imu topic written by rosbags' rosbag2 writer in ``storage`` (SQLITE3, MCAP) with
    rosbag2's zstd compression in ``mode`` (FILE, MESSAGE); returns the stream and the bag."""
    imu = imu_stream(TOPICS[0], SECONDS, 200, seed=5)
    writer = Rosbag2Writer(bag, version=8, storage_plugin=getattr(StoragePlugin, storage))
    writer.set_compression(getattr(CompressionMode, mode), CompressionFormat.ZSTD)
    with writer:
        connection = writer.add_connection(imu.topic, imu.msgtype, typestore=TYPESTORE)
        for t, payload in zip(imu.log_time.tolist(), imu.payloads, strict=True):
            writer.write(connection, t, payload)
    return imu, bag


@pytest.mark.parametrize("storage", ["SQLITE3", "MCAP"])
@pytest.mark.parametrize("mode", ["FILE", "MESSAGE"])
def test_bags_compressed_by_rosbag2_read_as_rosbags_reads_them(
    tmp_path: Path, storage: str, mode: str
) -> None:
    """rosbag2's own compression (zstd), as rosbags writes it: each split file compressed whole
    (``bag.db3.zstd``, ``bag.mcap.zstd``: inflated into a temporary file while read) or each
    message's payload (SQLite: inflated message by message; MCAP: refused in one line)."""
    _, bag = _compressed_bag(tmp_path / "bag", storage, mode)
    if storage == "MCAP" and mode == "MESSAGE":
        with pytest.raises(InputError, match=r"bag\.mcap: MCAP compressed message by message"):
            decode(bag)
        return
    rec = decode(bag)
    stamps, axes = rosbags_imu(bag, TOPICS[0])
    assert rec.frames.height == len(stamps) == 300
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps)
    ours = rec.frames.select(AXES).to_numpy()
    np.testing.assert_array_equal(ours.view(np.uint64), axes.view(np.uint64))
    assert rec.warnings == []
    assert describe(bag).topics[0].messages == 300


def test_a_compressed_file_that_does_not_inflate_is_one_line(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  compression_format: zstd\n  compression_mode: file\n"
        "  relative_file_paths:\n  - bag_0.db3.zstd\n"
    )
    (bag / "bag_0.db3.zstd").write_bytes(b"not zstd at all")
    with pytest.raises(InputError, match=r"bag_0\.db3\.zstd: cannot decompress it \(zstd: "):
        decode(bag)


def test_a_file_that_would_inflate_past_the_free_disk_is_refused(
    tmp_path: Path, monkeypatch
) -> None:
    """A decompression bomb stops at a share of the temporary directory's free space."""
    _, bag = _compressed_bag(tmp_path / "bag", "SQLITE3", "FILE")
    monkeypatch.setattr(rosbag2, "FREE_DISK_SHARE", 1e-15)
    with pytest.raises(
        InputError, match=r"bag\.db3\.zstd: inflates beyond 0% of the free space of "
    ):
        decode(bag)
    assert not list(Path(tempfile.gettempdir()).glob("imupipe-inflated-*/bag.db3"))


def test_a_message_that_does_not_inflate_is_skipped_and_counted(tmp_path: Path) -> None:
    """Per-message compression: a payload that is no zstd frame is one skipped message."""
    imu, bag = _compressed_bag(tmp_path / "bag", "SQLITE3", "MESSAGE")
    with sqlite3.connect(next(bag.glob("*.db3"))) as db:
        db.execute("UPDATE messages SET data = x'00112233' WHERE id = 10")
    rec = decode(bag)
    stamps, _ = rosbags_imu_values(imu.payloads)
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), np.delete(stamps, 9))
    assert rec.warnings == [
        "1 message(s) skipped unread (larger than the memory budget allows, or no readable "
        "binary payload with an integer timestamp)"
    ]


def test_the_lost_stretches_are_worded_with_their_share_of_the_database() -> None:
    report = db3_scan.Db3Report(last_row=2000)
    report.lost = [(967, 1002, "malformed"), (1500, None, "malformed")]
    assert report.damage() == [
        "database damaged (malformed): messages 968–1002 of 2000 (1.8 %, all topics) could not "
        "be read; read on after them",
        "database damaged (malformed): read up to message 1500; the last 25.0 % of the messages "
        "could not be read",
    ]
    report.last_row = 0  # the last page unreadable: the total is unknown
    assert report.damage()[0] == (
        "database damaged (malformed): messages 968–1002 (all topics) could not be read; read on "
        "after them"
    )


def test_the_progress_of_a_database_read_rises_to_its_size(
    tmp_path: Path, db3_bag: Path, monkeypatch
) -> None:
    """Reported after each full block, in bytes of the file as the share of messages read
    (rowid / the last rowid): never beyond the file, never backwards, the last full block's
    past 80 % of it."""
    monkeypatch.setattr(db3_scan, "FETCH_ROWS", 32)
    monkeypatch.setattr(db3_scan, "BLOCK_ROWS", 128)
    seen: list[int] = []
    decode(db3_bag, topic=TOPICS[1], progress=seen.append)
    size = sum(f.stat().st_size for f in db3_bag.glob("*.db3"))
    assert len(seen) >= 5
    assert seen == sorted(seen) and 0 < seen[0] and seen[-1] <= size
    assert seen[-1] > 0.8 * size


def test_a_database_whose_first_page_of_messages_is_damaged_is_read_after_it(
    tmp_path: Path,
) -> None:
    """Nothing read before the damage is no reason to refuse the rest: reading starts at the
    first readable message after it."""
    db3 = write_rosbag2_db3(tmp_path / "bag", [imu_stream(TOPICS[0], 10.0, 200, seed=4)])
    stamps, _ = rosbags_imu(tmp_path / "bag", TOPICS[0])
    with sqlite3.connect(db3) as db:  # the messages table's first leaf
        (page,) = db.execute(
            "SELECT min(pageno) FROM dbstat WHERE name = 'messages' AND pagetype = 'leaf'"
        ).fetchone()
    with open(db3, "r+b") as f:
        f.seek((page - 1) * 4096)
        f.write(bytes([0xFF]) * 4096)
    rec = decode(db3)
    (warning,) = rec.warnings
    last = int(re.search(r"messages 1–(\d+) of 2000", warning).group(1))
    assert 0 < last < 20  # one page of ~9 messages
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps[last:])
