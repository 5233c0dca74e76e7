"""The final noise model in the units and files of the filters users paste it into.

Every export reads the ``report.json`` document (:func:`imupipe.analysis.results.report_json`):
per axis the FINAL model's white-noise density N (``ieee952.random_walk``, u/√Hz) and rate
random walk K (``ieee952.rate_random_walk``, u/s/√Hz), in SI (u = rad/s or m/s²).  A term the
data cannot resolve is exported as its 95 % upper bound (conservative, never optimistic) and the
file says so.  ``imupipe export RESULT_DIR --format F`` and ``imupipe analyze --export F`` both
call :func:`write_exports`.

Conventions (continuous vs discrete time; density, standard deviation or variance; which random
walk), each read in the project's own documentation or source and cited in the written file:

======== ============================ =====================================================
format   file                         values
======== ============================ =====================================================
kalibr   imu.yaml                     N, K continuous (Kalibr wiki "IMU Noise Model")
openvins kalibr_imu_chain.yaml        N, K continuous (rpng/open_vins kalibr_imu_chain.yaml)
vins     vins_imu.yaml                N·√rate, K·√rate per-sample (VINS-Fusion integration_base.h)
orbslam3 orbslam3_imu.yaml            N, K continuous (ORB_SLAM3 Tracking.cc: ×√f, ÷√f inside)
basalt   basalt_imu.json              N, K continuous per axis (basalt calibration.h)
gtsam    gtsam_imu.yaml               N², K² continuous covariances (gtsam PreintegrationParams.h)
ros      imu_covariance.yaml          N²·rate per-sample variance (sensor_msgs/Imu.msg)
======== ============================ =====================================================

A format that takes one value per sensor gets the ``combine``d axes (``worst``: the largest,
conservative; ``mean``: the root mean square, the density of the average axis), stated in the
file.  ``inflate`` multiplies every noise strength (variances by its square): Allan terms are
measured at rest and constant temperature, and the Kalibr wiki ("Kalibr IMU noise parameters in
practice") advises filter users to inflate them for a moving platform, where scale factor,
misalignment, vibration and temperature add error the static model does not contain.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import yaml

from imupipe.errors import ExportError
from imupipe.vocab import AXES

Sensor = Literal["gyro", "accel"]
SENSORS: tuple[Sensor, ...] = ("accel", "gyro")
_LABEL = {"gyro": "gyroscope", "accel": "accelerometer"}
_UNITS = {  # N, K, rate
    "gyro": ("rad/s/sqrt(Hz)", "rad/s^2/sqrt(Hz)", "rad/s"),
    "accel": ("m/s^2/sqrt(Hz)", "m/s^3/sqrt(Hz)", "m/s^2"),
}
OPENCV_HEADER = "%YAML:1.0"
"""First line of an OpenCV ``cv::FileStorage`` YAML file (ORB-SLAM3, VINS-Fusion, OpenVINS)."""


@dataclass(frozen=True)
class ExportOptions:
    """``combine``: how one value per sensor is made of three axes; ``inflate``: factor on
    every noise strength (≥ 1 is the common practice); ``rate_hz``: the rate the filter or
    driver runs at (default: the recording's)."""

    combine: Literal["worst", "mean"] = "worst"
    inflate: float = 1.0
    rate_hz: float | None = None


@dataclass(frozen=True)
class AxisNoise:
    """One axis of the final model: N (u/√Hz) and K (u/s/√Hz), and how each was obtained."""

    axis: str
    density: float
    random_walk: float
    notes: tuple[str, str]


@dataclass(frozen=True)
class NoiseModel:
    """What every export writes: per sensor its axes (x, y, z order), the rate (Hz), the topic
    and source path (untrusted strings from the input), and the options."""

    sensors: dict[str, tuple[AxisNoise, ...]]
    rate_hz: float
    topic: str
    path: str
    options: ExportOptions

    def per_axis(self, sensor: Sensor, term: Literal["density", "random_walk"]) -> list[float]:
        """The ``inflate``d value of every axis of ``sensor`` (SI)."""
        return [getattr(a, term) * self.options.inflate for a in self.sensors[sensor]]

    def three_axes(self, sensor: Sensor, term: Literal["density", "random_walk"]) -> list[float]:
        """:meth:`per_axis` for a format that holds x, y and z of a sensor: an
        :class:`ExportError` naming the axes the unit provides when they are fewer."""
        axes = [a.axis for a in self.sensors[sensor]]
        if len(axes) != 3:
            raise ExportError(
                f"it needs all three axes of a sensor; the {sensor}'s are {', '.join(axes)} only"
            )
        return self.per_axis(sensor, term)

    def combined(self, sensor: Sensor, term: Literal["density", "random_walk"]) -> float:
        """One value for the sensor: the largest axis (``worst``) or the root mean square
        (``mean``: the density whose square is the mean PSD of the axes)."""
        values = self.per_axis(sensor, term)
        if self.options.combine == "worst":
            return max(values)
        return math.sqrt(sum(v * v for v in values) / len(values))

    def header(self, fmt: str, convention: str) -> list[str]:
        """Comment lines every file starts with: source, what the numbers are, how combined."""
        lines = [
            f"{fmt} IMU noise written by imupipe from its final noise model (SI units).",
            f"Source: {json.dumps(self.path)}, topic {json.dumps(self.topic)}.",
            f"Convention: {convention}",
            f"Inflation factor on noise strengths: {self.options.inflate:g} (variances: its "
            "square); 1 = as measured at rest.",
        ]
        for sensor, axes in self.sensors.items():
            for a in axes:
                lines.append(
                    f"{a.axis}: N {a.density:.6e} {_UNITS[sensor][0]} ({a.notes[0]}), "
                    f"K {a.random_walk:.6e} {_UNITS[sensor][1]} ({a.notes[1]})"
                )
        return lines


def _term(axis_doc: dict, name: str, where: str) -> tuple[float, str]:
    """(value, how obtained) of an IEEE 952 term of the final model in report.json."""
    term = axis_doc.get("ieee952", {}).get(name)
    if not isinstance(term, dict):
        raise ExportError(f"{where}: report.json has no ieee952.{name}")
    if term.get("value") is not None:
        return float(term["value"]), "fitted"
    if term.get("hi") is not None:
        return float(term["hi"]), "not resolved: its 95 % upper bound"
    return _curve_bound(axis_doc.get("allan", {}), name, where)


_ASYMPTOTE = {
    "random_walk": lambda tau: tau**-0.5,
    "rate_random_walk": lambda tau: (tau / 3) ** 0.5,
}
"""σ(τ) of a unit N and K (IEEE 952 Annex C: N/√τ, K√(τ/3))."""


def _curve_bound(allan: dict, name: str, where: str) -> tuple[float, str]:
    """A term with neither value nor bound (a report from elsewhere): the largest value whose
    asymptote stays below the measured deviation's upper bound (its value where none) at every
    τ, min over τ of adev_hi(τ) / σ₁(τ)."""
    taus, adev, hi = allan.get("tau_s") or [], allan.get("adev") or [], allan.get("adev_hi") or []
    ratios = [
        (h if h is not None else a) / _ASYMPTOTE[name](t)
        for t, a, h in zip(taus, adev, hi or [None] * len(taus), strict=False)
        if t and (h is not None or a is not None)
    ]
    if not ratios:
        raise ExportError(f"{where}: ieee952.{name} has no value or bound and no Allan curve")
    return min(ratios), "not resolved: upper bound from the Allan curve"


def check_options(options: ExportOptions) -> None:
    """Raise :class:`ExportError` for options no export can use."""
    if options.combine not in ("worst", "mean"):
        raise ExportError(f"--combine {options.combine!r}: use worst or mean")
    if not (math.isfinite(options.inflate) and options.inflate > 0):
        raise ExportError(f"--inflate {options.inflate!r}: must be a positive number")
    rate = options.rate_hz
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise ExportError(f"--rate {rate!r}: must be a positive number of Hz")


def noise_model(doc: dict, options: ExportOptions = ExportOptions()) -> NoiseModel:
    """The :class:`NoiseModel` of a report.json document (its final model)."""
    check_options(options)
    axes = doc.get("axes", {})
    inp = doc.get("input", {})
    sensors: dict[str, tuple[AxisNoise, ...]] = {}
    for sensor in SENSORS:
        found = []
        for name in (a for a in AXES if a.startswith(sensor) and a in axes):
            n, n_note = _term(axes[name], "random_walk", name)
            k, k_note = _term(axes[name], "rate_random_walk", name)
            found.append(AxisNoise(name, n, k, (n_note, k_note)))
        if found:
            sensors[sensor] = tuple(found)
    if not sensors:
        raise ExportError("report.json holds no gyro or accelerometer axis to export")
    rate = options.rate_hz if options.rate_hz is not None else inp.get("rate_hz")
    if not (isinstance(rate, int | float) and math.isfinite(rate) and rate > 0):
        raise ExportError(f"rate {rate!r} Hz: give a positive --rate")
    return NoiseModel(
        sensors, float(rate), str(inp.get("topic", "")), str(inp.get("path", "")), options
    )


def _comments(lines: list[str]) -> str:
    """``# `` lines; any line break inside a line (from an untrusted string) is escaped by
    :func:`json.dumps` before it gets here, the rest are split so nothing leaves the comment."""
    return "".join(f"# {part}\n" for line in lines for part in line.splitlines())


class _Dumper(yaml.SafeDumper):
    """PyYAML's safe dumper as cv::FileStorage reads it: no anchors/aliases, sequences
    indented under their key, a list of numbers on one line ``[a, b, c]``."""

    def ignore_aliases(self, data: object) -> bool:
        return True

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        return super().increase_indent(flow, False)


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flat = all(not isinstance(v, list | dict) for v in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flat)


_Dumper.add_representer(list, _represent_list)


def _yaml(body: dict, comments: list[str], opencv: bool = False) -> str:
    """YAML written by PyYAML (``safe_dump``: strings quoted as needed, so no value can add a
    key), after ``# `` comments; with ``opencv`` the ``%YAML:1.0`` line cv::FileStorage needs."""
    text = yaml.dump(body, Dumper=_Dumper, sort_keys=False, default_flow_style=False, width=1000)
    return (OPENCV_HEADER + "\n" if opencv else "") + _comments(comments) + text


def _kalibr_keys(m: NoiseModel) -> dict:
    out = {}
    for sensor in SENSORS:
        if sensor in m.sensors:
            out[f"{_LABEL[sensor]}_noise_density"] = m.combined(sensor, "density")
            out[f"{_LABEL[sensor]}_random_walk"] = m.combined(sensor, "random_walk")
    return out


def _combine_note(m: NoiseModel) -> str:
    how = {"worst": "the largest axis (conservative)", "mean": "the root mean square of the axes"}
    return f"One value per sensor: {how[m.options.combine]} (--combine {m.options.combine})."


KALIBR_CITE = (
    "continuous-time noise density N [u/sqrt(Hz)] (*_noise_density) and bias random walk K "
    "[u/s/sqrt(Hz)] (*_random_walk), as the Kalibr wiki 'IMU Noise Model' defines them "
    "(https://github.com/ethz-asl/kalibr/wiki/IMU-Noise-Model); Kalibr discretises itself: "
    "sigma_d = N / sqrt(dt), sigma_bd = K * sqrt(dt)."
)


def kalibr(m: NoiseModel) -> str:
    """Kalibr ``imu.yaml``."""
    body = _kalibr_keys(m) | {"rostopic": m.topic, "update_rate": m.rate_hz}
    return _yaml(body, [*m.header("Kalibr", KALIBR_CITE), _combine_note(m)])


def openvins(m: NoiseModel) -> str:
    """OpenVINS ``kalibr_imu_chain.yaml`` (read by ov_core's YamlParser, cv::FileStorage)."""
    eye3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    imu0 = {
        "T_i_b": [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)],
        **_kalibr_keys(m),
        "rostopic": m.topic,
        "time_offset": 0.0,
        "update_rate": m.rate_hz,
        "model": "kalibr",
        "Tw": eye3,
        "R_IMUtoGYRO": eye3,
        "Ta": eye3,
        "R_IMUtoACC": eye3,
        "Tg": [[0.0] * 3 for _ in range(3)],
    }
    cite = (
        "the Kalibr continuous-time densities, as rpng/open_vins config/*/kalibr_imu_chain.yaml "
        "label them ([rad/s/sqrt(Hz)] gyro 'white noise', [rad/s^2/sqrt(Hz)] gyro bias "
        "diffusion, [m/s^2/sqrt(Hz)], [m/s^3/sqrt(Hz)]); OpenVINS' propagator discretises them "
        "with the IMU dt. " + KALIBR_CITE
    )
    notes = [*m.header("OpenVINS", cite), _combine_note(m)]
    notes.append(
        "Intrinsics Tw, Ta, R_IMUto*, Tg: identity / zero (imupipe does not estimate "
        "them); T_i_b identity."
    )
    return _yaml({"imu0": imu0}, notes, opencv=True)


def vins(m: NoiseModel) -> str:
    """VINS-Fusion / VINS-Mono ``acc_n, gyr_n, acc_w, gyr_w`` (cv::FileStorage YAML)."""
    root_rate = math.sqrt(m.rate_hz)
    cite = (
        "per-sample (discrete-time) standard deviations at update rate f = "
        f"{m.rate_hz:g} Hz: acc_n, gyr_n = N * sqrt(f); acc_w, gyr_w = K * sqrt(f).  VINS "
        "(HKUST-Aerial-Robotics/VINS-Fusion vins_estimator/src/factor/integration_base.h, "
        "midPointIntegration) propagates covariance = F P F^T + V Q V^T with Q = diag(acc_n^2, "
        "gyr_n^2, ..., acc_w^2, gyr_w^2) and V = 0.5 R dt on the measurement noise, I dt on "
        "the bias noise: per step the bias variance grows by acc_w^2 dt^2, which equals the "
        "continuous K^2 dt for acc_w = K / sqrt(dt); its config calls acc_n the 'measurement "
        "noise standard deviation', N / sqrt(dt) for a sample of white noise of density N."
    )
    body: dict = {}
    if "accel" in m.sensors:
        body["acc_n"] = m.combined("accel", "density") * root_rate
        body["acc_w"] = m.combined("accel", "random_walk") * root_rate
    if "gyro" in m.sensors:
        body["gyr_n"] = m.combined("gyro", "density") * root_rate
        body["gyr_w"] = m.combined("gyro", "random_walk") * root_rate
    body |= {"g_norm": 9.80665, "imu_topic": m.topic}
    notes = [
        *m.header("VINS-Fusion", cite),
        _combine_note(m),
        "g_norm: standard gravity (m/s^2); set your local value.",
    ]
    return _yaml(body, notes, opencv=True)


def orbslam3(m: NoiseModel) -> str:
    """ORB-SLAM3 ``IMU.*`` settings (cv::FileStorage YAML)."""
    cite = (
        "continuous-time densities, as ORB-SLAM3 (UZ-SLAMLab/ORB_SLAM3 src/Tracking.cc) reads "
        "them: sf = sqrt(IMU.Frequency); IMU::Calib(Tbc, NoiseGyro*sf, NoiseAcc*sf, "
        "GyroWalk/sf, AccWalk/sf) - it discretises itself; its log prints the units "
        "rad/s/sqrt(Hz), rad/s^2/sqrt(Hz), m/s^2/sqrt(Hz), m/s^3/sqrt(Hz)."
    )
    body = {}
    if "gyro" in m.sensors:
        body["IMU.NoiseGyro"] = m.combined("gyro", "density")
        body["IMU.GyroWalk"] = m.combined("gyro", "random_walk")
    if "accel" in m.sensors:
        body["IMU.NoiseAcc"] = m.combined("accel", "density")
        body["IMU.AccWalk"] = m.combined("accel", "random_walk")
    body["IMU.Frequency"] = m.rate_hz
    return _yaml(body, [*m.header("ORB-SLAM3", cite), _combine_note(m)], opencv=True)


def basalt(m: NoiseModel) -> str:
    """Basalt calibration JSON fragment (cereal): the IMU noise members of ``value0``."""
    cite = (
        "per axis (x, y, z), continuous time, as VladyslavUsenko/basalt-headers "
        "include/basalt/calibration/calibration.hpp documents the members of Calibration: "
        "gyro_noise_std / accel_noise_std 'continuous time noise standard deviation' (N, "
        "u/sqrt(Hz)), gyro_bias_std / accel_bias_std 'continuous time bias random walk "
        "standard deviation' (K, u/s/sqrt(Hz)); discretised by basalt as sigma_c * "
        "sqrt(imu_update_rate).  Merge these members into the value0 object of your "
        "calib.json (it also needs the camera members)."
    )
    value0: dict = {"imu_update_rate": m.rate_hz}
    keys = {
        "accel": ("accel_noise_std", "accel_bias_std"),
        "gyro": ("gyro_noise_std", "gyro_bias_std"),
    }
    for sensor in SENSORS:
        if sensor in m.sensors:
            noise, bias = keys[sensor]
            value0[noise] = m.three_axes(sensor, "density")
            value0[bias] = m.three_axes(sensor, "random_walk")
    doc = {"value0": value0, "imupipe": m.header("Basalt", cite)}
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def _diagonal(values: list[float]) -> list[list[float]]:
    """3 × 3 matrix with ``values`` on the diagonal (x, y, z)."""
    return [[values[i] if i == j else 0.0 for j in range(3)] for i in range(3)]


def gtsam(m: NoiseModel) -> str:
    """GTSAM PreintegrationParams / PreintegrationCombinedParams covariances (YAML)."""
    cite = (
        "continuous-time covariances, per axis on the diagonal, as borglab/gtsam "
        "gtsam/navigation/PreintegratedRotation.h and PreintegrationParams.h declare "
        "gyroscopeCovariance ('continuous-time Covariance of gyroscope measurements') = N^2 "
        "[rad^2/s^2/Hz], accelerometerCovariance = N^2 [m^2/s^4/Hz], and "
        "PreintegrationCombinedParams.h biasOmegaCovariance / biasAccCovariance "
        "('continuous-time Covariance describing gyroscope / accelerometer bias random "
        "walk') = K^2 [rad^2/s^3], [m^2/s^5]. Python: "
        "p = gtsam.PreintegrationCombinedParams.MakeSharedU(g); "
        "p.setGyroscopeCovariance(np.array(d['gyroscopeCovariance'])); ... "
        "integrationCovariance is a filter choice, not an IMU property: not written."
    )
    body = {}
    keys = {
        "gyro": ("gyroscopeCovariance", "biasOmegaCovariance"),
        "accel": ("accelerometerCovariance", "biasAccCovariance"),
    }
    for sensor in ("gyro", "accel"):
        if sensor in m.sensors:
            white, bias = keys[sensor]
            body[white] = _diagonal([v * v for v in m.three_axes(sensor, "density")])
            body[bias] = _diagonal([v * v for v in m.three_axes(sensor, "random_walk")])
    return _yaml(body, m.header("GTSAM", cite))


def ros(m: NoiseModel) -> str:
    """sensor_msgs/msg/Imu per-sample covariance diagonals for a driver at ``rate_hz``."""
    cite = (
        f"per-sample variances at {m.rate_hz:g} Hz, row major about x, y, z (common_interfaces "
        "sensor_msgs/msg/Imu.msg): the white-noise variance of one sample, N^2 * f "
        "(sigma(tau0)^2 = N^2 / tau0, IEEE Std 952 Annex C) [rad^2/s^2, m^2/s^4]; the bias "
        "terms are not a per-sample covariance and are not included. orientation_covariance "
        "element 0 = -1: 'no orientation estimate' (Imu.msg)."
    )
    body: dict = {"rate_hz": m.rate_hz, "orientation_covariance": [-1.0] + [0.0] * 8}
    names = {"gyro": "angular_velocity_covariance", "accel": "linear_acceleration_covariance"}
    for sensor in ("gyro", "accel"):
        if sensor in m.sensors:
            variances = [v * v * m.rate_hz for v in m.three_axes(sensor, "density")]
            body[names[sensor]] = [x for row in _diagonal(variances) for x in row]
    return _yaml(body, m.header("sensor_msgs/Imu", cite))


FORMATS: dict[str, tuple[str, Callable[[NoiseModel], str]]] = {
    "kalibr": ("imu.yaml", kalibr),
    "openvins": ("kalibr_imu_chain.yaml", openvins),
    "vins": ("vins_imu.yaml", vins),
    "orbslam3": ("orbslam3_imu.yaml", orbslam3),
    "basalt": ("basalt_imu.json", basalt),
    "gtsam": ("gtsam_imu.yaml", gtsam),
    "ros": ("imu_covariance.yaml", ros),
}
"""format name: (file name, writer)."""


def _known(formats: list[str]) -> None:
    """An :class:`ExportError` naming the first of ``formats`` that is neither ``all`` nor one
    of :data:`FORMATS`."""
    unknown = [f for f in formats if f != "all" and f not in FORMATS]
    if unknown:
        raise ExportError(f"unknown export format {unknown[0]!r}; known: {', '.join(FORMATS)}")


def _rendered(model: NoiseModel, fmt: str) -> tuple[str, str]:
    """(file name, text) of the export ``fmt`` (one of :data:`FORMATS`) of ``model``."""
    name, write = FORMATS[fmt]
    return name, write(model)


def render(doc: dict, fmt: str, options: ExportOptions = ExportOptions()) -> tuple[str, str]:
    """(file name, text) of one export of a report.json document."""
    _known([fmt])
    return _rendered(noise_model(doc, options), fmt)


@dataclass(frozen=True)
class Written:
    """The files :func:`write_exports` wrote, and one sentence per format it left out."""

    paths: list[Path]
    skipped: list[str]


def write_exports(
    doc: dict, formats: list[str], out_dir: Path, options: ExportOptions = ExportOptions()
) -> Written:
    """Write each export of ``formats`` (``all``: every one) into ``out_dir``, every check
    before any write.  A format that cannot hold the model (Basalt's, GTSAM's and the ROS
    covariances' three values per sensor, for a unit that provides fewer axes) is an
    :class:`ExportError` naming it when it was asked for by name; under ``all`` it is left
    out and said in :attr:`Written.skipped` (a gyro-only unit still gets its Kalibr file)."""
    _known(formats)
    model = noise_model(doc, options)  # what no format can write: said once, not per format
    everything = "all" in formats
    rendered, skipped = [], []
    for fmt in list(FORMATS) if everything else formats:
        try:
            rendered.append(_rendered(model, fmt))
        except ExportError as exc:
            if not everything:
                raise ExportError(f"{fmt}: {exc}") from None
            skipped.append(f"export {fmt} not written: {exc}")
    paths = []
    for name, text in rendered:
        path = Path(out_dir) / name
        path.write_text(text)
        paths.append(path)
    return Written(paths, skipped)


def export_result_dir(
    result_dir: Path,
    formats: list[str],
    out_dir: Path | None = None,
    options: ExportOptions = ExportOptions(),
) -> Written:
    """``imupipe export``: the exports of an analysis folder's report.json, written into
    ``out_dir`` (default: that folder)."""
    doc = read_report(result_dir)
    target = Path(out_dir) if out_dir is not None else Path(result_dir)
    target.mkdir(parents=True, exist_ok=True)
    return write_exports(doc, formats, target, options)


def read_report(result_dir: Path) -> dict:
    """The report.json of an ``imupipe analyze`` output folder."""
    path = Path(result_dir) / "report.json"
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ExportError(
            f"{path}: not found (give the output folder of imupipe analyze)"
        ) from None
    except (OSError, json.JSONDecodeError) as exc:
        raise ExportError(f"{path}: unreadable ({exc})") from None
