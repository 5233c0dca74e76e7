"""Unit conversions between SI and the units inertial-sensor papers and datasheets use.

All analysis runs in SI (rad/s for gyros, m/s² for accelerometers).  Reports convert to the units of
the ADIS16364 paper (°/√s, °/s, mg/√s, mg) and of datasheets (°/√h, m/s/√h, °/h) here and only
here.  ``SI_PER_UNIT[u]`` is the SI value of one ``u``: ``x_si = x_u * SI_PER_UNIT[u]``.

Conventions (IEEE Std 952-1997, Annex C): a white-noise density in rad/s/√Hz equals an angle
random walk in rad/√s, so the paper's "°/√s" and a datasheet's "°/s/√Hz" carry the same factor;
√h = 60 √s.  Standard gravity g = 9.80665 m/s² (CGPM 1901, ISO 80000-3).
"""

from __future__ import annotations

import math
from typing import Literal

STANDARD_GRAVITY = 9.80665
"""g in m/s² (exact by definition)."""

RAD_PER_DEG = math.pi / 180.0
SQRT_S_PER_SQRT_H = 60.0
"""√(3600 s) / √(1 s): one √h is 60 √s."""

SI_PER_UNIT: dict[str, float] = {
    # angular rate and its noise terms, SI (spelled as imupipe.model.ieee952.UNITS spells them)
    "rad/s": 1.0,
    "rad": 1.0,
    "rad/s/sqrt(Hz)": 1.0,
    "rad/s^2/sqrt(Hz)": 1.0,
    "rad/s^2": 1.0,
    # angular rate, paper and datasheet units
    "°/s": RAD_PER_DEG,
    "°/h": RAD_PER_DEG / 3600.0,
    "°": RAD_PER_DEG,
    "°/√s": RAD_PER_DEG,
    "°/s/√Hz": RAD_PER_DEG,
    "°/√h": RAD_PER_DEG / SQRT_S_PER_SQRT_H,
    "°/s/√s": RAD_PER_DEG,
    "°/h/√h": RAD_PER_DEG / 3600.0 / SQRT_S_PER_SQRT_H,
    "°/s²": RAD_PER_DEG,
    # acceleration and its noise terms, SI
    "m/s^2": 1.0,
    "m/s": 1.0,
    "m/s^2/sqrt(Hz)": 1.0,
    "m/s^3/sqrt(Hz)": 1.0,
    "m/s^3": 1.0,
    # acceleration, paper and datasheet units
    "g": STANDARD_GRAVITY,
    "mg": STANDARD_GRAVITY * 1e-3,
    "mg·s": STANDARD_GRAVITY * 1e-3,
    "mg/√s": STANDARD_GRAVITY * 1e-3,
    "mg/√Hz": STANDARD_GRAVITY * 1e-3,
    "m/s/√h": 1.0 / SQRT_S_PER_SQRT_H,
    "mg/s/√s": STANDARD_GRAVITY * 1e-3,
    "mg/s": STANDARD_GRAVITY * 1e-3,
}

Sensor = Literal["gyro", "accel"]
Quantity = Literal[
    "mean",
    "rms",
    "quantization",
    "random_walk",
    "bias_instability",
    "rate_random_walk",
    "rate_ramp",
]

SI_UNIT: dict[Sensor, dict[Quantity, str]] = {
    "gyro": {
        "mean": "rad/s",
        "rms": "rad/s",
        "quantization": "rad",
        "random_walk": "rad/s/sqrt(Hz)",
        "bias_instability": "rad/s",
        "rate_random_walk": "rad/s^2/sqrt(Hz)",
        "rate_ramp": "rad/s^2",
    },
    "accel": {
        "mean": "m/s^2",
        "rms": "m/s^2",
        "quantization": "m/s",
        "random_walk": "m/s^2/sqrt(Hz)",
        "bias_instability": "m/s^2",
        "rate_random_walk": "m/s^3/sqrt(Hz)",
        "rate_ramp": "m/s^3",
    },
}
"""SI unit of each reported quantity (issue 3 report.json contract), spelled as
:data:`imupipe.model.ieee952.UNITS` spells them."""

PAPER_UNIT: dict[Sensor, dict[Quantity, str]] = {
    "gyro": {
        "mean": "°/s",
        "rms": "°/s",
        "quantization": "°",
        "random_walk": "°/√s",
        "bias_instability": "°/s",
        "rate_random_walk": "°/s/√s",
        "rate_ramp": "°/s²",
    },
    "accel": {
        "mean": "mg",
        "rms": "mg",
        "quantization": "mg·s",
        "random_walk": "mg/√s",
        "bias_instability": "mg",
        "rate_random_walk": "mg/s/√s",
        "rate_ramp": "mg/s",
    },
}
"""Display units: those of the ADIS16364 paper's results table (section 4: °/√s, °/s, mg/√s, mg),
extended with the same base units (°, mg, s) to the terms the paper does not list."""


def to_si(value: float, unit: str) -> float:
    """Convert ``value`` expressed in ``unit`` to SI (see :data:`SI_PER_UNIT`)."""
    return value * SI_PER_UNIT[unit]


def from_si(value: float, unit: str) -> float:
    """Convert an SI ``value`` to ``unit`` (see :data:`SI_PER_UNIT`)."""
    return value / SI_PER_UNIT[unit]
