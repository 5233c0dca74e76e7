"""The compiled rows of wanted CDR messages (:func:`imupipe.io.mcap_walk.cdr_rows`): each
well-formed message's header and fields copied exactly, malformed ones counted, channels
unknown to a chunk read ahead left for later, declarations repeated by a summary harmless."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
from numba.core.registry import CPUDispatcher

from imupipe.io.mcap_walk import SKIPPED, CdrLayout, CdrTable, cdr_rows, index_messages
from imupipe.testing.ros_cdr import temperature_payloads

TEMPERATURE = CdrLayout(8, 16, ((0, 8),))  # sensor_msgs/msg/Temperature: the °C value


def message(channel: int, log_time: int, payload: bytes) -> bytes:
    """An MCAP Message record (opcode 0x05, u64 length, channel u16, sequence u32, log and
    publish time u64, data)."""
    body = struct.pack("<HIQQ", channel, 0, log_time, log_time) + payload
    return struct.pack("<BQ", 0x05, len(body)) + body


def temperatures(celsius: list[float], frame_id: str) -> list[bytes]:
    stamps = np.arange(len(celsius), dtype=np.int64) * 1_000_000_000 + 7
    return [row.tobytes() for row in temperature_payloads(stamps, np.array(celsius), frame_id)]


def test_rows_hold_each_wanted_message_exactly_and_stop_at_an_unknown_channel() -> None:
    wanted = temperatures([20.5, -0.0], "imu") + temperatures([1e-310], "a_longer_frame")
    other = temperatures([99.0], "x")[0]
    records = [
        message(1, 10, wanted[0]),
        message(2, 11, other),  # skipped channel
        message(1, 12, wanted[1][:-3]),  # cut short: malformed for the layout
        message(1, 13, wanted[1]),
        message(3, 14, other),  # channel 3 not declared yet
        message(1, 15, wanted[2]),
    ]
    buf = np.frombuffer(b"".join(records), np.uint8)
    index = index_messages(buf)
    table = CdrTable()
    table.set(1, TEMPERATURE)
    table.set(2, None)
    ahead = cdr_rows(buf, index, table, stop_at_unknown=True)
    assert ahead.used == 4 and ahead.good.tolist() == [2] and ahead.bad.tolist() == [1]
    assert ahead.first.tolist() == [0]
    np.testing.assert_array_equal(ahead.log_time[0], [10, 13])
    celsius = ahead.rows[0][:, 16:24].copy().view("<f8")[:, 0]
    assert celsius.view(np.uint64).tolist() == np.array([20.5, -0.0]).view(np.uint64).tolist()
    np.testing.assert_array_equal(
        ahead.rows[0][:, :16], [list(wanted[0][:16]), list(wanted[1][:16])]
    )

    now = cdr_rows(buf, index, table, stop_at_unknown=False)  # channel 3: skipped now
    assert now.used == 6 and now.good.tolist() == [3] and now.bad.tolist() == [1]
    last = now.rows[0][2, 16:24].copy().view("<f8")[0]
    assert last == 1e-310  # the fields after a 15-byte frame_id, aligned to 8


def test_a_repeated_declaration_keeps_its_slot_and_a_changed_one_is_reported() -> None:
    """``set``'s return (whether a declaration changed) and the slots: a declaration repeated
    (a summary's Channel records), also with an equal layout built anew, keeps its slot and is
    no change; another layout or none is one."""
    table = CdrTable()
    assert table.set(4, TEMPERATURE) is False  # first declaration
    assert table.set(4, TEMPERATURE) is False and table.layouts == [TEMPERATURE]  # summary
    assert table.set(4, CdrLayout(8, 16, ((0, 8),))) is False  # equal, not the same object
    assert table.layouts == [TEMPERATURE] and table.slot_of[4] == 0
    other = CdrLayout(8, 24, ((8, 8),))
    assert table.set(4, other) is True and table.slot_of[4] == 1
    assert table.set(4, None) is True and table.slot_of[4] == SKIPPED
    assert table.set(5, None) is False and table.set(5, None) is False
    snapshot = table.copy()
    table.set(6, TEMPERATURE)
    assert snapshot.slot_of[6] != table.slot_of[6] and len(snapshot.layouts) == 2


def test_frame_ids_of_every_length_byte_and_a_foreign_header_among_good_messages() -> None:
    """The frame_id's u32 length is read from all four bytes (frame_ids of 300, 70 000 and
    2²⁴ + 2 characters: the fields after each are found), and a message that is not
    little-endian plain CDR (encapsulation ``00 00``, big-endian) is counted malformed without
    ending the rows of its channel: the messages after it are read."""
    lengths = [3, 300, 70_000, (1 << 24) + 2]
    payloads = [temperatures([float(k) + 0.25], "f" * n)[0] for k, n in enumerate(lengths)]
    foreign = bytearray(payloads[0])
    foreign[1] = 0  # big-endian CDR: not what ROS 2 writes, not read
    records = [message(1, 10 + k, p) for k, p in enumerate(payloads)]
    records.insert(1, message(1, 9, bytes(foreign)))
    buf = np.frombuffer(b"".join(records), np.uint8)
    table = CdrTable()
    table.set(1, TEMPERATURE)
    rows = cdr_rows(buf, index_messages(buf), table, stop_at_unknown=False)
    assert rows.good.tolist() == [4] and rows.bad.tolist() == [1]
    np.testing.assert_array_equal(rows.log_time[0], [10, 11, 12, 13])
    celsius = rows.rows[0][:, 16:24].copy().view("<f8")[:, 0]
    assert celsius.tolist() == [0.25, 1.25, 2.25, 3.25]


def _string(text: str) -> bytes:
    return struct.pack("<I", len(text)) + text.encode()


def test_a_channel_declared_again_after_a_chunk_was_read_ahead_reads_that_chunk_anew(
    tmp_path,
) -> None:
    """A channel declared with the Temperature layout, then again as a topic that is not read,
    just before a chunk of its messages: the chunk was read ahead (its rows made) while the
    first declaration held, and its messages are skipped all the same when it is reached; the
    chunk before the new declaration is read whole."""
    from imupipe.io.mcap_scan import MAGIC, McapScanner
    from imupipe.testing import hostile_mcap as hm

    def channel(topic: str) -> bytes:  # id 1, schema 0 (none), cdr, no metadata
        body = struct.pack("<HH", 1, 0) + _string(topic) + _string("cdr") + bytes(4)
        return hm.record(0x04, body)

    def chunk_of(celsius: list[float], first_ns: int) -> bytes:
        payloads = temperatures(celsius, "imu")
        return hm.chunk(b"".join(message(1, first_ns + k, p) for k, p in enumerate(payloads)))

    # 3 Metadata records: the redeclaration is parsed only after the chunk following it was
    # read ahead (4 records ahead), and the first declaration before that chunk was
    pad = [hm.record(0x0C, _string(f"pad{k}") + bytes(4)) for k in range(3)]
    records = [channel("/t"), chunk_of([20.5, 21.5], 100), *pad, channel("/x")]
    records.append(chunk_of([30.5, 31.5, 32.5], 200))
    path = tmp_path / "redeclared.mcap"
    path.write_bytes(MAGIC + b"".join(records))

    def layout(channel, schema) -> CdrLayout | None:
        return TEMPERATURE if channel.topic == "/t" else None

    scanner = McapScanner(path)
    read = [(b.log_time.tolist(), b.rows[:, 16:24].copy().view("<f8")[:, 0].tolist())
            for b in scanner.cdr_batches(layout)]  # fmt: skip
    assert read == [([100, 101], [20.5, 21.5])]
    assert scanner.report.chunks == 2 and scanner.report.read_counts == {1: 2}


def test_a_message_with_no_data_among_good_ones_loses_nothing(tmp_path: Path) -> None:
    """A Message record with empty data (its length exactly the fixed fields: e.g. an empty
    protobuf message) between two temperatures, on a topic not read: both °C values and their
    log times are read, no chunk is reported lost (the walk goes on past it)."""
    from imupipe.io.mcap_scan import MAGIC, McapScanner
    from imupipe.testing import hostile_mcap as hm

    def channel(cid: int, topic: str) -> bytes:  # schema 0 (none), cdr, no metadata
        body = struct.pack("<HH", cid, 0) + _string(topic) + _string("cdr") + bytes(4)
        return hm.record(0x04, body)

    good = temperatures([20.5, 21.5], "imu")
    messages = [message(1, 100, good[0]), message(2, 101, b""), message(1, 102, good[1])]
    path = tmp_path / "empty_message.mcap"
    path.write_bytes(MAGIC + channel(1, "/t") + channel(2, "/e") + hm.chunk(b"".join(messages)))
    scanner = McapScanner(path)
    batches = scanner.cdr_batches(lambda c, s: TEMPERATURE if c.topic == "/t" else None)
    read = [(b.log_time.tolist(), b.rows[:, 16:24].copy().view("<f8")[:, 0].tolist())
            for b in batches]  # fmt: skip
    assert read == [([100, 102], [20.5, 21.5])]
    assert scanner.report.bad_chunks == [] and scanner.report.message_records == 3
    index = index_messages(np.frombuffer(b"".join(messages), np.uint8))
    assert index.size.tolist() == [len(good[0]), 0, len(good[1])]


def test_the_walk_and_rows_are_compiled_kernels_that_release_the_gil() -> None:
    """How fast a bag is read: each kernel of the walk is numba-compiled and releases the GIL
    (the rows are made on the scanner's unpack thread beside the decompression).  Without its
    decorator ``_fill_rows`` makes the same rows as Python, ~2000x slower (20 000 temperatures:
    1.4 s instead of 0.7 ms) and holding the GIL: no value differs, only this can tell."""
    import imupipe.io.mcap_walk as walk

    kernels = [walk._walk, walk._copy, walk._gather, walk._count_slots, walk._fill_rows]
    assert all(isinstance(k, CPUDispatcher) for k in kernels)
    assert all(k.targetoptions["nogil"] for k in kernels)
