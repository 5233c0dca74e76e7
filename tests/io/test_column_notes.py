"""What the low-memory path tells the user and hands the report, value by value: its notes,
the raw signals' envelope, the temporary disk it asks for, and the errors it turns into one
line (:mod:`imupipe.io.columns`)."""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest

import imupipe.io.columns as columns_module
from imupipe.errors import InputError
from imupipe.io.columns import (
    ENVELOPE_BINS,
    PEAK_BYTES_PER_FRAME,
    SIGNALS,
    InMemoryColumns,
    SpilledColumns,
    envelope,
    envelope_times,
    message_count,
    open_columns,
    peak_estimate,
)
from imupipe.progress import StageProgress

QUIET = StageProgress(quiet=True)


def test_notes_give_the_estimate_budget_store_and_envelope(tmp_path: Path, small_recordings):
    path = small_recordings.make("adis", tmp_path / "in.mcap")  # temperature and supply too
    with open_columns(path, None, QUIET, 0, tmp_path) as spilled:
        assert spilled.spilled is True
        source = SpilledColumns(spilled.scanned, estimate=2_500_000_000, budget=1_500_000_000)
        store = source.disk_bytes()
        first = (
            "low-memory path: the whole frame would need ~2.50 GB (budget 1.50 GB); decoded "
            f"once into a temporary on-disk store ({store / 1e9:.2f} GB) and analysed"
        )
        assert source.notes(2 * ENVELOPE_BINS, rrd=True) == [f"{first} one axis at a time"]
        assert source.notes(2 * ENVELOPE_BINS + 1, rrd=True, at_once=2) == [
            f"{first} 2 axes at a time",
            "recording.rrd shows the raw signals as a min/max envelope of 100000 bins "
            "(3 samples each) (low-memory path)",
        ]
        assert source.notes(3 * ENVELOPE_BINS, rrd=True)[1].endswith(
            "(3 samples each) (low-memory path)"
        )
        assert len(source.notes(10**9, rrd=False)) == 1  # no rrd, no envelope note
        rows = slice(100, 5_000)
        assert list(spilled.signals(rows).columns) == list(SIGNALS)
        part = spilled.column("gyro_x", rows)
        assert part.base is None  # a copy: nothing keeps the whole mapped column alive
    assert InMemoryColumns.spilled is False


def test_envelope_is_the_samples_up_to_two_per_bin_then_min_max_from_the_first():
    t = np.arange(20) * 0.5
    y = np.arange(20.0)
    assert envelope(y, bins=10) is y and envelope_times(t, bins=10) is t
    np.testing.assert_array_equal(envelope(y[:21], bins=10), y)
    y21, t21 = np.arange(21.0), np.arange(21) * 0.5
    np.testing.assert_array_equal(envelope(y21, bins=10)[:4], [0.0, 2.0, 3.0, 5.0])
    np.testing.assert_array_equal(envelope_times(t21, bins=10)[:4], [0.0, 0.5, 1.5, 2.0])


def test_the_temporary_disk_asked_for_is_the_estimate_in_frames(tmp_path, monkeypatch):
    """The spill is sized for estimate / 210 bytes a frame, at 65 bytes a frame on disk; short
    of it, one line with both figures."""
    path = tmp_path / "in.mcap"
    path.write_bytes(b"\x00" * 4_000)  # no readable summary: 4000 / 40 bytes a frame
    assert message_count(path) == 100
    assert peak_estimate([path]) == 100 * PEAK_BYTES_PER_FRAME

    class Disk:
        free = 1_500_000_000

    monkeypatch.setattr(columns_module.shutil, "disk_usage", lambda _: Disk)
    with pytest.raises(InputError) as error:
        with columns_module._spill_directory(tmp_path, 3_000_000_000 // 65):
            pass
    assert str(error.value) == (
        f"{tmp_path}: 1.5 GB free, the low-memory path needs ~3.0 GB of temporary disk "
        "(choose another place with --tmp-dir)"
    )
    asked: list[int] = []

    def spill_directory(tmp_dir, frames):
        asked.append(frames)
        raise InputError("stop")

    monkeypatch.setattr(columns_module, "_spill_directory", spill_directory)
    with pytest.raises(InputError, match="stop"):
        with open_columns(path, None, QUIET, 0, tmp_path):
            pass
    assert asked == [100]


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT])
def test_a_full_disk_while_spilling_is_one_line(tmp_path, monkeypatch, small_recordings, code):
    path = small_recordings.make("ros", tmp_path / "in.mcap")

    def full(*args, **kwargs):
        raise OSError(code, "No space left on device")

    monkeypatch.setattr(columns_module, "scan", full)
    with pytest.raises(InputError, match="cannot write the temporary columns: No space left"):
        with open_columns(path, None, QUIET, 0, tmp_path):
            pass


def test_other_os_errors_while_spilling_are_not_disguised(tmp_path, monkeypatch, small_recordings):
    path = small_recordings.make("ros", tmp_path / "in.mcap")

    def denied(*args, **kwargs):
        raise OSError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(columns_module, "scan", denied)
    with pytest.raises(PermissionError):
        with open_columns(path, None, QUIET, 0, tmp_path):
            pass
