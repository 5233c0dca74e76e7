"""What decoding gives a user, pinned value by value: ADIS16364 words -> SI (1 mg/LSB × 9.80665,
0.05 °/s/LSB × π/180, written out here), ND/EA flags, saturation at the 14-bit rails, the
temperature of the three sensors, the time base chosen and its warning, column subsets, damaged
or unlabelled files, the files of a rosbag2 folder, and the Temperature topic paired with an Imu
topic.  Behaviour only: no internal of the decoder is used."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from imupipe.device.adis16364 import EA_BIT, ND_BIT, DeviceConfig, FrameBlock, encode_words
from imupipe.device.frame_schema import (
    DEFAULT_TOPIC,
    MESSAGE_ENCODING,
    METADATA_NAME,
    PROFILE,
    SCHEMA_ENCODING,
    SCHEMA_NAME,
    TAIL_SIZE,
    encode_frames,
    message_definition,
)
from imupipe.errors import InputError
from imupipe.io.decode import decode, scan
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.testing.ros_cdr import temperature_payloads
from imupipe.vocab import AXES

T0 = 1_700_000_000_000_000_000
G = 9.80665  # m/s² per g
ACCEL_SI = 1e-3 * G  # ADIS16364 accelerometer: 1 mg/LSB (datasheet)
GYRO_SI = 0.05 * math.pi / 180  # ±300 °/s range: 0.05 °/s/LSB, in rad/s


def _block(counts: np.ndarray, stamps: np.ndarray, flags: np.ndarray | None = None) -> FrameBlock:
    """Frames whose six inertial words hold ``counts`` (n, 6); TEMP words 10, 20, 33 LSB,
    SUPPLY 2068 LSB; ND set on every word unless ``flags`` (n, 11) says otherwise."""
    n = len(counts)
    burst = np.zeros((n, 11), np.uint16)
    burst[:, 0] = 2068
    burst[:, 1:7] = encode_words(counts, 14, signed=True)[0]
    burst[:, 7:10] = encode_words(np.array([10, 20, 33]), 12, signed=True)[0]
    burst |= np.uint16(ND_BIT) if flags is None else flags.astype(np.uint16)
    return FrameBlock(
        stamp_ns=np.asarray(stamps, np.int64),
        counter=np.arange(n, dtype=np.uint32) + 7,
        burst=burst,
        diag_stat=np.arange(n, dtype=np.uint16) * 16,
        diag_valid=np.ones(n, bool),
    )


def write_adis(
    path: Path,
    block: FrameBlock,
    log_time: np.ndarray | None = None,
    meta: dict[str, str] | None = None,
    extra: tuple[np.ndarray, ...] = (),
) -> Path:
    """An MCAP of ADIS16364 frames (as the recorder writes it, with a chosen log time), plus a
    chunk of raw payloads (n, size) on the same channel for each of ``extra``."""
    config = DeviceConfig()
    with open(path, "wb") as f:
        w = BulkWriter(f, profile=PROFILE)
        sid = w.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, message_definition().encode())
        cid = w.register_channel(DEFAULT_TOPIC, MESSAGE_ENCODING, sid, {"frame_id": "adis"})
        if meta is not False:
            w.add_metadata(METADATA_NAME, config.to_metadata() if meta is None else meta)
        payloads = encode_frames(block, "adis")
        times = block.stamp_ns if log_time is None else log_time
        w.write_chunk(cid, times, payloads, block.counter)
        for raw in extra:
            w.write_chunk(cid, times[: len(raw)] + 1, np.ascontiguousarray(raw))
        w.finish()
    return path


def _counts(n: int) -> np.ndarray:
    return (np.arange(n * 6).reshape(n, 6) * 37 % 8000 - 4000).astype(np.int64)


def test_adis_frames_in_si_with_flags_and_time(tmp_path: Path) -> None:
    counts = np.array(
        [[1, -1, 0, 1000, -1000, 2], [8191, 0, 0, 0, 0, 0], [0, 0, -8192, 0, 0, 0],
         [8190, -8191, 0, 0, 0, 0], [0, 0, 0, 0, 8191, 0], [0, 0, 0, 0, 0, -8192]]
    )  # fmt: skip
    flags = np.full((6, 11), ND_BIT)
    flags[1, 10] = 0  # AUX_ADC word without ND: the frame is not all new data
    flags[2, 3] = ND_BIT | EA_BIT  # one word with the alarm bit
    stamps = T0 + 5_000_000 + np.arange(6) * 10_000_000
    rec = decode(write_adis(tmp_path / "f.mcap", _block(counts, stamps, flags)))
    f = rec.frames
    for i, axis in enumerate(("gyro_x", "gyro_y", "gyro_z")):
        np.testing.assert_allclose(f[axis].to_numpy(), counts[:, i] * GYRO_SI, rtol=1e-15, atol=0)
    for i, axis in enumerate(("accel_x", "accel_y", "accel_z")):
        np.testing.assert_allclose(f[axis].to_numpy(), counts[:, 3 + i] * ACCEL_SI, rtol=1e-15)
    assert f["accel_x"][0] == pytest.approx(9.80665, rel=1e-15)  # 1000 LSB = 1 g
    assert f["flag_nd"].to_list() == [True, False, True, True, True, True]
    assert f["flag_ea"].to_list() == [False, False, True, False, False, False]
    assert f["saturated"].to_list() == [False, True, True, False, True, True]
    assert f["counter"].to_list() == [7, 8, 9, 10, 11, 12]
    assert f["diag_stat"].to_list() == [0, 16, 32, 48, 64, 80]
    # temperature: mean of the three sensors, 0.136 °C/LSB with 0 LSB = 25 °C
    np.testing.assert_allclose(f["temp_c"].to_numpy(), 25 + 0.136 * (10 + 20 + 33) / 3, rtol=1e-14)
    np.testing.assert_allclose(f["supply_v"].to_numpy(), 2068 * 2.418e-3, rtol=1e-14)
    np.testing.assert_array_equal(f["stamp_ns"].to_numpy(), stamps)
    np.testing.assert_allclose(f["t_s"].to_numpy(), np.arange(6) * 0.01, rtol=0, atol=1e-12)
    assert (rec.time_source, rec.source, rec.topic) == ("header.stamp", SCHEMA_NAME, DEFAULT_TOPIC)
    assert rec.device["accel_scale_mg_per_lsb"] == "1.0" and rec.warnings == []


def test_column_subsets_hold_the_same_values(tmp_path: Path) -> None:
    n = 50
    stamps = T0 + np.arange(n) * 10_000_000
    path = write_adis(tmp_path / "f.mcap", _block(_counts(n), stamps))
    whole = decode(path).frames
    for cols in ({"accel_y", "t_s"}, {"gyro_z", "temp_c"}, {"stamp_ns", "supply_v", "counter"}):
        part = decode(path, columns=frozenset(cols)).frames
        assert sorted(part.columns) == sorted(cols)
        assert part.equals(whole.select(part.columns))
    flags = decode(path, columns=frozenset({"nonfinite", "flag_nd", "saturated"})).frames
    assert flags["nonfinite"].to_list() == [0] * n  # integer words are always finite
    assert flags["flag_nd"].all() and not flags["saturated"].any()


def _time_base(tmp_path: Path, stamps: np.ndarray, log_time: np.ndarray, **kw):
    n = len(stamps)
    return decode(write_adis(tmp_path / "f.mcap", _block(_counts(n), stamps), log_time), **kw)


def test_unset_stamps_use_the_log_time(tmp_path: Path) -> None:
    n = 40
    log = T0 + np.arange(n) * 2_500_000
    for kw in ({}, {"keep_one_time_base": True}):  # the latter reads the file a second time
        rec = _time_base(tmp_path, np.zeros(n, np.int64), log, **kw)
        assert rec.time_source == "log_time"
        assert rec.warnings == [
            "header.stamp is unset or not monotonic (39 non-increasing steps); using MCAP log "
            "time as the time base"
        ]
        np.testing.assert_allclose(rec.frames["t_s"].to_numpy(), np.arange(n) * 0.0025, atol=1e-12)


@pytest.mark.parametrize(
    ("stamp_bad", "log_bad", "base"),
    [(10, 0, "header.stamp"), (11, 0, "log_time"), (20, 2, "header.stamp"),
     (21, 2, "log_time"), (0, 5, "header.stamp")],
)  # fmt: skip
def test_time_base_follows_the_more_monotonic_clock(
    tmp_path: Path, stamp_bad: int, log_bad: int, base: str
) -> None:
    # the header stamps win unless they are unset or have more than max(10 × log's, 10)
    # non-increasing steps
    n = 200
    good = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    stamps, log = good.copy(), good.copy() + 3_000_000
    stamps[np.arange(1, 2 * stamp_bad, 2) + 10] -= 20_000_000  # each: one step back
    log[np.arange(1, 2 * log_bad, 2) + 100] -= 20_000_000
    rec = _time_base(tmp_path, stamps, log)
    assert rec.time_source == base
    chosen = stamps if base == "header.stamp" else log
    np.testing.assert_allclose(rec.frames["t_s"].to_numpy(), (chosen - chosen[0]) / 1e9, atol=1e-9)


def test_malformed_messages_are_counted_and_skipped(tmp_path: Path) -> None:
    n = 30
    block = _block(_counts(n), T0 + np.arange(n) * 10_000_000)
    good = encode_frames(block, "adis")
    # frame_id length 0 (a CDR string has at least its NUL), the fields right after it
    no_nul = np.hstack([good[:2, :12], np.zeros((2, 4), np.uint8), good[:2, -TAIL_SIZE:]])
    big_endian = good[:3].copy()
    big_endian[:, 1] = 0
    extra = (good[:4, :-1], no_nul, big_endian, good[:5, :8])  # the last: shorter than a header
    rec = decode(write_adis(tmp_path / "f.mcap", block, extra=extra))
    assert rec.frames.height == n
    assert rec.warnings == [
        f"{DEFAULT_TOPIC}: 14 malformed messages (size does not match the schema) skipped"
    ]


def test_adis_frames_need_readable_scale_factors(tmp_path: Path) -> None:
    block = _block(_counts(5), T0 + np.arange(5) * 10_000_000)
    with pytest.raises(InputError, match="without the 'adis16364' metadata record"):
        decode(write_adis(tmp_path / "a.mcap", block, meta=False))
    meta = DeviceConfig().to_metadata() | {"sens_avg": str(0x0302)}  # no gyro range 3
    with pytest.raises(
        InputError,
        match=r"b\.mcap: invalid 'adis16364' metadata record \(SENS_AVG 0x0302 selects no valid "
        r"gyro range\): scale factors unknown",
    ):
        decode(write_adis(tmp_path / "b.mcap", block, meta=meta))
    meta = {k: v for k, v in DeviceConfig().to_metadata().items() if k != "smpl_prd"}
    with pytest.raises(InputError, match=r"unreadable .*'smpl_prd'.*scale factors unknown"):
        decode(write_adis(tmp_path / "c.mcap", block, meta=meta))
    meta = DeviceConfig().to_metadata() | {"sens_avg": str(0x0202)}  # ±150 °/s: 0.025 °/s/LSB
    f = decode(write_adis(tmp_path / "d.mcap", block, meta=meta)).frames
    assert f["gyro_x"][1] == pytest.approx(_counts(5)[1, 0] * 0.025 * math.pi / 180, rel=1e-15)


def _split_bag(folder: Path, names: list[str], listed: list[str] | None) -> None:
    folder.mkdir()
    for name in names:
        start = int(name.split("_")[1].split(".")[0])
        stamps = T0 + (start * 10 + np.arange(10)) * 10_000_000
        write_adis(folder / name, _block(_counts(10), stamps))
    if listed is not None:
        lines = "\n".join(f"      - {x}" for x in listed)
        (folder / "metadata.yaml").write_text(
            f"rosbag2_bagfile_information:\n  version: 9\n  relative_file_paths:\n{lines}\n"
            "  duration:\n    nanoseconds: 0\n"
        )


def test_split_files_in_natural_order_or_as_listed(tmp_path: Path) -> None:
    names = ["bag_0.mcap", "bag_2.mcap", "bag_10.mcap"]
    _split_bag(tmp_path / "a", names, None)  # no metadata.yaml (a killed recorder)
    t = decode(tmp_path / "a").frames["stamp_ns"].to_numpy()
    starts = (t[::10] - T0) // 100_000_000
    assert starts.tolist() == [0, 2, 10]  # bag_2 before bag_10
    _split_bag(tmp_path / "b", names, ["bag_10.mcap", "bag_0.mcap", "gone.mcap", "notes.txt"])
    rec = decode(tmp_path / "b")
    assert ((rec.frames["stamp_ns"].to_numpy()[::10] - T0) // 100_000_000).tolist() == [10, 0]
    assert "metadata.yaml lists gone.mcap, which is missing" in rec.warnings


@pytest.mark.parametrize("entry", ["../outside.mcap", "/etc/x.mcap"])
def test_listed_paths_outside_the_bag_are_refused(tmp_path: Path, entry: str) -> None:
    _split_bag(tmp_path / "a", ["bag_0.mcap"], [entry])
    with pytest.raises(InputError, match="outside the bag directory; refusing to read it"):
        decode(tmp_path / "a")


TS = get_typestore(Stores.ROS2_HUMBLE)


def _imu_bag(
    folder: Path, imu_topic: str, temps: dict[str, tuple[str, float]], bad: int = -1
) -> None:
    """100 Imu messages at 100 Hz on ``imu_topic`` (frame_id "imu_link"); each Temperature topic
    of ``temps`` (topic -> (frame_id, offset °C)) at 10 Hz, offset + 0.1 °C per message;
    accel_y of message ``bad`` infinite, the covariance of the next one NaN."""
    T = TS.types
    header = lambda s, fid: T["std_msgs/msg/Header"](  # noqa: E731
        stamp=T["builtin_interfaces/msg/Time"](sec=s // 10**9, nanosec=s % 10**9), frame_id=fid
    )
    vec = T["geometry_msgs/msg/Vector3"]
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        imu = w.add_connection(imu_topic, "sensor_msgs/msg/Imu", typestore=TS)
        tconn = {t: w.add_connection(t, "sensor_msgs/msg/Temperature", typestore=TS) for t in temps}
        for i in range(100):
            s = T0 + i * 10_000_000
            msg = T["sensor_msgs/msg/Imu"](
                header=header(s, "imu_link"),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=vec(x=0.001 * i, y=0.0, z=0.0),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=vec(x=0.0, y=math.inf if i == bad else 0.0, z=-G),
                linear_acceleration_covariance=np.full(9, np.nan if i == bad + 1 else 0.0),
            )
            w.write(imu, s, TS.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
            for t, (fid, offset) in temps.items():
                if i % 10 == 0:
                    tm = T["sensor_msgs/msg/Temperature"](
                        header=header(s, fid), temperature=offset + i / 100, variance=0.0
                    )
                    w.write(tconn[t], s, TS.serialize_cdr(tm, "sensor_msgs/msg/Temperature"))


@pytest.mark.parametrize(
    ("imu_topic", "temps", "chosen"),
    [
        ("/imu/data", {"/imu/temperature": ("x", 20.0), "/battery/temperature": ("bat", 40.0)},
         "/imu/temperature"),
        ("/imu/data", {"/imu/sub/temp": ("x", 20.0), "/z/temp": ("y", 40.0)}, "/imu/sub/temp"),
        ("/imu/data", {"/board/temp": ("imu_link", 20.0), "/a/temp": ("other", 40.0)},
         "/board/temp"),
        ("/imu/data", {"/battery/temperature": ("bat", 40.0)}, None),
        ("/imu", {"/temp": ("x", 20.0)}, "/temp"),  # both at the top level
        ("/a/imu", {"/b/temp": ("x", 20.0)}, None),  # a sibling namespace is not its own
    ],
)  # fmt: skip
def test_imu_temperature_is_its_own_interpolated(
    tmp_path: Path, imu_topic: str, temps: dict, chosen: str | None
) -> None:
    _imu_bag(tmp_path / "bag", imu_topic, temps)
    rec = decode(tmp_path / "bag")
    assert rec.temperature_topic == chosen
    f = rec.frames
    np.testing.assert_allclose(f["gyro_x"].to_numpy(), 0.001 * np.arange(100), rtol=0, atol=0)
    assert f["accel_z"].to_list() == [-G] * 100
    assert f["counter"].null_count() == 100 and f["supply_v"].null_count() == 100
    assert f["flag_nd"].all() and not f["flag_ea"].any() and not f["saturated"].any()
    assert f["diag_stat"].to_list() == [0] * 100
    if chosen is None:
        assert f["temp_c"].null_count() == 100
    else:  # linear between the 10 Hz readings, held after the last one
        expected = np.minimum(temps[chosen][1] + np.arange(100) / 100, temps[chosen][1] + 0.9)
        np.testing.assert_allclose(f["temp_c"].to_numpy(), expected, rtol=0, atol=1e-6)
    sub = decode(tmp_path / "bag", columns=frozenset({"temp_c", "gyro_x"})).frames
    assert sub.columns == ["gyro_x", "temp_c"] and sub.equals(f.select("gyro_x", "temp_c"))


def test_an_empty_frame_id_pairs_the_imu_with_no_temperature_elsewhere(
    tmp_path: Path, imu_mcap
) -> None:
    """An Imu topic and a Temperature topic in another namespace, both with an empty
    header.frame_id: an empty frame_id names no device, so the temperature (another device's)
    is not used, and none is named."""
    stamps = T0 + np.arange(50, dtype=np.int64) * 10_000_000
    path = imu_mcap(
        tmp_path / "f.mcap",
        {"/a/imu": (stamps, np.zeros((50, 3)), np.zeros((50, 3)))},
        frame_id="",
        temperature=(
            "/b/temp",
            stamps[::10],
            temperature_payloads(stamps[::10], np.full(5, 30.0), ""),
        ),
    )
    rec = decode(path)
    assert rec.temperature_topic is None and rec.frame_ids == ("",)
    assert rec.frames["temp_c"].null_count() == 50


def test_split_files_of_different_devices_are_refused(tmp_path: Path) -> None:
    folder = tmp_path / "bag"
    folder.mkdir()
    block = _block(_counts(10), T0 + np.arange(10) * 10_000_000)
    write_adis(folder / "bag_0.mcap", block)
    write_adis(folder / "bag_1.mcap", block, meta=DeviceConfig(sens_avg=0x0202).to_metadata())
    with pytest.raises(
        InputError,
        match=r"bag_1.mcap carries different 'adis16364' metadata than the files before it "
        r"\(gyro_range_dps, gyro_scale_dps_per_lsb, sens_avg\): one scale for all would be wrong",
    ):
        decode(folder)
    write_adis(folder / "bag_1.mcap", block)  # the same device: read as one recording
    assert decode(folder).frames.height == 20


def test_what_is_not_a_recording(tmp_path: Path) -> None:
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(InputError, match=r"empty\.mcap: empty file"):
        decode(tmp_path / "empty.mcap")
    bag = tmp_path / "bag"
    bag.mkdir()
    os.mkfifo(bag / "a.mcap")
    with pytest.raises(InputError, match=r"a.mcap: not a regular file \(a FIFO"):
        decode(bag)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "x.txt").write_text("x")
    with pytest.raises(InputError, match=r"notes: a directory without MCAP or \.db3 files"):
        decode(tmp_path / "notes")


def test_imu_nonfinite_marks_the_bad_message(tmp_path: Path) -> None:
    _imu_bag(tmp_path / "bag", "/imu", {}, bad=42)
    f = decode(tmp_path / "bag", columns=frozenset({"nonfinite", "accel_z"})).frames
    assert f.columns == ["accel_z", "nonfinite"]
    assert f["nonfinite"].to_numpy().nonzero()[0].tolist() == [42]  # a NaN covariance is not
    assert f["nonfinite"][42] == 1 << AXES.index("accel_y")  # which axis: the bit of accel_y


def test_scan_in_memory_or_spilled(tmp_path: Path) -> None:
    n = 40
    log = T0 + np.arange(n) * 2_500_000
    path = write_adis(tmp_path / "f.mcap", _block(_counts(n), np.zeros(n, np.int64)), log)
    whole = decode(path).frames
    # scan keeps both time bases unless told otherwise: the log time is there when needed
    rec = scan(path).recording()
    assert rec.time_source == "log_time" and rec.frames.equals(whole)
    spill = tmp_path / "spill"
    spill.mkdir()
    scanned = scan(path, spill_dir=spill)
    assert sorted(p.name for p in spill.iterdir()) == ["channel0"]
    for _ in range(2):  # spilled columns can be read as often as wanted
        assert scanned.recording().frames.equals(whole)
    part = scanned.recording(frozenset({"t_s", "accel_x"})).frames
    assert part.equals(whole.select("accel_x", "t_s"))


def test_damage_is_reported_per_split_file(tmp_path: Path) -> None:
    _split_bag(tmp_path / "a", ["bag_0.mcap", "bag_1.mcap"], None)
    cut = tmp_path / "a" / "bag_1.mcap"
    cut.write_bytes(cut.read_bytes()[:-40])  # footer and part of the summary gone
    rec = decode(tmp_path / "a")
    assert rec.frames.height == 20
    assert rec.warnings and all(w.startswith("bag_1.mcap: ") for w in rec.warnings)
    single = decode(cut)  # one file: no file name in front
    assert single.warnings == [w.removeprefix("bag_1.mcap: ") for w in rec.warnings]


def test_stamps_one_nanosecond_apart_are_increasing(tmp_path: Path) -> None:
    n = 30
    rec = _time_base(tmp_path, T0 + np.arange(n), T0 + np.arange(n) * 10_000_000)
    assert rec.time_source == "header.stamp" and rec.warnings == []
    np.testing.assert_allclose(rec.frames["t_s"].to_numpy(), np.arange(n) * 1e-9, rtol=1e-12)


def test_keeping_one_time_base_gives_the_same_frame(tmp_path: Path) -> None:
    n = 30
    path = write_adis(tmp_path / "f.mcap", _block(_counts(n), T0 + np.arange(n) * 10_000_000))
    whole = decode(path).frames
    assert decode(path, keep_one_time_base=True).frames.equals(whole)
    cols = frozenset({"t_s", "gyro_y"})
    assert decode(path, columns=cols, keep_one_time_base=True).frames.equals(
        whole.select("gyro_y", "t_s")
    )
