"""The fleet report writer's outputs a user reads (session 54's mutation sample of
``fleet/report.py``): fleet.json's counts, fleet.rrd written by default, and fleet.md's
datasheet verdict per term."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import polars as pl

from imupipe.analysis.results import ALLAN_SCHEMA
from imupipe.fleet.population import UnitTerm, term_stats
from imupipe.fleet.report import population_rows, write_fleet_report
from imupipe.fleet.task import UnitOutcome
from imupipe.report.datasheet import load_datasheet
from imupipe.units import RAD_PER_DEG, SI_UNIT
from imupipe.vocab import TERM_NAMES


def _ok_unit(name: str, scale: float) -> UnitOutcome:
    """An analysed unit of one axis (gyro_x): every term resolved, adev = scale / √τ."""
    terms = {
        term: {"value": scale, "lo": 0.9 * scale, "hi": 1.1 * scale,
               "unit": SI_UNIT["gyro"][term], "reason": None}
        for term in TERM_NAMES
    }  # fmt: skip
    report = {
        "input": {"topic": "/imu", "frames": 1000, "rate_hz": 100.0, "duration_s": 10.0},
        "axes": {"gyro_x": {"sensor": "gyro", "ieee952": terms}},
    }
    tau = np.array([0.1, 1.0, 10.0])
    nan = [float("nan")] * len(tau)
    allan = pl.DataFrame(
        {
            "axis": ["gyro_x"] * len(tau), "unit": ["rad/s"] * len(tau), "tau": tau,
            "adev": scale / np.sqrt(tau), "lo": nan, "hi": nan, "edf": 1.0, "terms": 1,
            "alpha": 0.0, "adev_after": nan, "model_before": nan, "model_after": nan,
            "z_before": nan, "z_after": nan,
        },
        schema=ALLAN_SCHEMA,
    )  # fmt: skip
    return UnitOutcome(name, f"{name}.mcap", "ok", None, report, allan, 1.5, "h:1")


def _no_figures(fn, jobs):
    """A mapper that draws nothing (the figures are not what these tests read)."""
    return [b"png" for _ in jobs]


def test_the_fleet_report_counts_recordings_and_writes_fleet_rrd_by_default(tmp_path: Path):
    failed = UnitOutcome("bad", "bad.mcap", "failed", "not MCAP", None, None, 0.2, "h:1")
    outcomes = [_ok_unit("u1", 1e-4), failed, _ok_unit("u2", 2e-4)]
    doc, stats = write_fleet_report(outcomes, tmp_path, mapper=_no_figures)
    on_disk = json.loads((tmp_path / "fleet.json").read_text())
    assert on_disk == doc
    # "ok" > "failed" as strings: an analysed unit must not count as failed
    assert (doc["recordings"], doc["analysed"], doc["failed"]) == (3, 2, 1)
    assert "3 recordings: 2 analysed, 1 failed." in (tmp_path / "fleet.md").read_text()
    # the docstring's outputs, fleet.rrd among them when not asked otherwise
    rrd = tmp_path / "fleet.rrd"
    assert rrd.is_file() and rrd.stat().st_size > 0
    assert (tmp_path / "fleet.parquet").is_file()
    assert {s.term for s in stats} == set(TERM_NAMES)
    # and none when asked not to
    other = tmp_path / "no_rrd"
    other.mkdir()
    write_fleet_report(outcomes, other, rrd=False, mapper=_no_figures)
    assert not (other / "fleet.rrd").exists() and (other / "fleet.json").is_file()


def test_fleet_md_gives_each_terms_datasheet_verdict(tmp_path: Path):
    """The population table's datasheet column: "pass", "**fail**", or "—" when undecided."""
    path = tmp_path / "sheet.toml"
    path.write_text(
        'part = "P"\n[gyro]\nrandom_walk = { value = 2.0, unit = "°/√h" }\n'
        'bias_instability = { value = 0.5, unit = "rad/s", kind = "max" }\n'
    )
    sheet = load_datasheet(path)
    limit = 2.0 * RAD_PER_DEG / 60.0  # 2 °/√h in rad/s/√Hz
    rw = sheet.get("gyro", "random_walk")
    low = [UnitTerm(f"u{k}", f * limit, 0.9 * f * limit, 1.1 * f * limit)
           for k, f in enumerate((0.5, 0.6, 0.7))]  # fmt: skip
    high = [UnitTerm(f"u{k}", f * limit, 0.99 * f * limit, 1.01 * f * limit)
            for k, f in enumerate((1.5, 1.6, 1.7))]  # fmt: skip
    bi = sheet.get("gyro", "bias_instability")
    bounded = [UnitTerm("b0", None, None, 0.3), UnitTerm("b1", None, None, 0.7)]
    stats = [
        term_stats("gyro_x", "random_walk", "rad/s/sqrt(Hz)", low, rw),
        term_stats("gyro_y", "random_walk", "rad/s/sqrt(Hz)", high, rw),
        term_stats("gyro_z", "bias_instability", "rad/s", bounded, bi),
    ]
    assert [s.population_pass for s in stats] == [True, False, None]
    verdicts = [row[-1] for row in population_rows(stats)]
    assert verdicts == [
        "typical 2 °/√h: pass",
        "typical 2 °/√h: **fail** (3 unit(s) above: u0, u1, u2)",
        "max 0.5 rad/s: —",
    ]
