"""Reports: report.json against its schema, the paper table, Kalibr imu.yaml, allan.parquet."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from imupipe.analysis.results import AnalysisResult
from imupipe.model import loop
from imupipe.report.report import format_table, kalibr_yaml, write_report
from imupipe.units import from_si, to_si

SCHEMA = Path(__file__).resolve().parents[2] / "schemas" / "report.schema.json"


@pytest.fixture(scope="module")
def written(
    tmp_path_factory: pytest.TempPathFactory, synthetic_result
) -> tuple[AnalysisResult, dict, Path]:
    result = synthetic_result()
    out = tmp_path_factory.mktemp("report")
    doc = write_report(result, out, figures=True)
    return result, doc, out


def test_report_json_matches_schema_and_contract(written, schema_errors) -> None:
    result, doc, out = written
    schema = json.loads(SCHEMA.read_text())
    on_disk = json.loads((out / "report.json").read_text())
    assert on_disk == doc
    assert schema_errors(on_disk, schema, schema) == []
    gyro = on_disk["axes"]["gyro_x"]
    assert gyro["unit"] == "rad/s"
    assert gyro["mean"] == pytest.approx(to_si(0.331, "°/s"), rel=1e-12)
    assert gyro["ieee952"]["random_walk"]["value"] == pytest.approx(to_si(0.05, "°/√s"))
    assert gyro["ieee952"]["random_walk"]["unit"] == "rad/s/sqrt(Hz)"
    assert gyro["allan"]["edf"][-1] is None  # NaN is written as null, not as invalid JSON
    curve = result.axes["gyro_x"].curve
    assert gyro["allan"]["tau_s"] == curve.tau_s.tolist()
    assert gyro["allan"]["adev"] == curve.adev.tolist()
    accel = on_disk["axes"]["accel_x"]
    # the model block of a looped axis: the FINAL model's terms (SI, with units) and the
    # goodness before -> after, in that order, with the dof of the final fit
    model = accel["model"]
    assert model["terms"]["random_walk"]["value"] == pytest.approx(to_si(0.29, "mg/√s"))
    assert model["terms"]["random_walk"]["unit"] == "m/s^2/sqrt(Hz)"
    assert "reason" not in model["terms"]["random_walk"]
    assert (model["error_before"], model["error_after"], model["dof"]) == (4.2, 1.03, 38)
    assert (model["tau_max_abs_z_before"], model["tau_max_abs_z_after"]) == (4000.0, 80.0)
    assert accel["effects"][0]["kind"] == "temperature"
    assert "model" not in on_disk["axes"]["accel_y"]


def test_the_schema_names_every_effect_kind_the_loop_can_add() -> None:
    """report.json of a real ADIS16405 unit failed its own schema: "narrowband" (and "ramp",
    "prefilter") were missing from the effect kinds' enum.  The enum is the loop's list, and
    the loop's kind sets all lie in it (an AcceptedEffect of another kind is refused)."""
    for schema in (SCHEMA, SCHEMA.with_name("fleet.schema.json")):  # fleet.json copies them
        enum = json.loads(schema.read_text())["$defs"]["effect"]["properties"]["kind"]["enum"]
        assert sorted(enum) == sorted(loop.EFFECT_KINDS), schema.name
    sets = loop.AVAR_ONLY | loop.SLOW_KINDS | loop.COUPLING_KINDS | loop.SPIKE_KINDS
    assert sets | set(loop.LINE_KINDS) | {"gauss_markov"} == set(loop.EFFECT_KINDS)
    with pytest.raises(ValueError, match="'warmup' is not one of EFFECT_KINDS"):
        loop.AcceptedEffect("warmup", {}, {}, {}, 1.0, 0.5)


def test_a_vibrating_units_report_json_validates(tmp_path: Path, schema_errors) -> None:
    """What real ADIS16405 units give, end to end: a bag (the mcap library's writer) whose
    accel_x carries a 10 Hz spread line below the baseline's fit start, analysed by
    imupipe.analyze: a narrowband effect, the fitted range widened, and report.json valid."""
    from scipy import signal

    from imupipe.api import analyze
    from imupipe.testing.busy_bag import Stream, write_bag
    from imupipe.testing.ros_cdr import imu_payloads

    n, tau0, sigma = 2**18, 0.01, 0.03
    rng = np.random.default_rng(1)
    r = np.exp(-np.pi * 0.5 * tau0)  # a damped oscillator: 10 Hz, 0.5 Hz wide
    line = signal.lfilter(
        [1.0], [1, -2 * r * np.cos(2 * np.pi * 10.0 * tau0), r * r], rng.standard_normal(n)
    )
    accel = sigma * rng.standard_normal((n, 3)) + [0.0, 0.0, 9.81]
    accel[:, 0] += 0.3 * sigma * line / line.std()
    gyro = 1e-3 * rng.standard_normal((n, 3))
    stamps = 10**18 + np.arange(n, dtype=np.int64) * 10_000_000
    payloads = [row.tobytes() for row in imu_payloads(stamps, gyro, accel)]
    bag = tmp_path / "vibrating.mcap"
    write_bag(bag, [Stream("/imu/data", "sensor_msgs/msg/Imu", payloads, stamps)])
    result = analyze(bag, tmp_path / "out", rrd=False)
    assert [e.kind for e in result.axes["accel_x"].loop.accepted] == ["narrowband"]
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    schema = json.loads(SCHEMA.read_text())
    assert schema_errors(doc, schema, schema) == []
    model = doc["axes"]["accel_x"]["model"]
    assert model["fit_tau_range_s_after"][0] == 0.01 < model["fit_tau_range_s_before"][0]
    assert model["error_before_final_range"] > 50 * model["error_after"]  # 122 against 1.31


def test_schema_check_catches_broken_reports(written, schema_errors) -> None:
    _, doc, _ = written
    schema = json.loads(SCHEMA.read_text())
    broken = json.loads(json.dumps(doc))
    del broken["input"]["frames"]
    broken["axes"]["gyro_y"]["ieee952"]["rate_ramp"]["unit"] = 3
    broken["axes"]["accel_x"]["effects"][0]["kind"] = "gremlin"
    # the shipped schema rejects each of the three breakages, where it is
    errors = schema_errors(broken, schema, schema)
    assert errors[:2] == [
        "$.input: missing frames",
        "$.axes.gyro_y.ieee952.rate_ramp.unit: int is not ['string']",
    ]
    assert errors[2].startswith("$.axes.accel_x.effects[0].kind: 'gremlin' not in [")
    assert len(errors) == 3, errors


def test_markdown_embeds_figures_and_paper_values(written) -> None:
    _, _, out = written
    md = (out / "report.md").read_text()
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == ["allan_accel.png", "allan_gyro.png", "loop_accel.png"]
    for png in pngs:
        assert f"({png})" in md
        assert (out / png).stat().st_size > 10_000
    assert "2 gaps; analysed the longest clean segment" in md
    assert "accepted **temperature** (coefficient = 0.00012 [0.00011, 0.00013])" in md
    assert "rejected candidate sinusoid: ΔBIC 2.1 < 10" in md
    assert "- gyro_y rate_random_walk: recording too short" in md


def test_terminal_table_is_in_paper_units(written) -> None:
    result, _, _ = written
    table = format_table(result)
    rows = {tuple(line.split()[:4]): line for line in table.splitlines()}
    rows |= {tuple(line.split()[:5]): line for line in table.splitlines()}
    # Random walk of accel_x: measured 0.29 [0.2842, 0.2958] mg/√s next to paper 0.29 and the
    # datasheet's 0.12 m/s/√h = 0.12 / 60 / 9.80665e-3 = 0.2039 mg/√s (the paper rounds it to 0.2)
    lines = [line for line in table.splitlines() if line.startswith("Random walk N       accel_x")]
    assert "0.29 [0.2842, 0.2958]" in lines[0]
    assert lines[0].split()[-3:] == ["0.29", "0.2039", "mg/√s"]
    # ... and again in the datasheet's unit: 0.29 mg/√s = 0.1706 m/s/√h, datasheet 0.12 m/s/√h
    assert lines[1].split()[-3:] == ["0.1706", "0.12", "m/s/√h"]
    assert "0.1706 [0.1672, 0.174]" in lines[1]
    # The paper's accel bias is printed as mg but is in g: 0.0273 g = 27.3 mg
    line = rows[("Bias", "(mean)", "accel_x", "27.3")]
    assert line.split()[-1] == "mg"
    assert rows[("Rate", "random", "walk", "K", "gyro_y")].split()[5] == "—"  # no bound given
    loop_line = next(ln for ln in table.splitlines() if ln.startswith("accel_x "))
    assert "4.2 → 1.03" in loop_line and "5.9 → 2.2 (τ 4000 → 80 s)" in loop_line


def test_kalibr_yaml_uses_worst_axis_and_upper_bound_for_missing_k(written, stand_in_truth) -> None:
    result, _, out = written
    text = (out / "imu.yaml").read_text()
    assert text == kalibr_yaml(result)
    values = {
        k: v.split("#")[0].strip()
        for k, v in (ln.split(":", 1) for ln in text.splitlines() if ln and ln[0] != "#")
    }
    gyro_n = max(result.axes[a].terms.random_walk.value for a in ("gyro_x", "gyro_y", "gyro_z"))
    assert float(values["gyroscope_noise_density"]) == pytest.approx(gyro_n, rel=1e-6)
    accel_n = to_si(0.29, "mg/√s")  # accel_x has the largest N of the paper's table
    assert float(values["accelerometer_noise_density"]) == pytest.approx(accel_n, rel=1e-6)
    # K is null on gyro_y/z: bounded by min over tau of adev_hi / sqrt(tau/3), which exceeds
    # gyro_x's resolved K here, so the worst axis is a bound and the file says so.
    c = result.axes["gyro_y"].curve
    hi = np.where(np.isfinite(c.adev_hi), c.adev_hi, c.adev)
    bound = float(np.min(hi / np.sqrt(c.tau_s / 3)))
    assert bound > stand_in_truth.k_gyro_x
    assert float(values["gyroscope_random_walk"]) == pytest.approx(bound, rel=1e-6)
    assert f"gyro_y: N {result.axes['gyro_y'].terms.random_walk.value:.6e}" in text
    how = "not resolved: upper bound from the Allan curve"
    assert f"K {bound:.6e} rad/s^2/sqrt(Hz) ({how})" in text
    assert float(values["update_rate"]) == stand_in_truth.rate_hz
    assert values["rostopic"] == "/imu/adis16364"


def test_allan_parquet_round_trips(written) -> None:
    result, _, out = written
    df = pl.read_parquet(out / "allan.parquet")
    assert df.columns[:9] == ["axis", "unit", "tau", "adev", "lo", "hi", "edf", "terms", "alpha"]
    for name, axis in result.axes.items():  # every axis' curve, tau by tau, in SI
        rows = df.filter(pl.col("axis") == name)
        np.testing.assert_array_equal(rows["tau"].to_numpy(), axis.curve.tau_s)
        assert set(rows["unit"]) == {"rad/s" if name.startswith("gyro") else "m/s^2"}
    gz = df.filter(pl.col("axis") == "gyro_z")
    np.testing.assert_array_equal(gz["adev"].to_numpy(), result.axes["gyro_z"].curve.adev)
    ax = df.filter(pl.col("axis") == "accel_x")
    loop = result.axes["accel_x"].loop
    np.testing.assert_array_equal(ax["z_after"].to_numpy(), loop.z_after)


def test_units_round_trip_and_known_factors() -> None:
    assert from_si(to_si(2.0, "°/√h"), "°/√s") == pytest.approx(2.0 / 60)
    assert to_si(1.0, "mg") == pytest.approx(9.80665e-3)
    assert from_si(to_si(0.12, "m/s/√h"), "mg/√s") == pytest.approx(0.12 / 60 / 9.80665e-3)
