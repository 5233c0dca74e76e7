"""Names shared by every stage, defined once: the axes, the sensors, the IEEE 952 terms.

Values are SI throughout imupipe (rad/s for gyros, m/s² for accelerometers); display units
live in :mod:`imupipe.units`.
"""

from __future__ import annotations

from typing import Literal

from scipy import special

Sensor = Literal["gyro", "accel"]

AXES: tuple[str, ...] = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
"""Axis names in report order (the report.json contract)."""

GYRO_AXES: tuple[str, ...] = AXES[:3]
ACCEL_AXES: tuple[str, ...] = AXES[3:]
AXES_OF: dict[str, tuple[str, ...]] = {"gyro": GYRO_AXES, "accel": ACCEL_AXES}
SENSOR_TITLES: dict[str, str] = {"gyro": "Gyroscopes", "accel": "Accelerometers"}
"""Each sensor's name in figure titles."""

SI_RATE_UNIT: dict[str, str] = {"gyro": "rad/s", "accel": "m/s^2"}
"""The SI unit of each sensor's samples."""

TERM_NAMES: tuple[str, ...] = (
    "quantization",
    "random_walk",
    "bias_instability",
    "rate_random_walk",
    "rate_ramp",
)
"""The IEEE Std 952-1997 Annex C noise terms Q, N, B, K, R, in the order of their τ slopes
(σ² ∝ τ⁻², τ⁻¹, τ⁰, τ¹, τ²)."""


def sensor_of(axis: str) -> Sensor:
    """``"gyro"`` for gyro_x..z, ``"accel"`` for accel_x..z."""
    return "gyro" if axis.startswith("gyro") else "accel"


TERM_UNITS: dict[str, tuple[str, ...]] = {
    "gyro": ("rad", "rad/s/sqrt(Hz)", "rad/s", "rad/s^2/sqrt(Hz)", "rad/s^2"),
    "accel": ("m/s", "m/s^2/sqrt(Hz)", "m/s^2", "m/s^3/sqrt(Hz)", "m/s^3"),
}
"""SI unit of each term of :data:`TERM_NAMES`, per sensor."""


def chi2_ppf_1dof(level: float) -> float:
    """Quantile of χ² with one degree of freedom, ``scipy.stats.chi2.ppf(level, 1)``, computed
    as 2·P⁻¹(½, level) with P the regularised lower incomplete gamma function."""
    return float(2 * special.gammaincinv(0.5, level))


CHI2_95 = chi2_ppf_1dof(0.95)
"""χ²₁(0.95) = 3.8415: the likelihood-ratio drop of a 95 % profile interval (Wilks)."""
