"""SI values of decoded ADIS16364 frames, against conversions written out here from the
datasheet facts (../shared/reference/adis16364_facts.json), not from imupipe's constants:
gyro 0.05 °/s/LSB at ±300 °/s (0.025 at ±150, 0.0125 at ±75), accel 1 mg/LSB, temperature
0.136 °C/LSB with 0 LSB = 25 °C, supply 2.418 mV/LSB; g = 9.80665 m/s² (CGPM 1901)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from imupipe.device.adis16364 import DeviceConfig, FrameBlock, encode_words
from imupipe.io.decode import decode
from imupipe.recording.recorder import FrameWriter

G = 9.80665
COUNTS = np.array([-8192, -1000, -1, 0, 1, 7, 1234, 8191])


def _recording(path: Path, sens_avg: int) -> Path:
    n = len(COUNTS)
    burst = np.zeros((n, 11), np.uint16)
    for col in range(1, 7):  # gyro x/y/z, accel x/y/z: 14-bit two's complement
        burst[:, col] = encode_words(np.roll(COUNTS, col), 14, signed=True)[0]
    burst[:, 0] = 2068  # SUPPLY_OUT, 12-bit unsigned
    temp = np.array([-100, -1, 0, 1, 37, 100, 200, 300])
    for col in (7, 8, 9):  # X/Y/Z TEMP_OUT, 12-bit two's complement
        burst[:, col] = encode_words(temp, 12, signed=True)[0]
    block = FrameBlock(
        stamp_ns=1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 10_000_000,
        counter=np.arange(n, dtype=np.uint32),
        burst=burst,
        diag_stat=np.zeros(n, np.uint16),
        diag_valid=np.zeros(n, bool),
    )
    with open(path, "wb") as f:
        writer = FrameWriter(f, DeviceConfig(sens_avg=sens_avg))
        writer.write(block)
        writer.finish()
    return path


@pytest.mark.parametrize(("sens_avg", "deg_per_lsb"), [(0x0402, 0.05), (0x0202, 0.025)])
def test_decoded_values_are_si(tmp_path: Path, sens_avg: int, deg_per_lsb: float) -> None:
    frames = decode(_recording(tmp_path / "f.mcap", sens_avg)).frames
    for col, axis in enumerate(("gyro_x", "gyro_y", "gyro_z"), start=1):
        expected = np.roll(COUNTS, col) * deg_per_lsb * math.pi / 180.0  # rad/s
        np.testing.assert_allclose(frames[axis].to_numpy(), expected, rtol=1e-15, atol=0)
    for col, axis in enumerate(("accel_x", "accel_y", "accel_z"), start=4):
        expected = np.roll(COUNTS, col) * 1e-3 * G  # m/s²
        np.testing.assert_allclose(frames[axis].to_numpy(), expected, rtol=1e-15, atol=0)
    # temperature is the mean of the three sensors' readings
    temp = np.array([-100, -1, 0, 1, 37, 100, 200, 300]) * 0.136 + 25.0
    np.testing.assert_allclose(frames["temp_c"].to_numpy(), temp, rtol=1e-12)
    np.testing.assert_allclose(frames["supply_v"].to_numpy(), 2068 * 2.418e-3, rtol=1e-12)
