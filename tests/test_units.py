"""Unit conversions and shared names against values written out independently (not recomputed
from the module's own constants), so a changed factor or a swapped name fails here."""

from __future__ import annotations

import pytest

from imupipe.units import (
    PAPER_UNIT,
    RAD_PER_DEG,
    SI_PER_UNIT,
    SI_UNIT,
    SQRT_S_PER_SQRT_H,
    STANDARD_GRAVITY,
    from_si,
    to_si,
)
from imupipe.vocab import (
    ACCEL_AXES,
    AXES,
    AXES_OF,
    CHI2_95,
    GYRO_AXES,
    SI_RATE_UNIT,
    TERM_NAMES,
    TERM_UNITS,
    chi2_ppf_1dof,
    sensor_of,
)

# SI value of one unit, written out by hand: π/180 = 0.0174532925199433 rad, g = 9.80665 m/s²
# (CGPM 1901), 1 h = 3600 s, √h = 60 √s.
SI_OF_ONE = {
    "rad/s": 1.0,
    "rad": 1.0,
    "rad/s/sqrt(Hz)": 1.0,
    "rad/s^2/sqrt(Hz)": 1.0,
    "rad/s^2": 1.0,
    "°/s": 0.017453292519943295,
    "°/h": 4.84813681109536e-06,
    "°": 0.017453292519943295,
    "°/√s": 0.017453292519943295,
    "°/s/√Hz": 0.017453292519943295,
    "°/√h": 2.908882086657216e-04,
    "°/s/√s": 0.017453292519943295,
    "°/h/√h": 8.080228018492267e-08,
    "°/s²": 0.017453292519943295,
    "m/s^2": 1.0,
    "m/s": 1.0,
    "m/s^2/sqrt(Hz)": 1.0,
    "m/s^3/sqrt(Hz)": 1.0,
    "m/s^3": 1.0,
    "g": 9.80665,
    "mg": 0.00980665,
    "mg·s": 0.00980665,
    "mg/√s": 0.00980665,
    "mg/√Hz": 0.00980665,
    "m/s/√h": 0.016666666666666666,
    "mg/s/√s": 0.00980665,
    "mg/s": 0.00980665,
}


def test_every_unit_has_its_independent_si_factor() -> None:
    assert set(SI_PER_UNIT) == set(SI_OF_ONE)
    for unit, factor in SI_OF_ONE.items():
        assert SI_PER_UNIT[unit] == pytest.approx(factor, rel=1e-9, abs=0), unit


def test_named_constants() -> None:
    assert STANDARD_GRAVITY == 9.80665
    assert RAD_PER_DEG == pytest.approx(0.017453292519943295, rel=1e-15)
    assert SQRT_S_PER_SQRT_H == 60.0


def test_to_si_multiplies_and_from_si_divides() -> None:
    # the paper's gyro ARW 0.0333 °/√s (2 °/√h) in rad/√s; an accel VRW of 0.5 mg/√s in m/s^1.5
    assert to_si(2.0, "°/√h") == pytest.approx(5.817764173314432e-04, rel=1e-12, abs=0)
    assert to_si(0.5, "mg/√s") == pytest.approx(0.004903325, rel=1e-12, abs=0)
    assert from_si(9.80665, "g") == pytest.approx(1.0, rel=1e-15)
    assert from_si(0.01, "°/s") == pytest.approx(0.5729577951308232, rel=1e-12)
    assert from_si(4.84813681109536e-06, "°/h") == pytest.approx(1.0, rel=1e-9)


def test_unknown_unit_is_not_silently_si() -> None:
    with pytest.raises(KeyError):
        to_si(1.0, "deg/s")


def test_si_units_are_the_term_units_of_vocab() -> None:
    for sensor in ("gyro", "accel"):
        assert tuple(SI_UNIT[sensor][t] for t in TERM_NAMES) == TERM_UNITS[sensor]
        assert SI_UNIT[sensor]["mean"] == SI_RATE_UNIT[sensor]
        assert SI_UNIT[sensor]["rms"] == SI_RATE_UNIT[sensor]
    assert SI_RATE_UNIT == {"gyro": "rad/s", "accel": "m/s^2"}


def test_paper_units_are_the_papers() -> None:
    # ADIS16364 paper, section 4 results table: °/√s and °/s for gyros, mg/√s and mg for accels
    assert PAPER_UNIT["gyro"]["random_walk"] == "°/√s"
    assert PAPER_UNIT["gyro"]["bias_instability"] == "°/s"
    assert PAPER_UNIT["accel"]["random_walk"] == "mg/√s"
    assert PAPER_UNIT["accel"]["bias_instability"] == "mg"
    for sensor in ("gyro", "accel"):
        assert set(PAPER_UNIT[sensor]) == set(SI_UNIT[sensor])
        assert all(u in SI_PER_UNIT for u in PAPER_UNIT[sensor].values())


def test_axes_and_sensors() -> None:
    assert AXES == ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
    assert GYRO_AXES == ("gyro_x", "gyro_y", "gyro_z")
    assert ACCEL_AXES == ("accel_x", "accel_y", "accel_z")
    assert AXES_OF == {"gyro": GYRO_AXES, "accel": ACCEL_AXES}
    assert [sensor_of(a) for a in AXES] == ["gyro"] * 3 + ["accel"] * 3
    assert TERM_NAMES == (
        "quantization",
        "random_walk",
        "bias_instability",
        "rate_random_walk",
        "rate_ramp",
    )


def test_chi2_quantiles_match_tables() -> None:
    # χ²₁ quantiles (Abramowitz & Stegun table 26.8; scipy.stats.chi2.ppf(p, 1))
    assert CHI2_95 == pytest.approx(3.841458820694124, rel=1e-12)
    assert chi2_ppf_1dof(0.99) == pytest.approx(6.634896601021214, rel=1e-12)
    assert chi2_ppf_1dof(0.6826894921370859) == pytest.approx(1.0, rel=1e-12)
