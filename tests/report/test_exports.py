"""Exports of the final noise model: each file parsed as its users parse it, every value checked
against the model with the unit conversion written out here, independently of the exporter."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from imupipe.report.exports import FORMATS, ExportError, ExportOptions, render, write_exports

RATE = 200.0
# final model per axis: N (u/√Hz), K (u/s/√Hz); None = not resolved, exported as its bound
N = {"gyro_x": 1.1e-4, "gyro_y": 1.3e-4, "gyro_z": 1.2e-4,
     "accel_x": 2.0e-3, "accel_y": 2.4e-3, "accel_z": 2.2e-3}  # fmt: skip
K = {"gyro_x": 2.0e-6, "gyro_y": None, "gyro_z": 1.0e-6,
     "accel_x": 3.0e-5, "accel_y": 4.0e-5, "accel_z": None}  # fmt: skip
K_BOUND = {"gyro_y": 5.0e-6, "accel_z": 9.0e-5}  # the 95 % upper bounds report.json states
GYROS, ACCELS = ("gyro_x", "gyro_y", "gyro_z"), ("accel_x", "accel_y", "accel_z")


def _term(value: float | None, bound: float | None, unit: str) -> dict:
    if value is None:
        return {"value": None, "lo": None, "hi": bound, "unit": unit, "reason": "not resolved"}
    return {"value": value, "lo": value * 0.9, "hi": value * 1.1, "unit": unit, "reason": None}


def report_doc(topic: str = "/imu0", path: str = "run.mcap") -> dict:
    axes = {}
    for name in (*GYROS, *ACCELS):
        u = "rad/s" if name.startswith("gyro") else "m/s^2"
        axes[name] = {
            "ieee952": {
                "random_walk": _term(N[name], None, f"{u}/sqrt(Hz)"),
                "rate_random_walk": _term(K[name], K_BOUND.get(name), f"{u[:-2]}^2/sqrt(Hz)"),
            }
        }
    return {"input": {"path": path, "topic": topic, "rate_hz": RATE}, "axes": axes}


def k_of(name: str) -> float:
    return K[name] if K[name] is not None else K_BOUND[name]


def parse_opencv_yaml(path: Path) -> dict:
    """As ORB-SLAM3 / VINS-Fusion / OpenVINS read it: cv::FileStorage when OpenCV is installed;
    otherwise PyYAML after removing the ``%YAML:1.0`` directive only OpenCV understands."""
    text = path.read_text()
    assert text.startswith("%YAML:1.0\n")
    try:
        import cv2
    except ImportError:
        return yaml.safe_load(text.split("\n", 1)[1])
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)

    def node_value(node):
        if node.isMap():
            return {k: node_value(node.getNode(k)) for k in node.keys()}
        if node.isSeq():
            return [node_value(node.at(i)) for i in range(node.size())]
        if node.isString():
            return node.string()
        return node.real()

    out = node_value(fs.root())
    fs.release()
    return out


@pytest.fixture
def written(tmp_path: Path) -> dict[str, Path]:
    paths = write_exports(report_doc(), ["all"], tmp_path).paths
    return {p.name: p for p in paths}


def test_every_format_is_written(written) -> None:
    assert sorted(written) == sorted(name for name, _ in FORMATS.values())


def test_kalibr_continuous_worst_axis(written) -> None:
    doc = yaml.safe_load(written["imu.yaml"].read_text())
    assert doc["gyroscope_noise_density"] == pytest.approx(1.3e-4, rel=1e-12)  # gyro_y
    assert doc["gyroscope_random_walk"] == pytest.approx(5.0e-6, rel=1e-12)  # gyro_y's bound
    assert doc["accelerometer_noise_density"] == pytest.approx(2.4e-3, rel=1e-12)
    assert doc["accelerometer_random_walk"] == pytest.approx(9.0e-5, rel=1e-12)  # accel_z bound
    assert doc["update_rate"] == RATE and doc["rostopic"] == "/imu0"
    text = written["imu.yaml"].read_text()
    assert "gyro_y: N 1.300000e-04 rad/s/sqrt(Hz) (fitted), K 5.000000e-06" in text
    assert "not resolved: its 95 % upper bound" in text and "--combine worst" in text


def test_openvins_chain_is_kalibr_densities(written) -> None:
    imu0 = parse_opencv_yaml(written["kalibr_imu_chain.yaml"])["imu0"]
    assert imu0["gyroscope_noise_density"] == pytest.approx(1.3e-4, rel=1e-12)
    assert imu0["gyroscope_random_walk"] == pytest.approx(5.0e-6, rel=1e-12)
    assert imu0["accelerometer_noise_density"] == pytest.approx(2.4e-3, rel=1e-12)
    assert imu0["accelerometer_random_walk"] == pytest.approx(9.0e-5, rel=1e-12)
    assert imu0["update_rate"] == RATE and imu0["rostopic"] == "/imu0"
    assert imu0["T_i_b"][3] == [0.0, 0.0, 0.0, 1.0]


def test_vins_per_sample_standard_deviations(written) -> None:
    doc = parse_opencv_yaml(written["vins_imu.yaml"])
    # one sample of white noise of density N at 200 Hz: N / sqrt(1/200 s); bias noise K * sqrt(f)
    assert doc["gyr_n"] == pytest.approx(1.3e-4 / math.sqrt(1 / 200), rel=1e-12)
    assert doc["acc_n"] == pytest.approx(2.4e-3 / math.sqrt(0.005), rel=1e-12)
    assert doc["gyr_w"] == pytest.approx(5.0e-6 * math.sqrt(200), rel=1e-12)
    assert doc["acc_w"] == pytest.approx(9.0e-5 / math.sqrt(0.005), rel=1e-12)
    assert doc["g_norm"] == pytest.approx(9.80665)


def test_orbslam3_continuous_with_real_frequency(written) -> None:
    doc = parse_opencv_yaml(written["orbslam3_imu.yaml"])
    assert doc["IMU.NoiseGyro"] == pytest.approx(1.3e-4, rel=1e-12)
    assert doc["IMU.GyroWalk"] == pytest.approx(5.0e-6, rel=1e-12)
    assert doc["IMU.NoiseAcc"] == pytest.approx(2.4e-3, rel=1e-12)
    assert doc["IMU.AccWalk"] == pytest.approx(9.0e-5, rel=1e-12)
    assert doc["IMU.Frequency"] == RATE
    # ORB-SLAM3 reads IMU.Frequency with readParameter<float>: it must be written as a real
    assert "IMU.Frequency: 200.0" in written["orbslam3_imu.yaml"].read_text()


def test_basalt_per_axis_continuous(written) -> None:
    doc = json.loads(written["basalt_imu.json"].read_text())
    v = doc["value0"]
    assert v["imu_update_rate"] == RATE
    assert v["gyro_noise_std"] == pytest.approx([N[a] for a in GYROS], rel=1e-12)
    assert v["accel_noise_std"] == pytest.approx([N[a] for a in ACCELS], rel=1e-12)
    assert v["gyro_bias_std"] == pytest.approx([k_of(a) for a in GYROS], rel=1e-12)
    assert v["accel_bias_std"] == pytest.approx([k_of(a) for a in ACCELS], rel=1e-12)
    assert next(iter(doc)) == "value0"  # cereal reads the first member unnamed


def test_gtsam_continuous_covariances(written) -> None:
    doc = yaml.safe_load(written["gtsam_imu.yaml"].read_text())
    for key, axes, values in (
        ("gyroscopeCovariance", GYROS, N),
        ("accelerometerCovariance", ACCELS, N),
        ("biasOmegaCovariance", GYROS, None),
        ("biasAccCovariance", ACCELS, None),
    ):
        m = doc[key]
        for i, a in enumerate(axes):
            sigma = values[a] if values is not None else k_of(a)
            assert m[i][i] == pytest.approx(sigma**2, rel=1e-12), (key, a)
            assert [m[i][j] for j in range(3) if j != i] == [0.0, 0.0]


def test_ros_imu_per_sample_variances(written) -> None:
    doc = yaml.safe_load(written["imu_covariance.yaml"].read_text())
    av, la = doc["angular_velocity_covariance"], doc["linear_acceleration_covariance"]
    assert len(av) == len(la) == 9
    for i, a in enumerate(GYROS):  # row major: diagonal at 0, 4, 8
        assert av[4 * i] == pytest.approx((N[a] / math.sqrt(1 / RATE)) ** 2, rel=1e-12)
    for i, a in enumerate(ACCELS):
        assert la[4 * i] == pytest.approx(N[a] ** 2 * RATE, rel=1e-12)
    assert doc["orientation_covariance"][0] == -1.0


def test_combine_mean_inflate_and_rate(tmp_path: Path) -> None:
    options = ExportOptions(combine="mean", inflate=3.0, rate_hz=50.0)
    write_exports(report_doc(), ["kalibr", "ros"], tmp_path, options)
    doc = yaml.safe_load((tmp_path / "imu.yaml").read_text())
    rms = math.sqrt((1.1e-4**2 + 1.3e-4**2 + 1.2e-4**2) / 3)
    assert doc["gyroscope_noise_density"] == pytest.approx(3.0 * rms, rel=1e-12)
    assert doc["update_rate"] == 50.0
    assert "--combine mean" in (tmp_path / "imu.yaml").read_text()
    ros = yaml.safe_load((tmp_path / "imu_covariance.yaml").read_text())
    assert ros["angular_velocity_covariance"][0] == pytest.approx(9.0 * 1.1e-4**2 * 50, rel=1e-12)


def test_topic_and_path_cannot_inject_keys() -> None:
    topic = "/imu\ngyroscope_noise_density: 1e-12"
    path = "run.mcap\naccelerometer_noise_density: 1e-12\n# x"
    _, text = render(report_doc(topic, path), "kalibr")
    doc = yaml.safe_load(text)
    assert doc["gyroscope_noise_density"] == pytest.approx(1.3e-4, rel=1e-12)
    assert doc["accelerometer_noise_density"] == pytest.approx(2.4e-3, rel=1e-12)
    assert doc["rostopic"] == topic
    assert set(doc) == {
        "accelerometer_noise_density",
        "accelerometer_random_walk",
        "gyroscope_noise_density",
        "gyroscope_random_walk",
        "rostopic",
        "update_rate",
    }


def test_bad_options_and_reports_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="inflate"):
        render(report_doc(), "kalibr", ExportOptions(inflate=0.0))
    with pytest.raises(ExportError, match="unknown export format"):
        render(report_doc(), "rovio")
    doc = report_doc()
    doc["axes"]["gyro_x"]["ieee952"]["random_walk"] = {"value": None, "hi": None}
    with pytest.raises(ExportError, match="no value or bound and no Allan curve"):
        render(doc, "kalibr")
    run = subprocess.run(
        [sys.executable, "-m", "imupipe", "export", str(tmp_path), "--format", "kalibr"],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2
    assert run.stderr.strip().endswith("not found (give the output folder of imupipe analyze)")


def test_cli_export_writes_from_report_json(tmp_path: Path) -> None:
    (tmp_path / "report.json").write_text(json.dumps(report_doc()))
    run = subprocess.run(
        [sys.executable, "-m", "imupipe", "export", str(tmp_path), "-f", "orbslam3", "-f",
         "basalt", "--inflate", "2"],
        capture_output=True,
        text=True,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    doc = parse_opencv_yaml(tmp_path / "orbslam3_imu.yaml")
    assert doc["IMU.NoiseGyro"] == pytest.approx(2 * 1.3e-4, rel=1e-12)
    assert (tmp_path / "basalt_imu.json").is_file() and not (tmp_path / "imu.yaml").exists()


def test_cli_export_all_of_a_gyro_only_unit_writes_what_it_can_and_warns(tmp_path: Path) -> None:
    doc = report_doc()
    doc["axes"] = {"gyro_x": doc["axes"]["gyro_x"]}  # a single-axis gyro, as the real MTi-G
    (tmp_path / "report.json").write_text(json.dumps(doc))
    run = subprocess.run(
        [sys.executable, "-m", "imupipe", "export", str(tmp_path), "-f", "all"],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    assert run.stderr.splitlines() == [
        f"warning: export {fmt} not written: it needs all three axes of a sensor; the gyro's "
        "are gyro_x only"
        for fmt in ("basalt", "gtsam", "ros")
    ]
    assert run.stdout.splitlines() == [
        str(tmp_path / name)
        for name in ("imu.yaml", "kalibr_imu_chain.yaml", "vins_imu.yaml", "orbslam3_imu.yaml")
    ]
    asked = subprocess.run(
        [sys.executable, "-m", "imupipe", "export", str(tmp_path), "-f", "ros"],
        capture_output=True,
        text=True,
    )
    assert asked.returncode == 2
    assert asked.stderr.splitlines() == [
        "imupipe: error: ros: it needs all three axes of a sensor; the gyro's are gyro_x only"
    ]
