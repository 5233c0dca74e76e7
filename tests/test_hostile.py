"""Hostile and careless input (issue 11): strings from a recording never reach an output raw,
paths stay where they belong, structurally hostile MCAP cannot exhaust memory or recurse,
outputs are replaced all at once, and every careless input is one line and exit 2.

Each test names the item of issue 11 it pins; docs/robustness.md has the table."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imupipe.api import default_out_dir
from imupipe.cli import main, topic_folder
from imupipe.device.adis16364 import config_for_rate
from imupipe.device.frame_schema import SCHEMA_NAME
from imupipe.errors import InputError
from imupipe.io.decode import IMU_SCHEMA, decode
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.recording.recorder import FrameWriter
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.testing import hostile_mcap as hm
from imupipe.testing.ros_cdr import imu_payloads, temperature_payloads

CONFIG = config_for_rate(100.0)
HOSTILE_TOPIC = (
    "/imu\n# Injected\nimupipe: error: forged <img src=x onerror=alert(1)> ```"
    "\x1b[2J\x1b]0;owned\x07\u202e"
)
RAW = ("\x1b", "\x07", "\u202e", "\x00")


def one_error_line(code: int, err: str, expected: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("imupipe: error: ") and expected in lines[0], lines[0]


def analyze_args(path: Path, out: Path, *extra: str) -> list[str]:
    return ["analyze", str(path), "--out", str(out), "--no-rrd", "--no-loop", "-q", *extra]


def write_adis(path: Path, config=CONFIG, n: int = 3000, seed: int = 1) -> Path:
    with open(path, "wb") as f:
        writer = FrameWriter(f, config)
        writer.write(VirtualADIS16364(CONFIG, None, seed=seed).frames(n))
        writer.finish()
    return path


# --- 1. injection: terminal and Markdown ---------------------------------------------------


def test_a_newline_in_a_topic_cannot_forge_an_error_line(tmp_path: Path, cli) -> None:
    path = hm.imu_file(tmp_path / "f.mcap", topics=(HOSTILE_TOPIC, "/imu/data"))
    code, out, err = cli(analyze_args(path, tmp_path / "out"))
    one_error_line(code, err, "several IMU topics, choose one with --topic")
    assert "\\n# Injected\\nimupipe: error: forged" in err  # shown, escaped, on the one line
    assert not any(c in err + out for c in RAW)


@pytest.fixture(scope="module")
def hostile_run(tmp_path_factory) -> tuple[Path, int, str, str]:
    """One analysis of a recording whose only topic is :data:`HOSTILE_TOPIC`."""
    d = tmp_path_factory.mktemp("hostile_topic")
    path = hm.imu_file(d / "f.mcap", topics=(HOSTILE_TOPIC,))
    out, err = io.StringIO(), io.StringIO()  # capsys is function-scoped: captured by hand
    old = sys.argv
    args = ["analyze", str(path), "--out", str(d / "out"), "--no-rrd", "--no-loop"]
    sys.argv = ["imupipe", *args, "--topic", HOSTILE_TOPIC]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                main()
            except SystemExit as exc:
                code = exc.code
    finally:
        sys.argv = old
    return d / "out", code, out.getvalue(), err.getvalue()


def test_escape_codes_never_reach_the_terminal(hostile_run) -> None:
    """Item 1: the table names the topic with its control characters escaped."""
    _, code, out, err = hostile_run
    assert code == 0, err
    assert not any(c in out + err for c in RAW)
    assert not any(line.startswith(("imupipe: error", "# Injected")) for line in out.splitlines())
    assert "[/imu\\n# Injected\\nimupipe: error: forged" in out


def test_report_md_shows_input_strings_as_literal_text(hostile_run) -> None:
    """Item 1: no heading, HTML or broken fence comes from a topic into report.md."""
    out_dir = hostile_run[0]
    md = (out_dir / "report.md").read_text()
    prose, _, kalibr = md.partition("## Kalibr")
    assert "# Injected" not in prose.splitlines()
    assert "<img" not in prose.replace("\\<img", "") and "\x1b" not in prose
    assert "\\<img src=x onerror=alert(1)\\> \\`\\`\\`" in prose  # CommonMark escapes
    fence = kalibr.splitlines()[2]
    assert fence.startswith("````") and fence.endswith("yaml")  # longer than the topic's ```
    assert kalibr.rstrip().endswith(fence.removesuffix("yaml"))


# --- 2. path traversal ----------------------------------------------------------------------

HOSTILE_TOPICS = [
    *("..", "/..", ".", "/.", "/", "", "//", "/a/", "imu", "/imu", "/a/b", "/a_b", "/a.b"),
    *("/a%2Fb", "/%%imu", "/imu\x00nul", "/" + "x" * 300, "/" + "x" * 299 + "y", "/ü/\u202e"),
]


def test_topic_folders_are_injective_and_stay_inside_out(tmp_path: Path) -> None:
    names = [topic_folder(t) for t in HOSTILE_TOPICS]
    assert len(set(names)) == len(names)  # /a/b and /a_b no longer share a folder
    for name in names:
        assert name not in ("", ".", "..") and "/" not in name and "\x00" not in name
        assert len(name.encode()) <= 200
        assert (tmp_path / name).resolve().parent == tmp_path.resolve()
    assert topic_folder("/imu0/data_raw") == "imu0.data_raw"


def test_topic_all_with_hostile_names_writes_every_report_inside_out(tmp_path: Path, cli) -> None:
    topics = ("..", "/a/b", "/a_b", "/imu\x00nul", "/" + "x" * 300)
    path = hm.imu_file(tmp_path / "f.mcap", n=2000, topics=topics)
    code, _, err = cli(analyze_args(path, tmp_path / "out", "--topic", "all"))
    assert code == 0, err
    reports = sorted((tmp_path / "out").glob("*/report.json"))
    assert len(reports) == len(topics)
    seen = {json.loads(r.read_text())["input"]["topic"] for r in reports}
    assert seen == set(topics)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.mcap", "out"]


@pytest.mark.parametrize("where", ["parent", "absolute"])
def test_rosbag2_metadata_listing_files_outside_the_bag_is_refused(
    tmp_path: Path, where: str, cli
) -> None:
    outside = hm.imu_file(tmp_path / "outside.mcap")
    bag = tmp_path / "bag"
    bag.mkdir()
    hm.imu_file(bag / "bag_0.mcap")
    entry = "../outside.mcap" if where == "parent" else str(outside)
    (bag / "metadata.yaml").write_text(
        f"rosbag2_bagfile_information:\n  relative_file_paths:\n    - bag_0.mcap\n    - {entry}\n"
    )
    with pytest.raises(InputError, match="outside the bag directory; refusing"):
        decode(bag)
    code, _, err = cli(["info", str(bag)])
    one_error_line(code, err, "outside the bag directory")


# --- 3. nested chunks, 4. bombs and lying sizes, 11. a header claiming 1 TB -----------------


def test_nested_chunks_are_counted_not_unpacked(tmp_path: Path) -> None:
    records = hm.imu_message_records(1, 500)
    extra = tuple(hm.nested_chunk(records, depth) for depth in (2, 3, 400))
    rec = decode(hm.imu_file(tmp_path / "f.mcap", extra=extra))
    assert rec.frames.height == 3000  # the nested frames are not read (nor multiplied)
    assert "skipped 3 unreadable nested chunk record(s)" in rec.warnings


MEASURE_CHILD = """
import json, sys
from imupipe.cli import main
sys.argv = ["imupipe", *sys.argv[1:]]
try:
    main()
except SystemExit as exc:
    code = exc.code
with open("/proc/self/status") as f:
    peak = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))
print(json.dumps({"code": code, "peak": peak}))
"""


def test_decompression_bomb_is_skipped_before_inflating(tmp_path: Path) -> None:
    """Item 4: a 1 GiB zstd bomb (~30 KB in the file) under a 1 GB budget: the whole
    ``imupipe analyze`` child stays under the budget (its VmHWM) and says what it skipped."""
    bomb = hm.bomb_chunk(1 << 30)
    assert len(bomb) < 100_000
    path = hm.imu_file(tmp_path / "f.mcap", extra=(bomb,))
    out = tmp_path / "out"
    child = subprocess.run(
        [sys.executable, "-c", MEASURE_CHILD, *analyze_args(path, out, "--memory-budget-gb", "1")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    result = json.loads(child.stdout.splitlines()[-1])
    assert result["code"] == 0, child.stderr
    assert result["peak"] < 1e9, result
    warnings = json.loads((out / "report.json").read_text())["input"]["warnings"]
    assert any(
        f"it declares {1 << 30} bytes uncompressed" in w and "skipped unread" in w for w in warnings
    ), warnings


def test_chunks_that_lie_about_their_size_are_not_inflated(tmp_path: Path) -> None:
    """Item 4: a chunk header declaring 1000 bytes over 64 MiB of records: refused whether the
    zstd frame states its size (zstandard would allocate it), does not, or it is lz4."""
    size = 64 << 20
    extra = (
        hm.bomb_chunk(size, "zstd", declared_size=1000),
        hm.bomb_chunk(size, "zstd", declared_size=1000, content_size=False),
        hm.bomb_chunk(size, "lz4", declared_size=1000),
    )
    rec = decode(hm.imu_file(tmp_path / "f.mcap", extra=extra))
    assert rec.frames.height == 3000
    lost = [w for w in rec.warnings if w.startswith("a chunk was lost (decompression failed")]
    assert len(lost) == 3, rec.warnings
    assert "its zstd frame declares 67108864 bytes, its header 1000" in lost[0]


@pytest.mark.parametrize("cut", [False, True])
def test_a_header_claiming_a_terabyte_gives_no_message_count(tmp_path: Path, cut: bool) -> None:
    """Item 11: neither a complete nor a cut chunk claiming 1 TB is turned into a count."""
    claim = hm.chunk(bytes(100), declared_size=10**12)
    path = hm.imu_file(tmp_path / "f.mcap", extra=(claim,))
    if cut:  # the file ends 60 bytes into that chunk (its fixed fields are complete)
        with open(path, "r+b") as f:
            f.truncate(path.read_bytes().index(claim) + 60)
    lost = [w for w in decode(path).warnings if w.startswith("a chunk was lost")]
    assert len(lost) == 1 and "an unknown number of messages" in lost[0], lost
    reason = lost[0].split("(", 1)[1]
    assert reason.strip() and not reason.startswith(")")


# --- 5. split bag with two devices, 7. rosbag2 directories ---------------------------------


def test_split_files_with_different_device_metadata_are_refused(tmp_path: Path, cli) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    write_adis(bag / "bag_0.mcap")
    write_adis(bag / "bag_1.mcap", dataclasses.replace(CONFIG, sens_avg=0x0202), seed=2)
    code, _, err = cli(analyze_args(bag, tmp_path / "out"))
    one_error_line(code, err, "bag_1.mcap carries different 'adis16364' metadata")
    assert "gyro_range_dps" in err and "sens_avg" in err


def split_bag(imu_mcap, bag: Path, files: int, n: int = 100) -> Path:
    """``files`` split files of ``n`` consecutive 100 Hz Imu messages each."""
    bag.mkdir()
    for k in range(files):
        log = hm.T0_NS + (k * n + np.arange(n, dtype=np.int64)) * 10_000_000
        imu_mcap(bag / f"bag_{k}.mcap", {"/imu": (log, np.zeros((n, 3)), np.ones((n, 3)))})
    return bag


def test_split_files_without_metadata_are_read_in_natural_order(tmp_path: Path, imu_mcap) -> None:
    rec = decode(split_bag(imu_mcap, tmp_path / "bag", 12))
    t = rec.frames["t_s"].to_numpy()
    assert len(t) == 1200 and np.all(np.diff(t) > 0)  # bag_2 .. bag_9 before bag_10


def test_a_listed_file_that_is_missing_is_warned_about(tmp_path: Path, imu_mcap) -> None:
    bag = split_bag(imu_mcap, tmp_path / "bag", 2)
    (bag / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  relative_file_paths:\n"
        "    - bag_0.mcap\n    - bag_1.mcap\n    - bag_2.mcap\n"
    )
    rec = decode(bag)
    assert rec.frames.height == 200
    assert "metadata.yaml lists bag_2.mcap, which is missing" in rec.warnings


def test_a_fifo_named_mcap_is_refused_not_waited_on(tmp_path: Path, imu_mcap) -> None:
    bag = split_bag(imu_mcap, tmp_path / "bag", 2)
    os.mkfifo(bag / "bag_2.mcap")
    proc = subprocess.run(
        [sys.executable, "-m", "imupipe", "info", str(bag)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    one_error_line(proc.returncode, proc.stderr, "bag_2.mcap: not a regular file")


@pytest.mark.parametrize("kind", ["folder", "dangling link"])
def test_a_split_file_that_is_no_file_exits_2(tmp_path: Path, kind: str, cli, imu_mcap) -> None:
    bag = split_bag(imu_mcap, tmp_path / "bag", 2)
    if kind == "folder":
        (bag / "bag_2.mcap").mkdir()
    else:
        (bag / "bag_2.mcap").symlink_to(tmp_path / "gone.mcap")
    code, _, err = cli(["info", str(bag)])
    one_error_line(code, err, "bag_2.mcap: not a regular file")


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads a file without read permission")
def test_an_unreadable_split_file_exits_2(tmp_path: Path, cli, imu_mcap) -> None:
    bag = split_bag(imu_mcap, tmp_path / "bag", 2)
    (bag / "bag_1.mcap").chmod(0)
    code, _, err = cli(["info", str(bag)])
    one_error_line(code, err, "bag_1.mcap: cannot be read")


# --- 6. atomic outputs ----------------------------------------------------------------------


def snapshot(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()}


def partial_folders(out: Path) -> list[Path]:
    return sorted(out.parent.glob(f".{out.name}.partial-*"))


def test_interrupted_runs_leave_the_old_output_and_no_rrd_leaves_no_stale_recording(
    tmp_path: Path, cli
) -> None:
    """Item 6 (and 9: Ctrl-C says ``imupipe: interrupted``): a second analysis into the same
    --out, stopped by SIGINT, SIGTERM or SIGKILL while it runs, leaves the first one's files
    byte for byte; a finished --no-rrd rerun leaves no recording.rrd of the first."""
    first = hm.imu_file(tmp_path / "a.mcap", n=6000)
    second = hm.imu_file(tmp_path / "b.mcap", n=5000, rate_hz=50.0)
    out = tmp_path / "out"
    code, _, err = cli(["analyze", str(first), "--out", str(out), "--no-loop", "-q"])
    assert code == 0, err
    old = snapshot(out)
    assert "recording.rrd" in old
    expected = {
        signal.SIGINT: (130, "imupipe: interrupted\n"),
        signal.SIGTERM: (143, "imupipe: stopped by SIGTERM\n"),
        signal.SIGKILL: (-signal.SIGKILL, ""),
    }
    for signum, (code, message) in expected.items():
        proc = subprocess.Popen(
            [sys.executable, "-m", "imupipe", "analyze", str(second), "--out", str(out), "-q"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + 120
        while not partial_folders(out) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert partial_folders(out), "the run never started writing"
        time.sleep(0.2)
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=120)
        assert (proc.returncode, stderr) == (code, message), stderr
        assert snapshot(out) == old
        assert len(partial_folders(out)) == (signum == signal.SIGKILL)
    code, _, err = cli(analyze_args(second, out))  # --no-rrd, to completion
    assert code == 0, err
    assert "recording.rrd" not in snapshot(out)
    assert json.loads((out / "report.json").read_text())["input"]["frames"] == 5000
    assert partial_folders(out) == []  # the killed run's leftovers are gone too


def test_default_out_names_do_not_collide(tmp_path: Path, monkeypatch, cli) -> None:
    assert default_out_dir(tmp_path / "calib.day1") != default_out_dir(tmp_path / "calib.day2")
    assert default_out_dir(tmp_path / "calib.day1").name == "calib.day1.imupipe"
    assert default_out_dir(tmp_path / "run.mcap").name == "run.imupipe"
    bag = tmp_path / "bag"
    bag.mkdir()
    hm.imu_file(bag / "f.mcap")
    monkeypatch.chdir(bag)
    code, _, err = cli(["analyze", ".", "--no-rrd", "--no-loop", "-q"])
    assert code == 0, err  # item 8: `analyze .`
    assert (tmp_path / "bag.imupipe" / "report.json").is_file()


# --- 8. careless input: exit 2 and one line -------------------------------------------------


def out_cases(d: Path) -> dict[str, tuple[Path, str]]:
    (d / "a_file").write_text("x")
    (d / "dangling").symlink_to(d / "nowhere")
    (d / "notes").mkdir()
    (d / "notes" / "thesis.tex").write_text("do not delete")
    return {
        "existing file": (d / "a_file", "exists and is not a folder"),
        "dangling link": (d / "dangling", "is a dangling symbolic link"),
        "unwritable": (Path("/proc/imupipe-out"), "cannot write"),
        "foreign folder": (d / "notes", "holds files an analysis does not write"),
    }


@pytest.mark.parametrize("case", ["existing file", "dangling link", "unwritable", "foreign folder"])
def test_an_out_that_cannot_take_the_reports_is_one_line(tmp_path: Path, case, cli) -> None:
    out, expected = out_cases(tmp_path)[case]
    path = hm.imu_file(tmp_path / "f.mcap")
    code, _, err = cli(analyze_args(path, out))
    one_error_line(code, err, expected)
    assert (tmp_path / "notes" / "thesis.tex").read_text() == "do not delete"


def scaled_imu(
    imu_mcap, path: Path, factor: float, alternate: bool = False, glitch: bool = False
) -> Path:
    n = 3000
    rng = np.random.default_rng(5)
    gyro, accel = rng.normal(0, 1e-3, (n, 3)) * factor, rng.normal(0, 1e-2, (n, 3)) * factor
    if alternate:
        gyro[:, 1] = (np.arange(n) % 2) * 1e-3  # a quiet channel flipping one LSB
    if glitch:
        gyro[:, 2] = 0.25
        gyro[1234, 2] = 0.5
    log = hm.T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    return imu_mcap(path, {"/imu": (log, gyro, accel)})


@pytest.mark.parametrize(
    ("factor", "expected"),
    [(1e200, "beyond what float64 Allan sums hold"), (1e-310, "below what float64 Allan sums")],
)
def test_values_float64_cannot_square_are_one_line(tmp_path: Path, factor, expected, cli, imu_mcap):
    path = scaled_imu(imu_mcap, tmp_path / "f.mcap", factor)
    code, _, err = cli(analyze_args(path, tmp_path / "out"))
    one_error_line(code, err, "no axis can be analysed: gyro_x ")
    assert expected in err


def test_an_alternating_lsb_and_a_glitch_are_not_fitted(tmp_path: Path, cli, imu_mcap) -> None:
    """Items 8 and 11: a channel flipping 0/1 LSB and a constant channel with one glitch get
    no fitted N (they are treated like a stuck channel); the other axes are analysed."""
    path = scaled_imu(imu_mcap, tmp_path / "f.mcap", 1.0, alternate=True, glitch=True)
    code, _, err = cli(analyze_args(path, tmp_path / "out"))
    assert code == 0 and "Traceback" not in err and "RuntimeWarning" not in err, err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    warnings = report["input"]["warnings"]
    assert (
        "gyro_y repeats every 2 samples (a deterministic alternation, no noise): "
        "it is not analysed" in warnings
    )
    assert "gyro_z is constant but for 1 sample(s) (glitches?): it is not analysed" in warnings
    assert set(report["axes"]) == {"gyro_x", "accel_x", "accel_y", "accel_z"}


@pytest.mark.parametrize("rate", ["0", "-100", "inf"])
def test_device_metadata_with_an_impossible_rate_is_one_line(tmp_path: Path, rate, cli):
    path = tmp_path / "f.mcap"
    write_adis(path, dataclasses.replace(CONFIG, output_rate_hz=float(rate)))
    code, _, err = cli(analyze_args(path, tmp_path / "out"))
    one_error_line(code, err, f"output_rate_hz {float(rate)} is not a positive rate")


def test_one_topic_with_two_message_types_is_one_line(tmp_path: Path, cli) -> None:
    path = tmp_path / "f.mcap"
    log = hm.T0_NS + np.arange(100, dtype=np.int64) * 10_000_000
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        imu = w.register_channel("/imu", "cdr", w.register_schema(IMU_SCHEMA, "ros2msg", b""))
        adis = w.register_channel("/imu", "cdr", w.register_schema(SCHEMA_NAME, "ros2msg", b""))
        w.write_chunk(imu, log, imu_payloads(log, np.zeros((100, 3)), np.zeros((100, 3))))
        w.write_chunk(adis, log, np.zeros((100, 64), np.uint8))
        w.finish()
    code, _, err = cli(analyze_args(path, tmp_path / "out"))
    one_error_line(code, err, "topic '/imu' carries two message types (imu and adis16364)")


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--memory-budget-gb", "inf"], "--memory-budget-gb must be a finite number"),
        (["--start", "nan"], "the time window needs a finite --start >= 0 and --end (s)"),
        (["--end", "-inf"], "the time window needs a finite --start >= 0 and --end (s)"),
        (["--start", "1e9"], "the window --start 1e+09 --end (last frame) s holds 0 frame(s)"),
    ],
)
def test_analyze_options_that_are_not_finite_are_one_line(tmp_path, args, expected, cli):
    path = hm.imu_file(tmp_path / "f.mcap", n=100)
    code, _, err = cli(analyze_args(path, tmp_path / "out", *args))
    one_error_line(code, err, expected)


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--duration", "nan"], "duration must be a positive, finite length"),
        (["--duration", "1e400"], "duration must be a positive, finite length"),
        (["--rate", "nan"], "output rate must be positive and finite"),
        (["--duration", "1s", "--truth", "."], "--truth . is a folder"),
    ],
)
def test_record_options_that_make_no_recording_are_one_line(tmp_path, args, expected, cli):
    out = tmp_path / "r.mcap"
    code, _, err = cli(["record", "-o", str(out), "-q", *args])
    one_error_line(code, err, expected)


# --- 10. a Temperature topic of another device ----------------------------------------------


def imu_with_temperature(imu_mcap, path: Path, temperature_topic: str, frame: str = "bat") -> Path:
    """An Imu topic /imu/data (frame_id "imu") and a Temperature topic (frame_id ``frame``,
    3 characters) at 31.5 °C."""
    n = 3000
    rng = np.random.default_rng(8)
    log = hm.T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    gyro, accel = rng.normal(0, 1e-3, (n, 3)), rng.normal(0, 1e-2, (n, 3))
    temp = temperature_payloads(log[::100], np.full(30, 31.5), frame)
    return imu_mcap(
        path, {"/imu/data": (log, gyro, accel)}, temperature=(temperature_topic, log[::100], temp)
    )


def test_a_temperature_topic_of_another_device_is_not_the_imus(
    tmp_path: Path, cli, imu_mcap
) -> None:
    rec = decode(imu_with_temperature(imu_mcap, tmp_path / "a.mcap", "/battery/temperature"))
    assert rec.frames["temp_c"].null_count() == 3000  # 31.5 °C of the battery is not used
    assert rec.temperature_topic is None
    path = imu_with_temperature(imu_mcap, tmp_path / "b.mcap", "/imu/temperature")
    code, _, err = cli(analyze_args(path, tmp_path / "out"))
    assert code == 0, err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["input"]["temperature_topic"] == "/imu/temperature"


# --- the property: structurally hostile MCAP ------------------------------------------------

BUDGET_GB = 0.5


def _status(key: str) -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key))


pieces = st.one_of(
    st.tuples(st.just("nested"), st.integers(2, 60)),
    st.tuples(st.just("bomb"), st.integers(70, 200), st.sampled_from(["zstd", "lz4"])),
    st.tuples(st.just("lie"), st.integers(1, 40), st.sampled_from(["zstd", "lz4", "zstd-"])),
    st.tuples(st.just("claim"), st.integers(10**9, 2**63)),
)
hostile_text = st.text(
    st.characters(codec="utf-8", exclude_characters="/"), min_size=1, max_size=40
).map(lambda s: "/imu/" + s)


@settings(
    max_examples=6,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(st.lists(pieces, min_size=1, max_size=3), hostile_text, st.booleans())
def test_structurally_hostile_mcap_is_exit_2_or_a_warning(
    tmp_path: Path, cli, parts, topic: str, cut: bool
) -> None:
    """Nested chunks, bombs beyond the budget, chunks lying about their size, headers claiming
    absurd sizes, a cut tail, a hostile topic: ``imupipe analyze`` exits 0 with a warning for
    each, or 2 with one line; never a traceback, never a raw control character, and the memory
    it takes beyond its start stays within the budget (VmHWM, reset before the run)."""
    records = hm.imu_message_records(1, 300)
    extra = []
    for kind, size, *how in parts:
        if kind == "nested":
            extra.append(hm.nested_chunk(records, size))
        elif kind == "bomb":
            extra.append(hm.bomb_chunk(size << 20, how[0]))
        elif kind == "lie":
            codec = how[0].rstrip("-")
            extra.append(
                hm.bomb_chunk(size << 20, codec, declared_size=999, content_size=how[0] == "zstd")
            )
        else:
            extra.append(hm.chunk(bytes(64), declared_size=size))
    path = hm.imu_file(tmp_path / "f.mcap", n=2000, topics=(topic,), extra=tuple(extra))
    if cut:
        with open(path, "r+b") as f:
            f.truncate(path.stat().st_size - 7)
    out = tmp_path / "out"
    if out.exists():
        shutil.rmtree(out)
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # VmHWM := VmRSS
    before = _status("VmRSS:")
    code, stdout, err = cli(
        analyze_args(path, out, "--memory-budget-gb", str(BUDGET_GB), "--topic", topic)
    )
    assert _status("VmHWM:") - before < BUDGET_GB * 1e9
    assert "Traceback" not in err and "internal error" not in err
    assert not any(c in stdout + err for c in RAW)
    if code == 2:
        assert len(err.splitlines()) == 1 and err.startswith("imupipe: error: ")
    else:
        assert code == 0, err
        assert err.startswith("warning: "), err  # what was skipped is stated


# --- 11. a rate switching from 200 to 100 Hz -----------------------------------------------


def test_a_rate_switch_is_cut_not_averaged_into_jitter(tmp_path: Path, cli, imu_mcap) -> None:
    """White noise of N = 1e-3 rad/s/√Hz, 24000 frames at 200 Hz then 16000 at 100 Hz: the
    200 Hz part is analysed alone and N comes out right (as one series it was ~10 % low)."""
    fast, slow = 24_000, 16_000
    t_ns = np.concatenate(
        [np.arange(fast) * 5_000_000, fast * 5_000_000 + np.arange(1, slow + 1) * 10_000_000]
    )
    rate = np.where(np.arange(fast + slow) < fast, 200.0, 100.0)
    rng = np.random.default_rng(4)
    white = rng.normal(0, 1, (fast + slow, 6)) * (1e-3 * np.sqrt(rate))[:, None]
    log = hm.T0_NS + t_ns
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": (log, white[:, :3], white[:, 3:])})
    code, _, err = cli(analyze_args(path, tmp_path / "out"))
    assert code == 0, err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["input"]["rate_hz"] == pytest.approx(200.0, rel=1e-9)
    assert report["input"]["frames"] == fast  # the switch found to the row, not the block
    assert any(
        w.startswith("the sample rate changes 1 time(s) (200 Hz from frame 0, 100 Hz from frame")
        and w.endswith(f"frames 0..{fast - 1} (200 Hz)")
        for w in report["input"]["warnings"]
    )
    assert not any("jitter" in w for w in report["input"]["warnings"])
    for axis in ("gyro_x", "gyro_y", "gyro_z"):
        n_fit = report["axes"][axis]["ieee952"]["random_walk"]["value"]
        assert n_fit == pytest.approx(1e-3, rel=0.03)


def test_a_temperature_topic_by_frame_id_or_by_choice(tmp_path: Path, cli, imu_mcap) -> None:
    """Item 10: a Temperature topic elsewhere but with the IMU's frame_id is the IMU's; any
    other is used only when named by --temperature-topic; a wrong name is one line."""
    rec = decode(imu_with_temperature(imu_mcap, tmp_path / "a.mcap", "/sensors/temp", frame="imu"))
    assert rec.temperature_topic == "/sensors/temp"
    assert rec.frames["temp_c"].to_numpy() == pytest.approx(31.5)
    path = imu_with_temperature(imu_mcap, tmp_path / "b.mcap", "/battery/temperature")
    args = analyze_args(path, tmp_path / "out", "--temperature-topic", "/battery/temperature")
    code, _, err = cli(args)
    assert code == 0, err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["input"]["temperature_topic"] == "/battery/temperature"
    code, _, err = cli(analyze_args(path, tmp_path / "o2", "--temperature-topic", "/no"))
    one_error_line(code, err, "--temperature-topic '/no' is not a Temperature topic")
    assert "(Temperature topics: /battery/temperature)" in err


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # the swallowed stop
def test_a_stop_whose_exception_python_swallowed_still_keeps_the_old_output(
    tmp_path: Path, monkeypatch
) -> None:
    """SIGTERM landing in a weak-reference callback (importlib's module lock, seen in CI): Python
    prints "Exception ignored" and goes on, and the run used to finish, replace the output and
    exit 0. The stop is remembered and raised before the output is put in place."""
    import weakref

    from imupipe import stopping
    from imupipe.report.staging import staged_output

    monkeypatch.setattr(stopping, "_requested", None)
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.json").write_text("old")

    class Thing:
        pass

    with pytest.raises(stopping.Stopped) as stop, staged_output(out) as tmp:
        (tmp / "report.json").write_text("new")
        thing = Thing()
        ref = weakref.ref(thing, lambda _: stopping.request(signal.SIGTERM, None))
        del thing  # the callback runs here; its Stopped is printed and swallowed
        assert stopping._requested == signal.SIGTERM and ref() is None
    assert stop.value.signum == signal.SIGTERM
    assert (out / "report.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # the staged folder is gone
    # the next command in this process starts with no stop recorded
    previous = stopping.install((signal.SIGUSR1,))
    signal.signal(signal.SIGUSR1, previous[signal.SIGUSR1])
    assert stopping._requested is None
