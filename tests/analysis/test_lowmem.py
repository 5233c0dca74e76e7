"""The spilled column source (decoded once into a temporary on-disk store, analysed one axis
at a time) gives the in-memory source's numbers.

Forced with ``memory_budget_bytes=0`` on small recordings: an ADIS16364 recording from our
recorder with a NaN frame (cut into segments), and a ROS ``sensor_msgs/msg/Imu`` bag with a
Temperature topic, a gap and a stuck axis.  report.json must be equal apart from the warnings
that name the low-memory path, and allan.parquet identical.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.io.columns import envelope, envelope_times, peak_estimate


@pytest.mark.parametrize("kind", ["adis", "ros"])
def test_low_memory_path_equals_normal_path(tmp_path: Path, kind, small_recordings) -> None:
    path = small_recordings.make(kind, tmp_path / "in.mcap")
    assert peak_estimate([path]) < AnalyzeOptions().memory_budget_bytes
    normal, normal_allan = small_recordings.run(
        path, tmp_path / "normal", AnalyzeOptions().memory_budget_bytes
    )
    low, low_allan = small_recordings.run(path, tmp_path / "low", 0)
    assert normal["input"]["segments"] == low["input"]["segments"]
    assert len(normal["input"]["segments"]) > 1  # conditioning had something to cut
    extra = [w for w in low["input"]["warnings"] if w not in normal["input"]["warnings"]]
    assert len(extra) == 1 and extra[0].startswith("low-memory path")
    low["input"]["warnings"] = [w for w in low["input"]["warnings"] if w not in extra]
    assert low == normal
    assert low_allan.equals(normal_allan)


def test_imu_bag_stuck_axis_and_temperature_seen(tmp_path: Path, small_recordings) -> None:
    low, _ = small_recordings.run(
        small_recordings.imu_bag(tmp_path / "in.mcap"), tmp_path / "low", 0
    )
    assert "accel_y" not in low["axes"] and "gyro_x" in low["axes"]
    assert any("accel_y is constant" in w for w in low["input"]["warnings"])


def test_envelope_keeps_extremes_and_stamps_order() -> None:
    y = np.sin(np.arange(1_000) / 7.0)
    y[123] = 5.0
    env = envelope(y, bins=10)
    t = envelope_times(np.arange(1_000) * 0.01, bins=10)
    assert len(env) == len(t) == 20
    assert env.max() == 5.0 and env.min() == y.min()
    assert np.all(np.diff(t) > 0)
    assert envelope(y[:15], bins=10) is not None and len(envelope(y[:15], bins=10)) == 15


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_fastest_rate_model_below_fit_range_is_null_not_nan_warning(
    tmp_path: Path, small_recordings
) -> None:
    """At 819.2 SPS the fitted prefilter term −P/τ² makes the model negative at the two
    shortest τ (below the fitted range): no sqrt/log of a negative, null in the report."""
    path = small_recordings.recording(tmp_path / "fast.mcap", 819.2, 120_000, seed=4)
    report, _ = small_recordings.run(path, tmp_path / "out", 2_000_000_000)
    allan = report["axes"]["gyro_x"]["allan"]
    assert allan["model_adev_before"][0] is None
    assert all(v is not None for v in allan["model_adev_before"][3:])
