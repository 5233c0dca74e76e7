"""Bad data and other producers, end to end through ``imupipe analyze`` (issue 5).

Each case is a small recording (2 min at 100 Hz from the virtual ADIS16364, or a
``sensor_msgs/msg/Imu`` stream), edited to break one assumption, then analysed by the command
line's own entry point (:func:`imupipe.cli.main`, in process to save the interpreter start-up);
the checks read ``report.json``: the right warnings, the documented policy applied (the longest
clean segment), and no Allan deviation computed over a break.  Exit codes and the one-line
errors of a separate process are in ``test_cli.py``.
"""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from scipy import signal

from imupipe.cli import main, topic_folder
from imupipe.device.adis16364 import (
    EA_BIT,
    FrameBlock,
    config_for_rate,
    decode_words,
    encode_words,
)
from imupipe.device.frame_schema import (
    DEFAULT_TOPIC,
    MESSAGE_ENCODING,
    METADATA_NAME,
    PROFILE,
    SCHEMA_ENCODING,
    SCHEMA_NAME,
    encode_frames,
    message_definition,
)
from imupipe.io import mcap_scan
from imupipe.io.decode import decode
from imupipe.recording.recorder import FrameWriter
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.testing.busy_bag import Stream, write_bag
from imupipe.testing.ros_cdr import imu_payloads, temperature_payloads
from imupipe.vocab import AXES

RATE_HZ = 100.0
N = 12_000  # 2 min
CONFIG = config_for_rate(RATE_HZ)
IMU_SCHEMA = "sensor_msgs/msg/Imu"


@pytest.fixture(scope="module")
def clean() -> FrameBlock:
    return VirtualADIS16364(CONFIG, None, seed=5).frames(N)


def edit(block: FrameBlock, **cols: np.ndarray) -> FrameBlock:
    return replace(block, **cols)


def write_adis(path: Path, block: FrameBlock, chunk: int = 4096, compression: str = "zstd") -> Path:
    with open(path, "wb") as f:
        writer = FrameWriter(f, CONFIG, compression=compression)
        for i in range(0, len(block), chunk):
            writer.write(block[i : i + chunk])
        writer.finish()
    return path


def imu_stream(n: int = N, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    stamps = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 10_000_000
    return stamps, rng.normal(0, 1e-3, (n, 3)), rng.normal(0, 3e-3, (n, 3)) + np.array([0, 0, 9.81])


def analyze(path: Path, capsys, *extra: str) -> tuple[int, dict, str]:
    """``imupipe analyze PATH --no-rrd --no-loop -q``: exit code, report.json, stderr."""
    out = path.parent / "out"
    argv = ["imupipe", "analyze", str(path), "--out", str(out), "--no-rrd", "--no-loop", "-q"]
    old = sys.argv
    sys.argv = [*argv, *extra]
    try:
        with pytest.raises(SystemExit) as exit_info:
            main()
    finally:
        sys.argv = old
    err = capsys.readouterr().err
    code = exit_info.value.code
    report = (
        json.loads((out / "report.json").read_text()) if (out / "report.json").is_file() else {}
    )
    if code == 0 and "--topic" not in extra:
        shutil.rmtree(out)
    return code, report, err


def warnings_of(report: dict) -> str:
    return "\n".join(report["input"]["warnings"])


def test_clean_recording_has_no_warnings(tmp_path: Path, capsys, clean: FrameBlock) -> None:
    code, report, err = analyze(write_adis(tmp_path / "f.mcap", clean), capsys)
    assert code == 0 and err == ""
    assert report["input"]["warnings"] == [] and report["input"]["frames"] == N
    assert set(report["axes"]) == {"gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"}


def test_stuck_channel_saturation_ea_flag_and_counter_wrap(
    tmp_path: Path, capsys, clean: FrameBlock
) -> None:
    burst = clean.burst.copy()
    burst[:, 2] = (burst[:, 2] & 0xC000) | 0x0005  # gyro_y stuck at 5 LSB
    burst[3000:3010] |= EA_BIT  # alarm flag on 10 frames
    burst[9000:9003, 4] = (burst[9000:9003, 4] & 0xC000) | 0x1FFF  # accel_x at the +rail
    counter = (clean.counter.astype(np.int64) + (1 << 32) - 6000) % (1 << 32)
    block = edit(clean, burst=burst, counter=counter.astype(np.uint32))
    code, report, err = analyze(write_adis(tmp_path / "f.mcap", block), capsys)
    w = warnings_of(report)
    assert code == 0
    assert "gyro_y is constant over the segment (stuck channel?)" in w
    assert "gyro_y" not in report["axes"]  # no Allan deviation of a stuck channel
    assert "10 frame(s) with the EA (error/alarm) flag set" in w
    assert "3 saturated (over-range) frame(s)" in w
    assert "gap" not in w  # the u32 counter wrapping at frame 6000 is not a gap
    segs = report["input"]["segments"]
    assert [s["frames"] for s in segs] == [9000, N - 9003]  # saturated frames cut out
    assert report["input"]["frames"] == N - 3  # the default masks them: the rest is analysed
    assert "warning: " + report["input"]["warnings"][0] in err  # printed too


def test_the_command_prints_each_warning_once_after_its_table(
    tmp_path: Path, capsys, clean: FrameBlock
) -> None:
    """Not quiet: the table on stdout, then each warning once on stderr (the table repeated them,
    so a terminal showed every warning twice)."""
    burst = clean.burst.copy()
    burst[:, 2] = (burst[:, 2] & 0xC000) | 0x0005  # gyro_y stuck at 5 LSB
    path = write_adis(tmp_path / "f.mcap", edit(clean, burst=burst))
    old = sys.argv
    sys.argv = ["imupipe", "analyze", str(path), "--out", str(tmp_path / "o"), "--no-rrd"]
    try:
        with pytest.raises(SystemExit) as exit_info:
            main()
    finally:
        sys.argv = old
    out, err = capsys.readouterr()
    assert exit_info.value.code == 0
    stuck = "warning: gyro_y is constant over the segment (stuck channel?)"
    assert err.count(stuck) == 1 and "warning" not in out
    assert "Random walk N       gyro_x" in out and out.rstrip().endswith("o/")


def test_stamps_duplicate_backwards_and_gaps(tmp_path: Path, capsys, clean: FrameBlock) -> None:
    keep = np.delete(np.arange(N), 2000)  # one frame lost: stamp and counter skip
    block = clean[keep]
    stamps = block.stamp_ns.copy()
    stamps[500] = stamps[499]  # duplicate stamp
    stamps[1000] = stamps[998]  # one stamp backwards
    stamps[7000:] += 3600 * 10**9  # an hour-long pause (counter continuous)
    code, report, _ = analyze(write_adis(tmp_path / "f.mcap", edit(block, stamp_ns=stamps)), capsys)
    w = warnings_of(report)
    assert code == 0
    assert "1 duplicate stamp(s)" in w
    assert "1 stamp(s) going backwards" in w
    # the frame counter says exactly one frame is missing; the hour-long pause is the other gap
    # (the long steps that make up for the duplicate and backwards stamps are not gaps)
    assert "2 gap(s) in time or frame counter (1 frames missing)" in w
    # longest clean stretch: rows 2000..6999, after the lost frame and before the pause
    assert report["input"]["frames"] == 5000
    assert "analysing the longest clean segment" in w
    code, report, err = analyze(
        write_adis(tmp_path / "g.mcap", edit(block, stamp_ns=stamps)), capsys, "--gaps", "fail"
    )
    assert code == 2 and err.count("\n") == 1 and "--gaps longest" in err


def test_drifting_host_timer(tmp_path: Path, capsys, clean: FrameBlock) -> None:
    rng = np.random.default_rng(2)
    period = 0.0102 + 0.0004 * np.linspace(0, 1, N)  # a slow host timer, drifting by 4 %
    stamps = clean.stamp_ns[0] + np.concatenate([[0], np.cumsum(period[1:])]) * 1e9
    stamps += rng.uniform(-1.5e-3, 1.5e-3, N) * 1e9  # latency jitter
    code, report, _ = analyze(
        write_adis(tmp_path / "f.mcap", edit(clean, stamp_ns=stamps.astype(np.int64))), capsys
    )
    w = warnings_of(report)
    assert code == 0
    assert "measured mean rate" in w and "differs from the nominal 100 Hz" in w
    assert report["input"]["rate_hz"] == pytest.approx(1 / period.mean(), rel=1e-3)
    assert report["input"]["frames"] == N  # jitter is not a gap
    assert "stamp jitter is" in w


def test_nan_and_inf_values_from_a_ros_driver(tmp_path: Path, capsys, imu_mcap) -> None:
    stamps, gyro, accel = imu_stream()
    gyro[4000, 1] = np.nan
    accel[4001, 2] = np.inf
    path = imu_mcap(tmp_path / "f.mcap", {"/imu/data_raw": (stamps, gyro, accel)})
    code, report, _ = analyze(path, capsys)
    w = warnings_of(report)
    assert code == 0
    assert "2 frame(s) with NaN/inf values" in w
    assert report["input"]["frames"] == N - 2  # masked (default gap policy), not cut
    assert all(np.isfinite(a["allan"]["adev"]).all() for a in report["axes"].values())


@pytest.mark.parametrize("budget", [[], ["--memory-budget-gb", "0.001"]])
def test_an_axis_nan_in_every_frame_is_not_provided_not_a_bad_frame(
    tmp_path: Path, capsys, budget: list[str], imu_mcap
) -> None:
    """A gyro-only unit publishing Imu with NaN accelerations: its gyros are analysed as if
    the accelerometers were finite (in memory and through the spilled columns), and a NaN
    gyro sample still makes its frame bad."""
    stamps, gyro, accel = imu_stream()
    gyro[4000, 1] = np.nan
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
    with_accel = imu_mcap(tmp_path / "a" / "f.mcap", {"/imu": (stamps, gyro, accel)})
    gyro_only = imu_mcap(
        tmp_path / "b" / "f.mcap", {"/imu": (stamps, gyro, np.full_like(accel, np.nan))}
    )
    _, expected, _ = analyze(with_accel, capsys, *budget)
    code, report, err = analyze(gyro_only, capsys, *budget)
    assert code == 0, err
    assert sorted(report["axes"]) == ["gyro_x", "gyro_y", "gyro_z"]
    for axis in ("accel_x", "accel_y", "accel_z"):
        assert f"{axis} is NaN/inf in every frame" in err
    assert "1 frame(s) with NaN/inf values" in warnings_of(report)
    assert report["input"]["frames"] == N - 1
    for axis in report["axes"]:
        assert report["axes"][axis]["allan"] == expected["axes"][axis]["allan"]
        assert report["axes"][axis]["ieee952"] == expected["axes"][axis]["ieee952"]


def test_every_axis_nan_in_every_frame_is_one_line(tmp_path: Path, capsys, imu_mcap) -> None:
    stamps, gyro, _ = imu_stream(3000)
    nan = np.full_like(gyro, np.nan)
    code, _, err = analyze(imu_mcap(tmp_path / "f.mcap", {"/imu": (stamps, nan, nan)}), capsys)
    assert code == 2
    assert err.count("\n") == 1 and "no axis can be analysed: gyro_x is NaN/inf" in err


@pytest.mark.parametrize(
    ("scale", "offset", "says"),
    [
        (1 / 9.80665, 0.0, "the accelerations look like g, not the m/s²"),
        (1.0, 6.0, "or a sensor that was not at rest"),
        (1.0, 0.0, None),
    ],
)
def test_accelerations_in_g_or_not_at_rest_are_warned(
    tmp_path: Path, capsys, scale: float, offset: float, says: str | None, imu_mcap
) -> None:
    """A driver publishing Imu accelerations in g (REP 103 says m/s²) would give terms 9.81×
    too small under m/s² labels: the mean specific force, gravity at rest, says so."""
    stamps, gyro, accel = imu_stream(3000)
    accel = accel * scale + np.array([offset, 0.0, 0.0])
    code, report, err = analyze(
        imu_mcap(tmp_path / "f.mcap", {"/imu": (stamps, gyro, accel)}), capsys
    )
    assert code == 0
    if says is None:
        assert "specific force" not in err and "specific force" not in warnings_of(report)
    else:
        assert says in err and says in warnings_of(report)


@pytest.mark.parametrize("budget", [[], ["--memory-budget-gb", "0.001"]])
def test_a_time_window_analyses_what_the_same_frames_alone_give(
    tmp_path: Path, capsys, budget: list[str], imu_mcap
) -> None:
    """--start 20 --end -40 on 0..119.99 s: frames 2000..7999 (t = 20..79.99 s) analysed, as if
    they had been recorded alone (in memory and through the spilled columns); the report says so."""
    stamps, gyro, accel = imu_stream()
    for folder in ("whole", "alone"):
        (tmp_path / folder).mkdir()
    whole = imu_mcap(tmp_path / "whole" / "f.mcap", {"/imu": (stamps, gyro, accel)})
    part = slice(2000, 8000)
    alone = imu_mcap(
        tmp_path / "alone" / "f.mcap", {"/imu": (stamps[part], gyro[part], accel[part])}
    )
    code, windowed, err = analyze(whole, capsys, "--start", "20", "--end", "-40", *budget)
    assert code == 0, err
    _, expected, _ = analyze(alone, capsys, *budget)
    assert windowed["input"]["window_s"] == [20.0, -40.0]
    assert expected["input"]["window_s"] == [0.0, None]
    assert windowed["input"]["frames"] == expected["input"]["frames"] == 6000
    (segment,) = windowed["input"]["segments"]
    assert (segment["start_frame"], segment["t_start_s"], segment["t_stop_s"]) == (
        2000,
        20.0,
        79.99,
    )
    assert sorted(windowed["axes"]) == sorted(expected["axes"]) == sorted(AXES)
    for axis, result in windowed["axes"].items():  # τ0 from stamps 20..79.99 s or 0..59.99 s
        other = expected["axes"][axis]
        np.testing.assert_allclose(result["allan"]["adev"], other["allan"]["adev"], rtol=1e-12)
        assert result["allan"]["tau_s"] == pytest.approx(other["allan"]["tau_s"], rel=1e-12)
        for term, value in result["ieee952"].items():
            if isinstance(value, dict) and "value" in value:
                theirs = other["ieee952"][term]
                assert value["reason"] == theirs["reason"]
                assert (value["value"] is None) == (theirs["value"] is None)
                if value["value"] is not None:
                    assert value["value"] == pytest.approx(theirs["value"], rel=1e-9)


def two_imus_on_one_topic(
    path: Path, offset_ms: float, frames: tuple[str, str] = ("imu_left", "imu_right")
) -> Path:
    """Two 100 Hz IMUs (``frames``; the right one 5× noisier) publishing on /imu, the right
    one stamped ``offset_ms`` after the left, in arrival order."""
    stamps, gyro, accel = imu_stream(6000)
    payloads: list[bytes] = [b""] * 12_000
    times = np.empty(12_000, np.int64)
    for k, frame in enumerate(frames):
        at = stamps + round(k * offset_ms * 1e6)
        rows = imu_payloads(at, gyro * (1 + 4 * k), accel, frame_id=frame)
        payloads[k::2] = [r.tobytes() for r in rows]
        times[k::2] = at
    write_bag(path, [Stream("/imu", IMU_SCHEMA, payloads, times)], "")
    return path


@pytest.mark.parametrize("offset_ms", [0, 3])
def test_two_imus_publishing_on_one_topic_are_one_line_not_a_crash(
    tmp_path: Path, capsys, offset_ms: int
) -> None:
    """Stamped together or 3 ms apart, no uniform grid keeps two consecutive samples, so no
    averaging time is left.  It was an IndexError deep in the fit (``imupipe: internal
    error``, exit 1); now one line, exit 2, naming the likely cause and the frames."""
    code, _, err = analyze(two_imus_on_one_topic(tmp_path / "f.mcap", offset_ms), capsys)
    assert code == 2 and err.count("\n") == 1
    assert "the longest run of clean samples is" in err
    assert "several IMUs publishing on one topic? Its messages carry header.frame_id " in err
    assert "'imu_left', 'imu_right'" in err


def test_two_imus_half_a_period_apart_are_analysed_with_a_warning(tmp_path: Path, capsys, imu_mcap):
    """5 ms apart, the two streams look like one at 200 Hz (and give a mixture's terms): the
    frames the topic carries are named in a warning; one IMU per topic gets none."""
    code, report, _ = analyze(two_imus_on_one_topic(tmp_path / "f.mcap", 5), capsys)
    assert code == 0 and report["input"]["rate_hz"] == pytest.approx(200.0)
    warning = (
        "topic /imu carries messages of 2 frames (header.frame_id 'imu_left', 'imu_right') "
        "among its first 64: if several IMUs publish on it, they are analysed as one stream"
    )
    assert any(w.startswith(warning) for w in report["input"]["warnings"])
    stamps, gyro, accel = imu_stream(3000)
    (tmp_path / "one").mkdir()
    one = imu_mcap(tmp_path / "one" / "f.mcap", {"/imu": (stamps, gyro, accel)})
    _, single, _ = analyze(one, capsys)
    assert not any("frames (header.frame_id" in w for w in single["input"]["warnings"])


def test_several_topics_all_gives_a_report_per_topic(tmp_path: Path, capsys, imu_mcap) -> None:
    streams = {t: imu_stream(3000, seed=k) for k, t in enumerate(["/imu0/data", "/imu1/data"])}
    path = imu_mcap(tmp_path / "f.mcap", streams)
    code, _, err = analyze(path, capsys)
    assert (
        code == 2 and "several IMU topics, choose one with --topic: /imu0/data, /imu1/data" in err
    )
    code, _, err = analyze(path, capsys, "--topic", "all")
    assert code == 0, err
    for topic in streams:
        report = json.loads((tmp_path / "out" / topic_folder(topic) / "report.json").read_text())
        assert report["input"]["topic"] == topic and report["input"]["frames"] == 3000
    # a third topic too short to analyse: the others' reports, then one line and exit 2
    (tmp_path / "three").mkdir()
    three = imu_mcap(
        tmp_path / "three" / "f.mcap", {**streams, "/imu2/data": imu_stream(10, seed=2)}
    )
    code, _, err = analyze(three, capsys, "--topic", "all")
    assert code == 2
    assert err.endswith("imupipe: error: 1 of 3 IMU topics could not be analysed: /imu2/data\n")
    assert "warning: topic /imu2/data: " in err and "segment has 10 frames, too few" in err
    for topic in streams:
        folder = tmp_path / "three" / "out" / topic_folder(topic)
        assert json.loads((folder / "report.json").read_text())["input"]["frames"] == 3000


def run_info(path: Path, cli) -> str:
    code, out, _ = cli(["info", str(path)])
    assert code == 0
    return out


def test_killed_recorder_with_a_bad_crc_chunk(
    tmp_path: Path, capsys, clean: FrameBlock, cli
) -> None:
    path = write_adis(tmp_path / "f.mcap", clean, chunk=3000, compression="")
    data = bytearray(path.read_bytes())
    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) == 4
    second = chunks[1]
    data[second.chunk_start_offset + second.chunk_length // 2] ^= 0x10  # corrupt chunk 2
    last = chunks[3]  # killed while writing chunk 4: no summary, no footer, chunk 4 half written
    path.write_bytes(bytes(data[: last.chunk_start_offset + last.chunk_length // 2]))
    lost = "a chunk was lost ({}): about 3000 messages whose log times span 29.990 s"
    code, report, _ = analyze(path, capsys)
    w = warnings_of(report)
    assert code == 0
    assert lost.format("CRC mismatch") in w
    assert lost.format("cut off by the end of the file") in w
    assert "file has no footer/summary" in w
    assert "1 gap(s) in time or frame counter (3000 frames missing)" in w
    assert [s["frames"] for s in report["input"]["segments"]] == [3000, 3000]
    info = run_info(path, cli)
    for reason in ("CRC mismatch", "cut off by the end of the file"):
        assert "warning: " + lost.format(reason) in info
    assert "6000 messages" in info


@pytest.mark.parametrize("compression, chunk", [("lz4", 1000), ("", 12_000), ("zstd", 77)], ids=str)
def test_other_compression_and_chunk_sizes(
    tmp_path: Path, capsys, clean: FrameBlock, compression: str, chunk: int
) -> None:
    path = write_adis(tmp_path / "f.mcap", clean, chunk=chunk, compression=compression)
    code, report, _ = analyze(path, capsys)
    assert code == 0 and report["input"]["warnings"] == [] and report["input"]["frames"] == N


@pytest.mark.parametrize("chunked", [False, True], ids=["unchunked", "lz4-chunks"])
def test_our_frames_written_by_the_mcap_library(
    tmp_path: Path, capsys, clean: FrameBlock, chunked: bool
) -> None:
    """The mcap library's own Writer (one message per call), unchunked or lz4-chunked."""
    payloads = encode_frames(clean, "imu_link_with_a_longer_frame_id")
    buf = io.BytesIO()
    w = Writer(buf, use_chunking=chunked, compression=CompressionType.LZ4, chunk_size=50_000)
    w.start(profile=PROFILE, library="mcap-python")
    sid = w.register_schema(SCHEMA_NAME, SCHEMA_ENCODING, message_definition().encode())
    cid = w.register_channel(DEFAULT_TOPIC, MESSAGE_ENCODING, sid)
    w.add_metadata(METADATA_NAME, CONFIG.to_metadata())
    for stamp, raw in zip(clean.stamp_ns.tolist(), payloads, strict=True):
        w.add_message(cid, log_time=stamp, data=raw.tobytes(), publish_time=stamp)
    w.finish()
    path = tmp_path / "f.mcap"
    path.write_bytes(buf.getvalue())
    reference = write_adis(tmp_path / "ref.mcap", clean)
    code, report, _ = analyze(path, capsys)
    _, expected, _ = analyze(reference, capsys)
    assert code == 0 and report["input"]["warnings"] == []
    assert report["axes"]["gyro_z"]["allan"] == expected["axes"]["gyro_z"]["allan"]


def test_rosbag2_directory_with_split_files(tmp_path: Path, capsys, imu_mcap) -> None:
    """metadata.yaml lists the split files in order; they are analysed as one recording."""
    stamps, gyro, accel = imu_stream()
    bag = tmp_path / "bag"
    bag.mkdir()
    names = []
    for k, rows in enumerate(np.array_split(np.arange(N), 3)):
        names.append(f"bag_{k}.mcap")
        imu_mcap(bag / names[-1], {"/imu": (stamps[rows], gyro[rows], accel[rows])})
    (bag / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n"
        "  relative_file_paths:\n" + "".join(f"    - {n}\n" for n in names)
    )
    code, report, _ = analyze(bag, capsys)
    assert code == 0 and report["input"]["warnings"] == []
    assert report["input"]["frames"] == N and report["input"]["rate_hz"] == pytest.approx(100)


def test_gaps_mask_analyses_the_whole_recording(tmp_path: Path, capsys, clean: FrameBlock) -> None:
    """``--gaps mask``: one lost frame costs the Allan terms that touch it, not a segment."""
    block = clean[np.delete(np.arange(N), 2000)]  # stamp and counter skip one frame
    code, report, err = analyze(write_adis(tmp_path / "f.mcap", block), capsys, "--gaps", "mask")
    assert code == 0, err
    w = warnings_of(report)
    assert "1 gap(s) in time or frame counter (1 frames missing)" in w
    assert f"uniform grid of {N} samples with 1 masked" in w
    assert "longest clean segment" not in w
    assert report["input"]["frames"] == N - 1
    allan = report["axes"]["gyro_x"]["allan"]
    assert allan["n_terms"][0] == (N + 1 - 2) - 2  # m = 1: the two terms over sample 2000
    assert allan["n_terms"][2] == (N + 1 - 6) - 6  # m = 3: 2m terms lost


CONVERT_HINT = "a ROS 1 bag converts to a ROS 2 one with `rosbags-convert --src BAG --dst DIR`"


def write_encoded(path: Path, schema: str, encoding: str, payloads: np.ndarray) -> Path:
    """One ``/imu/data`` channel of ``schema`` in message ``encoding`` (the mcap library's
    writer), one message a row of ``payloads``, 100 Hz."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="another producer")
        sid = w.register_schema(schema, "jsonschema" if encoding == "json" else "ros1msg", b"")
        cid = w.register_channel("/imu/data", encoding, sid)
        for k, row in enumerate(payloads):
            t = 1_700_000_000_000_000_000 + k * 10_000_000
            w.add_message(cid, log_time=t, data=row.tobytes(), publish_time=t)
        w.finish()
    return path


def test_imu_messages_in_another_encoding_are_named_not_read_as_cdr(
    tmp_path: Path, capsys, cli
) -> None:
    """A channel's message encoding decides how its bytes are read (MCAP spec): Imu messages
    on a ``json`` channel are refused by name even when their bytes happen to be CDR, and a
    ROS 1 bag converted to MCAP (``sensor_msgs/Imu``, ``ros1``) is named as such."""
    cdr = imu_payloads(*imu_stream(3000))
    for schema, encoding in ((IMU_SCHEMA, "json"), ("sensor_msgs/Imu", "ros1")):
        path = write_encoded(tmp_path / f"{encoding}.mcap", schema, encoding, cdr)
        code, report, err = analyze(path, capsys)
        assert code == 2 and report == {}
        assert err.strip() == (
            f"imupipe: error: {path}: no IMU topic imupipe can read (/imu/data is {schema} in "
            f"'{encoding}' encoding): imupipe reads ROS 2 messages (sensor_msgs/msg/Imu, 'cdr'); "
            + CONVERT_HINT
        )
        assert f"  /imu/data  [{schema}, '{encoding}' encoding: not read]  3000 messages" in (
            run_info(path, cli)
        )
    both = tmp_path / "both.mcap"  # the CDR topic beside it is read, alone
    with open(both, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="another producer")
        sid = w.register_schema(IMU_SCHEMA, "ros2msg", b"")
        channels = {e: w.register_channel(f"/imu/{e}", e, sid) for e in ("json", "cdr")}
        for k, row in enumerate(cdr):
            t = 1_700_000_000_000_000_000 + k * 10_000_000
            for cid in channels.values():
                w.add_message(cid, log_time=t, data=row.tobytes(), publish_time=t)
        w.finish()
    code, report, err = analyze(both, capsys, "--topic", "all")
    assert code == 0, err
    assert [p.name for p in (tmp_path / "out").iterdir()] == [topic_folder("/imu/cdr")]


def test_a_ros1_bag_is_named_and_its_conversion_reads_bit_for_bit(tmp_path: Path, capsys) -> None:
    """A ROS 1 bag (rosbags' writer, ``sensor_msgs/Imu`` in ROS 1 serialisation) is refused in
    one line that says how to convert it, and what that conversion (rosbags' converter) writes
    decodes to the very values written."""
    from rosbags.rosbag1 import Writer as Ros1Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    stamps, gyro, accel = imu_stream(3000, seed=3)
    bag = tmp_path / "night.bag"
    with Ros1Writer(bag) as w:
        conn = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        for k, t in enumerate(stamps.tolist()):
            msg = types["sensor_msgs/msg/Imu"](
                types["std_msgs/msg/Header"](
                    k, types["builtin_interfaces/msg/Time"](t // 10**9, t % 10**9), "imu"
                ),
                types["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
                np.zeros(9),
                types["geometry_msgs/msg/Vector3"](*gyro[k]),
                np.zeros(9),
                types["geometry_msgs/msg/Vector3"](*accel[k]),
                np.zeros(9),
            )
            w.write(conn, t, store.serialize_ros1(msg, "sensor_msgs/msg/Imu"))
    code, _, err = analyze(bag, capsys)
    assert code == 2 and err.strip() == (
        f"imupipe: error: {bag} is a ROS 1 bag, not MCAP: imupipe reads ROS 2 bags (MCAP or "
        f"SQLite); {CONVERT_HINT}"
    )
    converted = tmp_path / "converted"
    cmd = [sys.executable, "-m", "rosbags.convert", "--src", str(bag), "--dst", str(converted)]
    subprocess.run(cmd, check=True, capture_output=True)
    frames = decode(converted).frames
    assert frames["stamp_ns"].to_list() == stamps.tolist()
    for k, axis in enumerate(("gyro_x", "gyro_y", "gyro_z")):
        np.testing.assert_array_equal(frames[axis].to_numpy(), gyro[:, k])
        np.testing.assert_array_equal(frames[f"accel_{axis[-1]}"].to_numpy(), accel[:, k])


def test_an_imu_without_gyros_and_gravity_removed_is_named_so(
    tmp_path: Path, capsys, imu_mcap
) -> None:
    """An orientation filter's Imu: angular velocity 0 in every message (not measured, and not
    marked so with the covariance -1 the message definition asks for: next test) and gravity
    already removed from the accelerations. The gyros are named as not measured rather than
    stuck, and the accelerometers as gravity-removed rather than in a wrong unit; the
    accelerometers are analysed."""
    stamps, gyro, accel = imu_stream()
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": (stamps, 0.0 * gyro, accel - accel.mean(0))})
    code, report, _ = analyze(path, capsys)
    w = warnings_of(report)
    assert code == 0
    for axis in ("gyro_x", "gyro_y", "gyro_z"):
        assert f"{axis} is 0 in every sample over the segment (not measured by this sensor?)" in w
    assert "stuck channel" not in w
    assert "about 0, as if the driver removed gravity" in w
    assert set(report["axes"]) == {"accel_x", "accel_y", "accel_z"}


def test_gyros_marked_no_estimate_are_left_out_as_the_message_says(
    tmp_path: Path, capsys, imu_mcap
) -> None:
    """The same gyro-less driver following sensor_msgs/msg/Imu.msg: its angular velocity's
    covariance starts with -1 ("no estimate"). The gyros are left out as not provided, with the
    mark named, instead of being read as zeros; the accelerometers are analysed."""
    stamps, gyro, accel = imu_stream()
    path = imu_mcap(
        tmp_path / "f.mcap", {"/imu": (stamps, 0.0 * gyro, accel)}, no_estimate=(True, False)
    )
    code, report, _ = analyze(path, capsys)
    w = warnings_of(report)
    assert code == 0
    assert "angular_velocity_covariance[0] is -1 in every message" in w
    for axis in ("gyro_x", "gyro_y", "gyro_z"):
        assert f"{axis} is NaN/inf in every frame (an axis the sensor does not provide?)" in w
    assert "is 0 in every sample" not in w
    assert set(report["axes"]) == {"accel_x", "accel_y", "accel_z"}


@pytest.mark.parametrize("budget", [[], ["--memory-budget-gb", "0.001"]])
def test_a_reset_of_the_stamping_clock_is_placed_by_the_log_time(
    tmp_path: Path, capsys, budget: list[str], imu_mcap
) -> None:
    """A driver stamping with the sensor's clock restarts after frame 6000, 3 s later, its
    clock from 0.2 s: the stamps jump back by ~560 s. Before session 39 the record read as
    60 s long at ~2× its rate (N 29 % low, silently but for a rate warning). The messages after
    the reset are placed by the receive times (log time, with latency), so the restart is a
    3 s gap, masked like any other: the same grid and N as stamps that never reset."""
    stamps, gyro, accel = imu_stream()
    true_ns = stamps - stamps[0] + np.where(np.arange(N) >= 6000, 3 * 10**9, 0)
    rng = np.random.default_rng(7)
    log_ns = np.maximum.accumulate(
        stamps[0] + true_ns + np.abs(rng.normal(0, 3e6, N)).astype(np.int64)
    )
    header_ns = np.where(
        np.arange(N) < 6000, 500 * 10**9 + true_ns, 2 * 10**8 + true_ns - true_ns[6000]
    )
    for folder in ("reset", "never"):
        (tmp_path / folder).mkdir()
    reset = imu_mcap(
        tmp_path / "reset" / "f.mcap", {"/imu": (header_ns, gyro, accel)}, log_ns=log_ns
    )
    never = imu_mcap(
        tmp_path / "never" / "f.mcap", {"/imu": (stamps[0] + true_ns, gyro, accel)}, log_ns=log_ns
    )
    code, report, err = analyze(reset, capsys, *budget)
    assert code == 0, err
    _, expected, _ = analyze(never, capsys, *budget)
    assert (
        "header.stamp jumps back 1 time(s) (by 559.79 s at message 6000: the clock that stamps "
        "them was reset, e.g. a driver restarted with the sensor's clock): the messages after "
        "each jump are placed by the MCAP log time" in warnings_of(report)
    )
    assert "going backwards" not in err and "measured mean rate" not in err
    assert report["input"]["duration_s"] == pytest.approx(expected["input"]["duration_s"])
    assert report["input"]["counts"] == expected["input"]["counts"]
    assert report["input"]["counts"]["masked_samples"] == 300  # the 3 s of the restart
    assert expected["input"]["rate_hz"] == 100.0  # the restart's 3 s, from the latencies' medians:
    assert report["input"]["rate_hz"] == pytest.approx(100.0, rel=1e-6)  # 27 µs off here
    for axis in AXES:
        n, truth = (
            report["axes"][axis]["ieee952"]["random_walk"],
            expected["axes"][axis]["ieee952"]["random_walk"],
        )
        assert n["value"] == pytest.approx(truth["value"], rel=1e-6)


@pytest.mark.parametrize("budget", [[], ["--memory-budget-gb", "0.001"]])
def test_a_few_stray_stamps_cost_nothing(
    tmp_path: Path, capsys, budget: list[str], imu_mcap
) -> None:
    """One message stamped 0 (a field left unset once), one 5 s early and one 1 h late, among
    12,000 at 100 Hz received with 0-3 ms of latency. Before session 40 the first and last
    read as clock resets, then as steps back: more than half the grid masked, so only the
    6000 frames before the first stray were analysed (the -5 s one alone: 1001 samples masked,
    rate 100.28 Hz). Each stray now takes its neighbours' interpolated stamp: the same report
    as the clean stamps'."""
    stamps, gyro, accel = imu_stream()
    rng = np.random.default_rng(8)
    log_ns = np.maximum.accumulate(stamps + np.abs(rng.normal(0, 1e6, N)).astype(np.int64))
    strayed = stamps.copy()
    strayed[6000] = 0
    strayed[8000] -= 5 * 10**9
    strayed[10_000] += 3600 * 10**9
    for folder in ("stray", "clean"):
        (tmp_path / folder).mkdir()
    stray = imu_mcap(tmp_path / "stray" / "f.mcap", {"/imu": (strayed, gyro, accel)}, log_ns=log_ns)
    clean = imu_mcap(tmp_path / "clean" / "f.mcap", {"/imu": (stamps, gyro, accel)}, log_ns=log_ns)
    code, report, err = analyze(stray, capsys, *budget)
    assert code == 0, err
    _, expected, _ = analyze(clean, capsys, *budget)
    assert warnings_of(report).startswith(
        "3 message(s) have a header.stamp more than 1 s off their neighbours' (message 6000 by "
        "-1.7e+09 s, …): each is replaced by its neighbours' stamps, interpolated"
    )
    assert report["input"]["warnings"][1:] == expected["input"]["warnings"]
    assert report["input"]["counts"] == expected["input"]["counts"]
    assert report["input"]["counts"]["non_monotonic_stamps"] == 0
    assert report["input"]["frames"] == N and len(report["input"]["segments"]) == 1
    assert report["input"]["rate_hz"] == expected["input"]["rate_hz"] == 100.0
    assert report["axes"] == expected["axes"]


@pytest.mark.parametrize(("log_time", "host"), [("copied", False), ("zero", True)])
def test_a_reset_the_log_time_cannot_place_joins_the_runs(
    tmp_path: Path, capsys, log_time: str, host: bool, imu_mcap
) -> None:
    """The stamping clock reset after frame 6000 (from ~1.7e9 s to 1 s) in a bag whose log time
    cannot place it: copied from the stamps (it resets too), or left at 0 by its writer; the
    stamps of the sensor's clock, or a host's receive times (0-3 ms late). The runs are
    joined one sample apart (the time between them unknown: a lost frame, masked). Before
    session 40 the record's end points gave a negative period: "internal error: IndexError"
    (with host stamps a step jitter of 1e8 ppm)."""
    stamps, gyro, accel = imu_stream()
    rng = np.random.default_rng(9)
    late = rng.integers(0, 3_000_000, N) if host else np.zeros(N, np.int64)
    header = stamps + late
    header[6000:] += 10**9 - header[6000] + late[6000]
    log_ns = header if log_time == "copied" else np.zeros(N, np.int64)
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": (header, gyro, accel)}, log_ns=log_ns)
    code, report, err = analyze(path, capsys)
    assert code == 0, err
    assert warnings_of(report).startswith(
        "header.stamp jumps back 1 time(s) (by 1.7e+09 s at message 6000: the clock that stamps "
        "them was reset, e.g. a driver restarted with the sensor's clock): the log time cannot "
        "place the runs (it resets with the stamps, or does not advance): each is joined one "
        "sample after the run before, the time between them unknown"
    )
    assert "placed by the MCAP log time" not in warnings_of(report)  # (it cannot)
    counts = report["input"]["counts"]
    assert counts["gaps"] == counts["missed_frames"] == counts["masked_samples"] == 1
    assert counts["non_monotonic_stamps"] == 0 and counts["grid_samples"] == N + 1
    assert report["input"]["frames"] == N and len(report["input"]["segments"]) == 2
    assert report["input"]["segments"][1]["t_start_s"] == pytest.approx(60.01, abs=3e-3)
    # the latency at the runs' ends (host), times of ~1.7e9 s before the reset as f64 s
    assert report["input"]["rate_hz"] == pytest.approx(100.0, rel=5e-5 if host else 1e-12)
    for axis in AXES:  # white noise of 1e-3 / 3e-3 a sample at 100 Hz
        n = report["axes"][axis]["ieee952"]["random_walk"]["value"]
        assert n == pytest.approx((1e-3 if axis.startswith("gyro") else 3e-3) / 10, rel=0.03)


def write_host_stamped_temperature(
    imu_mcap, path: Path, n: int, wander_c: float, seed: int
) -> Path:
    """A bag of ``n`` frames at 100 Hz, the IMU stamped by its own clock (from 5 s after
    power-up), its temperature (1 Hz, a random wander of ``wander_c`` °C a second) by the
    host's, both received 2 ms late, in chunks of 30 s; gyro_x's bias follows the temperature
    by 1e-3 rad/s/K."""
    sensor_ns = 5 * 10**9 + np.arange(n, dtype=np.int64) * 10_000_000
    host_ns = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 10_000_000
    _, gyro, accel = imu_stream(n)
    wander = np.cumsum(np.random.default_rng(seed).normal(0, wander_c, n // 100 + 1))  # 1 Hz
    celsius = 25.0 + np.interp(np.arange(n) / 100, np.arange(len(wander)), wander)
    gyro[:, 0] += 1e-3 * (celsius - 25.0)
    each_second = slice(0, n, 100)
    temperature = (
        "/imu/temperature",
        host_ns[each_second] + 2_000_000,
        temperature_payloads(host_ns[each_second], celsius[each_second]),
    )
    return imu_mcap(
        path,
        {"/imu/data": (sensor_ns, gyro, accel)},
        log_ns=host_ns + 2_000_000,
        chunk=3000,
        temperature=temperature,
    )


@pytest.mark.parametrize("budget", [[], ["--memory-budget-gb", "0.001"]])
def test_a_temperature_the_host_stamps_still_drives_the_loop(
    tmp_path: Path, capsys, budget: list[str], imu_mcap
) -> None:
    """A temperature stamped by the host's clock and an IMU by the sensor's
    (:func:`write_host_stamped_temperature`, 2 min, a wander of 1 °C a second). Before
    session 40 no temperature message fell within the IMU's stamps, so every frame read the
    last one and the loop could not see the effect. Both are now placed by their log time, in
    memory and on the low-memory path (whose conditioning says so too), and the loop finds the
    effect with the coefficient."""
    path = write_host_stamped_temperature(imu_mcap, tmp_path / "f.mcap", N, 1.0, 5)
    code, report, err = analyze(path, capsys, "--loop", *budget)
    assert code == 0, err
    assert report["input"]["warnings"][0] == (
        "the temperature topic's 120 message(s) are stamped outside the IMU's time span "
        "(header.stamp: another clock?): it is placed by the MCAP log time"
    )
    found = {axis: [e["kind"] for e in a["effects"]] for axis, a in report["axes"].items()}
    assert "temperature" in found.pop("gyro_x")  # (with a ramp: the wander's own trend)
    assert found == {axis: [] for axis in AXES[1:]}
    (effect,) = [e for e in report["axes"]["gyro_x"]["effects"] if e["kind"] == "temperature"]
    lo, hi = effect["intervals"]["coefficient"]
    assert 0.5e-3 < lo <= 1e-3 <= hi < 2e-3  # (wide: the ramp shares part of the trend)


def test_a_fast_temperature_is_corrected_unfiltered(tmp_path: Path, capsys, imu_mcap) -> None:
    """A temperature that wanders 0.2 °C a second (5 min; :func:`write_host_stamped_temperature`)
    moves within the coupling's low-pass window (31 blocks, 18 s here). Before session 41 the
    loop corrected only the low-passed level: the wander within the window stayed in the
    corrected curve, the Allan error rose 0.16 → 2.93 and the coupling was refused ("flags do
    not clear"), its drift read as a rate random walk K of 1.5e-4 rad/s²/√Hz. The channel's
    changes are not read noise, so its block means are the level now
    (``effects.read_noise_dominates``), and the corrected curve takes the change below one block
    and between block factors (``loop._Axis.corrected_avar``): the coefficient to ±2 %, K
    unresolved (its truth is 0), both errors fall."""
    path = write_host_stamped_temperature(imu_mcap, tmp_path / "f.mcap", 30_000, 0.2, 2)
    code, report, err = analyze(path, capsys, "--loop")
    assert code == 0, err
    gyro_x = report["axes"]["gyro_x"]
    (effect,) = gyro_x["effects"]
    assert effect["kind"] == "temperature"
    assert effect["params"]["lowpass_s"] == 0.0 and effect["params"]["lag_s"] == 0.0
    assert effect["params"]["coefficient"] == pytest.approx(1e-3, rel=0.02)
    lo, hi = effect["intervals"]["coefficient"]
    assert lo < 1e-3 < hi and hi - lo < 0.05e-3
    assert gyro_x["ieee952"]["rate_random_walk"]["value"] is None  # unresolved: the truth is 0
    assert gyro_x["ieee952"]["rate_random_walk"]["hi"] < 2e-5
    assert gyro_x["ieee952"]["random_walk"]["value"] == pytest.approx(1e-4, rel=0.03)
    assert effect["error_after"] < effect["error_before"]  # the Allan error
    assert effect["evidence"]["time_domain_deviance_fall"] > 100
    assert all(not a["effects"] for axis, a in report["axes"].items() if axis != "gyro_x")


def write_imu_and_temperature(
    imu_mcap, path: Path, imu: tuple[np.ndarray, ...], temp_ns: np.ndarray, celsius: np.ndarray
) -> Path:
    """``/imu/data`` (stamps ns, gyro, accel; logged at the stamps) and ``/imu/temperature``
    (°C at ``temp_ns``), one chunk each."""
    temperature = ("/imu/temperature", temp_ns, temperature_payloads(temp_ns, celsius))
    return imu_mcap(path, {"/imu/data": imu}, temperature=temperature)


@pytest.mark.parametrize("curvature", [0.0, 3e-5])
def test_a_curved_temperature_coupling(tmp_path: Path, capsys, curvature: float, imu_mcap) -> None:
    """gyro_x's bias 1e-4 (T − 25) + c₂ (T − 25)² rad/s while the lab cycles 25 ± 3 °C every
    20 min (30 min at 100 Hz; the temperature at 1 Hz to 0.01 °C): with c₂ = 3e-5 rad/s/°C²
    the coupling is found with its curvature, each coefficient's interval holding the truth
    (the linear one as the slope at the reference level), and B stays unresolved (the truth
    is white noise alone). Before session 41 the linear coupling alone was found and the
    curvature it left was read as a bias instability B of 1.45e-4 rad/s (on 2 h). Without
    curvature the linear option is chosen."""
    n = 180_000
    stamps, gyro, accel = imu_stream(n, seed=3)
    celsius = 25 + 3 * np.sin(2 * np.pi * np.arange(n) / 100 / 1200 + 0.3)
    gyro[:, 0] += 1e-4 * (celsius - 25) + curvature * (celsius - 25) ** 2
    each = slice(0, n, 100)
    path = write_imu_and_temperature(
        imu_mcap,
        tmp_path / "f.mcap",
        (stamps, gyro, accel),
        stamps[each],
        np.round(celsius[each], 2),
    )
    code, report, err = analyze(path, capsys, "--loop")
    assert code == 0, err
    gyro_x = report["axes"]["gyro_x"]
    (effect,) = gyro_x["effects"]
    assert effect["kind"] == "temperature" and effect["params"]["lag_s"] == 0.0
    if curvature:
        params, intervals = effect["params"], effect["intervals"]
        slope = 1e-4 + 2 * curvature * (params["reference_level"] - 25)
        lo, hi = intervals["coefficient"]
        assert lo < slope < hi and hi - lo < 0.2 * slope
        lo, hi = intervals["coefficient_quadratic"]
        assert lo < curvature < hi and hi - lo < 0.2 * curvature
    else:
        assert set(effect["params"]) == {"lag_s", "lowpass_s", "coefficient"}
    assert gyro_x["ieee952"]["bias_instability"]["value"] is None
    assert all(not a["effects"] for axis, a in report["axes"].items() if axis != "gyro_x")


def test_a_bias_that_follows_the_temperature_through_a_thermal_lag(
    tmp_path: Path, capsys, imu_mcap
) -> None:
    """gyro_x's bias follows a lab's 25 → 26.5 °C with a 1 °C, 30 min cycle through a
    first-order lag of 600 s (the bag's temperature read beside the sensor, which the heat
    reaches later), 3e-4 rad/s/°C, 1 h at 100 Hz: one coupling, its lag estimated (572 s) with
    an interval holding 600 s and ruling out 300 s, its coefficient's holding 3e-4; B stays
    unresolved.  Before session 43 (pure delays of 0, 60 and 300 s): a 300 s delay with
    1.30e-4 [1.07, 1.45]e-4 rad/s/°C; on 2 h, four effects."""
    n = 360_000
    stamps, gyro, accel = imu_stream(n, seed=4)
    t = np.arange(n) / 100
    celsius = 25 + 1.5 * t / 3600 + np.sin(2 * np.pi * t / 1800)
    die = 25 + signal.lfilter([0.01 / 600], [1, 0.01 / 600 - 1], celsius - 25)
    gyro[:, 0] += 3e-4 * (die - 25)
    each = slice(0, n, 100)
    read = np.round(celsius[each], 2)
    path = write_imu_and_temperature(
        imu_mcap, tmp_path / "f.mcap", (stamps, gyro, accel), stamps[each], read
    )
    code, report, err = analyze(path, capsys, "--loop")
    assert code == 0, err
    gyro_x = report["axes"]["gyro_x"]
    (effect,) = gyro_x["effects"]
    assert effect["kind"] == "temperature"
    lo, hi = effect["intervals"]["lag_s"]
    assert 300 < lo < effect["params"]["lag_s"] < hi and lo < 600 < hi < 1200
    lo, hi = effect["intervals"]["coefficient"]
    assert lo < 3e-4 < hi and hi - lo < 0.2 * 3e-4
    assert gyro_x["ieee952"]["bias_instability"]["value"] is None
    assert all(not a["effects"] for axis, a in report["axes"].items() if axis != "gyro_x")


@pytest.mark.parametrize(("resolution", "width"), [(0.25, 0.07), (1.0, 0.75)])
def test_a_temperature_read_in_steps_is_read_through_them(
    tmp_path: Path, capsys, resolution: float, width: float, imu_mcap
) -> None:
    """A bag's temperature in 0.25 (or 1) °C steps at 1 Hz while the lab warms 25 → 26.5 °C
    with a 1 °C, 30 min cycle, gyro_x's bias following it by 3e-4 rad/s/°C (1 h at 100 Hz):
    the coupling is found, regressed on a spline through the steps' midpoints (a staircase
    passing through its levels), its interval holding the truth (6 % wide; 1 °C steps: 69 %),
    and B stays unresolved (the truth is white noise alone).  Before session 42 no effect was
    found and the cycle was read as a bias instability B of 4.3e-4 rad/s: the steps
    or the low-passed steps were the level, and under the baseline's whitener (B had soaked up
    the coupling) the steps outweighed the slow motion the bias follows."""
    n = 360_000
    stamps, gyro, accel = imu_stream(n, seed=4)
    t = np.arange(n) / 100
    celsius = 25 + 1.5 * t / 3600 + np.sin(2 * np.pi * t / 1800)
    gyro[:, 0] += 3e-4 * (celsius - 25)
    each = slice(0, n, 100)
    read = np.round(celsius[each] / resolution) * resolution
    path = write_imu_and_temperature(
        imu_mcap, tmp_path / "f.mcap", (stamps, gyro, accel), stamps[each], read
    )
    code, report, err = analyze(path, capsys, "--loop")
    assert code == 0, err
    gyro_x = report["axes"]["gyro_x"]
    (effect,) = gyro_x["effects"]
    assert effect["kind"] == "temperature" and effect["params"]["lag_s"] == 0.0
    assert set(effect["params"]) == {"lag_s", "lowpass_s", "coefficient"}
    assert effect["evidence"]["level"].startswith("a spline through its steps' midpoints")
    lo, hi = effect["intervals"]["coefficient"]
    assert lo < 3e-4 < hi and hi - lo < width * 3e-4
    assert gyro_x["ieee952"]["bias_instability"]["value"] is None
    assert all(not a["effects"] for axis, a in report["axes"].items() if axis != "gyro_x")


@pytest.mark.parametrize("bad", ["nan", "inf", "every"])
def test_temperature_messages_that_are_not_numbers_leave_it_unknown(
    tmp_path: Path, capsys, bad: str, imu_mcap
) -> None:
    """A driver publishing NaN (or inf) for a temperature it cannot read: the temperature is
    unknown (null) between those messages' neighbours, with a warning, and the loop reads the
    rest; all of them such, the temperature is not used. Before session 41 one infinite
    message stopped the analysis ("internal error: LinAlgError: SVD did not converge" in the
    loop's regression), and NaN ones were not warned about."""
    n = 12_000
    stamps, gyro, accel = imu_stream(n)
    celsius = 25.0 + np.arange(n // 100) * 0.01  # 1 Hz
    sent = celsius.copy()
    dropped = {"nan": [7, 8, 50], "inf": [30], "every": list(range(n // 100))}[bad]
    sent[dropped] = np.nan if bad != "inf" else np.inf
    path = write_imu_and_temperature(
        imu_mcap, tmp_path / "f.mcap", (stamps, gyro, accel), stamps[::100], sent
    )
    rec = decode(path)
    said = [w for w in rec.warnings if "NaN or infinite" in w]
    temp_c = rec.frames["temp_c"]
    if bad == "every":
        assert said == [
            "120 of the temperature topic's 120 message(s) are NaN or infinite: the temperature "
            "is not used"
        ]
        assert temp_c.null_count() == n and rec.temperature_topic is None  # (report.json: null)
    else:
        assert rec.temperature_topic == "/imu/temperature"
        assert said == [
            f"{len(dropped)} of the temperature topic's 120 message(s) are NaN or infinite: "
            "the temperature is unknown (null) between their neighbours"
        ]
        unknown = np.zeros(n, bool)
        for j in dropped:  # the frames after the message before and before the message after
            unknown[(j - 1) * 100 + 1 : (j + 1) * 100] = True
        assert temp_c.null_count() == unknown.sum()
        want = np.interp(np.arange(n), np.arange(0, n, 100), celsius)
        np.testing.assert_allclose(temp_c.to_numpy()[~unknown], want[~unknown], rtol=0, atol=1e-9)
    code, report, err = analyze(path, capsys, "--loop")
    assert code == 0, err
    assert said[0] in report["input"]["warnings"]


def test_an_imu_topic_whose_only_chunk_is_over_the_budget_says_why(
    tmp_path: Path, capsys, monkeypatch, imu_mcap
) -> None:
    """A writer that put the whole IMU topic in one chunk larger than the memory budget lets
    a chunk take: the one-line error says the chunk was skipped and which option raises it,
    not only that the topic has no readable messages."""
    monkeypatch.setattr(mcap_scan, "MIN_CHUNK_LIMIT", 100_000)  # the 0.9 MB chunk is too big
    stamps, gyro, accel = imu_stream(3000)
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": (stamps, gyro, accel)})
    code, _, err = analyze(path, capsys, "--memory-budget-gb", "0.001")
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(f"imupipe: error: {path}: topic /imu has no readable messages (a chunk")
    assert "a chunk may take under the memory budget (--memory-budget-gb); skipped unread" in err


@pytest.mark.parametrize("n", [15, 16])
def test_sixteen_frames_are_the_fewest_analysed(tmp_path: Path, capsys, n: int, imu_mcap) -> None:
    """MIN_FRAMES: 16 consecutive clean frames give the shortest averaging times; 15 are one
    clear line and exit 2."""
    stamps, gyro, accel = imu_stream(n)
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": (stamps, gyro, accel)})
    code, report, err = analyze(path, capsys)
    if n == 15:
        assert code == 2 and err == (
            f"imupipe: error: {path}: the longest clean segment has 15 frames, too few for any "
            "averaging time (need at least 16)\n"
        )
    else:
        assert code == 0 and report["input"]["frames"] == 16


def test_mean_and_rms_are_the_received_frames_whatever_masks_the_rest(
    tmp_path: Path, capsys, imu_mcap
) -> None:
    """1 % of the messages lost one by one (short holes, bridged at long tau) and 50 in a row
    (a gap, masked): each axis' mean and rms are those of the frames received, not of the
    grid's fill."""
    stamps, gyro, accel = imu_stream()
    keep = np.random.default_rng(4).random(N) > 0.01
    keep[6000:6050] = False
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": (stamps[keep], gyro[keep], accel[keep])})
    code, report, err = analyze(path, capsys)
    assert code == 0, err
    assert "are read by the Allan variance as their fill" in warnings_of(report)  # bridged
    for k, axis in enumerate(AXES):
        values = (gyro if k < 3 else accel)[keep, k % 3]
        assert report["axes"][axis]["mean"] == pytest.approx(values.mean(), rel=1e-9, abs=1e-15)
        assert report["axes"][axis]["rms"] == pytest.approx(values.std(), rel=1e-9)


@pytest.mark.parametrize("budget", [[], ["--memory-budget-gb", "0.001"]])
def test_two_imus_with_one_frame_id_on_one_topic_are_warned(
    tmp_path: Path, capsys, budget: list[str]
) -> None:
    """Both IMUs' messages in one frame, stamped together: no stamp tells them apart (one
    IMU stamping its samples in pairs looks the same), so the stream is analysed, but the
    even and odd messages' gyro noise differs 5× and a warning says what that means (in
    memory and through the spilled columns). One IMU's pairs (tests/analysis/
    test_host_stamps.py) and the real recordings read 1.01-1.06×."""
    path = two_imus_on_one_topic(tmp_path / "f.mcap", 0, ("imu", "imu"))
    code, report, err = analyze(path, capsys, *budget)
    assert code == 0, err
    (w,) = [w for w in report["input"]["warnings"] if w.startswith("the even and odd")]
    assert w.startswith("the even and odd messages differ as two sensors' would (gyro_x: means ")
    assert "noise 5× apart; gyro_y: " in w and "accel" not in w  # the accelerations alike
    assert w.endswith(
        "one sensor's are alike): several IMUs publishing on one topic under one "
        "header.frame_id? Their samples are analysed as one stream"
    )


def test_a_devices_counted_frames_alternating_are_one_sensor_not_two(
    tmp_path: Path, capsys, clean: FrameBlock
) -> None:
    """Our recorder's frames carry the device's frame counter: one sensor's, even when every
    other frame's gyro_x sits 40 LSB higher (a tone at half the sample rate), so no "two
    sensors" warning (a stream without a counter gets it: the test above)."""
    burst = clean.burst.copy()
    words, _ = encode_words(decode_words(burst[1::2, 1], 14, signed=True) + 40, 14, signed=True)
    burst[1::2, 1] = (burst[1::2, 1] & 0xC000) | words
    code, report, err = analyze(write_adis(tmp_path / "f.mcap", edit(clean, burst=burst)), capsys)
    assert code == 0, err
    assert report["input"]["warnings"] == [] and report["input"]["frames"] == N


def test_two_gross_outliers_are_excised_and_the_curve_recomputed_without_them(
    tmp_path: Path, capsys, clean: FrameBlock
) -> None:
    """gyro_y at +4000 LSB (200 °/s) in two frames: both excised (replaced by the local median)
    and warned, and gyro_y's Allan curve, recomputed without them, has the clean recording's
    averaging times and nearly its deviations."""
    burst = clean.burst.copy()
    burst[[3000, 7000], 2] = (burst[[3000, 7000], 2] & 0xC000) | 4000
    code, report, err = analyze(write_adis(tmp_path / "f.mcap", edit(clean, burst=burst)), capsys)
    assert code == 0, err
    (w,) = report["input"]["warnings"]
    assert w.startswith("gyro_y: 2 outlier sample(s) up to ") and "first at 30.00 s" in w
    assert report["axes"]["gyro_y"]["outliers"]["count"] == 2
    (tmp_path / "clean").mkdir()
    _, expected, _ = analyze(write_adis(tmp_path / "clean" / "f.mcap", clean), capsys)
    allan, truth = report["axes"]["gyro_y"]["allan"], expected["axes"]["gyro_y"]["allan"]
    assert allan["tau_s"] == truth["tau_s"]
    np.testing.assert_allclose(allan["adev"], truth["adev"], rtol=0.01)
