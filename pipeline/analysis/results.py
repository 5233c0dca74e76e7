"""Typed result of ``imupipe analyze``: what the stages produce and the reports consume.

The orchestrator fills an :class:`AnalysisResult`; :mod:`imupipe.report.report`,
:mod:`imupipe.report.figures` and :mod:`imupipe.report.rerun_view` only read it.  All values are SI
(rad/s for gyros, m/s² for accelerometers); conversions to display units live in
:mod:`imupipe.units`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, is_dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import polars as pl

from imupipe import __version__
from imupipe.vocab import AXES

if TYPE_CHECKING:
    from imupipe.analysis.events import EventsFound
    from imupipe.model.ieee952 import NoiseTerms
    from imupipe.model.loop import LoopResult
    from imupipe.stats.allan import AllanCurve


@dataclass(frozen=True)
class AxisResult:
    """Everything measured on one axis.

    ``mean`` is the bias (average of the data) and ``rms`` the standard deviation about the mean
    (the paper's "output noise"), both in ``unit`` ("rad/s" or "m/s^2").  ``terms`` is the
    FINAL model: after the closed loop (``loop.terms_after``), or the IEEE 952 fit where the loop
    did not run or accepted nothing; every report and export shows it.  :attr:`baseline` is the
    fit before the loop.
    """

    name: str
    sensor: Literal["gyro", "accel"]
    unit: str
    mean: float
    rms: float
    curve: AllanCurve
    terms: NoiseTerms
    loop: LoopResult | None = None
    outliers: dict | None = None
    """Samples excised before the fit (:func:`imupipe.analysis.analyze.excise_outliers`)."""

    @property
    def baseline(self) -> NoiseTerms:
        """The IEEE 952 fit before the closed loop (the final model when the loop did not run)."""
        return self.terms if self.loop is None else self.loop.terms_before


@dataclass(frozen=True)
class InputSummary:
    """What was analysed: file, topic, frame count, rate (Hz), duration (s) of the analysed data,
    the clean segments found (dicts from the condition stage), the warnings raised, the message
    type, the time base (``header.stamp`` or ``log_time``), what conditioning counted, the
    Temperature topic used as the IMU's temperature (None: none, or the ADIS16364's own) and
    the time window analysed."""

    path: str
    topic: str
    frames: int
    rate_hz: float
    duration_s: float
    segments: list[dict] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    source: str = "adis16364"
    time_source: str = "header.stamp"
    counts: dict[str, int] = field(default_factory=dict)
    temperature_topic: str | None = None
    window_s: tuple[float, float | None] = (0.0, None)
    """The time window asked for (``--start``, ``--end``: s from the first frame; end None: the
    last frame, negative: before it)."""


@dataclass(frozen=True)
class AnalysisResult:
    """The input summary, the per-axis results keyed by axis name, and device metadata."""

    input: InputSummary
    axes: dict[str, AxisResult]
    device: dict[str, str] = field(default_factory=dict)
    events: EventsFound | None = None
    """Disturbance events found jointly on all axes (None: the search did not run)."""

    def by_sensor(self, sensor: str) -> list[AxisResult]:
        """The axes of one sensor ("gyro" or "accel") in report order."""
        return [self.axes[a] for a in AXES if a in self.axes and self.axes[a].sensor == sensor]

    def to_dict(self) -> dict:
        """The ``report.json`` document: SI units, every term labelled with its unit, no NaN
        (non-finite values become ``None``); its JSON Schema is ``schemas/report.schema.json``."""
        return report_json(self)

    def to_polars(self) -> pl.DataFrame:
        """The Allan curves in long form (:data:`ALLAN_SCHEMA`; the content of allan.parquet)."""
        return allan_frame(self)


SCHEMA_VERSION = 1
ERROR_MEASURE = "gamma deviance per degree of freedom of the Allan-variance model fit"
"""What ``error_before``/``error_after`` are (issue 4; lower is better)."""
TIME_ERROR_MEASURE = (
    "mean square of the whitened residual: first differences of the coarse block means "
    "(<= 1024 blocks, tau >= T/1024) as standardised one-step prediction errors under the "
    "fitted model's rate PSD, linear ramp projected out; about 1 when the model describes the "
    "series in the time domain, above 1 when something is missing"
)
"""What ``model.time_domain_error_before``/``after`` are (issue 13 item 7)."""

ALLAN_SCHEMA = pl.Schema(
    {
        "axis": pl.String,
        "unit": pl.String,
        "tau": pl.Float64,
        "adev": pl.Float64,
        "lo": pl.Float64,
        "hi": pl.Float64,
        "edf": pl.Float64,
        "terms": pl.Int64,
        "alpha": pl.Float64,
        "adev_after": pl.Float64,
        "model_before": pl.Float64,
        "model_after": pl.Float64,
        "z_before": pl.Float64,
        "z_after": pl.Float64,
    }
)
"""The contract of ``allan.parquet`` and :meth:`AnalysisResult.to_polars`."""


def jsonable(obj: object) -> object:
    """``obj`` with numpy scalars/arrays turned into Python values, non-finite floats into
    ``None`` (JSON has no NaN) and dataclass instances (the loop's records) into dicts of their
    fields, recursively through dicts, lists and tuples."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return jsonable(asdict(obj))
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    return obj


def _axis_json(axis: AxisResult) -> dict:
    curve = axis.curve
    out: dict = {
        "sensor": axis.sensor,
        "unit": axis.unit,
        "mean": axis.mean,
        "rms": axis.rms,
        "allan": {
            "tau_s": curve.tau_s,
            "adev": curve.adev,
            "adev_lo": curve.adev_lo,
            "adev_hi": curve.adev_hi,
            "edf": curve.edf,
            "n_terms": curve.n_terms,
            "alpha": curve.alpha,
            "confidence": curve.confidence,
            "model_adev": axis.terms.adev(curve.tau_s),
        },
        "ieee952": axis.terms.as_dict(),
        "ieee952_fit": axis.terms.fit_summary(),
    }
    if axis.outliers is not None:
        out["outliers"] = axis.outliers
    loop = axis.loop
    if loop is not None:
        out["allan"]["adev_after"] = loop.adev_after
        out["allan"]["model_adev_before"] = loop.model_adev_before
        out["allan"]["model_adev_after"] = loop.model_adev_after
        out["residual"] = {"z_before": loop.z_before, "z_after": loop.z_after}
        out["model"] = loop.as_model_dict()
        out["effects"] = loop.accepted
        out["candidates"] = loop.rejected
        out["before"] = {
            "ieee952": loop.terms_before.as_dict(),
            "ieee952_fit": loop.terms_before.fit_summary(),
            "error": loop.before.error,
        }
    return out


def report_json(result: AnalysisResult) -> dict:
    """The ``report.json`` document (SI units; every term carries its unit)."""
    return jsonable(
        {
            "schema_version": SCHEMA_VERSION,
            "generator": {"name": "imupipe", "version": __version__},
            "error_measure": ERROR_MEASURE,
            "time_domain_error_measure": TIME_ERROR_MEASURE,
            "input": asdict(result.input),
            "device": dict(result.device),
            "axes": {name: _axis_json(axis) for name, axis in result.axes.items()},
        }
        | ({} if result.events is None else {"events": result.events.as_dict()})
    )


def allan_frame(result: AnalysisResult) -> pl.DataFrame:
    """The Allan curves in long form: axis, tau (s), adev, lo, hi (axis unit), edf, terms (number
    of overlapping differences averaged), alpha (noise type), and, after the loop, the measured
    deviation after its time-domain corrections, the model deviations before/after and the
    normalised residuals."""
    frames = [pl.DataFrame(schema=ALLAN_SCHEMA)]
    for axis in result.axes.values():
        c = axis.curve
        n = len(c.tau_s)
        cols = {
            "axis": [axis.name] * n,
            "unit": [axis.unit] * n,
            "tau": np.asarray(c.tau_s, dtype=np.float64),
            "adev": np.asarray(c.adev, dtype=np.float64),
            "lo": np.asarray(c.adev_lo, dtype=np.float64),
            "hi": np.asarray(c.adev_hi, dtype=np.float64),
            "edf": np.asarray(c.edf, dtype=np.float64),
            "terms": np.asarray(c.n_terms, dtype=np.int64),
            "alpha": np.asarray(c.alpha, dtype=np.float64),
        }
        nan = np.full(n, np.nan)
        loop = axis.loop
        cols["adev_after"] = nan if loop is None else np.asarray(loop.adev_after, float)
        cols["model_before"] = nan if loop is None else np.asarray(loop.model_adev_before, float)
        cols["model_after"] = nan if loop is None else np.asarray(loop.model_adev_after, float)
        cols["z_before"] = nan if loop is None else np.asarray(loop.z_before, float)
        cols["z_after"] = nan if loop is None else np.asarray(loop.z_after, float)
        frames.append(pl.DataFrame(cols, schema=ALLAN_SCHEMA))
    return pl.concat(frames)
