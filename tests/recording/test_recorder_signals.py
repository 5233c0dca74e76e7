"""``imupipe record`` under signals and a full disk (issue 5): SIGINT/SIGTERM finish a valid file,
SIGKILL at real-time pace loses at most ~1 s, no room to write is one clear line and the chunks
written so far stay readable."""

from __future__ import annotations

import re
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from imupipe.io.decode import decode

RATE_HZ = 100.0


def start_recorder(out: Path, *extra: str, **popen) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "imupipe", "record", "-o", str(out), "-q", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


def wait_for_first_chunk(out: Path, timeout_s: float = 120.0) -> float:
    """Wall time at which the recorder had written its first chunk (file past its header)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if out.exists() and out.stat().st_size > 1500:  # header+schema+channel+metadata ≈ 1.3 kB
            return time.monotonic()
        time.sleep(0.02)
    raise AssertionError(f"{out} never grew past its header")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_sigint_sigterm_finish_a_valid_file(tmp_path: Path, signum: int) -> None:
    out = tmp_path / "f.mcap"
    proc = start_recorder(out, "--duration", "1h", "--realtime")
    wait_for_first_chunk(out)
    time.sleep(1.5)
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signum, stderr  # shell convention: stopped by a signal
    assert "Traceback" not in stderr
    name = signal.Signals(signum).name
    assert re.fullmatch(
        rf"warning: {name}: recorded \d+ of 360000 frames; file finished\n", stderr
    ), stderr
    with open(out, "rb") as f:  # the indexed reader needs the summary and footer
        reader = make_reader(f)
        stats = reader.get_summary().statistics
        assert stats.message_count == sum(1 for _ in reader.iter_messages())
    assert 100 <= stats.message_count <= 600  # ~2–3 s of real time at 100 Hz
    rec = decode(out)
    assert rec.frames.height == stats.message_count and rec.warnings == []
    rerun = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    check = subprocess.run([rerun, "mcap", "check", str(out)], capture_output=True, text=True)
    assert check.returncode == 0, check.stderr


@pytest.mark.parametrize("rate_hz", [RATE_HZ, 10.0])
def test_sigkill_at_real_time_loses_at_most_a_second(tmp_path: Path, rate_hz: float) -> None:
    # at 10 Hz a second of frames is far smaller than any write buffer: only the flush after
    # each chunk puts it on disk
    out = tmp_path / "f.mcap"
    proc = start_recorder(out, "--duration", "1h", "--realtime", "--rate", str(rate_hz))
    t_first = wait_for_first_chunk(out)
    sizes = []
    for _ in range(2):  # each second's chunk reaches the file in its second
        time.sleep(1.3)
        sizes.append(out.stat().st_size)
    t_kill = time.monotonic()
    proc.kill()
    proc.wait(timeout=10)
    elapsed_s = t_kill - t_first
    rec = decode(out)  # no summary, no footer: the linear scan recovers every chunk
    assert any("no footer" in w for w in rec.warnings)
    assert sizes[0] > 1500 and sizes[1] > sizes[0], f"file sizes {sizes}: chunks not flushed"
    frames = rec.frames.height
    print(f"SIGKILL after {elapsed_s:.2f} s of recording: {frames} frames recovered")
    # The first chunk (one second of frames) is written at t_first, then one chunk per second:
    # every second of real time before the kill is in the file, except the one being collected.
    assert frames >= (elapsed_s - 1.0) * rate_hz
    counters = rec.frames["counter"].to_numpy()
    assert (counters == range(frames)).all()


def test_full_disk_is_one_line(tmp_path: Path) -> None:
    proc = start_recorder(Path("/dev/full"), "--duration", "60s")
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    assert lines[0].startswith("imupipe: error: no room to write /dev/full (No space left")


def _limit_file_size(limit_bytes: int):
    def preexec() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of death by SIGXFSZ

    return preexec


def test_file_size_limit_keeps_the_file_so_far_readable(tmp_path: Path) -> None:
    out = tmp_path / "f.mcap"
    limit = 1_000_000  # 10 min at 100 Hz is 4 chunks of ≤ 16384 frames, ~0.6 MB each
    proc = start_recorder(out, "--duration", "10m", preexec_fn=_limit_file_size(limit))
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "File too large" in lines[0], stderr
    assert "remain readable" in lines[0]
    stopped_after = int(re.search(r"stopped after (\d+) frames", lines[0]).group(1))
    assert 0 < stopped_after < 60000
    assert out.stat().st_size == limit  # written up to the limit, cut mid-chunk
    rec = decode(out)
    assert rec.frames.height == stopped_after  # every chunk the recorder finished
    assert any("cut off by the end of the file" in w for w in rec.warnings)
