"""The paper's measured values that the human report shows beside ours are the paper's own.

``tests/data/paper_results_table.txt`` is the section "RESULTS FOR ADIS16364" copied verbatim
from the seed paper (its PDF's text, line breaks and stray spaces included).  Every measured
value of :data:`imupipe.report.paper.PAPER_TABLE` is read back from it, with its unit; a value
typed wrong in the table would be printed in every report next to the measured one.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from imupipe.report.paper import PAPER_TABLE, PaperValue
from imupipe.units import to_si

TABLE = Path(__file__).parents[1] / "data" / "paper_results_table.txt"

HEADINGS = {
    "Random Walk": "random_walk",
    "Bias Instability": "bias_instability",
    "Bias  measured": "mean",
    "Output noise": "rms",
}
SENSORS = {"Accelerometer": "accel", "Gyroscope": "gyro"}
UNITS = {"mg/√ s": "mg/√s", "°/√ s": "°/√s", "mg": "mg", "°/sec": "°/s", "°/s": "°/s"}
ROW = re.compile(r"^(Accelerometer|Gyroscope) ([XYZ])\s+(-?[0-9.]+)\s*(mg/√ s|°/√ s|°/sec|°/s|mg)")


def paper_rows() -> dict[tuple[str, str], tuple[float, str]]:
    """{(quantity, axis): (measured value, unit as printed, normalised)} from the copied text."""
    rows: dict[tuple[str, str], tuple[float, str]] = {}
    quantity = None
    for line in TABLE.read_text(encoding="utf-8").splitlines():
        heading = next((q for h, q in HEADINGS.items() if line.startswith(h)), None)
        if heading:
            quantity = heading
        elif match := ROW.match(line):
            sensor, axis, value, unit = match.groups()
            rows[(quantity, f"{SENSORS[sensor]}_{axis.lower()}")] = (float(value), UNITS[unit])
    return rows


def test_every_measured_value_is_the_papers() -> None:
    rows = paper_rows()
    assert len(rows) == 24  # 4 quantities x 6 axes, each read once
    table = {(q, axis): v for q, axes in PAPER_TABLE.items() for axis, v in axes.items()}
    assert set(table) == set(rows)
    for key, (value, unit) in rows.items():
        stored = table[key]
        assert stored.measured == value, key
        if key[0] == "mean" and key[1].startswith("accel"):
            # printed "mg", but Z's -0.9986 "including gravity" is in g (the module's note)
            assert (unit, stored.unit) == ("mg", "g")
        else:
            assert stored.unit == unit, key


def test_values_convert_to_si_in_their_own_unit() -> None:
    gyro_n = PAPER_TABLE["random_walk"]["gyro_x"]
    assert gyro_n.measured_si() == pytest.approx(to_si(0.05, "°/√s"))
    assert gyro_n.measured_si() == pytest.approx(0.05 * 3.141592653589793 / 180)
    bias_z = PAPER_TABLE["mean"]["accel_z"]
    assert bias_z.measured_si() == pytest.approx(-0.9986 * 9.80665)  # gravity, in m/s²


def test_a_paper_value_cannot_be_changed() -> None:
    value = PAPER_TABLE["rms"]["gyro_y"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        value.measured = 1.0  # type: ignore[misc]
    assert value == PaperValue(0.51, "°/s")
