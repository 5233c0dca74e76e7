"""The committed sample_logs/ are exactly what their documented commands produce, and analyse."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from imupipe.api import analyze
from imupipe.device.adis16364 import config_for_rate
from imupipe.recording.recorder import record
from imupipe.recording.scenario import load_scenario
from imupipe.recording.simulator import VirtualADIS16364

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"

# name: (duration s, rate Hz, seed, scenario) — the commands in README.md "sample_logs/"
RECIPES = {
    "adis16364_default_5min.mcap": (300, 100.0, 1, None),
    "lab_2h_10hz.mcap": (7200, 10.0, 7, "lab.toml"),
}


@pytest.mark.parametrize("name", sorted(RECIPES))
def test_sample_regenerates_byte_for_byte(tmp_path: Path, name: str) -> None:
    duration, rate, seed, scenario = RECIPES[name]
    source = VirtualADIS16364(
        config_for_rate(rate), load_scenario(SAMPLES / scenario) if scenario else None, seed=seed
    )
    out = tmp_path / name
    record(out, source, round(duration * rate))
    assert out.read_bytes() == (SAMPLES / name).read_bytes()


def test_default_sample_analyses_to_the_paper_random_walk(tmp_path: Path) -> None:
    result = analyze(
        SAMPLES / "adis16364_default_5min.mcap",
        tmp_path,
        rrd=False,
        figures=False,
    )
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["input"]["frames"] == 30000
    assert report["input"]["time_source"] == "header.stamp"
    assert report["input"]["counts"]["gaps"] == 0 and report["input"]["counts"]["frames"] == 30000
    assert result.input.warnings == []
    # gyro N = 0.05 °/√s = 8.73e-4 rad/s/√Hz in the simulator's defaults (the paper's table)
    n = report["axes"]["gyro_x"]["ieee952"]["random_walk"]
    assert n["lo"] <= 0.05 * 3.141592653589793 / 180 <= n["hi"]


def test_lab_sample_loop_finds_the_temperature_effect(tmp_path: Path) -> None:
    """The committed scenario recording: the loop traces gyro_x's misfit to temperature, with the
    truth (from the truth file beside it) inside the coefficient's interval, and nothing else."""
    truth = json.loads((SAMPLES / "lab_2h_10hz.truth.json").read_text())
    true_coefficient = truth["temperature"]["coefficients_si_per_kelvin"]["gyro_x"]
    analyze(
        SAMPLES / "lab_2h_10hz.mcap",
        tmp_path,
        rrd=False,
        figures=False,
    )
    axes = json.loads((tmp_path / "report.json").read_text())["axes"]
    found = {name: [e["kind"] for e in axis["effects"]] for name, axis in axes.items()}
    assert found == {name: (["temperature"] if name == "gyro_x" else []) for name in axes}
    effect = axes["gyro_x"]["effects"][0]
    lo, hi = effect["intervals"]["coefficient"]
    assert lo <= true_coefficient <= hi
    assert effect["error_after"] < effect["error_before"]
