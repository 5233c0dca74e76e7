"""Scenario TOML parsing, validation, defaults and the ground-truth dictionary."""

import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from imupipe.recording.scenario import (
    RRW_CROSSOVER_S,
    Scenario,
    ScenarioError,
    load_scenario,
    scenario_from_dict,
)

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "sample_logs"


def test_documented_example_parses():
    text = (SAMPLE_LOGS.parent / "docs" / "user-guide.md").read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    s = scenario_from_dict(tomllib.loads(block))
    assert s.noise["gyro_x"].rate_random_walk == 1.3e-4
    assert [e.axis for e in (*s.sinusoid, *s.bias_step, *s.drift, *s.spikes)] == [
        "gyro_z",
        "accel_x",
        "gyro_x",
        "accel_z",
    ]
    assert s.temperature.at(np.array([1800.0]))[0] == pytest.approx(23.5)
    assert s.supply.sensitivity == {"accel_z": 2.0}


def test_lab_example_has_one_effect():
    s = load_scenario(SAMPLE_LOGS / "lab.toml")
    assert s.name == "lab"
    assert [a for a in s.noise if s.has_effects(a)] == ["gyro_x"]
    assert s.noise == Scenario().noise  # noise terms are the defaults
    t = np.array([0.0, 450.0, 1350.0])
    assert np.allclose(s.deterministic("gyro_x", t), [0.0, 0.015, -0.015])


def test_override_merges_with_defaults():
    s = scenario_from_dict({"noise": {"accel_y": {"random_walk": 0.5}}})
    assert s.noise["accel_y"].random_walk == 0.5
    assert s.noise["accel_y"].bias_instability == 0.161
    assert s.noise["accel_y"].bias == -21.1
    assert s.noise["gyro_x"] == Scenario().noise["gyro_x"]


@pytest.mark.parametrize(
    ("doc", "match"),
    [
        ({"noise": {"gyro_w": {"bias": 1.0}}}, "unknown axis"),
        ({"noise": {"gyro_x": {"arw": 1.0}}}, "unknown key"),
        ({"sinusoid": [{"axis": "gyro_x", "amplitude": 1.0}]}, "frequency_hz"),
        ({"sinusoid": [{"axis": "mag_x", "amplitude": 1.0, "frequency_hz": 1.0}]}, "axis"),
        ({"temperature": {"amplitude_c": 1.0}}, "period_s"),
        ({"drift": [{"axis": "gyro_x", "warmup_tau_s": 0.0}]}, "warmup_tau_s"),
        ({"bogus": 1}, "top-level"),
        ({"host": {"jitter": 1}}, "host"),
        ({"noise": {"gyro_x": {"gm_sigma": 0.1}}}, "gm_tau_s"),
    ],
)
def test_invalid_scenarios_are_rejected(doc, match):
    with pytest.raises(ScenarioError, match=match):
        scenario_from_dict(doc)


def test_unreadable_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("noise = [")
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(bad)


def test_default_rate_random_walk_crosses_plateau_at_6h():
    gx = Scenario().noise["gyro_x"]
    plateau = 0.664 * gx.bias_instability
    assert gx.rrw * math.sqrt(RRW_CROSSOVER_S / 3) == pytest.approx(plateau, rel=1e-3)
    assert RRW_CROSSOVER_S == 21600.0


def test_truth_dict_units():
    s = scenario_from_dict(
        {
            "bias_step": [{"axis": "accel_x", "time_s": 10.0, "size": 2.0}],
            "temperature": {"coefficients": {"gyro_z": 0.02}},
        }
    )
    truth = json.loads(json.dumps(s.truth_dict()))
    gx, ax = truth["noise"]["gyro_x"], truth["noise"]["accel_x"]
    assert gx["paper_units"]["units"]["random_walk"] == "°/√s"
    assert gx["si"]["random_walk"] == pytest.approx(0.05 * math.pi / 180)
    assert gx["si"]["adev_plateau"] == pytest.approx(0.664 * 0.008 * math.pi / 180, rel=1e-3)
    assert ax["si"]["random_walk"] == pytest.approx(0.29e-3 * 9.80665)
    assert ax["si"]["mean"] == pytest.approx(27.3e-3 * 9.80665)
    step = truth["effects"]["bias_step"][0]
    assert step["unit"] == "mg" and step["size_si"] == pytest.approx(2e-3 * 9.80665)
    coeff = truth["temperature"]["coefficients_si_per_kelvin"]["gyro_z"]
    assert coeff == pytest.approx(0.02 * math.pi / 180)


def test_effect_shapes_are_the_documented_ones():
    """The supply's ripple, a warm-up and a drift, value by value (unit, V, s)."""
    s = scenario_from_dict(
        {
            "supply": {"nominal_v": 5.0, "ripple_amplitude_v": 0.2, "ripple_frequency_hz": 0.5},
            "drift": [
                {"axis": "gyro_x", "warmup_amplitude": 2.0, "warmup_tau_s": 600.0,
                 "slope_per_hour": 0.5},
                {"axis": "gyro_y", "warmup_amplitude": 1.0, "warmup_tau_s": 10.0},
            ],
        }
    )  # fmt: skip
    t = np.array([0.0, 0.5, 1.5, 3600.0])
    np.testing.assert_allclose(s.supply.at(t), [5.0, 5.2, 4.8, 5.0], atol=1e-12)
    full, warmup_only = s.drift
    np.testing.assert_allclose(full.at(t), 2.0 * np.exp(-t / 600.0) + 0.5 * t / 3600.0, rtol=1e-15)
    assert full.at(np.array([3600.0]))[0] == pytest.approx(2.0 * math.exp(-6.0) + 0.5)
    np.testing.assert_allclose(warmup_only.at(t), np.exp(-t / 10.0), rtol=1e-15)  # no slope


def test_valid_corner_values_are_accepted():
    """Host jitter, a fast temperature cycle and spikes of the default 20 ms parse."""
    s = scenario_from_dict(
        {
            "host": {"jitter_s": 0.002},
            "temperature": {"amplitude_c": 1.0, "period_s": 0.5},
            "spikes": [{"axis": "accel_z", "rate_per_hour": 2.0, "amplitude": 5.0}],
        }
    )
    assert s.jitter_s == 0.002
    assert s.temperature.at(np.array([0.125]))[0] == pytest.approx(21.0 + 1.0)
    assert s.spikes[0].duration_s == 0.02
    with pytest.raises(AttributeError):
        s.spikes[0].duration_s = 1.0  # frozen: a scenario read is not changed behind its truth
