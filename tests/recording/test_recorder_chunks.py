"""The recorder in process: how frames are cut into chunks (what a SIGKILL can lose), the summary a
user is shown, pacing of a simulated real-time recording, SIGTERM finishing the file, write
errors as one line, durations as typed, the truth file.  Pacing runs on a stand-in clock (no
timed test).  (The subprocess tests with real signals
and a full disk are tests/test_recorder_signals.py.)"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from imupipe.device.adis16364 import DeviceConfig, FrameBlock
from imupipe.errors import ImupipeError
from imupipe.io.decode import decode
from imupipe.recording import recorder
from imupipe.recording.recorder import FAST_CHUNK_FRAMES, parse_duration, record, write_truth

T0 = 1_700_000_000_000_000_000


class Source:
    """Frames with a running counter; ``on_call`` runs before the n-th call's frames (1-based)."""

    def __init__(self, rate_hz: float = 100.0, source: str = "spi", on_call=None) -> None:
        self.config = DeviceConfig(output_rate_hz=rate_hz, source=source, rate_method="smpl_prd")
        self.sizes: list[int] = []
        self.on_call = on_call or {}
        self.done = 0

    def frames(self, n: int) -> FrameBlock:
        self.sizes.append(n)
        if len(self.sizes) in self.on_call:
            self.on_call[len(self.sizes)]()
        k = self.done + np.arange(n)
        self.done += n
        burst = np.zeros((n, 11), np.uint16)
        burst[:, 4] = k % 1000  # XACCL_OUT counts
        return FrameBlock(
            stamp_ns=T0 + k.astype(np.int64) * 10_000_000,
            counter=k.astype(np.uint32),
            burst=burst,
            diag_stat=np.zeros(n, np.uint16),
            diag_valid=np.zeros(n, bool),
        )


def _chunks(path: Path) -> list[int]:
    """Messages per chunk, from the file's summary (the file must be finished)."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    starts = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert summary.statistics.chunk_count == len(starts)
    return [int((c.message_end_time - c.message_start_time) // 10_000_000) + 1 for c in starts]


def test_fast_recording_uses_large_chunks_and_reports_every_frame(tmp_path: Path) -> None:
    seen: list[int] = []
    src = Source(rate_hz=100.0)
    n = 2 * FAST_CHUNK_FRAMES + 7
    s = record(tmp_path / "f.mcap", src, n, progress=seen.append)
    assert FAST_CHUNK_FRAMES == 16384
    assert src.sizes == [16384, 16384, 7]
    assert _chunks(tmp_path / "f.mcap") == [16384, 16384, 7]
    assert seen == [16384, 32768, 32775]
    assert (s.frames, s.requested, s.chunks, s.stop_signal) == (n, n, 3, None)
    assert s.duration_s == pytest.approx(327.75, rel=1e-12) and s.rate_hz == 100.0
    assert s.rate_method == "smpl_prd" and s.path == tmp_path / "f.mcap"
    frames = decode(tmp_path / "f.mcap").frames
    assert np.array_equal(frames["counter"].to_numpy(), np.arange(n))
    # 1 mg/LSB of XACCL_OUT in m/s²
    assert frames["accel_x"][999] == pytest.approx(999 * 1e-3 * 9.80665, rel=1e-15)


@pytest.mark.parametrize(
    ("rate_hz", "n", "sizes"),
    [(10.0, 35, [10, 10, 10, 5]), (4.4, 9, [4, 4, 1]), (0.4, 3, [1, 1, 1])],
)
def test_real_time_chunks_hold_one_second(
    tmp_path: Path, rate_hz: float, n: int, sizes: list[int]
) -> None:
    # a real source paces itself (no sleep here): chunks of round(rate) frames, at least one,
    # so a recorder killed with SIGKILL loses at most about one second
    src = Source(rate_hz=rate_hz, source="spi")
    s = record(tmp_path / "f.mcap", src, n, realtime=True)
    assert src.sizes == sizes
    assert _chunks(tmp_path / "f.mcap") == sizes
    assert (s.frames, s.chunks) == (n, len(sizes))
    assert s.duration_s == pytest.approx(n / rate_hz, rel=1e-12)


class Clock:
    """Stands in for the recorder's ``time``: ``sleep`` advances ``monotonic`` and is logged,
    and each chunk "takes" ``work_s`` of the clock."""

    def __init__(self, work_s: float = 0.0) -> None:
        self.now, self.work_s, self.sleeps = 100.0, work_s, []

    def monotonic(self) -> float:
        self.now += self.work_s
        return self.now

    def sleep(self, s: float) -> None:
        self.sleeps.append(round(s, 9))
        self.now += s


@pytest.mark.parametrize(
    ("source", "realtime", "sleeps"),
    [("sim", True, [1.0, 1.0, 0.5]), ("sim", False, []), ("spi", True, []), ("hw", True, [])],
)
def test_only_a_simulated_real_time_recording_is_paced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, source: str, realtime: bool, sleeps: list
) -> None:
    clock = Clock()
    monkeypatch.setattr(recorder, "time", clock)
    s = record(tmp_path / "f.mcap", Source(rate_hz=10.0, source=source), 25, realtime=realtime)
    assert s.frames == 25
    assert clock.sleeps == sleeps  # chunk k ends at k s of frames: sleep until then


def test_pacing_subtracts_the_time_already_spent(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    clock = Clock(work_s=0.125)  # every clock reading is 0.125 s after the previous one
    monkeypatch.setattr(recorder, "time", clock)
    record(tmp_path / "f.mcap", Source(rate_hz=10.0, source="sim"), 20, realtime=True)
    # start at 100.125; chunk 1 done at 100.25: 1 - 0.125 ahead; chunk 2 read at 101.25: 0.875
    assert clock.sleeps == [0.875, 0.875]
    slow = Clock(work_s=2.0)  # behind real time: no sleep
    monkeypatch.setattr(recorder, "time", slow)
    record(tmp_path / "g.mcap", Source(rate_hz=10.0, source="sim"), 20, realtime=True)
    assert slow.sleeps == []


def test_sigterm_stops_after_the_current_chunk_and_finishes_the_file(tmp_path: Path) -> None:
    previous = signal.getsignal(signal.SIGTERM)
    src = Source(on_call={2: lambda: os.kill(os.getpid(), signal.SIGTERM)})
    s = record(tmp_path / "f.mcap", src, 5 * FAST_CHUNK_FRAMES)
    assert s.stop_signal == signal.SIGTERM
    assert (s.frames, s.chunks, s.requested) == (2 * FAST_CHUNK_FRAMES, 2, 5 * FAST_CHUNK_FRAMES)
    assert _chunks(tmp_path / "f.mcap") == [FAST_CHUNK_FRAMES] * 2  # summary and footer written
    assert signal.getsignal(signal.SIGTERM) is previous  # handlers restored afterwards


def test_signal_during_the_last_chunk_still_completes(tmp_path: Path) -> None:
    # every requested frame was recorded: a complete recording, not one stopped by the signal
    src = Source(on_call={1: lambda: os.kill(os.getpid(), signal.SIGINT)})
    s = record(tmp_path / "f.mcap", src, 3)
    assert (s.frames, s.chunks, s.stop_signal) == (3, 1, None)
    src = Source()
    s = record(tmp_path / "g.mcap", src, 0)
    assert (s.frames, s.chunks, s.stop_signal, src.sizes) == (0, 0, None, [])


def test_write_errors_are_one_line(tmp_path: Path) -> None:
    with pytest.raises(ImupipeError, match=r"^cannot write .*missing/f\.mcap: No such file"):
        record(tmp_path / "missing" / "f.mcap", Source(), 10)
    with pytest.raises(ImupipeError, match=r"^no room to write /dev/full \(No space left on dev"):
        record(Path("/dev/full"), Source(), 3 * FAST_CHUNK_FRAMES)

    def broken() -> None:
        raise OSError(5, "Input/output error")

    with pytest.raises(ImupipeError, match=r"^error writing .*f\.mcap: Input/output error$"):
        record(tmp_path / "f.mcap", Source(on_call={2: broken}), 3 * FAST_CHUNK_FRAMES)


@pytest.mark.parametrize(
    ("text", "seconds"),
    [("12h", 43200.0), ("30m", 1800.0), ("90s", 90.0), ("1.5h", 5400.0), (" 2H ", 7200.0),
     ("45", 45.0), ("0.25", 0.25)],
)  # fmt: skip
def test_durations(text: str, seconds: float) -> None:
    assert parse_duration(text) == seconds


@pytest.mark.parametrize(
    ("text", "message"),
    [("abc", "cannot read duration 'abc'"), ("", "cannot read duration ''"),
     ("h", "cannot read duration 'h'"), ("0s", "must be a positive"), ("-1m", "must be a positive"),
     ("inf", "must be a positive"), ("nan", "must be a positive")],
)  # fmt: skip
def test_bad_durations(text: str, message: str) -> None:
    with pytest.raises(ImupipeError, match=message):
        parse_duration(text)


def test_truth_file(tmp_path: Path) -> None:
    write_truth(tmp_path / "t.json", {"b": 1, "a": [0.5]})
    text = (tmp_path / "t.json").read_text()
    assert text == '{\n  "a": [\n    0.5\n  ],\n  "b": 1\n}\n'
    assert json.loads(text) == {"a": [0.5], "b": 1}
    message = r"^cannot write the truth file .*nope/t\.json: No such file or directory$"
    with pytest.raises(ImupipeError, match=message):
        write_truth(tmp_path / "nope" / "t.json", {})
