"""Bags as robots record them (issue 10): IMU messages interleaved one by one with other topics,
several IMU channels, a frame_id whose length changes per message, written by OTHER libraries
(the mcap library's Writer, rosbags' rosbag2 writer), lz4/zstd/none, chunked and unchunked.

The decoded values must equal rosbags' deserialisation of the same file BIT FOR BIT (NaN
payloads, -0.0, subnormals included): the reference reads the file with the mcap library's
reader and decodes each message with rosbags' CDR deserialiser, neither of them our code.
"""

from __future__ import annotations

import io
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.typesys import get_types_from_msg

import imupipe
from imupipe.device import adis16364 as adis
from imupipe.device.frame_schema import METADATA_NAME, SCHEMA_NAME, message_definition
from imupipe.errors import ImupipeError
from imupipe.io.decode import IMU_SCHEMA, decode
from imupipe.io.mcap_scan import McapScanner
from imupipe.testing.busy_bag import (
    AWKWARD,
    TWO_IMU_TOPICS,
    TYPESTORE,
    adis_stream,
    imu_stream,
    other_streams,
    rosbags_imu_values,
    two_imu_streams,
    write_bag,
    write_rosbag2,
)
from imupipe.units import RAD_PER_DEG
from imupipe.vocab import AXES

TOPICS = TWO_IMU_TOPICS
SECONDS = 1.5


def rosbags_imu(path: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """(stamps ns int64, (n, 6) gyro+accel float64) of ``topic`` as rosbags decodes them."""
    with open(path, "rb") as f:
        messages = make_reader(f).iter_messages(topics=[topic])
        return rosbags_imu_values(message.data for _, _, message in messages)


def longest_run(path: Path) -> int:
    """The longest run of consecutive messages of one channel in the file."""
    with open(path, "rb") as f:
        channels = [m.channel_id for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    cuts = np.flatnonzero(np.diff(channels)) + 1
    return int(np.diff([0, *cuts.tolist(), len(channels)]).max())


def assert_bits_equal(ours: np.ndarray, reference: np.ndarray) -> None:
    assert ours.shape == reference.shape
    np.testing.assert_array_equal(ours.view(np.uint64), reference.view(np.uint64))


@pytest.fixture(scope="module")
def streams():
    return two_imu_streams(SECONDS)


@pytest.mark.parametrize("chunked", [True, False], ids=["chunked", "unchunked"])
@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_interleaved_imu_equals_rosbags_bit_for_bit(
    tmp_path: Path, streams, compression: str, chunked: bool
) -> None:
    path = tmp_path / "busy.mcap"
    # chunks of 16 kB: ~25 chunks, a camera image alone fills one
    write_bag(path, streams, compression if chunked else "", chunked, chunk_size=16_000)
    assert longest_run(path) <= 2  # runs of one: the IMUs alternate with each other and /tf
    for topic in TOPICS:
        rec = decode(path, topic=topic)
        stamps, axes = rosbags_imu(path, topic)
        assert rec.frames.height == len(stamps) > 0 and not rec.warnings
        np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps)
        assert_bits_equal(rec.frames.select(AXES).to_numpy(), axes)
        assert np.isin(AWKWARD.view(np.uint64), axes.view(np.uint64)).all()  # all were read
        # the sibling temperature (10 Hz, 25 °C ± 0.1) interpolated on the IMU stamps
        assert abs(rec.frames["temp_c"].mean() - 25) < 0.2


def test_sizes_vary_and_batches_are_exact(tmp_path: Path, streams) -> None:
    """The fixture really varies the payload size (every frame_id of FRAME_IDS, CDR padding
    0-7 bytes), and the scanner's batches give each message's bytes exactly."""
    path = tmp_path / "busy.mcap"
    write_bag(path, streams, "lz4", chunk_size=16_000)
    with open(path, "rb") as f:
        reference = [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]
    scanner = McapScanner(path)
    ours = []
    for batch in scanner.batches():
        topic = scanner.report.channels[batch.channel_id].topic
        for t, o, s in zip(batch.log_time, batch.offset, batch.size, strict=True):
            ours.append((topic, int(t), batch.data[o : o + s].tobytes()))
    assert sorted(ours) == sorted(reference)
    sizes = {len(d) for topic, _, d in reference if topic == TOPICS[0]}
    # header 16 bytes + frame_id "", "ab", "imu" (+3, 1, 0 bytes of padding), "imu_link",
    # "base_imu_link_", the 30-character one, then the 296 bytes of the fields after it
    assert sizes == {316, 324, 332, 348}
    channels = scanner.report.channels
    from_runs = [
        (channels[run.channel_id].topic, int(t), p.tobytes())
        for run in McapScanner(path).runs()
        for t, p in zip(run.log_time, run.payloads, strict=True)
    ]
    assert sorted(from_runs) == sorted(reference)


def test_channel_registered_mid_chunk(tmp_path: Path) -> None:
    """A Channel record between Message records of a chunk (a topic that appears later) is
    parsed where it stands and the walk resumes after it."""
    imu0, imu1 = (imu_stream(t, 0.5, 200, seed=k) for k, t in enumerate(TOPICS))
    buf = io.BytesIO()
    w = Writer(buf, chunk_size=1 << 20)
    w.start(profile="ros2", library="test")
    text = TYPESTORE.generate_msgdef(IMU_SCHEMA, ros_version=2)[0].encode()
    sid = w.register_schema(IMU_SCHEMA, "ros2msg", text)
    first = w.register_channel(TOPICS[0], "cdr", sid)
    for i in range(50):
        w.add_message(first, int(imu0.log_time[i]), imu0.payloads[i], int(imu0.log_time[i]))
    second = w.register_channel(TOPICS[1], "cdr", sid)
    for i in range(50, 100):
        for cid, s in ((first, imu0), (second, imu1)):
            w.add_message(cid, int(s.log_time[i]), s.payloads[i], int(s.log_time[i]))
    w.finish()
    path = tmp_path / "late.mcap"
    path.write_bytes(buf.getvalue())
    scanner = McapScanner(path)
    counts = {}
    for batch in scanner.batches():
        counts[batch.channel_id] = counts.get(batch.channel_id, 0) + len(batch)
    assert scanner.report.chunks == 1 and counts == {first: 100, second: 50}
    for topic in TOPICS:
        stamps, axes = rosbags_imu(path, topic)
        rec = decode(path, topic=topic)
        np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps)
        assert_bits_equal(rec.frames.select(AXES).to_numpy(), axes)


@pytest.mark.parametrize("compression", ["zstd", ""])
def test_interleaved_adis_frames_equal_rosbags(tmp_path: Path, compression: str) -> None:
    """Our ADIS16364 frames interleaved 1:1 with /tf, frame_id varying: stamps, counters and
    DIAG_STAT as rosbags reads them (from the schema text in the file), and the axes are those
    words in SI units."""
    frames = adis_stream(TOPICS[0], 3.0, 100, seed=4)
    tf = other_streams(3.0, camera=False, seed=5)[0]
    device = adis.DeviceConfig()
    path = tmp_path / "adis.mcap"
    meta = {METADATA_NAME: device.to_metadata()}
    write_bag(path, [frames, tf], compression, chunk_size=8_000, metadata=meta)
    assert longest_run(path) <= 2
    TYPESTORE.register(get_types_from_msg(message_definition(), SCHEMA_NAME))
    with open(path, "rb") as file:
        messages = make_reader(file).iter_messages(topics=[TOPICS[0]])
        ref = [TYPESTORE.deserialize_cdr(m.data, SCHEMA_NAME) for _, _, m in messages]
    f = decode(path).frames
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in ref]
    np.testing.assert_array_equal(f["stamp_ns"].to_numpy(), stamps)
    np.testing.assert_array_equal(f["counter"].to_numpy(), [m.frame_counter for m in ref])
    np.testing.assert_array_equal(f["diag_stat"].to_numpy(), [m.diag_stat for m in ref])
    fields = [word.lower() for word in adis.BURST_WORDS]  # the .msg names the registers
    words = np.array([[getattr(m, w) for w in fields] for m in ref], np.uint16)
    counts, new_data, _ = adis.decode_burst(words)
    gyro_scale = device.gyro_scale_dps * RAD_PER_DEG
    np.testing.assert_array_equal(f["gyro_x"].to_numpy(), counts[1] * gyro_scale)
    np.testing.assert_array_equal(f["flag_nd"].to_numpy(), new_data)


def test_rosbags_writer_bag(tmp_path: Path, streams) -> None:
    """The same topics written by rosbags' rosbag2 MCAP writer (its own chunking), read as the
    rosbag2 directory."""
    bag = tmp_path / "bag"
    with Rosbag2Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = [
            writer.add_connection(s.topic, s.msgtype, typestore=TYPESTORE) for s in streams
        ]
        arrivals = sorted(
            (t, k, i) for k, s in enumerate(streams) for i, t in enumerate(s.log_time.tolist())
        )
        for t, k, i in arrivals:
            writer.write(connections[k], t, streams[k].payloads[i])
    path = next(bag.glob("*.mcap"))
    assert longest_run(path) <= 2
    for topic in TOPICS:
        rec = decode(bag, topic=topic)
        stamps, axes = rosbags_imu(path, topic)
        np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps)
        assert_bits_equal(rec.frames.select(AXES).to_numpy(), axes)


def test_unchunked_messages_between_other_records(tmp_path: Path) -> None:
    """Top-level Message records (an unchunked file) read in blocks: stretches of messages
    broken by attachments, the blocks growing and shrinking, every message read once."""
    imu = imu_stream(TOPICS[0], 2.0, 200, seed=3)
    buf = io.BytesIO()
    w = Writer(buf, use_chunking=False)
    w.start(profile="ros2", library="test")
    text = TYPESTORE.generate_msgdef(IMU_SCHEMA, ros_version=2)[0].encode()
    cid = w.register_channel(TOPICS[0], "cdr", w.register_schema(IMU_SCHEMA, "ros2msg", text))
    for i, t in enumerate(imu.log_time.tolist()):
        w.add_message(cid, t, imu.payloads[i], t)
        if i % 97 in (0, 1, 5):  # stretches of 1, 4 and 92 messages
            w.add_attachment(create_time=t, log_time=t, name="a", media_type="x", data=b"z" * i)
    w.finish()
    path = tmp_path / "unchunked.mcap"
    path.write_bytes(buf.getvalue())
    rec = decode(path)
    stamps, axes = rosbags_imu(path, TOPICS[0])
    assert rec.frames.height == len(imu.log_time) == len(stamps)
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps)
    assert_bits_equal(rec.frames.select(AXES).to_numpy(), axes)


def test_imu_messages_lost_from_a_busy_bag_are_masked_on_the_grid(
    tmp_path: Path, analysed_with_two_gaps
) -> None:
    """A robot's bag (Imu at 100 Hz interleaved with /tf, /odom and a temperature topic, written
    by the mcap library, stamps jittered) that lost IMU messages (one, then 1.5 s): the default
    gap policy analyses the whole recording on its grid with exactly the lost places masked,
    and the Allan variance at m = 1 loses the r + 1 terms touching each run of r."""
    seconds, n = 120.0, 12_000
    imu = imu_stream("/imu/data", seconds, 100.0, seed=4, awkward=False)
    lost = {3000, *range(7000, 7150)}
    kept = np.array([i for i in range(n) if i not in lost])
    gapped = replace(imu, payloads=[imu.payloads[i] for i in kept], log_time=imu.log_time[kept])
    write_rosbag2(tmp_path / "bag", [gapped, *other_streams(seconds, camera=False, seed=5)])
    analysed_with_two_gaps(tmp_path / "bag", tmp_path / "out", n)


def test_a_gapped_bag_with_awkward_values_drops_the_axes_beyond_float64_sums(
    tmp_path: Path,
) -> None:
    """A bag that lost one IMU message is analysed on its grid, NaN/inf frames masked: an axis
    whose usable frames reach 1.8e308 is still refused with its one-line warning (it crashed
    the noise fit with an IndexError when the range check read the raw column, NaN included),
    and the outlier search counts only the real outlier (accel_z's -2.2e-308 beside 9.8
    m/s²), not the fills of the masked frames next to it."""
    imu = imu_stream("/imu/data", 120.0, 100.0, seed=3)
    kept = np.delete(np.arange(len(imu.payloads)), 7980)
    gapped = replace(imu, payloads=[imu.payloads[i] for i in kept], log_time=imu.log_time[kept])
    write_bag(tmp_path / "gapped.mcap", [gapped])
    result = imupipe.analyze(tmp_path / "gapped.mcap", tmp_path / "out", rrd=False, figures=False)
    assert list(result.axes) == ["gyro_x", "gyro_z", "accel_x", "accel_z"]
    refused = "reaches 1.8e+308, beyond what float64 Allan sums hold (1e100): it is not analysed"
    assert {f"gyro_y {refused}", f"accel_y {refused}"} <= set(result.input.warnings)
    assert result.axes["accel_z"].outliers["count"] == 1
    assert result.axes["accel_z"].outliers["max_size"] == pytest.approx(9.82, abs=0.01)
    assert all(np.isfinite(a.terms.random_walk.value) for a in result.axes.values())


@pytest.fixture(scope="module")
def awkward_gapped_bag(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """60 s of a robot's Imu at 100 Hz with the awkward values, one message lost, interleaved
    with /tf, /odom and a temperature topic in 16 kB zstd chunks (the mcap library's writer)."""
    imu = imu_stream("/imu/data", 60.0, 100.0, seed=6)
    kept = np.delete(np.arange(len(imu.payloads)), 2500)
    gapped = replace(imu, payloads=[imu.payloads[i] for i in kept], log_time=imu.log_time[kept])
    path = tmp_path_factory.mktemp("awkward") / "bag.mcap"
    write_bag(path, [gapped, *other_streams(60.0, camera=False, seed=7)], chunk_size=1 << 14)
    return path.read_bytes()


DAMAGE = st.one_of(
    st.tuples(st.just("flip"), st.lists(st.tuples(st.floats(0, 1), st.integers(0, 7)), max_size=8)),
    st.tuples(st.just("cut"), st.floats(0.05, 1.0)),
    st.tuples(st.just("zero"), st.floats(0, 1), st.integers(1, 4000)),
)


@settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(DAMAGE)
def test_a_damaged_awkward_bag_is_analysed_or_refused_in_one_line(
    tmp_path: Path, awkward_gapped_bag: bytes, damage: tuple
) -> None:
    """The whole analysis, loop included, of the awkward gapped bag with bits flipped, its tail
    cut or a stretch zeroed: it returns (finite N on every analysed axis) or raises our
    one-line ImupipeError — no other exception (the fuzzing that found the range check's
    IndexError ran 650 such cases of five bags)."""
    data = bytearray(awkward_gapped_bag)
    if damage[0] == "flip":
        for where, bit in damage[1]:
            data[min(int(where * len(data)), len(data) - 1)] ^= 1 << bit
    elif damage[0] == "cut":
        data = data[: int(damage[1] * len(data))]
    else:
        start = int(damage[1] * len(data))
        data[start : start + damage[2]] = bytes(len(data[start : start + damage[2]]))
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(data))
    try:
        result = imupipe.analyze(path, tmp_path / "out", rrd=False, figures=False)
    except ImupipeError as exc:
        assert "\n" not in str(exc)
        return
    assert all(np.isfinite(a.terms.random_walk.value) for a in result.axes.values())
