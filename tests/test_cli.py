"""The command line as a user meets it (issue 3 "CLI behaviour", issue 5 "bad data"): a separate
``python -m imupipe`` process for a representative set of cases (they run concurrently; each pays
~2 s of imports), the same entry point in process for the others: bad input exits 2 with exactly
one line on stderr and no traceback, a good recording exits 0 with its reports."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import typer

from imupipe.cli import app
from imupipe.device.adis16364 import FrameBlock, config_for_rate
from imupipe.errors import ImupipeError
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.recording.recorder import FrameWriter
from imupipe.recording.simulator import VirtualADIS16364

CONFIG = config_for_rate(100.0)


def write_adis(path: Path, block: FrameBlock) -> Path:
    with open(path, "wb") as f:
        writer = FrameWriter(f, CONFIG)
        writer.write(block)
        writer.finish()
    return path


def no_imu(path: Path) -> Path:
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        for topic in ("/chatter", "/rosout"):
            cid = w.register_channel(topic, "cdr", sid)
            w.write_chunk(cid, np.arange(1, 4), np.zeros((3, 12), np.uint8))
        w.finish()
    return path


def make_inputs(d: Path) -> dict[str, tuple[Path, str]]:
    """Each bad input and the start of the one error line it must produce."""
    sim = VirtualADIS16364(CONFIG, None, seed=1)
    (d / "empty.mcap").write_bytes(b"")
    (d / "random.mcap").write_bytes(np.random.default_rng(0).bytes(4096))
    (d / "notes.txt").write_text("gyro bias 0.01 deg/s\n" * 20)
    (d / "no_mcap").mkdir()
    (d / "no_mcap" / "readme.txt").write_text("nothing here\n")
    one = write_adis(d / "one.mcap", sim.frames(1))
    ten = write_adis(d / "ten.mcap", sim.frames(10))
    return {
        "missing": (d / "missing.mcap", "missing.mcap: not a file"),
        "empty": (d / "empty.mcap", "empty.mcap: empty file"),
        "random": (d / "random.mcap", "random.mcap is not an MCAP file (bad magic)"),
        "text": (d / "notes.txt", "notes.txt is not an MCAP file (bad magic)"),
        "dir": (d / "no_mcap", "no_mcap: a directory without MCAP or .db3 files"),
        "no_imu": (
            no_imu(d / "chat.mcap"),
            "chat.mcap: no IMU topic (topics in the file: /chatter, /rosout)",
        ),
        "one_frame": (one, "one.mcap: 1 frame(s), too few for any averaging time"),
        "ten_frames": (ten, "ten.mcap: the longest clean segment has 10 frames, too few"),
    }


def imupipe(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "imupipe", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


SUBPROCESS = {"missing", "random", "no_imu", "one_frame"}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("cli")


@pytest.fixture(scope="module")
def cases(workdir: Path) -> dict[str, tuple[list[str], str]]:
    """Each bad input: the arguments and the text its one error line must hold."""
    inputs = make_inputs(workdir)
    out = {
        name: (["analyze", str(p), "--no-rrd", "-q", "--out", str(workdir / name)], expected)
        for name, (p, expected) in inputs.items()
    }
    out["info_missing"] = (["info", str(workdir / "missing.mcap")], "missing.mcap: not a file")
    out["info_text"] = (["info", str(workdir / "notes.txt")], "notes.txt is not an MCAP file")
    return out


@pytest.fixture(scope="module")
def runs(workdir: Path, cases) -> dict[str, tuple[int, str, str]]:
    """The subprocess cases, a good recording and a usage error, run concurrently."""
    good = write_adis(workdir / "good.mcap", VirtualADIS16364(CONFIG, None, seed=2).frames(6000))
    args = {name: cases[name][0] for name in SUBPROCESS}
    args["good"] = ["analyze", str(good), "--no-rrd", "--no-loop", "--out", str(workdir / "good")]
    args["bad_option"] = ["analyze", str(good), "--gaps", "sometimes"]
    procs = {name: imupipe(*a) for name, a in args.items()}
    out = {}
    for name, proc in procs.items():
        stdout, stderr = proc.communicate(timeout=120)
        out[name] = (proc.returncode, stdout, stderr)
    return out


@pytest.mark.parametrize(
    "case",
    [
        *("missing", "empty", "random", "text", "dir", "no_imu", "one_frame", "ten_frames"),
        *("info_missing", "info_text"),
    ],
)
def test_bad_input_exits_2_with_one_line(runs, cases, case: str, cli) -> None:
    args, expected = cases[case]
    code, stdout, stderr = runs[case] if case in SUBPROCESS else cli(args)
    assert code == 2, stderr
    assert "Traceback" not in stderr
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("imupipe: error: ") and expected in lines[0], lines[0]
    assert stdout == ""


def test_usage_error_is_short_and_not_a_traceback(runs) -> None:
    code, _, stderr = runs["bad_option"]
    assert code == 2 and "Traceback" not in stderr
    assert "'sometimes' is not one of 'auto', 'longest', 'fail', 'mask'" in stderr


def test_good_recording_exits_0_with_reports(runs, workdir: Path) -> None:
    code, stdout, stderr = runs["good"]
    assert code == 0, stderr
    assert stderr == ""  # a clean recording: no warnings
    out = workdir / "good"
    report = json.loads((out / "report.json").read_text())
    assert report["input"]["frames"] == 6000 and report["input"]["warnings"] == []
    taus = report["axes"]["gyro_x"]["allan"]["tau_s"]  # 10 a decade, 0.01 s to T/4 = 15 s
    assert (len(taus), taus[:3], taus[-1]) == (32, [0.01, 0.02, 0.03], 12.59)
    for name in ("report.md", "allan.parquet", "imu.yaml"):
        assert (out / name).is_file()
    assert not (out / "recording.rrd").exists()  # --no-rrd
    assert f"reports written to {out}/" in stdout


CONSOLE_SCRIPT = """
import atexit, sys, threading, time
from pathlib import Path
from imupipe.cli import console
done = Path(sys.argv[1])
def late_write():
    time.sleep(0.3)
    done.write_text("written")
threading.Thread(target=late_write).start()
atexit.register(print, "exit handler ran")
print("buffered line", end="")
sys.argv = ["imupipe", *sys.argv[2:]]
console()
print("never reached")
"""


@pytest.mark.parametrize(("args", "status"), [(["info", "/nonexistent.mcap"], 2), (["--help"], 0)])
def test_console_skips_finalization_but_keeps_status_threads_handlers_and_output(
    tmp_path: Path, args: list[str], status: int
) -> None:
    """``imupipe`` ends with ``os._exit`` (no interpreter finalization): main's exit status,
    a non-daemon thread's late write, an atexit handler and unflushed stdout all survive."""
    done = tmp_path / "late.txt"
    proc = subprocess.run(
        [sys.executable, "-c", CONSOLE_SCRIPT, str(done), *args],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == status, proc.stderr
    assert done.read_text() == "written"
    assert proc.stdout.startswith("buffered line")
    assert proc.stdout.rstrip().endswith("exit handler ran")
    assert "never reached" not in proc.stdout
    assert ("nonexistent.mcap: not a file" in proc.stderr) == (status == 2)


def test_the_command_is_the_console_entry_point() -> None:
    from importlib.metadata import entry_points

    (script,) = entry_points(group="console_scripts", name="imupipe")
    assert script.value == "imupipe.cli:console"


def test_version_is_the_installed_distributions_and_the_reports_generator(cli) -> None:
    """``imupipe --version`` prints the version ``report.json`` names as its generator, which
    is the installed distribution's (pyproject.toml's) too, and exits 0 without a command."""
    from importlib.metadata import version

    import imupipe

    assert cli(["--version"]) == (0, f"imupipe {version('imupipe')}\n", "")
    assert imupipe.__version__ == version("imupipe")


def test_fleet_passes_the_time_window_to_every_unit(tmp_path: Path, cli, monkeypatch) -> None:
    """``imupipe fleet --start 600 --end -300``: every unit's analysis gets the window (as
    ``imupipe analyze`` does); run_fleet stands in for the cluster."""
    import imupipe.fleet.run as fleet_run

    seen = {}

    def stand_in(recordings, out, **kw):
        seen.update(kw)
        raise ImupipeError("stop here")

    monkeypatch.setattr(fleet_run, "run_fleet", stand_in)
    code, _, err = cli(["fleet", str(tmp_path), "--out", str(tmp_path / "f"), "-q",
                        "--start", "600", "--end", "-300"])  # fmt: skip
    assert code == 2 and "stop here" in err
    assert (seen["options"].start_s, seen["options"].end_s) == (600.0, -300.0)


def test_fleet_defaults_and_a_failed_unit(tmp_path: Path, cli, monkeypatch) -> None:
    """Without options every unit is analysed whole under a 2 GB budget; a failed unit is a
    warning naming it, and the fleet ends with one line and exit 2 (a fleet without failures
    exits 0)."""
    import imupipe.fleet.run as fleet_run
    from imupipe.fleet.task import UnitOutcome

    seen = {}
    bad = UnitOutcome("u2", "u2.mcap", "failed", "u2.mcap: not MCAP", None, None, 1.0, "")
    good = UnitOutcome("u1", "u1.mcap", "ok", None, None, None, 1.0, "")

    def stand_in(recordings, out, **kw):
        seen.update(kw)
        units = [good, bad] if seen.get("fail") else [good]
        return fleet_run.FleetResult(units, [], {}, Path(out), 3.0)

    monkeypatch.setattr(fleet_run, "run_fleet", stand_in)
    code, out, err = cli(["fleet", str(tmp_path), "--out", str(tmp_path / "f")])
    options = seen["options"]
    assert code in (0, None) and err == ""
    assert (options.start_s, options.end_s, options.memory_budget_bytes) == (0.0, None, 2 * 10**9)
    assert (options.taus_per_decade, options.loop, options.rrd) == (10, True, True)
    assert f"1 of 1 recordings analysed in 3.0 s; fleet report in {tmp_path / 'f'}/fleet.md" in out
    seen["fail"] = True
    code, out, err = cli(["fleet", str(tmp_path), "--out", str(tmp_path / "f")])
    assert code == 2
    assert err == (
        "warning: u2: u2.mcap: not MCAP\n"
        f"imupipe: error: 1 of 2 recordings failed (listed in {tmp_path / 'f'}/fleet.md)\n"
    )


def test_record_says_what_it_wrote(tmp_path: Path, cli) -> None:
    """``imupipe record`` ends with one line: the file, its frames, duration, rate, rate method
    and size in MB."""
    path = tmp_path / "run.mcap"
    code, out, err = cli(["record", "-o", str(path), "--duration", "60s", "--rate", "100"])
    assert code in (0, None)
    size_mb = path.stat().st_size / 1e6
    assert 0.1 < size_mb < 1  # shown to 0.1 MB
    assert "live view" not in out + err  # said only with --serve
    assert f"{path}: 6000 frames, 60.0 s at 100 Hz (host_poll), {size_mb:.1f} MB\n" in out + err


def test_demo_records_and_analyses_into_its_folder(tmp_path: Path, cli) -> None:
    """``imupipe demo`` (the README's main job, here 2 min instead of 12 h): the recording,
    the simulator's truth and the reports in the folder, and the paper's table printed beside
    the measured one."""
    out = tmp_path / "demo"
    out.mkdir()  # a folder the user made first
    code, printed, _ = cli(["demo", "--out", str(out), "--duration", "2m"])
    assert code in (0, None)
    report = json.loads((out / "adis16364.imupipe" / "report.json").read_text())
    assert report["input"]["frames"] == 12_000
    assert report["input"]["path"] == str(out / "adis16364.mcap")
    truth = json.loads((out / "truth.json").read_text())
    assert truth["noise"]["gyro_x"]["paper_units"]["random_walk"] == 0.05
    assert f"{out / 'adis16364.mcap'}: 12000 frames, 120.0 s at 100 Hz" in printed
    assert f"reports written to {out / 'adis16364.imupipe'}/" in printed
    assert (
        "quantity            axis     measured [95 % interval]    paper   datasheet  unit"
        in printed
    )
    assert "\nBias (mean)         accel_z  " in printed and "  -998.6  —          mg\n" in printed


EXITS_SCRIPT = """
import sys
import imupipe.cli as cli
code = {"none": None, "text": "the message"}[sys.argv[1]]
def main():
    sys.exit(code)
cli.main = main
cli.console()
"""


@pytest.mark.parametrize(("how", "status", "said"), [("none", 0, ""), ("text", 1, "the message\n")])
def test_console_exit_status_of_no_code_and_of_a_message(how: str, status: int, said: str) -> None:
    """``sys.exit()`` ends the command with status 0; ``sys.exit("text")`` prints the text
    on stderr and ends with status 1, as the interpreter would."""
    proc = subprocess.run(
        [sys.executable, "-c", EXITS_SCRIPT, how], capture_output=True, text=True, timeout=120
    )
    assert (proc.returncode, proc.stderr) == (status, said)


def test_every_argument_and_option_says_what_it_is() -> None:
    """``imupipe COMMAND --help`` explains every parameter of every command (two had none)."""
    group = typer.main.get_command(app)
    silent = [
        f"{name} {param.name}"
        for name, command in group.commands.items()
        for param in command.params
        if not (getattr(param, "help", None) or "").strip()
    ]
    assert silent == []
