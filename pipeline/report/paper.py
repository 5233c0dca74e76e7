"""Reference values of the ADIS16364 Allan-variance paper, in the paper's own units.

Source: F. Adamčik, error analysis of the inertial measurement unit ADIS16364 by the Allan
variance method (Lithuanian abstract title "Inercinio matavimų bloko klaidų analizė"; 12 h static
test at 21 °C, 100 Hz), section 4, table "Results for ADIS16364", which lists the
measured value next to the ADIS16364 datasheet value for each axis.  The datasheet column is the
paper's; it rounds the datasheet's 2.0 °/√h ARW to 0.03 °/√s and its 0.12 m/s/√h VRW to 0.2 mg/√s.

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
DATASHEET_SOURCE = "ADIS16364 datasheet values as quoted in the same table of the paper"


@dataclass(frozen=True)
class PaperValue:
    """One row of the paper's results table for one axis.

    ``measured`` and ``datasheet`` are in ``unit`` (the paper's unit, a key of
    :data:`imupipe.units.SI_PER_UNIT`); ``None`` where the paper gives no value.
    """

    measured: float | None
    datasheet: float | None
    unit: str

    def measured_si(self) -> float | None:
        """The paper's measured value in SI."""
        return None if self.measured is None else to_si(self.measured, self.unit)

    def datasheet_si(self) -> float | None:
        """The datasheet value in SI."""
        return None if self.datasheet is None else to_si(self.datasheet, self.unit)


def _rows(unit: str, measured: tuple, datasheet: float | None, axes: tuple[str, ...]) -> dict:
    return {axis: PaperValue(m, datasheet, unit) for axis, m in zip(axes, measured, strict=True)}


PAPER_TABLE: dict[str, dict[str, PaperValue]] = {
    "random_walk": {
        **_rows("°/√s", (0.05, 0.05, 0.05), 0.03, GYRO_AXES),
        **_rows("mg/√s", (0.29, 0.27, 0.28), 0.2, ACCEL_AXES),
    },
    "bias_instability": {
        **_rows("°/s", (0.008, 0.008, 0.008), 0.007, GYRO_AXES),
        **_rows("mg", (0.107, 0.161, 0.135), 0.1, ACCEL_AXES),
    },
    "mean": {
        **_rows("°/s", (0.331, -0.104, -0.099), None, GYRO_AXES),
        **_rows("g", (0.0273, -0.0211, -0.9986), None, ACCEL_AXES),
    },
    "rms": {
        **_rows("°/s", (0.52, 0.51, 0.52), 0.8, GYRO_AXES),
        **_rows("mg", (3.0, 2.8, 2.9), 5.0, ACCEL_AXES),
    },
}
"""``PAPER_TABLE[quantity][axis]``: quantity is ``random_walk`` (N), ``bias_instability`` (B),
``mean`` (bias, average of the data) or ``rms`` (output noise)."""

DATASHEET_RANDOM_WALK: dict[str, PaperValue] = {
    "gyro": PaperValue(None, 2.0, "°/√h"),
    "accel": PaperValue(None, 0.12, "m/s/√h"),
}
"""The random walk as the datasheet states it (the paper's specification list: angular random
walk 2.0 °/√h, velocity random walk 0.12 m/s/√h), before the paper's rounding to °/√s, mg/√s."""
