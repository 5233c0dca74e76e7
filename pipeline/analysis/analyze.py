"""``imupipe analyze``: run the stages in order, from MCAP bytes to reports.

decode (:mod:`imupipe.io.decode`) → condition (:mod:`imupipe.analysis.condition`) → Allan
deviation with confidence intervals (:mod:`imupipe.stats.allan`) → IEEE 952 noise terms
(:mod:`imupipe.model.ieee952`) → closed loop (:mod:`imupipe.model.loop`) → reports
(:mod:`imupipe.report.report`) and Rerun (:mod:`imupipe.report.rerun_view`).  Each stage's
output is the next one's input; nothing else is shared.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
import polars as pl

from imupipe.analysis.condition import ConditionedSeries, condition
from imupipe.analysis.results import AnalysisResult, AxisResult, InputSummary
from imupipe.errors import ImupipeError, TooFewFramesError
from imupipe.io.decode import ImuRecording, decode, mcap_files
from imupipe.model.ieee952 import fit_noise_terms
from imupipe.model.loop import AxisSignals, aux_block_means, close_loop
from imupipe.progress import StageProgress
from imupipe.stats.allan import AllanCurve, allan_curves, tau_factors
from imupipe.vocab import AXES, sensor_of

if TYPE_CHECKING:
    from imupipe.report.rerun_view import RrdWriter

MEMORY_BUDGET_BYTES = 2_000_000_000
"""Recordings whose whole-frame analysis would need more (estimated with
:data:`imupipe.analysis.lowmem.PEAK_BYTES_PER_FRAME`) take the pass-wise path of
:mod:`imupipe.analysis.lowmem`."""

MIN_FRAMES = 16
"""Fewer frames than this cannot give even the shortest averaging times with any confidence."""


@dataclass(frozen=True)
class AnalyzeOptions:
    topic: str | None = None
    taus_per_decade: int = 10
    gaps: Literal["longest", "fail"] = "longest"
    loop: bool = True
    rrd: bool = True
    figures: bool = True
    memory_budget_bytes: int = MEMORY_BUDGET_BYTES


def analyze_options(**options: object) -> AnalyzeOptions:
    """:class:`AnalyzeOptions` from keyword arguments, naming any unknown one.

    Raises:
        ImupipeError: an option that is not a field of :class:`AnalyzeOptions`.
    """
    known = {f.name for f in fields(AnalyzeOptions)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ImupipeError(f"unknown analyze option(s) {unknown}; known: {sorted(known)}")
    return AnalyzeOptions(**options)


def housekeeping(frames: pl.DataFrame, name: str) -> np.ndarray | None:
    """A housekeeping column as numpy, nulls filled from the neighbours; None if all null.

    Without nulls it is a zero-copy view of the frame's column (a 12 h / 100 Hz column is
    35 MB; the fill would copy it)."""
    col = frames[name]
    if col.null_count() == len(col):
        return None
    if col.null_count():
        col = col.fill_null(strategy="forward").fill_null(strategy="backward")
    return col.to_numpy()


def check_frames(rec: ImuRecording, n: int) -> None:
    if n < MIN_FRAMES:
        raise TooFewFramesError(
            f"{rec.path}: the longest clean segment has {n} frames, too few for any "
            f"averaging time (need at least {MIN_FRAMES})"
        )


def axis_result(
    name: str,
    y: np.ndarray,
    curve: AllanCurve,
    tau0_s: float,
    temp_d: np.ndarray | None,
    supply_d: np.ndarray | None,
    loop: bool,
) -> AxisResult:
    """Stage 4 (+ loop) of one axis: mean, rms, IEEE 952 terms and the closed loop
    (``temp_d``, ``supply_d``: the segment's temperature and supply as
    :func:`imupipe.model.loop.aux_block_means`)."""
    sensor = sensor_of(name)
    return AxisResult(
        name=name,
        sensor=sensor,
        unit="rad/s" if sensor == "gyro" else "m/s^2",
        mean=float(y.mean()),
        rms=float(y.std()),
        curve=curve,
        terms=fit_noise_terms(curve, sensor),
        loop=close_loop(AxisSignals(name, sensor, y, tau0_s, temp_d, supply_d), curve)
        if loop
        else None,
    )


def input_summary(rec: ImuRecording, series: ConditionedSeries, n: int) -> InputSummary:
    """The report's ``input`` section for a segment of ``n`` frames."""
    return InputSummary(
        path=str(rec.path),
        topic=rec.topic,
        frames=n,
        rate_hz=series.rate_hz,
        duration_s=n * series.tau0_s,
        segments=[s.as_dict() for s in series.segments],
        warnings=series.warnings,
        source=rec.source,
        time_source=rec.time_source,
        counts=series.counts,
    )


def analyze_series(
    rec: ImuRecording,
    series: ConditionedSeries,
    options: AnalyzeOptions,
    progress: StageProgress,
) -> AnalysisResult:
    """Stages 3–4 (+ loop) on the conditioned segment of a recording."""
    n = series.frames.height
    check_frames(rec, n)
    axes = [a for a in AXES if a not in series.stuck_axes]
    y = [series.frames[a].to_numpy() for a in axes]  # zero-copy views of the frame's columns
    m = tau_factors(n, per_decade=options.taus_per_decade)
    with progress.stage("allan", len(axes), "axes") as advance:
        curves = allan_curves(y, series.tau0_s, m)
        advance(len(axes))
    temp_d = aux_block_means(housekeeping(series.frames, "temp_c"), series.tau0_s)
    supply_d = aux_block_means(housekeeping(series.frames, "supply_v"), series.tau0_s)
    results: dict[str, AxisResult] = {}
    with progress.stage("noise fit", len(axes), "axes") as advance:
        for i, (name, curve) in enumerate(zip(axes, curves, strict=True)):
            results[name] = axis_result(
                name, y[i], curve, series.tau0_s, temp_d, supply_d, options.loop
            )
            advance(i + 1)
    return AnalysisResult(input=input_summary(rec, series, n), axes=results, device=rec.device)


def analyze(
    path: Path,
    out_dir: Path,
    options: AnalyzeOptions,
    progress: StageProgress,
) -> AnalysisResult:
    """Decode ``path``, analyse it and write the reports into ``out_dir``.

    The Rerun recording's raw signals are sent as soon as the segment is known, so that Rerun
    encodes them while the Allan deviation and the loop are computed.  A recording whose
    estimated peak exceeds ``options.memory_budget_bytes`` is analysed pass by pass instead
    (:func:`imupipe.analysis.lowmem.analyze_low_memory`), with the same results.
    """
    from imupipe.analysis.lowmem import analyze_low_memory, peak_estimate
    from imupipe.report.rerun_view import RrdWriter

    files = mcap_files(Path(path))
    if peak_estimate(files) > options.memory_budget_bytes:
        return analyze_low_memory(path, out_dir, options, progress)
    size = sum(f.stat().st_size for f in files)
    with progress.stage("decode", size, "bytes") as advance:
        rec = decode(path, topic=options.topic, progress=advance)
    series = condition(rec, gaps=options.gaps)
    out_dir.mkdir(parents=True, exist_ok=True)
    rrd = RrdWriter(out_dir / "recording.rrd", series.frames) if options.rrd else None
    try:
        result = analyze_series(rec, series, options, progress)
    except BaseException:
        if rrd:
            rrd.discard()
        raise
    write_outputs(result, out_dir, options, progress, rrd)
    return result


def write_outputs(
    result: AnalysisResult,
    out_dir: Path,
    options: AnalyzeOptions,
    progress: StageProgress,
    rrd: RrdWriter | None,
) -> None:
    """report.json/.md, figures, allan.parquet, imu.yaml, and the rrd's analysis views."""
    from imupipe.report.report import write_report

    with progress.stage("report", 2 if rrd else 1, "files") as advance:
        write_report(result, out_dir, figures=options.figures)
        advance(1)
        if rrd:
            rrd.finish(result)
            advance(2)
