"""Register encoding, two's complement edges, saturation, flags and burst layout."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from imupipe.device.adis16364 import (
    BURST_BITS,
    BURST_COMMAND,
    BURST_SIGNED,
    BURST_WORDS,
    EA_BIT,
    ND_BIT,
    PROD_ID_VALUE,
    REGISTERS,
    DeviceConfig,
    bartlett_taps,
    burst_counts,
    decode_words,
    encode_words,
    gyro_scale_dps,
    sample_rate_sps,
)
from imupipe.errors import ConfigError


@given(st.integers(-8192, 8191))
def test_14bit_round_trip(count):
    words, sat = encode_words(np.array([count]), 14, signed=True)
    assert not sat[0]
    assert words[0] < (1 << 14)
    assert decode_words(words, 14, signed=True)[0] == count


@given(st.integers(0, 4095), st.booleans(), st.booleans())
def test_12bit_unsigned_round_trip_with_flags(count, nd, ea):
    words, _ = encode_words(np.array([count]), 12, signed=False)
    flagged = words | np.uint16((ND_BIT if nd else 0) | (EA_BIT if ea else 0))
    assert decode_words(flagged, 12, signed=False)[0] == count


@pytest.mark.parametrize(
    ("count", "word"),
    [(0, 0x0000), (1, 0x0001), (-1, 0x3FFF), (8191, 0x1FFF), (-8192, 0x2000)],
)
def test_twos_complement_edges_14bit(count, word):
    words, sat = encode_words(np.array([count]), 14, signed=True)
    assert words[0] == word and not sat[0]
    # ND/EA set must not change the value
    assert decode_words(np.array([word | ND_BIT | EA_BIT]), 14, True)[0] == count


def test_temperature_12bit_signed_edges():
    words, _ = encode_words(np.array([-1, -2048, 2047]), 12, signed=True)
    assert list(words) == [0x0FFF, 0x0800, 0x07FF]
    assert list(decode_words(words | np.uint16(ND_BIT), 12, True)) == [-1, -2048, 2047]


def test_saturation_clips_and_reports():
    words, sat = encode_words(np.array([8192, -8193, 100_000, 5]), 14, signed=True)
    assert list(decode_words(words, 14, True)) == [8191, -8192, 8191, 5]
    assert list(sat) == [True, True, True, False]
    words, sat = encode_words(np.array([-1, 4096]), 12, signed=False)
    assert list(words) == [0, 4095] and list(sat) == [True, True]


def test_burst_layout_and_decode():
    assert BURST_COMMAND == 0x3E00 == REGISTERS["GLOB_CMD"] << 8
    assert BURST_WORDS[0] == "SUPPLY_OUT" and BURST_WORDS[-1] == "AUX_ADC"
    # burst order is the register order 0x02..0x16
    assert [REGISTERS[w] for w in BURST_WORDS] == list(range(0x02, 0x18, 2))
    assert BURST_BITS == (12, 14, 14, 14, 14, 14, 14, 12, 12, 12, 12)
    counts = np.array([[2068, -6, 7, -8191, 27, -21, -999, -29, -29, -29, 0]])
    burst = np.empty_like(counts, dtype=np.uint16)
    for i, (bits, signed) in enumerate(zip(BURST_BITS, BURST_SIGNED, strict=True)):
        burst[:, i], _ = encode_words(counts[:, i], bits, signed)
    burst |= np.uint16(ND_BIT)
    assert np.array_equal(burst_counts(burst), counts)


def test_scales_and_rates():
    assert gyro_scale_dps(0x0402) == 0.05
    assert gyro_scale_dps(0x0202) == 0.025
    with pytest.raises(ConfigError, match="no valid gyro range"):
        gyro_scale_dps(0x0302)
    assert bartlett_taps(0x0402) == 4
    assert sample_rate_sps(0x0001) == pytest.approx(819.2, abs=0.01)
    cfg = DeviceConfig()
    assert DeviceConfig.from_metadata(cfg.to_metadata()) == cfg
    assert cfg.product_id == PROD_ID_VALUE == 16364


def test_the_simulators_diag_bits_name_what_the_datasheet_says() -> None:
    """DIAG_STAT bit 4 is over-range and bit 1 supply high (ADIS16364 DIAG_STAT table; the Linux
    driver's messages): what the simulator sets for a saturated axis or a high supply."""
    from imupipe.device.adis16364 import DIAG_OVER_RANGE, DIAG_SUPPLY_HIGH, diag_flags

    assert diag_flags(DIAG_OVER_RANGE) == ["sensor over-range"]
    assert diag_flags(DIAG_SUPPLY_HIGH) == ["supply above 5.25 V"]
    assert len(diag_flags(0xFFFF)) == 15  # every bit but the undefined bit 7


def test_a_short_filter_for_the_gyro_range_names_the_taps_it_got() -> None:
    from imupipe.device.adis16364 import check_sens_avg

    with pytest.raises(ConfigError) as refused:
        check_sens_avg(0x0103)  # ±75 °/s with 2³ taps: 2⁴ needed
    assert str(refused.value) == (
        "SENS_AVG 0x0103: the ±75 °/s range needs SENS_AVG[2:0] >= 4 (>= 16 filter taps), got 3"
    )
