"""Exports from report.json documents of other shapes than tests/test_exports.py's: a term with
neither value nor bound (bounded from the Allan curve), one sensor only, a missing axis, the
mean combination, the header lines, options checked before anything is written, and the
``imupipe export`` folder logic.  Expected values are computed here (the report_doc builder is a
small copy of tests/test_exports.py's, not an import)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml

from imupipe.errors import ExportError
from imupipe.report.exports import (
    ExportOptions,
    export_result_dir,
    noise_model,
    read_report,
    render,
    write_exports,
)

N = {"gyro_x": 1.0e-4, "gyro_y": 3.0e-4, "gyro_z": 2.0e-4,
     "accel_x": 2.0e-3, "accel_y": 1.0e-3, "accel_z": 4.0e-3}  # fmt: skip
K = {"gyro_x": 2.0e-6, "gyro_y": 1.0e-6, "gyro_z": 4.0e-6,
     "accel_x": 3.0e-5, "accel_y": 6.0e-5, "accel_z": 5.0e-5}  # fmt: skip


def _term(value: float | None, hi: float | None = None) -> dict:
    return {"value": value, "lo": None, "hi": hi, "unit": "u", "reason": None}


def report_doc(axes: tuple[str, ...] = tuple(N), rate: object = 100.0) -> dict:
    doc_axes = {
        a: {"ieee952": {"random_walk": _term(N[a]), "rate_random_walk": _term(K[a])}} for a in axes
    }
    return {"input": {"path": "p.mcap", "topic": "/t", "rate_hz": rate}, "axes": doc_axes}


def _kalibr(doc: dict, **options) -> dict:
    return yaml.safe_load(render(doc, "kalibr", ExportOptions(**options))[1])


def test_term_without_value_or_bound_is_bounded_by_the_allan_curve() -> None:
    doc = report_doc()
    ax = doc["axes"]["gyro_z"]
    ax["ieee952"]["rate_random_walk"] = _term(None)
    ax["ieee952"]["random_walk"] = _term(None)
    # hi where given, else the deviation itself; tau 0 ignored
    ax["allan"] = {
        "tau_s": [0.0, 1.0, 3.0, 12.0],
        "adev": [9.0, 5.0e-4, 2.0e-4, 1.0e-4],
        "adev_hi": [9.0, 6.0e-4, None, 1.5e-4],
    }
    # K ≤ min over τ of σ(τ) / √(τ/3): 6e-4/√(1/3), 2e-4/1, 1.5e-4/2 -> 7.5e-5
    # N ≤ min over τ of σ(τ) · √τ: 6e-4, 2e-4·√3, 1.5e-4·√12 -> 3.4641e-4
    m = noise_model(doc)
    z = m.sensors["gyro"][2]
    assert z.random_walk == pytest.approx(7.5e-5, rel=1e-12)
    assert z.density == pytest.approx(2.0e-4 * math.sqrt(3), rel=1e-12)
    assert z.notes == ("not resolved: upper bound from the Allan curve",) * 2
    assert _kalibr(doc)["gyroscope_random_walk"] == pytest.approx(7.5e-5, rel=1e-12)
    # without adev_hi at all, the deviation is the bound
    ax["allan"] = {"tau_s": [3.0, 12.0], "adev": [2.0e-4, 1.0e-4]}
    assert noise_model(doc).sensors["gyro"][2].random_walk == pytest.approx(5.0e-5, rel=1e-12)


def test_resolved_value_wins_over_its_bound() -> None:
    doc = report_doc()
    doc["axes"]["accel_y"]["ieee952"]["random_walk"] = _term(1.0e-3, hi=9.0)
    doc["axes"]["accel_z"]["ieee952"]["random_walk"] = _term(None, hi=5.0e-3)
    m = noise_model(doc)
    assert [a.density for a in m.sensors["accel"]] == [2.0e-3, 1.0e-3, 5.0e-3]
    assert m.sensors["accel"][2].notes[0] == "not resolved: its 95 % upper bound"
    assert m.sensors["accel"][1].notes == ("fitted", "fitted")


def test_mean_is_the_root_mean_square_and_inflate_scales_every_file() -> None:
    doc = report_doc()
    k = _kalibr(doc, combine="mean", inflate=2.0)
    assert k["gyroscope_noise_density"] == pytest.approx(
        2 * math.sqrt((1e-4**2 + 3e-4**2 + 2e-4**2) / 3), rel=1e-12
    )
    assert k["accelerometer_random_walk"] == pytest.approx(
        2 * math.sqrt((3e-5**2 + 6e-5**2 + 5e-5**2) / 3), rel=1e-12
    )
    worst = _kalibr(doc)
    assert worst["gyroscope_noise_density"] == 3e-4  # gyro_y
    assert worst["accelerometer_random_walk"] == 6e-5  # accel_y
    text = render(doc, "gtsam", ExportOptions(inflate=3.0))[1]
    g = yaml.safe_load(text)
    assert g["biasAccCovariance"][1][1] == pytest.approx((3 * 6e-5) ** 2, rel=1e-12)
    assert "# Inflation factor on noise strengths: 3 (variances: its square)" in text
    assert "# accel_z: N 4.000000e-03 m/s^2/sqrt(Hz) (fitted), K 5.000000e-05 m/s^3" in text
    assert "# gyro_x: N 1.000000e-04 rad/s/sqrt(Hz) (fitted), K 2.000000e-06 rad/s^2" in text
    assert '# Source: "p.mcap", topic "/t".' in text


def test_one_sensor_only() -> None:
    doc = report_doc(("gyro_x", "gyro_y", "gyro_z"))
    assert set(_kalibr(doc)) == {
        "gyroscope_noise_density", "gyroscope_random_walk", "rostopic", "update_rate"
    }  # fmt: skip
    vins = yaml.safe_load(render(doc, "vins")[1].split("\n", 1)[1])
    assert set(vins) == {"gyr_n", "gyr_w", "g_norm", "imu_topic"}
    assert vins["gyr_w"] == pytest.approx(4e-6 * 10, rel=1e-12)  # K · √(100 Hz)
    orb = yaml.safe_load(render(doc, "orbslam3")[1].split("\n", 1)[1])
    assert set(orb) == {"IMU.NoiseGyro", "IMU.GyroWalk", "IMU.Frequency"}
    ros = yaml.safe_load(render(doc, "ros")[1])
    assert "linear_acceleration_covariance" not in ros
    assert ros["angular_velocity_covariance"][4] == pytest.approx(9e-8 * 100, rel=1e-12)
    assert ros["angular_velocity_covariance"][1:4] == [0.0, 0.0, 0.0]
    basalt = json.loads(render(doc, "basalt")[1])["value0"]
    assert set(basalt) == {"imu_update_rate", "gyro_noise_std", "gyro_bias_std"}
    gtsam = yaml.safe_load(render(report_doc(("accel_x", "accel_y", "accel_z")), "gtsam")[1])
    assert set(gtsam) == {"accelerometerCovariance", "biasAccCovariance"}
    assert gtsam["accelerometerCovariance"][2] == [0.0, 0.0, pytest.approx(16e-6, rel=1e-12)]


def test_per_axis_formats_need_all_three_axes() -> None:
    doc = report_doc(("gyro_x", "gyro_z", "accel_x", "accel_y", "accel_z"))
    assert _kalibr(doc)["gyroscope_noise_density"] == 2e-4
    for fmt in ("basalt", "gtsam", "ros"):
        with pytest.raises(
            ExportError, match="three axes of a sensor; the gyro's are gyro_x, gyro_z only"
        ):
            render(doc, fmt)


def test_openvins_intrinsics_are_identity() -> None:
    text = render(report_doc(), "openvins")[1]
    imu0 = yaml.safe_load(text.split("\n", 1)[1])["imu0"]
    eye = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    assert imu0["Tw"] == imu0["Ta"] == imu0["R_IMUtoGYRO"] == imu0["R_IMUtoACC"] == eye
    assert imu0["Tg"] == [[0.0] * 3] * 3
    assert imu0["T_i_b"] == [[float(i == j) for j in range(4)] for i in range(4)]
    assert (imu0["model"], imu0["time_offset"], imu0["update_rate"]) == ("kalibr", 0.0, 100.0)
    assert imu0["accelerometer_noise_density"] == 4e-3


@pytest.mark.parametrize(
    ("options", "message"),
    [({"combine": "max"}, "--combine 'max': use worst or mean"),
     ({"inflate": -1.0}, "--inflate -1.0: must be a positive number"),
     ({"inflate": math.inf}, "--inflate inf"),
     ({"rate_hz": 0.0}, "--rate 0.0: must be a positive number of Hz"),
     ({"rate_hz": math.nan}, "--rate nan")],
)  # fmt: skip
def test_bad_options(options: dict, message: str, tmp_path: Path) -> None:
    with pytest.raises(ExportError, match=f"^{message}".replace("(", r"\(")):
        write_exports(report_doc(), ["kalibr"], tmp_path, ExportOptions(**options))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("rate", [None, 0, -5.0, "100", math.inf])
def test_rate_must_come_from_the_report_or_the_option(rate: object) -> None:
    with pytest.raises(ExportError, match=r"Hz: give a positive --rate"):
        render(report_doc(rate=rate), "kalibr")
    assert _kalibr(report_doc(rate=rate), rate_hz=40.0)["update_rate"] == 40.0
    assert _kalibr(report_doc(rate=250))["update_rate"] == 250.0


def test_reports_without_axes_or_terms() -> None:
    with pytest.raises(ExportError, match="holds no gyro or accelerometer axis to export"):
        render({"input": {"rate_hz": 100.0}, "axes": {"temp": {}}}, "kalibr")
    doc = report_doc()
    del doc["axes"]["accel_y"]["ieee952"]["rate_random_walk"]
    with pytest.raises(ExportError, match=r"^accel_y: report.json has no ieee952.rate_random_walk"):
        render(doc, "kalibr")


def test_one_bad_format_writes_nothing(tmp_path: Path) -> None:
    doc = report_doc(("gyro_x", "gyro_y"))  # kalibr can, gtsam cannot
    with pytest.raises(ExportError, match=r"^gtsam: it needs all three axes"):
        write_exports(doc, ["kalibr", "gtsam"], tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_an_unknown_format_is_named_first_and_nothing_is_written(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match=r"^unknown export format 'bogus'; known: kalibr, "):
        write_exports(report_doc(), ["kalibr", "bogus", "ghost", "all"], tmp_path)
    with pytest.raises(ExportError, match=r"^unknown export format 'ahrs'"):  # < "all"
        write_exports(report_doc(), ["ahrs"], tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_all_writes_what_a_unit_with_fewer_axes_allows_and_says_what_it_left_out(
    tmp_path: Path,
) -> None:
    """A gyro-only unit (a single-axis gyro, as the real MTi-G): ``all`` writes the formats
    that take one value per sensor and names each one it left out; a format asked for by name
    that cannot hold it is an error naming it; nothing to export at all is one error."""
    written = write_exports(report_doc(("gyro_x",)), ["all"], tmp_path)
    assert [p.name for p in written.paths] == [
        "imu.yaml", "kalibr_imu_chain.yaml", "vins_imu.yaml", "orbslam3_imu.yaml"
    ]  # fmt: skip
    assert written.skipped == [
        f"export {fmt} not written: it needs all three axes of a sensor; the gyro's are gyro_x only"
        for fmt in ("basalt", "gtsam", "ros")
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in written.paths)
    assert write_exports(report_doc(), ["all"], tmp_path).skipped == []
    with pytest.raises(ExportError, match=r"^report\.json holds no gyro or accelerometer axis"):
        write_exports({"input": {"rate_hz": 100.0}, "axes": {}}, ["all"], tmp_path)


def test_export_result_dir(tmp_path: Path) -> None:
    (tmp_path / "report.json").write_text(json.dumps(report_doc()))
    written = export_result_dir(tmp_path, ["vins", "ros"]).paths
    assert [p.name for p in written] == ["vins_imu.yaml", "imu_covariance.yaml"]
    assert all(p.parent == tmp_path for p in written)
    other = export_result_dir(tmp_path, ["all"], tmp_path / "new" / "dir").paths
    assert len(other) == 7 and (tmp_path / "new" / "dir" / "basalt_imu.json").is_file()
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "report.json").write_text("{not json")
    with pytest.raises(ExportError, match=r"report.json: unreadable \(Expecting"):
        read_report(tmp_path / "bad")
    with pytest.raises(ExportError, match="not found"):
        read_report(tmp_path / "nowhere")
