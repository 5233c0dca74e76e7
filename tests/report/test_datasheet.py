"""Datasheet columns: the paper's only for ADIS16364 recordings, any part's from --datasheet."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imupipe.analysis.analyze import axis_result
from imupipe.analysis.results import AnalysisResult, InputSummary
from imupipe.device.frame_schema import SCHEMA_NAME
from imupipe.report.datasheet import DatasheetError, adis16364, load_datasheet, parse_datasheet
from imupipe.report.report import format_table, report_markdown
from imupipe.stats.allan import allan_curves

SHEET = """
part = "ADIS16405"
source = "datasheet rev. B | table 1"
[gyro]
N = { value = 2.0, unit = "°/√h" }
B = { value = 25.0, unit = "°/h" }
"""


def result(source: str) -> AnalysisResult:
    rng = np.random.default_rng(1)
    tau0, n = 0.01, 2**15
    y = 8.7e-4 / np.sqrt(tau0) * rng.standard_normal(n)
    (curve,) = allan_curves([y], tau0)
    axis = axis_result("gyro_x", y, curve, tau0, None, None, loop=False)
    inp = InputSummary("r.mcap", "/imu", n, 100.0, n * tau0, source=source)
    return AnalysisResult(input=inp, axes={"gyro_x": axis})


def header(table: str) -> list[str]:
    return next(ln for ln in table.splitlines() if ln.startswith("quantity")).split()


def test_adis16364_recording_gets_paper_and_its_datasheet() -> None:
    table = format_table(result(SCHEMA_NAME))
    assert header(table)[-3:] == ["paper", "datasheet", "unit"]
    # the shipped ADIS16364 N: 2.0 °/√h = 2/60 °/√s; shown in °/√s and again in °/√h
    rows = [ln.split() for ln in table.splitlines() if ln.startswith("Random walk N")]
    assert rows[0][-3:] == ["0.05", "0.03333", "°/√s"]
    assert rows[1][-2:] == ["2", "°/√h"]


def test_other_recording_has_no_paper_column() -> None:
    table = format_table(result("sensor_msgs/msg/Imu"))
    assert header(table) == ["quantity", "axis", "measured", "[95", "%", "interval]", "unit"]


def test_given_datasheet_fills_its_column(tmp_path: Path) -> None:
    path = tmp_path / "adis16405.toml"
    path.write_text(SHEET, encoding="utf-8")
    sheet = load_datasheet(path)
    r = result("sensor_msgs/msg/Imu")
    table = format_table(r, sheet)
    assert header(table)[-2:] == ["datasheet", "unit"]
    b_row = next(ln.split() for ln in table.splitlines() if ln.startswith("Bias instability B"))
    assert b_row[-2:] == [f"{25.0 / 3600:.4g}", "°/s"]  # 25 °/h in the paper's °/s
    md = report_markdown(r, {}, sheet)
    assert 'Datasheet "ADIS16405": "datasheet rev. B | table 1".' in md


def test_datasheet_names_keep_their_letters_and_escape_the_rest() -> None:
    """The shipped sheet's source names F. Adamčik and §4 as written (report.md showed their
    JSON escapes); a line break, a terminal escape and a bidi override from a user's sheet stay
    escaped on one line."""
    md = report_markdown(result(SCHEMA_NAME), {}, adis16364())
    line = next(ln for ln in md.splitlines() if ln.startswith("Datasheet "))
    assert "Adamčik" in line and "§4" in line and "\\u" not in line
    hostile = parse_datasheet(
        'part = "X\\u202eY"\nsource = "a\\nb\\u001b[2J"\n' + SHEET.split("\n", 3)[3], "hostile.toml"
    )
    md = report_markdown(result("sensor_msgs/msg/Imu"), {}, hostile)
    line = next(ln for ln in md.splitlines() if ln.startswith("Datasheet "))
    assert line == 'Datasheet "X\\u202eY": "a\\nb\\u001b[2J".'
    assert not any(c in md for c in ("\u202e", "\x1b"))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[gyro]\nX = { value = 1.0, unit = '°/h' }", "use N, B, K or rms"),
        ("[gyro]\nN = { value = 1.0, unit = 'furlong' }", "unit 'furlong' unknown"),
        ("[gyro]\nN = { value = -1.0, unit = '°/h' }", "is not a number >= 0"),
        ("[gyro]\nN = 1.0", "must be {value = ..., unit = ...}"),
        ("part = 'x'", "no [gyro] or [accel] values"),
        ("[gyro", "not TOML"),
    ],
)
def test_bad_datasheets_are_refused(text: str, message: str) -> None:
    with pytest.raises(DatasheetError, match=message.replace("[", r"\[").replace("{", r"\{")):
        parse_datasheet(text, "x.toml")


def test_shipped_adis16364_values() -> None:
    sheet = adis16364()
    assert sheet.get("gyro", "random_walk").si() == pytest.approx(2.0 * np.pi / 180 / 60)
    assert sheet.get("accel", "bias_instability").si() == pytest.approx(0.1e-3 * 9.80665)


def test_cli_refuses_a_bad_datasheet_before_analysing(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[gyro]\nN = 3", encoding="utf-8")
    run = subprocess.run(
        [sys.executable, "-m", "imupipe", "analyze", str(tmp_path / "none.mcap"), "--datasheet",
         str(bad)],
        capture_output=True,
        text=True,
    )  # fmt: skip
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and "must be {value = ..., unit = ...}" in run.stderr
