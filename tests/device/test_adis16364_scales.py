"""The ADIS16364 scale factors a recording carries in its ``adis16364`` metadata (and report.md
shows as "Device: ..."), against the datasheet values written out here (ADIS1636x datasheet,
also quoted in /work/shared/reference/adis16364_facts.json): supply 2.418 mV/LSB, temperature
0.136 °C/LSB with 0 LSB = 25 °C, AUX_ADC 805.8 µV/LSB, accelerometer 1 mg/LSB, gyro ±300 / ±150 /
±75 °/s at 0.05 / 0.025 / 0.0125 °/s/LSB; internal rate 1638.404 SPS / (Ns + 1)."""

from __future__ import annotations

import pytest

from imupipe.device.adis16364 import DeviceConfig
from imupipe.errors import ConfigError


@pytest.mark.parametrize(
    ("sens_avg", "range_dps", "scale"),
    [(0x0402, "300.0", "0.05"), (0x0202, "150.0", "0.025"), (0x0104, "75.0", "0.0125")],
)
def test_metadata_scales_are_the_datasheets(sens_avg: int, range_dps: str, scale: str) -> None:
    meta = DeviceConfig(sens_avg=sens_avg, smpl_prd=0x0001).to_metadata()
    assert meta["gyro_range_dps"] == range_dps
    assert meta["gyro_scale_dps_per_lsb"] == scale
    assert meta["accel_scale_mg_per_lsb"] == "1.0"
    assert meta["temp_scale_c_per_lsb"] == "0.136"
    assert meta["temp_zero_c"] == "25.0"
    assert meta["supply_scale_v_per_lsb"] == "0.002418"
    assert meta["aux_adc_scale_v_per_lsb"] == "0.0008058"
    assert float(meta["internal_rate_sps"]) == pytest.approx(1638.404 / 2, rel=1e-15)


@pytest.mark.parametrize(
    ("smpl_prd", "sps"),
    [(0x00, 1638.404), (0x09, 163.8404), (0x7F, 1638.404 / 128), (0x81, 52.851 / 2)],
)
def test_internal_rate(smpl_prd: int, sps: float) -> None:
    # SMPL_PRD[6:0] = Ns: base / (Ns + 1); bit 7 selects the 52.851 SPS base
    meta = DeviceConfig(smpl_prd=smpl_prd).to_metadata()
    assert float(meta["internal_rate_sps"]) == pytest.approx(sps, rel=1e-15)


def test_a_range_code_the_part_lacks_is_refused() -> None:
    with pytest.raises(ConfigError, match="SENS_AVG 0x0302 selects no valid gyro range"):
        DeviceConfig(sens_avg=0x0302).gyro_scale_dps  # noqa: B018
