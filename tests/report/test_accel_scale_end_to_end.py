"""ADIS16364 accelerometer scale from raw words to what a user reads: report.json (SI), report.md
(the paper's mg units) and Kalibr's imu.yaml.  The expected values are written out here from the
datasheet (1.00 mg/LSB, "Initial Sensitivity" in the paper's specification list) and g =
9.80665 m/s², not taken from imupipe's constants: a scale that dropped the g factor (every accel
value 9.81x too small) fails each of them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import imupipe
from imupipe.device.adis16364 import ACCEL_MG_PER_LSB, FrameBlock, config_for_rate, encode_words
from imupipe.recording.recorder import FrameWriter

RATE_HZ = 100.0
N_FRAMES = 30_000
SIGMA_LSB = (20.0, 25.0, 30.0)  # white noise of accel x, y, z, LSB per sample
MS2_PER_LSB = 1.0e-3 * 9.80665  # 1 mg/LSB in m/s²


@pytest.fixture(scope="module")
def analysed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    d = tmp_path_factory.mktemp("accel")
    rng = np.random.default_rng(18)
    counts = np.zeros((N_FRAMES, 6))
    counts[:, :3] = rng.normal(0, 20.0, (N_FRAMES, 3))  # gyro
    counts[:, 3:] = rng.normal(0, SIGMA_LSB, (N_FRAMES, 3))
    counts[:, 5] -= 1000  # accel z reads -1 g at rest
    counts = np.rint(counts)
    burst = np.zeros((N_FRAMES, 11), np.uint16)
    burst[:, 0] = 2068
    burst[:, 1:7] = encode_words(counts, 14, signed=True)[0]
    block = FrameBlock(
        stamp_ns=1_700_000_000_000_000_000 + np.arange(N_FRAMES, dtype=np.int64) * 10_000_000,
        counter=np.arange(N_FRAMES, dtype=np.uint32),
        burst=burst,
        diag_stat=np.zeros(N_FRAMES, np.uint16),
        diag_valid=np.zeros(N_FRAMES, bool),
    )
    path = d / "run.mcap"
    with open(path, "wb") as f:
        writer = FrameWriter(f, config_for_rate(RATE_HZ))
        writer.write(block)
        writer.finish()
    out = d / "out"
    imupipe.analyze(path, out, loop=False, rrd=False, figures=False)
    return out, counts[:, 3:]


def test_datasheet_scale() -> None:
    assert ACCEL_MG_PER_LSB == 1.0  # ADIS16364 datasheet: 1.00 mg/LSB


def test_accel_values_in_report_json_are_si(analysed) -> None:
    out, counts = analysed
    import json

    axes = json.loads((out / "report.json").read_text())["axes"]
    for i, axis in enumerate(("accel_x", "accel_y", "accel_z")):
        a = axes[axis]
        assert a["unit"] == "m/s^2"
        assert a["mean"] == pytest.approx(counts[:, i].mean() * MS2_PER_LSB, rel=1e-9, abs=0)
        assert a["rms"] == pytest.approx(counts[:, i].std(ddof=1) * MS2_PER_LSB, rel=1e-3, abs=0)
        # white noise of σ per sample at rate f: N = σ / √f (IEEE 952 Annex C)
        n = a["ieee952"]["random_walk"]["value"]
        assert n == pytest.approx(SIGMA_LSB[i] * MS2_PER_LSB / math.sqrt(RATE_HZ), rel=0.05)
    assert axes["accel_z"]["mean"] == pytest.approx(-9.80665, rel=2e-3)


def test_kalibr_accel_density_is_si(analysed) -> None:
    out, _ = analysed
    doc = yaml.safe_load((out / "imu.yaml").read_text())
    # the worst axis (z, 30 LSB): 30 mg × √(10 ms) = 3 mg/√Hz = 0.0294 m/s²/√Hz
    expected = 30 * MS2_PER_LSB / math.sqrt(RATE_HZ)
    assert doc["accelerometer_noise_density"] == pytest.approx(expected, rel=0.05)


def test_report_md_accel_in_mg(analysed) -> None:
    out, counts = analysed
    md = (out / "report.md").read_text()
    rows = {}
    for line in md.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) > 3:
            rows[(cells[0], cells[1], cells[-1])] = cells
    # N in mg/√s: σ LSB × 1 mg/LSB × √(0.01 s)
    n = float(rows[("Random walk N", "accel_y", "mg/√s")][2].split()[0])
    assert n == pytest.approx(25 * 0.1, rel=0.05)
    mean = float(rows[("Bias (mean)", "accel_z", "mg")][2])
    assert mean == pytest.approx(counts[:, 2].mean(), rel=1e-3)  # 1 LSB = 1 mg
