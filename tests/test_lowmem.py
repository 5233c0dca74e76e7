"""The spilled column source (decoded once into a temporary on-disk store, analysed one axis
at a time) gives the in-memory source's numbers.

Forced with ``memory_budget_bytes=0`` on small recordings: an ADIS16364 recording from our
recorder with a NaN frame (cut into segments), and a ROS ``sensor_msgs/msg/Imu`` bag with a
Temperature topic, a gap and a stuck axis.  report.json must be equal apart from the warnings
that name the low-memory path, and allan.parquet identical.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.api import analyze
from imupipe.device.adis16364 import config_for_rate
from imupipe.io.columns import envelope, envelope_times, peak_estimate
from imupipe.io.decode import IMU_SCHEMA, TEMPERATURE_SCHEMA
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.recording.recorder import FrameWriter
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.testing.ros_cdr import imu_payloads, temperature_payloads

N = 24_000  # 100 Hz, 4 min


def recording(path: Path, rate_hz: float, frames: int, seed: int, edit=None) -> Path:
    """An ADIS16364 recording of the virtual device; ``edit(block)`` alters its words first."""
    config = config_for_rate(rate_hz)
    block = VirtualADIS16364(config, None, seed=seed).frames(frames)
    if edit is not None:
        edit(block)
    with open(path, "wb") as f:
        writer = FrameWriter(f, config)
        writer.write(block)
        writer.finish()
    return path


def adis_recording(path: Path) -> Path:
    def rail(block) -> None:  # ND + gyro_y at +8191 (rail): the frame is cut out
        block.burst[N // 3, 2] = 0x9FFF

    return recording(path, 100.0, N, seed=3, edit=rail)


def imu_bag(path: Path) -> Path:
    rng = np.random.default_rng(5)
    stamps = 1_700_000_000_000_000_000 + np.arange(N, dtype=np.int64) * 10_000_000
    stamps[N // 4 :] += 50_000_000  # a 5-frame gap
    gyro = rng.normal(0, 1e-3, (N, 3)) + np.cumsum(rng.normal(0, 1e-6, (N, 1)), axis=0)
    accel = rng.normal(0, 3e-3, (N, 3)) + np.array([0.0, 0.0, 9.81])
    accel[:, 1] = 0.25  # stuck
    gyro[N // 2, 0] = np.nan
    t_stamps = stamps[::100]
    temp = 25 + 0.01 * np.arange(len(t_stamps))
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        imu = w.register_channel("/imu/data", "cdr", w.register_schema(IMU_SCHEMA, "ros2msg", b""))
        tmp = w.register_channel(
            "/imu/temperature", "cdr", w.register_schema(TEMPERATURE_SCHEMA, "ros2msg", b"")
        )
        w.write_chunk(imu, stamps, imu_payloads(stamps, gyro, accel))
        w.write_chunk(tmp, t_stamps, temperature_payloads(t_stamps, temp))
        w.finish()
    return path


def run(path: Path, out: Path, budget: int, **options) -> tuple[dict, pl.DataFrame]:
    analyze(path, out, rrd=False, figures=False, memory_budget_bytes=budget, **options)
    return json.loads((out / "report.json").read_text()), pl.read_parquet(out / "allan.parquet")


@pytest.mark.parametrize("make", [adis_recording, imu_bag])
def test_low_memory_path_equals_normal_path(tmp_path: Path, make) -> None:
    path = make(tmp_path / "in.mcap")
    assert peak_estimate([path]) < AnalyzeOptions().memory_budget_bytes
    normal, normal_allan = run(path, tmp_path / "normal", AnalyzeOptions().memory_budget_bytes)
    low, low_allan = run(path, tmp_path / "low", 0)
    assert normal["input"]["segments"] == low["input"]["segments"]
    assert len(normal["input"]["segments"]) > 1  # conditioning had something to cut
    extra = [w for w in low["input"]["warnings"] if w not in normal["input"]["warnings"]]
    assert len(extra) == 1 and extra[0].startswith("low-memory path")
    low["input"]["warnings"] = [w for w in low["input"]["warnings"] if w not in extra]
    assert low == normal
    assert low_allan.equals(normal_allan)


def test_imu_bag_stuck_axis_and_temperature_seen(tmp_path: Path) -> None:
    low, _ = run(imu_bag(tmp_path / "in.mcap"), tmp_path / "low", 0)
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
def test_fastest_rate_model_below_fit_range_is_null_not_nan_warning(tmp_path: Path) -> None:
    """At 819.2 SPS the fitted prefilter term −P/τ² makes the model negative at the two
    shortest τ (below the fitted range): no sqrt/log of a negative, null in the report."""
    path = recording(tmp_path / "fast.mcap", 819.2, 120_000, seed=4)
    report, _ = run(path, tmp_path / "out", 2_000_000_000)
    allan = report["axes"]["gyro_x"]["allan"]
    assert allan["model_adev_before"][0] is None
    assert all(v is not None for v in allan["model_adev_before"][3:])
