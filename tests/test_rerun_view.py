"""The Rerun recording: bulk signals, log-log Allan view, blueprint; `rerun rrd verify` passes."""

from __future__ import annotations

import re
import subprocess
import time
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from test_report import synthetic_result

from imupipe.errors import ViewerError
from imupipe.report.rerun_view import open_viewer, rerun_executable, signal_columns, write_rrd


def _frames(n: int, ros: bool = False) -> pl.DataFrame:
    rng = np.random.default_rng(7)
    cols = {"t_s": np.arange(n) / 100.0}
    for name in ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"):
        cols[name] = rng.normal(0.0, 1e-2, n)
    cols["temp_c"] = 25.0 + np.cumsum(rng.normal(0, 1e-3, n))
    frame = pl.DataFrame(cols)
    if ros:  # a ROS bag without SUPPLY_OUT and with a null temperature column
        return frame.with_columns(pl.lit(None, dtype=pl.Float64).alias("temp_c"))
    return frame.with_columns(supply_v=pl.Series(np.full(n, 5.0)))


def _verify(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [rerun_executable(), "rrd", "verify", str(path)], capture_output=True, text=True
    )


def _chunks(path: Path) -> dict[str, int]:
    """{entity path: rows} of the data (not blueprint) chunks, from `rerun rrd print`."""
    out = subprocess.run(
        [rerun_executable(), "rrd", "print", str(path)], capture_output=True, text=True, check=True
    ).stdout
    chunks: dict[str, int] = {}
    for line in out.splitlines():
        match = re.match(r"Chunk\(\S+\) with (\d+) rows .* - (/\S+) - ", line)
        if match and match[2].split("/")[1] in ("signals", "allan", "residual", "summary"):
            chunks[match[2]] = max(chunks.get(match[2], 0), int(match[1]))
    return chunks


def test_rrd_verifies_and_holds_every_signal(tmp_path: Path) -> None:
    frames = _frames(20_000)
    path = write_rrd(synthetic_result(), frames, tmp_path / "recording.rrd")
    done = _verify(path)
    assert done.returncode == 0, done.stdout + done.stderr
    chunks = _chunks(path)
    for group in ("gyro", "accel", "housekeeping"):
        assert chunks[f"/signals/{group}"] == 20_000  # every raw frame, in one bulk chunk
    for axis in ("gyro_x", "gyro_y", "gyro_z", "accel_y", "accel_z"):
        sensor = axis.split("_")[0]
        for part in ("adev", "interval", "model"):
            assert f"/allan/{sensor}/{axis}/{part}" in chunks
    for part in ("adev", "interval", "model_before", "model_after"):
        assert f"/allan/accel/accel_x/{part}" in chunks
    assert {"/allan/gyro/grid", "/allan/gyro/grid_labels", "/summary"} <= set(chunks)
    assert {"/residual/accel/accel_x/z_before", "/residual/accel/accel_x/z_after"} <= set(chunks)
    assert not any(p.startswith("/residual/gyro") for p in chunks)  # no loop on the gyros


def test_ros_frames_without_temperature_or_supply(tmp_path: Path) -> None:
    frames = _frames(5_000, ros=True)
    assert list(signal_columns(frames)) == ["gyro", "accel"]
    path = write_rrd(synthetic_result(with_loop=False), frames, tmp_path / "ros.rrd")
    done = _verify(path)
    assert done.returncode == 0, done.stdout + done.stderr


def test_bulk_logging_is_fast(tmp_path: Path) -> None:
    """1 M frames x 8 columns in well under the 12 h budget share (bulk send_columns)."""
    frames = _frames(1_000_000)
    start = time.perf_counter()
    write_rrd(synthetic_result(), frames, tmp_path / "big.rrd")
    elapsed = time.perf_counter() - start
    assert elapsed < 5.0, f"{elapsed:.1f} s for 1 M frames"


def test_open_viewer_refuses_a_folder_without_recording(tmp_path: Path) -> None:
    with pytest.raises(ViewerError, match="no Rerun recording"):
        open_viewer(tmp_path)
