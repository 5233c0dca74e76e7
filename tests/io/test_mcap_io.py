"""Frame schema, bulk MCAP writer and tolerant scanner: decodable by independent readers, and
damaged files recover what can be recovered."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from imupipe.device.adis16364 import DeviceConfig, FrameBlock
from imupipe.device.frame_schema import (
    decode_frames,
    encode_frames,
    frame_dtype,
)
from imupipe.errors import InputError
from imupipe.io.decode import decode
from imupipe.io.info import describe
from imupipe.io.mcap_scan import NotMcapError
from imupipe.recording.recorder import FrameWriter

T0 = 1_700_000_000_000_000_000


def make_block(n: int, start: int = 0, rng_seed: int = 1) -> FrameBlock:
    rng = np.random.default_rng(rng_seed)
    burst = rng.integers(0, 1 << 16, size=(n, 11), dtype=np.uint16)
    return FrameBlock(
        stamp_ns=T0 + (start + np.arange(n, dtype=np.int64)) * 10_000_000,
        counter=(start + np.arange(n)).astype(np.uint32),
        burst=burst,
        diag_stat=rng.integers(0, 1 << 16, size=n, dtype=np.uint16),
        diag_valid=rng.integers(0, 2, size=n).astype(bool),
    )


def write_file(
    path: Path,
    blocks: list[FrameBlock],
    frame_id: str = "adis16364",
    compression: str = "zstd",
    finish: bool = True,
) -> None:
    with open(path, "wb") as f:
        writer = FrameWriter(f, DeviceConfig(frame_id=frame_id), compression=compression)
        for b in blocks:
            writer.write(b)
        if finish:
            writer.finish()


@pytest.mark.parametrize("frame_id", ["", "a", "adis16364", "imu_link_with_a_long_name"])
def test_cdr_round_trip_any_frame_id(frame_id: str) -> None:
    block = make_block(50)
    raw = encode_frames(block, frame_id)
    assert raw.shape == (50, frame_dtype(frame_id).itemsize)
    back = decode_frames(raw)
    for field in ("stamp_ns", "counter", "burst", "diag_stat", "diag_valid"):
        np.testing.assert_array_equal(getattr(back, field), getattr(block, field))


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_independent_readers_decode_our_frames(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "f.mcap"
    blocks = [make_block(300, 0), make_block(200, 300, rng_seed=2)]
    write_file(path, blocks, compression=compression)
    burst = np.concatenate([b.burst for b in blocks])
    # mcap-ros2-support, through the schema embedded in the file
    with open(path, "rb") as f:
        msgs = [
            m
            for *_, m in make_reader(
                f, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages()
        ]
    assert len(msgs) == 500
    m = msgs[321]
    assert (m.supply_out, m.zgyro_out, m.aux_adc) == tuple(burst[321, [0, 3, 10]])
    assert m.frame_counter == 321 and m.header.frame_id == "adis16364"
    # rosbags AnyReader
    with AnyReader([path]) as reader:
        rows = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert len(rows) == 500
    assert rows[499].xaccl_out == burst[499, 4]
    assert rows[10].diag_stat_valid == bool(blocks[0].diag_valid[10])
    # the mcap library's indexed reader and its summary statistics
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary.statistics.message_count == 500
        assert summary.statistics.chunk_count == 2
        assert summary.statistics.message_start_time == T0
        assert len(list(reader.iter_messages())) == 500


def test_rerun_mcap_check_accepts_file(tmp_path: Path) -> None:
    rerun = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    path = tmp_path / "f.mcap"
    write_file(path, [make_block(100)])
    out = subprocess.run([rerun, "mcap", "check", str(path)], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "ok" in out.stdout


def _decoded_counters(path: Path) -> np.ndarray:
    return decode(path).frames["counter"].to_numpy()


def test_unfinished_file_keeps_every_chunk(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    write_file(path, [make_block(100, i * 100) for i in range(3)], finish=False)
    with pytest.raises(Exception):  # noqa: B017 - the indexed reader gives up
        make_reader(open(path, "rb")).get_summary().statistics  # noqa: B018
    rec = decode(path)
    np.testing.assert_array_equal(rec.frames["counter"].to_numpy(), np.arange(300))
    assert any("no footer" in w for w in rec.warnings)


def test_file_cut_mid_chunk_keeps_complete_chunks(tmp_path: Path) -> None:
    path = tmp_path / "cut.mcap"
    write_file(path, [make_block(100, i * 100) for i in range(3)])
    data = path.read_bytes()
    cut = data[: len(data) * 2 // 3]
    path.write_bytes(cut)
    counters = _decoded_counters(path)
    assert len(counters) in (100, 200)
    np.testing.assert_array_equal(counters, np.arange(len(counters)))
    warnings = describe(path).damage
    assert any("ends mid-record" in w for w in warnings)


def test_a_file_cut_inside_a_record_says_which_record_and_how_many_bytes_were_lost(
    tmp_path: Path,
) -> None:
    """A file cut by the end of the disk keeps every record before the cut, and its warning
    names the record cut (its header, a Message, a Chunk) and the bytes lost, with their share
    of the file; a cut chunk is reported lost with its time range and estimated messages when
    its fixed fields (start, end, size: 24 bytes) survive, as unknown when they do not."""
    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    no_footer = (
        "file has no footer/summary (the writer stopped before finishing): every complete "
        "chunk was read by a linear scan"
    )

    def cut_at(path: Path, at: int) -> tuple[int, list[str]]:
        path.write_bytes(whole[:at])
        rec = decode(path)
        return rec.frames.height, list(rec.warnings)

    def mid_record(kind: str, lost: int, file_bytes: int) -> str:
        return (
            f"file ends mid-record (inside {kind}): the last {lost} bytes "
            f"({100 * lost / file_bytes:.2f} % of the file) could not be read"
        )

    messages = hm.imu_message_records(1, 5)  # unchunked, after the IMU chunk of 3000
    path = hm.imu_file(tmp_path / "m.mcap", extra=(messages,))
    whole = path.read_bytes()
    third = whole.index(messages) + 2 * len(messages) // 5
    assert cut_at(path, third + 1) == (
        3002,
        [mid_record("a record header", 1, third + 1), no_footer],
    )
    assert cut_at(path, third + 30) == (
        3002,
        [mid_record("a message record", 30, third + 30), no_footer],
    )

    span = (hm.T0_NS + 30 * 10**9, hm.T0_NS + 30_390_000_000)  # 40 messages at 100 Hz
    chunk = hm.chunk(hm.imu_message_records(1, 40), "", start_ns=span[0], end_ns=span[1])
    path = hm.imu_file(tmp_path / "c.mcap", extra=(chunk,))
    whole = path.read_bytes()
    body = whole.index(chunk) + 9
    cut = "a chunk was lost (cut off by the end of the file)"
    known = f"{cut}: about 40 messages whose log times span 0.390 s"
    for at, lost in ((body + 23, f"{cut}; its size and time range are unknown"),
                     (body + 24, known),
                     (body + len(chunk) - 10, known)):  # fmt: skip
        assert cut_at(path, at) == (
            3000,
            [lost, mid_record("a chunk record", at - (body - 9), at), no_footer],
        )


def test_bad_crc_chunk_is_skipped_and_reported(tmp_path: Path) -> None:
    path = tmp_path / "crc.mcap"
    write_file(path, [make_block(100, i * 100) for i in range(3)], compression="")
    data = bytearray(path.read_bytes())
    # flip a byte inside the middle chunk's payloads (uncompressed, so it decodes but fails CRC)
    middle = len(data) // 2
    data[middle] ^= 0xFF
    path.write_bytes(bytes(data))
    rec = decode(path)
    assert any("CRC mismatch" in w for w in rec.warnings)
    assert rec.frames.height == 200


def test_not_mcap_and_empty_are_input_errors(tmp_path: Path) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("hello\n")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(NotMcapError):
        decode(text)
    with pytest.raises(InputError, match="empty"):
        decode(empty)
    with pytest.raises(InputError, match="not a file"):
        decode(tmp_path / "missing.mcap")
    (tmp_path / "bag").mkdir()
    with pytest.raises(InputError, match=r"without MCAP or \.db3 files"):
        decode(tmp_path / "bag")


def test_unreadable_records_are_skipped_and_counted_per_kind(tmp_path: Path) -> None:
    """Records whose fields do not parse (two Metadata, one Channel after the data) are skipped
    and counted per kind in the warnings; every message is still read."""
    from mcap.records import Opcode

    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    bad = (
        hm.record(Opcode.METADATA, b"\xff\xff\xff\xff"),
        hm.record(Opcode.METADATA, b"\x05"),
        hm.record(Opcode.CHANNEL, b"\x01\x00\xff\xff\xff\xff"),
    )
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=bad))
    assert rec.frames.height == 3000
    assert list(rec.warnings) == [
        "skipped 2 unreadable metadata record(s)",
        "skipped 1 unreadable channel record(s)",
    ]


def test_a_malformed_message_outside_chunks_is_skipped_and_the_next_ones_read(
    tmp_path: Path,
) -> None:
    """Unchunked Message records are read in blocks; a malformed one (a 1-byte body) opening a
    block is counted and skipped, and the five good ones after it are read from where it ends."""
    from mcap.records import Opcode

    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    extra = (hm.record(Opcode.MESSAGE, b"\x01"), hm.imu_message_records(1, 5))
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=extra))
    assert rec.frames.height == 3005
    assert list(rec.warnings) == ["skipped 1 unreadable message record(s)"]


def test_a_chunk_with_as_many_malformed_as_good_messages_reads_the_good_and_counts_the_rest(
    tmp_path: Path,
) -> None:
    """A chunk whose IMU messages are half well-formed, half cut short (2 and 2): the two good
    ones are decoded and the two others counted in the malformed warning."""
    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    good = hm.imu_message_records(1, 4)
    one = len(good) // 4
    records = [good[k * one : (k + 1) * one] for k in range(4)]
    for k in (1, 3):  # the payload's last 8 bytes dropped, the record's length with them
        body = records[k][9:-8]
        records[k] = hm.record(0x05, body)
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=(hm.chunk(b"".join(records)),)))
    assert rec.frames.height == 3002
    assert list(rec.warnings) == [
        "/imu/data: 2 malformed messages (size does not match the schema) skipped"
    ]


def _channel_record(channel_id: int, topic: str) -> bytes:
    """A well-formed Channel record (MCAP spec: id u16, schema_id u16, topic, encoding, an
    empty metadata map)."""
    import struct

    from mcap.records import Opcode

    from imupipe.testing import hostile_mcap as hm

    text = b"".join(struct.pack("<I", len(s)) + s for s in (topic.encode(), b"cdr"))
    return hm.record(Opcode.CHANNEL, struct.pack("<HH", channel_id, 1) + text + b"\0\0\0\0")


def test_a_topics_frame_id_is_that_of_its_first_well_formed_message(tmp_path: Path) -> None:
    """An Imu topic whose first chunk holds only malformed messages (cut short, their
    frame_id "bad_link" intact) takes its frame_id from the first well-formed message, in the
    next chunk; the malformed ones are counted."""
    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm
    from imupipe.testing.ros_cdr import imu_payloads

    log = hm.T0_NS + np.arange(3000, 3002) * 10_000_000
    bad = imu_payloads(log, np.zeros((2, 3)), np.zeros((2, 3)), frame_id="bad_link")[:, :-8]
    cut = b"".join(hm.message(2, int(t), p.tobytes()) for t, p in zip(log, bad, strict=True))
    good = hm.imu_message_records(2, 5, first=3002)
    extra = (_channel_record(2, "/imu/b"), hm.chunk(cut), hm.chunk(good))
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=extra), topic="/imu/b")
    assert rec.frames.height == 5 and rec.frame_ids == ("imu",)
    assert list(rec.warnings) == [
        "/imu/b: 2 malformed messages (size does not match the schema) skipped"
    ]


def test_the_highest_channel_id_65535_is_listed_and_decoded(tmp_path: Path) -> None:
    """Channel ids are u16 (MCAP spec): a channel 65535 declared after the first IMU topic is
    counted by ``imupipe info`` and decoded like channel 1."""
    from imupipe.io.decode import decode
    from imupipe.io.info import describe
    from imupipe.testing import hostile_mcap as hm

    extra = (_channel_record(65535, "/imu/far"), hm.chunk(hm.imu_message_records(65535, 7)))
    path = hm.imu_file(tmp_path / "x.mcap", extra=extra)
    counts = {t.topic: t.messages for t in describe(path).topics}
    assert counts == {"/imu/data": 3000, "/imu/far": 7}
    rec = decode(path, topic="/imu/far")
    assert rec.frames.height == 7 and list(rec.warnings) == []


def test_a_chunk_may_end_with_a_channel_record(tmp_path: Path) -> None:
    """A record that ends exactly at the chunk's end is whole: the five messages before it
    are read and nothing is reported lost."""
    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    records = hm.imu_message_records(1, 5) + _channel_record(7, "/other")
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=(hm.chunk(records),)))
    assert rec.frames.height == 3005
    assert list(rec.warnings) == []


def test_a_record_running_past_its_chunk_stops_the_chunk_with_a_warning(tmp_path: Path) -> None:
    """A Channel record whose length runs past the chunk's end is not parsed: the messages
    before it are kept and the rest of the chunk is reported lost, with the byte it starts at."""
    import struct

    from mcap.records import Opcode

    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    messages = hm.imu_message_records(1, 5)
    records = messages + struct.pack("<BQ", Opcode.CHANNEL, 10_000) + bytes(40)
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=(hm.chunk(records),)))
    assert rec.frames.height == 3005
    assert len(rec.warnings) == 1
    assert f"malformed record at byte {len(messages)} of the chunk" in rec.warnings[0]


def test_a_chunk_inside_a_chunk_between_messages_is_counted_and_the_walk_goes_on(
    tmp_path: Path,
) -> None:
    """A nested chunk after a chunk's first messages is counted, never unpacked, and the
    messages after it are read: neither taken for a malformed record nor for a Channel."""
    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    inner = hm.chunk(hm.imu_message_records(1, 50), "none")
    records = hm.imu_message_records(1, 5) + inner + hm.imu_message_records(1, 7, first=3005)
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=(hm.chunk(records),)))
    assert rec.frames.height == 3012
    assert list(rec.warnings) == ["skipped 1 unreadable nested chunk record(s)"]
    # a private record (opcodes 0x80-0xFF: readers ignore them, MCAP spec) is no nested chunk
    private = hm.record(0x80, b"vendor data")
    records = hm.imu_message_records(1, 5) + private + hm.imu_message_records(1, 7, first=3005)
    rec = decode(hm.imu_file(tmp_path / "y.mcap", extra=(hm.chunk(records),)))
    assert rec.frames.height == 3012
    assert list(rec.warnings) == []


def test_a_header_or_footer_record_inside_a_chunk_is_skipped_not_taken_for_a_nested_chunk(
    tmp_path: Path,
) -> None:
    """A chunk holds Schema, Channel and Message records (MCAP spec); a Header or a Footer
    record among its messages (opcodes 0x01, 0x02: below Chunk's 0x06) is skipped like any
    record a chunk may not hold, without a warning, and the messages after it are read."""
    import struct

    from mcap.records import Opcode

    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    header = hm.record(Opcode.HEADER, struct.pack("<I", 4) + b"ros2" + struct.pack("<I", 0))
    footer = hm.record(Opcode.FOOTER, bytes(8 + 8 + 4))
    for stray in (header, footer):
        records = hm.imu_message_records(1, 5) + stray + hm.imu_message_records(1, 7, first=3005)
        rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=(hm.chunk(records),)))
        assert rec.frames.height == 3012
        assert list(rec.warnings) == []


def test_a_tiny_memory_budget_still_reads_chunks_up_to_64_mib(tmp_path: Path) -> None:
    """A chunk of up to 64 MiB is always inflated (writers make ~1 MB chunks; a tiny budget
    asks for the low-memory path, not for refusing data); a larger one under a tiny budget is
    skipped unread, with a warning naming its size.  Above 1 GiB of budget, 1/16 of it."""
    from imupipe.io.decode import decode
    from imupipe.io.mcap_scan import chunk_limit
    from imupipe.testing import hostile_mcap as hm

    limit = chunk_limit(0)
    assert limit == 64 << 20 == chunk_limit(16 * (64 << 20))
    assert chunk_limit(16 * (65 << 20)) == 65 << 20
    extra = (hm.bomb_chunk(limit), hm.bomb_chunk(limit + 1))
    rec = decode(hm.imu_file(tmp_path / "x.mcap", extra=extra), max_chunk_bytes=limit)
    assert rec.frames.height == 3000
    skipped = [w for w in rec.warnings if "skipped unread" in w]
    assert len(skipped) == 1 and f"it declares {limit + 1} bytes uncompressed" in skipped[0]


def test_info_shows_a_long_or_multiline_metadata_value_by_its_first_line_and_length() -> None:
    """rosbag2's serialized_metadata (every ROS 2 bag's metadata.yaml, ~1 KB) is one line of
    ``imupipe info``, not a kilobyte of escaped YAML; short values are shown whole."""
    from imupipe.io.info import METADATA_SHOWN, RecordingInfo

    yaml_text = "compression_format: ''\ncompression_mode: ''\n" + "x: 1\n" * 200
    long_line = "a" * (METADATA_SHOWN + 1)
    meta = {
        "rosbag2": {"serialized_metadata": yaml_text},
        "adis16364": {"serial": "42", "note": long_line, "exact": "b" * METADATA_SHOWN},
    }
    lines = RecordingInfo(Path("bag"), 10, 1, [], meta).lines()
    assert lines[1:] == [
        f"  metadata rosbag2: serialized_metadata=compression_format: '' … ({len(yaml_text)} "
        "characters)",
        f"  metadata adis16364: serial=42, note={'a' * METADATA_SHOWN} … "
        f"({METADATA_SHOWN + 1} characters), exact={'b' * METADATA_SHOWN}",
    ]


def test_a_chunk_whose_opcode_is_damaged_is_counted_lost_from_the_summary(tmp_path: Path) -> None:
    """A flipped bit turning a Chunk record (0x06) into a MessageIndex (0x07) makes the scan
    skip it as a record it need not read; only the file's Statistics record shows the loss, and
    the warning gives it to the message."""
    from mcap.records import Opcode

    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    extra = (hm.chunk(hm.imu_message_records(1, 40), ""),)
    path = hm.imu_file(tmp_path / "x.mcap", extra=extra)
    data = bytearray(path.read_bytes())
    at = data.index(extra[0])
    assert data[at] == Opcode.CHUNK
    data[at] ^= 1
    path.write_bytes(bytes(data))
    rec = decode(path)
    assert rec.frames.height == 3000
    assert rec.warnings == [
        "/imu/data: 3000 of the 3040 messages the file's summary counts were read (40 lost)"
    ]


def test_a_message_whose_channel_is_damaged_is_counted_lost(tmp_path: Path) -> None:
    """An unchunked Message record whose channel id was damaged belongs to no channel: it is
    not read, and the summary's count says one message is missing."""
    from imupipe.io.decode import decode
    from imupipe.testing import hostile_mcap as hm

    extra = (hm.imu_message_records(1, 3),)
    path = hm.imu_file(tmp_path / "x.mcap", extra=extra)
    data = bytearray(path.read_bytes())
    at = data.index(extra[0]) + 9  # the first message's channel id
    data[at : at + 2] = b"\xff\xff"
    path.write_bytes(bytes(data))
    rec = decode(path)
    assert rec.frames.height == 3002
    assert rec.warnings == [
        "/imu/data: 3002 of the 3003 messages the file's summary counts were read (1 lost)"
    ]


def test_more_messages_than_the_summary_counts_are_read_and_warned_about(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Messages the summary does not count (records repeated, or appended after it was
    written) are read, and the warning says how many more there are."""
    from imupipe.io.decode import decode
    from imupipe.io.mcap_bulk import BulkWriter
    from imupipe.testing import hostile_mcap as hm

    count = BulkWriter.count_messages
    monkeypatch.setattr(  # a summary that misses two of the five raw messages
        BulkWriter, "count_messages", lambda self, cid, n: count(self, cid, n - 2)
    )
    path = hm.imu_file(tmp_path / "x.mcap", extra=(hm.imu_message_records(1, 5),))
    rec = decode(path)
    assert rec.frames.height == 3005
    assert rec.warnings == [
        "/imu/data: 3005 messages read, 2 more than the file's summary counts (3003): records "
        "repeated, or a summary written before the end"
    ]


def test_our_writers_summary_indexes_and_footer_agree_with_its_data(tmp_path: Path) -> None:
    """What the bulk writer puts in the summary section is what its data section holds, read
    back with the mcap library's stream reader and checked against the MCAP spec field by field:
    schema and channel ids from 1, each chunk's MessageIndex pairs (log time, offset) pointing
    at that very Message record in the decompressed chunk, sequence 0 when none is given, the
    Statistics' counts per channel (chunks and raw records the caller counted), no
    attachments, and the footer's summary CRC over the summary section and the footer's own
    fields up to ``summary_offset_start`` ("Footer", MCAP spec)."""
    import struct
    import zlib

    import zstandard
    from mcap.records import Chunk, Footer, MessageIndex, Statistics
    from mcap.stream_reader import StreamReader

    from imupipe.io.mcap_bulk import BulkWriter

    path = tmp_path / "ours.mcap"
    stamps = [T0 + np.arange(k, dtype=np.int64) * 7 + 1000 * k for k in (5, 3, 4)]
    with open(path, "wb") as f:
        w = BulkWriter(f, compression="zstd", profile="ros2")
        assert [w.register_schema(n, "ros2msg", b"") for n in ("a/msg/A", "b/msg/B")] == [1, 2]
        topics = (("/a", 1), ("/b", 2), ("/c", 2))
        assert [w.register_channel(t, "cdr", s) for t, s in topics] == [1, 2, 3]
        for cid, t in zip((1, 2, 1), stamps, strict=True):
            payloads = np.full((len(t), 3 + cid), cid, np.uint8)
            w.write_chunk(cid, t, payloads)
        raw = struct.pack("<HIQQ", 3, 9, T0, T0) + b"xy"  # a raw Message the caller writes
        f.write(struct.pack("<BQ", 0x05, len(raw)) + raw)
        w.count_messages(3, 1)
        w.finish()
    with open(path, "rb") as f:
        records = list(StreamReader(f, emit_chunks=True, validate_crcs=True).records)
    chunks = [r for r in records if isinstance(r, Chunk)]
    indexes = [r for r in records if isinstance(r, MessageIndex)]
    assert [i.channel_id for i in indexes] == [1, 2, 1]
    for chunk, index, t in zip(chunks, indexes, stamps, strict=True):
        body = zstandard.ZstdDecompressor().decompress(chunk.data, chunk.uncompressed_size)
        assert [time for time, _ in index.records] == t.tolist()
        for time, offset in index.records:
            opcode, _, channel, sequence, log_time = struct.unpack_from("<BQHIQ", body, offset)
            assert (opcode, channel, sequence, log_time) == (0x05, index.channel_id, 0, time)
    (stats,) = [r for r in records if isinstance(r, Statistics)]
    assert stats.channel_message_counts == {1: 9, 2: 3, 3: 1} and stats.message_count == 13
    assert (stats.schema_count, stats.channel_count, stats.chunk_count) == (2, 3, 3)
    assert (stats.attachment_count, stats.metadata_count) == (0, 0)
    (footer,) = [r for r in records if isinstance(r, Footer)]
    data = path.read_bytes()
    footer_at = len(data) - 8 - (1 + 8 + 8 + 8 + 4)  # before the closing magic
    assert data[footer_at : footer_at + 9] == struct.pack("<BQ", 0x02, 8 + 8 + 4)
    covered = data[footer.summary_start : footer_at + 1 + 8 + 8 + 8]
    assert zlib.crc32(covered) == footer.summary_crc
