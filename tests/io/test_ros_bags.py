"""sensor_msgs/msg/Imu bags written by an independent writer (rosbags' rosbag2 MCAP writer) decode
to exactly the values that were written, whatever the frame_id, with the sibling Temperature."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from imupipe.errors import InputError
from imupipe.io.decode import decode

TS = get_typestore(Stores.ROS2_HUMBLE)
T0 = 1_700_000_000_000_000_000


def imu_msg(i: int, stamp_ns: int, gyro: np.ndarray, accel: np.ndarray, frame_id: str):
    Imu = TS.types["sensor_msgs/msg/Imu"]
    Header = TS.types["std_msgs/msg/Header"]
    Time = TS.types["builtin_interfaces/msg/Time"]
    Quaternion = TS.types["geometry_msgs/msg/Quaternion"]
    Vector3 = TS.types["geometry_msgs/msg/Vector3"]
    cov = np.full(9, 0.01 * (i % 7), dtype=np.float64)  # covariance fields set
    return Imu(
        header=Header(
            stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame_id
        ),
        orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=cov,
        angular_velocity=Vector3(x=gyro[0], y=gyro[1], z=gyro[2]),
        angular_velocity_covariance=cov,
        linear_acceleration=Vector3(x=accel[0], y=accel[1], z=accel[2]),
        linear_acceleration_covariance=cov,
    )


def write_bag(
    path: Path,
    n: int,
    topics: tuple[str, ...] = ("/imu/data_raw",),
    frame_ids: tuple[str, ...] = ("imu_link",),
    temperature: bool = True,
    log_offset_ns: int = 0,
    dropped: frozenset[int] = frozenset(),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A rosbag2 MCAP of ``n`` Imu frames at 100 Hz (their ``dropped`` indices not written:
    gaps) and a 1 Hz Temperature; returns every frame's stamps, gyro and accel."""
    rng = np.random.default_rng(3)
    gyro = rng.normal(0, 0.01, (n, 3))
    accel = rng.normal(0, 0.03, (n, 3)) + np.array([0.0, 0.0, -9.81])
    stamps = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    Temperature = TS.types["sensor_msgs/msg/Temperature"]
    Header = TS.types["std_msgs/msg/Header"]
    Time = TS.types["builtin_interfaces/msg/Time"]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [writer.add_connection(t, "sensor_msgs/msg/Imu", typestore=TS) for t in topics]
        tconn = (
            writer.add_connection("/imu/temperature", "sensor_msgs/msg/Temperature", typestore=TS)
            if temperature
            else None
        )
        for i in range(n):
            s = int(stamps[i])
            if i in dropped:
                continue
            for conn, fid in zip(conns, frame_ids, strict=True):
                fid_i = fid if fid != "varying" else "f" * (i % 5)
                raw = TS.serialize_cdr(imu_msg(i, s, gyro[i], accel[i], fid_i), conn.msgtype)
                writer.write(conn, s + log_offset_ns, raw)
            if tconn is not None and i % 100 == 0:
                msg = Temperature(
                    header=Header(stamp=Time(sec=s // 10**9, nanosec=s % 10**9), frame_id="imu"),
                    temperature=20.0 + i / 100,
                    variance=0.0,
                )
                writer.write(tconn, s, TS.serialize_cdr(msg, tconn.msgtype))
    return stamps, gyro, accel


@pytest.mark.parametrize(
    "frame_id", ["imu_link", "", "a_rather_long_frame_id_of_37_chars__", "varying"]
)
def test_imu_bag_decodes_exactly(tmp_path: Path, frame_id: str) -> None:
    bag = tmp_path / "bag"
    stamps, gyro, accel = write_bag(bag, 1000, frame_ids=(frame_id,))
    rec = decode(bag)  # the rosbag2 directory
    f = rec.frames
    assert rec.topic == "/imu/data_raw" and rec.source == "sensor_msgs/msg/Imu"
    assert rec.time_source == "header.stamp"
    np.testing.assert_array_equal(f["stamp_ns"].to_numpy(), stamps)
    np.testing.assert_array_equal(f.select("gyro_x", "gyro_y", "gyro_z").to_numpy(), gyro)
    np.testing.assert_array_equal(f.select("accel_x", "accel_y", "accel_z").to_numpy(), accel)
    # temperature published at 1 Hz, interpolated onto the IMU stamps
    np.testing.assert_allclose(f["temp_c"].to_numpy()[::100], 20.0 + np.arange(10))
    assert f["supply_v"].null_count() == f.height


def test_several_imu_topics_need_a_choice(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    write_bag(bag, 50, topics=("/imu0/data", "/imu1/data"), frame_ids=("a", "b"))
    with pytest.raises(InputError, match=r"several IMU topics.*/imu0/data, /imu1/data"):
        decode(bag)
    assert decode(bag, topic="/imu1/data").frames.height == 50
    with pytest.raises(InputError, match="not an IMU topic"):
        decode(bag, topic="/imu/temperature")


def test_no_imu_topic_lists_topics(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    String = TS.types["std_msgs/msg/String"]
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=TS)
        writer.write(conn, T0, TS.serialize_cdr(String(data="hi"), conn.msgtype))
    with pytest.raises(InputError, match=r"no IMU topic \(topics in the file: /chatter\)"):
        decode(bag)


def temperature_msg(stamp_ns: int, celsius: float):
    Temperature = TS.types["sensor_msgs/msg/Temperature"]
    Header = TS.types["std_msgs/msg/Header"]
    Time = TS.types["builtin_interfaces/msg/Time"]
    stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    header = Header(stamp=stamp, frame_id="imu")
    return Temperature(header=header, temperature=celsius, variance=0.0)


@pytest.mark.parametrize("keep_one", [False, True])
def test_log_time_used_when_header_stamps_are_unset(tmp_path: Path, keep_one: bool) -> None:
    """Stamps left at 0 by the IMU's driver and its temperature's: both are placed by the log
    time (200 Hz; the temperature at 2 Hz rises 1 °C a second)."""
    bag = tmp_path / "bag"
    n = 200
    Imu = TS.types["sensor_msgs/msg/Imu"]
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=TS)
        tconn = writer.add_connection("/imu/temp", "sensor_msgs/msg/Temperature", typestore=TS)
        for i in range(n):
            msg = imu_msg(i, 0, np.zeros(3), np.zeros(3), "imu")
            assert isinstance(msg, Imu)
            writer.write(conn, T0 + i * 5_000_000, TS.serialize_cdr(msg, conn.msgtype))
            if i % 100 == 0:
                temp = temperature_msg(0, 20.0 + i * 0.005)
                writer.write(tconn, T0 + i * 5_000_000, TS.serialize_cdr(temp, tconn.msgtype))
    rec = decode(bag, keep_one_time_base=keep_one)
    assert rec.time_source == "log_time"
    assert any("header.stamp is unset" in w for w in rec.warnings)
    np.testing.assert_allclose(np.diff(rec.frames["t_s"].to_numpy()), 0.005)
    expected = np.minimum(20.0 + np.arange(n) * 0.005, 20.5)  # held after the last message
    np.testing.assert_allclose(rec.frames["temp_c"].to_numpy(), expected, rtol=0, atol=1e-9)


def test_gaps_in_a_rosbags_bag_are_masked_not_cut(tmp_path: Path, analysed_with_two_gaps) -> None:
    """Messages lost from a bag another library wrote (one frame, then 1.5 s): the default gap
    policy analyses the whole recording on its 100 Hz grid with the lost places masked, and the
    Allan variance loses exactly the terms that touch them (a run of r masked samples costs
    r + 2m − 1 terms at factor m)."""
    n, lost = 12_000, frozenset({1000, *range(5000, 5150)})
    bag = tmp_path / "gapped"
    write_bag(bag, n, temperature=False, dropped=lost)
    analysed_with_two_gaps(bag, tmp_path / "out", n)


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_a_vector_marked_no_estimate_is_read_as_missing(tmp_path: Path, storage) -> None:
    """sensor_msgs/msg/Imu.msg: element 0 of a covariance at -1 means "no estimate, disregard
    it". A driver without gyros marks every angular velocity so (its values are 0); one whose
    accelerometer reading failed marks a few linear accelerations. Those values are NaN (the
    conditioning's missing rows: an absent axis, masked frames), every other value is as
    written, and the decode says how many messages were marked."""
    n = 500
    rng = np.random.default_rng(5)
    accel = rng.normal(0, 0.03, (n, 3)) + np.array([0.0, 0.0, 9.81])
    failed = {7, 8, 250, 499}
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=storage) as writer:
        conn = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=TS)
        for i in range(n):
            s = T0 + i * 10_000_000
            msg = imu_msg(i, s, np.zeros(3), 0.0 * accel[i] if i in failed else accel[i], "imu")
            msg.angular_velocity_covariance = np.r_[-1.0, np.zeros(8)]
            cov = np.full(9, 0.02)
            cov[0] = -1.0 if i in failed else 0.02
            msg.linear_acceleration_covariance = cov
            writer.write(conn, s, TS.serialize_cdr(msg, conn.msgtype))
    rec = decode(bag)
    assert rec.warnings == [
        "angular_velocity_covariance[0] is -1 in every message: the driver marks its "
        "angular_velocity as no estimate (sensor_msgs/msg/Imu: 'disregard the associated "
        "estimate'); gyro_x, gyro_y, gyro_z read as missing there",
        "linear_acceleration_covariance[0] is -1 in 4 of 500 messages: the driver marks its "
        "linear_acceleration as no estimate (sensor_msgs/msg/Imu: 'disregard the associated "
        "estimate'); accel_x, accel_y, accel_z read as missing there",
    ]
    frames = rec.frames
    for axis in ("gyro_x", "gyro_y", "gyro_z"):
        assert frames[axis].is_nan().all()
    kept = np.setdiff1d(np.arange(n), sorted(failed))
    for k, axis in enumerate(("accel_x", "accel_y", "accel_z")):
        values = frames[axis].to_numpy()
        assert np.flatnonzero(np.isnan(values)).tolist() == sorted(failed)
        np.testing.assert_array_equal(values[kept], accel[kept, k])


@pytest.mark.parametrize("keep_one", [False, True])
def test_runs_after_clock_resets_are_placed_by_the_log_time(tmp_path: Path, keep_one) -> None:
    """Header stamps from a sensor clock that two driver restarts reset (100 Hz; the restarts
    take 2.5 s and 7 s of log time, received 3 ms after each sample): t_s follows the log
    time across each reset and the stamps within each run; stamp_ns stays the header's.
    Read again when the scan kept one time base only."""
    n, first, second = 900, 300, 600
    true_ns = np.arange(n) * 10_000_000 + np.where(np.arange(n) >= first, 2_500_000_000, 0)
    true_ns += np.where(np.arange(n) >= second, 7_000_000_000, 0)
    run = np.searchsorted([first, second], np.arange(n), side="right")
    clock_zero = np.array([40_000_000_000, 1_000_000_000, 500_000_000])  # each run's clock at 0
    run_start = true_ns[[0, first, second]]
    header = clock_zero[run] + true_ns - run_start[run]
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=TS)
        tconn = writer.add_connection("/imu/temp", "sensor_msgs/msg/Temperature", typestore=TS)
        for i in range(n):
            msg = imu_msg(i, int(header[i]), np.zeros(3), np.array([0, 0, 9.8]), "imu")
            log = T0 + int(true_ns[i]) + 3_000_000
            writer.write(conn, log, TS.serialize_cdr(msg, conn.msgtype))
            if i % 50 == 0:  # 2 Hz on the same clock, 0.1 °C a second, received 1 ms later
                temp = temperature_msg(int(header[i]), 30.0 + true_ns[i] / 1e10)
                writer.write(tconn, log + 1_000_000, TS.serialize_cdr(temp, tconn.msgtype))
    rec = decode(bag, keep_one_time_base=keep_one)
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), header)
    np.testing.assert_allclose(rec.frames["t_s"].to_numpy(), true_ns / 1e9, rtol=0, atol=1e-9)
    # each run's temperature where it was measured: the runs' own, in their own order
    expected = 30.0 + np.minimum(true_ns, true_ns[850]) / 1e10  # held after the last message
    np.testing.assert_allclose(rec.frames["temp_c"].to_numpy(), expected, rtol=0, atol=1e-9)
    assert rec.time_source == "header.stamp"
    assert rec.warnings == [
        "header.stamp jumps back 2 time(s) (by 41.99 s at message 300, …: the clock that stamps "
        "them was reset, e.g. a driver restarted with the sensor's clock): the messages after "
        "each jump are placed by the MCAP log time"
    ]


@pytest.mark.parametrize("keep_one", [False, True])
def test_a_temperature_stamped_by_another_clock_is_placed_by_the_log_time(
    tmp_path: Path, keep_one: bool
) -> None:
    """The IMU stamped by the sensor's clock (seconds since its power-up), its temperature by
    the host's: no temperature message falls within the IMU's stamps, so both are placed by
    their log time (before: every frame got the last message's value). Without the log time
    (kept only for the time base's sake, ``keep_one_time_base``) it is not used."""
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=TS)
        tconn = writer.add_connection("/imu/temp", "sensor_msgs/msg/Temperature", typestore=TS)
        for i in range(300):
            msg = imu_msg(i, 7_000_000_000 + i * 10_000_000, np.zeros(3), np.zeros(3), "imu")
            writer.write(conn, T0 + i * 10_000_000 + 2_000_000, TS.serialize_cdr(msg, conn.msgtype))
            if i % 100 == 0:
                temp = temperature_msg(T0 + i * 10_000_000, 25.0 + i)
                log = T0 + i * 10_000_000 + 2_000_000  # received with the IMU's sample
                writer.write(tconn, log, TS.serialize_cdr(temp, tconn.msgtype))
    rec = decode(bag, keep_one_time_base=keep_one)
    outside = (
        "the temperature topic's 3 message(s) are stamped outside the IMU's time span "
        "(header.stamp: another clock?): "
    )
    if keep_one:
        assert rec.frames["temp_c"].null_count() == 300
        assert rec.warnings == [outside + "the temperature is not used"]
        assert rec.temperature_topic is None  # not used: report.json's is null
    else:
        assert rec.temperature_topic == "/imu/temp"
        expected = 25.0 + np.minimum(np.arange(300), 200)  # held after the last message
        np.testing.assert_allclose(rec.frames["temp_c"].to_numpy(), expected, rtol=0, atol=1e-9)
        assert rec.warnings == [outside + "it is placed by the MCAP log time"]


@pytest.mark.parametrize("keep_one", [False, True])
def test_stray_stamps_are_mended_beside_a_reset(tmp_path: Path, keep_one: bool) -> None:
    """A sensor clock (100 Hz, received 3 ms after each sample) reset once after message 600
    by a restart of 2.5 s, and seven messages whose stamp is wrong by more than a second: the
    first at 0, four in a row (-5 s, then +1 h), one just after the reset (0) and the last
    (+1 h). Each stray takes its neighbours' interpolated stamp (the ends: the log time less
    the latency), the reset is placed: t_s is the true time to 1 ns, stamp_ns the header's."""
    n, reset = 900, 600
    true_ns = np.arange(n) * 10_000_000 + np.where(np.arange(n) >= reset, 2_500_000_000, 0)
    clock_zero = np.where(np.arange(n) >= reset, 1_000_000_000, 40_000_000_000)
    header = clock_zero + true_ns - np.where(np.arange(n) >= reset, true_ns[reset], 0)
    header[[0, reset + 2]] = 0
    header[400] -= 5_000_000_000
    header[401:404] += 3600_000_000_000
    header[n - 1] += 3600_000_000_000
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=TS)
        for i in range(n):
            msg = imu_msg(i, int(header[i]), np.zeros(3), np.array([0, 0, 9.8]), "imu")
            log = T0 + int(true_ns[i]) + 3_000_000
            writer.write(conn, log, TS.serialize_cdr(msg, conn.msgtype))
    rec = decode(bag, keep_one_time_base=keep_one)
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), header)
    np.testing.assert_allclose(rec.frames["t_s"].to_numpy(), true_ns / 1e9, rtol=0, atol=1e-9)
    assert rec.warnings == [
        "7 message(s) have a header.stamp more than 1 s off their neighbours' (message 0 by "
        "-40 s, …): each is replaced by its neighbours' stamps, interpolated",
        "header.stamp jumps back 1 time(s) (by 44.99 s at message 600: the clock that stamps "
        "them was reset, e.g. a driver restarted with the sensor's clock): the messages after "
        "each jump are placed by the MCAP log time",
    ]


def test_a_stray_among_fewer_messages_than_its_window(tmp_path: Path) -> None:
    """Six messages (under the nine a stray is compared with), the third stamped 0: the window
    stays inside the record and the stray takes its neighbours' interpolated stamp."""
    header = T0 + np.arange(6) * 10_000_000
    header[2] = 0
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=TS)
        for i in range(6):
            msg = imu_msg(i, int(header[i]), np.zeros(3), np.array([0, 0, 9.8]), "imu")
            writer.write(conn, T0 + i * 10_000_000 + 1_000_000, TS.serialize_cdr(msg, conn.msgtype))
    rec = decode(bag)
    np.testing.assert_array_equal(rec.frames["t_s"].to_numpy(), np.arange(6) / 100)


def test_strays_at_both_ends_take_the_log_time_less_the_latency(tmp_path: Path, imu_mcap) -> None:
    """Stamps on the host's clock (received 3 ms after them, 100 Hz), the first and the last
    left at 0 (a driver stamping before its time was set, and as it stopped): each stray at an
    end has no good neighbour on one side and takes its log time less its neighbours' median
    latency, 3 ms: t_s is the true time to the nanosecond, and no clock reset is left."""
    n = 50
    true_ns = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    header = true_ns.copy()
    header[[0, -1]] = 0
    path = imu_mcap(
        tmp_path / "f.mcap",
        {"/imu": (header, np.zeros((n, 3)), np.zeros((n, 3)))},
        log_ns=true_ns + 3_000_000,
    )
    rec = decode(path)
    assert rec.time_source == "header.stamp"
    np.testing.assert_array_equal(rec.frames["t_s"].to_numpy(), np.arange(n) / 100)
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), header)
    assert rec.warnings == [
        "2 message(s) have a header.stamp more than 1 s off their neighbours' (message 0 by "
        "-1.7e+09 s, …): each is replaced by its neighbours' stamps, interpolated"
    ]


def test_the_median_of_nanoseconds_is_exact() -> None:
    """The offsets that place runs and strays: exact int64 medians (the upper one of an even
    count), not through float64 (256 ns apart at ~1.7e18 ns)."""
    from imupipe.io.decode import _median_ns

    assert _median_ns(np.array([5, 1, 4, 2, 3])) == 3
    assert _median_ns(np.array([9, 8, 7, 6, 5, 4, 3, 2, 1, 0]) + T0 + 1) == T0 + 6
    latency = np.random.default_rng(0).integers(0, 10**9, 1000)  # a run's log − stamp
    assert _median_ns(T0 + latency) == T0 + np.sort(latency)[500]


@pytest.mark.parametrize("resets", [1, 11])
def test_resets_a_log_time_cannot_place_are_joined_and_too_many_left(
    tmp_path: Path, resets: int
) -> None:
    """A log time copied from the stamps resets with them: the runs are joined one sample
    apart (the time between them unknown; before session 40: left as they are, the record's
    period then negative). Eleven resets are the clocks of several sensors or broken stamps:
    left as they are (conditioning names the steps back). (Eleven steps back in the stamps and
    none in the log time would make the log time the time base: here it repeats two values.)"""
    n = 600
    run = np.arange(n) * (resets + 1) // n
    header = 5_000_000_000 + (np.arange(n) - run * (n // (resets + 1))) * 10_000_000
    log = T0 + np.arange(n) * 10_000_000
    log[[100, 200]] = log[[99, 199]]
    if resets == 1:
        log = header
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=TS)
        for i in range(n):
            msg = imu_msg(i, int(header[i]), np.zeros(3), np.array([0, 0, 9.8]), "imu")
            writer.write(conn, int(log[i]), TS.serialize_cdr(msg, conn.msgtype))
    rec = decode(bag)
    assert rec.time_source == "header.stamp"
    t_s = rec.frames["t_s"].to_numpy()
    if resets == 1:
        assert rec.warnings == [
            "header.stamp jumps back 1 time(s) (by 2.99 s at message 300: the clock that stamps "
            "them was reset, e.g. a driver restarted with the sensor's clock): the log time "
            "cannot place the runs (it resets with the stamps, or does not advance): each is "
            "joined one sample after the run before, the time between them unknown"
        ]
        np.testing.assert_array_equal(t_s, (np.arange(n) + (np.arange(n) >= 300)) / 100)
    else:
        assert rec.warnings == []
        np.testing.assert_array_equal(t_s, (header - header[0]) / 1e9)


def test_a_message_recorded_twice_is_read_once(tmp_path: Path) -> None:
    """Every 50th message written twice in a row (a publisher or recorder repeating it: the
    same bytes, a later log time) is read once; two messages with the same stamp and other
    values (samples stamped together) both stay."""
    n = 1000
    stamps, gyro, accel = T0 + np.arange(n) * 10_000_000, np.zeros((n, 3)), np.zeros((n, 3))
    gyro[:, 0] = np.arange(n)
    stamps[501] = stamps[500]  # a pair stamped together, values differ
    bag = tmp_path / "bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=TS)
        for i in range(n):
            raw = TS.serialize_cdr(
                imu_msg(i, int(stamps[i]), gyro[i], accel[i], "imu"), conn.msgtype
            )
            writer.write(conn, int(stamps[i]), raw)
            if i % 50 == 0:
                writer.write(conn, int(stamps[i]) + 1000, raw)
    rec = decode(bag)
    np.testing.assert_array_equal(rec.frames["gyro_x"].to_numpy(), np.arange(n))
    np.testing.assert_array_equal(rec.frames["stamp_ns"].to_numpy(), stamps)
    assert rec.warnings == [
        "20 message(s) repeat the one before them byte for byte (the same stamp and values: "
        "recorded twice?): each is read once"
    ]


def test_a_repeat_across_decoded_batches_is_found(tmp_path: Path, imu_mcap) -> None:
    """The first message of a chunk repeating the last of the chunk before, where the decoder
    takes the two chunks in separate batches (40,000 messages each)."""
    n = 60_000
    stamps = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    gyro = np.zeros((n, 3))
    gyro[:, 1] = np.arange(n)
    rows = np.r_[:40_000, 39_999, 40_000:n]  # the second chunk starts with message 39,999 again
    log = stamps[rows] + (np.arange(n + 1) >= 40_000)  # logged 1 ns later
    path = imu_mcap(
        tmp_path / "f.mcap",
        {"/imu": (stamps[rows], gyro[rows], np.zeros((n + 1, 3)))},
        log_ns=log,
        chunk=40_000,
    )
    rec = decode(path)
    np.testing.assert_array_equal(rec.frames["gyro_y"].to_numpy(), np.arange(n))
    assert rec.warnings[0].startswith("1 message(s) repeat the one before them byte for byte")


def test_the_frame_ids_of_a_topic_are_its_headers_as_written(tmp_path: Path) -> None:
    """``frame_ids`` (the names conditioning shows when several sensors share a topic): the
    distinct header.frame_id values of the topic's first messages, each the bytes after its
    u32 length without the NUL, sorted; an empty frame_id is the empty name."""
    bag = tmp_path / "bag"
    write_bag(bag, 20, frame_ids=("varying",), temperature=False)  # "", "f", ... "ffff"
    assert decode(bag).frame_ids == ("", "f", "ff", "fff", "ffff")
