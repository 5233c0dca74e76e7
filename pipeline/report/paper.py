"""Reference values of the ADIS16364 Allan-variance paper, in the paper's own units.

Source: F. Adamčik, error analysis of the inertial measurement unit ADIS16364 by the Allan
variance method (Lithuanian abstract title "Inercinio matavimų bloko klaidų analizė"; 12 h static
test at 21 °C, 100 Hz), section 4, table "Results for ADIS16364", which lists the
measured value next to the ADIS16364 datasheet value for each axis.  The datasheet values (the
paper rounds the datasheet's 2.0 °/√h ARW to 0.03 °/√s and its 0.12 m/s/√h VRW to 0.2 mg/√s)
live in the package's ``datasheets/adis16364.toml`` (:mod:`imupipe.report.datasheet`), in the
datasheet's own units.

One correction of units: the paper prints the accelerometer bias ("average of data") in "mg", but
its Z value of -0.9986 "including gravity" can only be in g (gravity is 1 g), so the three bias
values are stored here in g (X: 0.0273 g = 27.3 mg) and converted by :mod:`imupipe.units`.
"""

from __future__ import annotations

from dataclasses import dataclass

from imupipe.units import to_si
from imupipe.vocab import ACCEL_AXES, GYRO_AXES

PAPER_SOURCE = (
    "F. Adamčik, ADIS16364 Allan variance error analysis, §4 table 'Results for ADIS16364' "
    "(12 h static, 100 Hz, 21 °C)"
)


@dataclass(frozen=True)
class PaperValue:
    """One row of the paper's results table for one axis: the ``measured`` value in ``unit``
    (the paper's unit, a key of :data:`imupipe.units.SI_PER_UNIT`)."""

    measured: float
    unit: str

    def measured_si(self) -> float:
        """The paper's measured value in SI."""
        return to_si(self.measured, self.unit)


def _rows(unit: str, measured: tuple, axes: tuple[str, ...]) -> dict:
    return {axis: PaperValue(m, unit) for axis, m in zip(axes, measured, strict=True)}


PAPER_TABLE: dict[str, dict[str, PaperValue]] = {
    "random_walk": {
        **_rows("°/√s", (0.05, 0.05, 0.05), GYRO_AXES),
        **_rows("mg/√s", (0.29, 0.27, 0.28), ACCEL_AXES),
    },
    "bias_instability": {
        **_rows("°/s", (0.008, 0.008, 0.008), GYRO_AXES),
        **_rows("mg", (0.107, 0.161, 0.135), ACCEL_AXES),
    },
    "mean": {
        **_rows("°/s", (0.331, -0.104, -0.099), GYRO_AXES),
        **_rows("g", (0.0273, -0.0211, -0.9986), ACCEL_AXES),
    },
    "rms": {
        **_rows("°/s", (0.52, 0.51, 0.52), GYRO_AXES),
        **_rows("mg", (3.0, 2.8, 2.9), ACCEL_AXES),
    },
}
"""``PAPER_TABLE[quantity][axis]``: quantity is ``random_walk`` (N), ``bias_instability`` (B),
``mean`` (bias, average of the data) or ``rms`` (output noise)."""
