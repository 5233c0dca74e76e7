"""The column sources (:mod:`imupipe.io.columns`) and the decoded frame's contract.

The spilled source reads the recording once, into a temporary store that is gone afterwards
however the analysis ends; both sources hand out the decoded frame's values.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import imupipe.analysis.analyze as analyze_module
import imupipe.io.columns as columns_module
from imupipe.errors import InputError
from imupipe.io.columns import (
    CONDITION_COLUMNS,
    InMemoryColumns,
    SpilledColumns,
    open_columns,
)
from imupipe.io.decode import DECODED_SCHEMA, decode
from imupipe.progress import StageProgress
from imupipe.vocab import AXES

QUIET = StageProgress(quiet=True)


@pytest.mark.parametrize("kind", ["adis", "ros"])
def test_decoded_frame_has_the_declared_schema(tmp_path: Path, kind, small_recordings) -> None:
    rec = decode(small_recordings.make(kind, tmp_path / "in.mcap"))
    assert rec.frames.schema == DECODED_SCHEMA
    part = decode(tmp_path / "in.mcap", columns=frozenset({"gyro_z", "counter", "t_s"}))
    assert dict(part.frames.schema) == {k: DECODED_SCHEMA[k] for k in part.frames.columns}


@pytest.mark.parametrize("kind", ["adis", "ros"])
def test_sources_hand_out_the_decoded_values(tmp_path: Path, kind, small_recordings) -> None:
    """Each column of a segment, from memory and from the spilled store, equals the whole
    decode's (housekeeping nulls filled the same way); the recording is scanned once."""
    path = small_recordings.make(kind, tmp_path / "in.mcap")
    whole = decode(path).frames
    rows = slice(1_000, 20_000)
    scans = []
    real_scan = columns_module.scan

    def counted(*args, **kwargs):
        scans.append(args[0])
        return real_scan(*args, **kwargs)

    columns_module.scan = counted
    try:
        with open_columns(path, None, QUIET, 0, tmp_path) as spilled:
            assert isinstance(spilled, SpilledColumns)
            cond = spilled.conditioning().frames
            for name in [*AXES, "temp_c", "supply_v"]:
                got = spilled.column(name, rows)
                expected = whole[name][rows].fill_null(strategy="forward")
                expected = expected.fill_null(strategy="backward")
                if expected.null_count() == len(expected):
                    assert got is None, name
                else:
                    np.testing.assert_array_equal(got, expected.to_numpy(), err_msg=name)
            shown = spilled.signals(rows)
    finally:
        columns_module.scan = real_scan
    assert scans == [path]
    assert sorted(cond.columns) == sorted(CONDITION_COLUMNS)
    np.testing.assert_array_equal(cond["t_s"].to_numpy(), whole["t_s"].to_numpy())
    assert shown.height == rows.stop - rows.start  # short: every sample, not an envelope
    with open_columns(path, None, QUIET, 10**12, tmp_path) as memory:
        assert isinstance(memory, InMemoryColumns)
        np.testing.assert_array_equal(memory.column("gyro_y", rows), whole["gyro_y"][rows])
    assert os.listdir(tmp_path) == ["in.mcap"]  # the store is gone


def test_store_is_removed_when_the_analysis_fails(
    tmp_path: Path, monkeypatch, small_recordings
) -> None:
    """An exception (or Ctrl-C) in the middle of the analysis: the columns were on disk in
    the --tmp-dir (one file each, 8 bytes a frame for a float64 axis) and are removed."""
    path = small_recordings.imu_bag(tmp_path / "in.mcap")
    store = tmp_path / "store"
    store.mkdir()
    seen: dict[str, int] = {}

    def interrupted(*args, **kwargs):
        seen.update({f.name: f.stat().st_size for f in store.rglob("*.bin")})
        raise KeyboardInterrupt

    monkeypatch.setattr(analyze_module, "allan_curves", interrupted)
    with pytest.raises(KeyboardInterrupt):
        small_recordings.run(path, tmp_path / "out", 0, tmp_dir=store)
    assert seen["gyro_x.bin"] == seen["stamp_ns.bin"] == 8 * 24_000
    assert seen["nonfinite.bin"] == 24_000
    assert list(store.iterdir()) == []


def test_tmp_dir_must_exist_and_have_room(tmp_path: Path, monkeypatch, small_recordings) -> None:
    path = small_recordings.imu_bag(tmp_path / "in.mcap")
    with pytest.raises(InputError, match="not a directory"):
        small_recordings.run(path, tmp_path / "out", 0, tmp_dir=tmp_path / "missing")

    class Full:
        free = 1_000

    monkeypatch.setattr(columns_module.shutil, "disk_usage", lambda _: Full)
    with pytest.raises(InputError, match="GB of temporary disk"):
        small_recordings.run(path, tmp_path / "out", 0, tmp_dir=tmp_path)
    # in memory, no temporary disk is needed
    report, _ = small_recordings.run(path, tmp_path / "out", 10**12, tmp_dir=tmp_path)
    # frames analysed: all but the NaN at N/2 (the default masks it and the 5 missing frames
    # at N/4)
    assert report["input"]["frames"] == small_recordings.frames - 1


def test_cli_tmp_dir_option(tmp_path: Path, monkeypatch, small_recordings, cli) -> None:
    """``imupipe analyze --tmp-dir``: a directory that is not there is one line, exit 2."""

    path = small_recordings.imu_bag(tmp_path / "in.mcap")
    args = ["analyze", str(path), "-o", str(tmp_path / "o"), "--no-rrd", "-q"]
    code, _, err = cli([*args, "--memory-budget-gb", "0", "--tmp-dir", "/nonexistent"])
    assert code == 2 and err == "imupipe: error: /nonexistent: not a directory (--tmp-dir)\n"
