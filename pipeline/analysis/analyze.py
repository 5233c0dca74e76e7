"""``imupipe analyze``: the one orchestrator, running the stages in order once.

column source (:mod:`imupipe.io.columns`: decode in memory, or decode once and spill to a
temporary on-disk store when the recording would not fit the memory budget) → condition
(:mod:`imupipe.analysis.condition`) → per axis: Allan deviation with confidence intervals
(:mod:`imupipe.stats.allan`), IEEE 952 noise terms (:mod:`imupipe.model.ieee952`), closed loop
(:mod:`imupipe.model.loop`) → outputs (an :class:`Outputs`, e.g.
:class:`imupipe.report.outputs.ReportOutputs`: reports and Rerun).  Each stage's output is the
next one's input, a new value; no stage changes what it was given.  The axes are handed out one
at a time, whichever source, so the same code gives the same numbers on both.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Protocol

import numpy as np
import polars as pl
from numba.core.dispatcher import Dispatcher
from threadpoolctl import threadpool_limits

from imupipe.analysis.at_rest import coincident_step_warnings, specific_force_warning
from imupipe.analysis.condition import (
    ABSENT,
    ConditionedSeries,
    GapPolicy,
    condition,
    named_frames,
    no_axis_error,
    stuck_warning,
    two_sensors,
    unanalysable,
)
from imupipe.analysis.events import EventsFound, detect, event_mask, fill_excised, fine_means
from imupipe.analysis.results import AnalysisResult, AxisResult, InputSummary
from imupipe.analysis.workers import axes_at_once, axis_pool
from imupipe.errors import ImupipeError, TooFewFramesError
from imupipe.io.columns import HOUSEKEEPING, ColumnSource, open_columns
from imupipe.io.decode import ImuRecording
from imupipe.jit import disk_cached, imported_kernels
from imupipe.model.ahead import compile_ahead
from imupipe.model.effects import Candidate, NoisePsd, Whitener, psd_line, spike_candidate
from imupipe.model.ieee952 import fit_noise_terms
from imupipe.model.loop import AxisSignals, aux_block_means, close_loop
from imupipe.pages import small_pages
from imupipe.progress import StageProgress
from imupipe.stats import robust
from imupipe.stats.allan import FIT_MIN_TERMS, AllanCurve, allan_curves, tau_factors
from imupipe.stats.edf import ACF_WINDOW, b1_noise_id, noise_ids
from imupipe.vocab import AXES, sensor_of

MEMORY_BUDGET_BYTES = 2_000_000_000
"""Recordings whose in-memory analysis would need more (estimated by
:func:`imupipe.io.columns.peak_estimate`) are read through the spilled column source."""

MIN_FRAMES = 16
"""Fewer frames than this cannot give even the shortest averaging times with any confidence."""

BLAS_THREADS = 1
"""BLAS threads while the axes are analysed.  The loop's products are small (the whitening
matrix is at most 1024 x 1024) and many (~340 at 12 h / 100 Hz): OpenBLAS' threads cost far
more than they share, most of all on a busy machine where they spin waiting for a core
(measured: 300 products of a 1023 x 1023 matrix and a vector, 1.78 s of CPU with 2 threads on
a loaded 2-core machine, 0.04 s with one; the same bits either way)."""


AxisReader = Callable[[str], np.ndarray]
"""An axis' samples of the analysed rows, by name."""
AxisMap = Callable[[Callable[[str], object], Iterable[str]], Iterator[object]]
"""``map`` over axis names, maybe on threads (:func:`imupipe.analysis.workers.axis_pool`)."""


@dataclass(frozen=True)
class AnalyzeOptions:
    topic: str | None = None
    taus_per_decade: int = 10
    gaps: GapPolicy = "auto"
    loop: bool = True
    rrd: bool = True
    rrd_full: bool = False
    """Every raw frame in recording.rrd, not a min/max envelope (long recordings)."""
    figures: bool = True
    memory_budget_bytes: int = MEMORY_BUDGET_BYTES
    tmp_dir: Path | None = None
    datasheet: Path | None = None  # TOML of the part's noise specs (imupipe.report.datasheet)
    temperature_topic: str | None = None
    events: bool = True
    """Find disturbance events jointly on all axes and excise them (imupipe.analysis.events)."""
    compile_ahead: bool = True
    """On a cold numba cache, compile the fit's and the loop's kernels in a child process while
    this one decodes (imupipe.model.ahead); off in a fleet's Dask worker."""
    workers: int | None = None
    """Axes analysed at once, each on its own thread (default: the cores this process may use;
    fewer when the memory budget has no room for more, :func:`axis_concurrency`)."""
    start_s: float = 0.0
    """Analyse from this time on, s from the recording's first frame (its stamps' time base)."""
    end_s: float | None = None
    """Analyse up to this time, s from the first frame (None: the last frame; negative: that
    many seconds before the last frame)."""


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


class Outputs(Protocol):
    """Where the orchestrator's results go (the report stage implements it)."""

    def begin(self, signals: pl.DataFrame) -> None:
        """The raw signals of the analysed segment are known (columns of
        :data:`imupipe.io.columns.SIGNALS`); called before the axes are analysed."""

    def finish(self, result: AnalysisResult, progress: StageProgress) -> None:
        """The analysis is done: write everything."""

    def discard(self) -> None:
        """The analysis failed after :meth:`begin`: remove what was started."""


def check_frames(rec: ImuRecording, series: ConditionedSeries) -> None:
    """Refuse a recording without :data:`MIN_FRAMES` consecutive clean samples: its Allan
    variance has no averaging time to fit.  On the masked grid (policy ``"mask"``) that is a
    set of stamps that are not one uniformly sampled stream, e.g. two IMUs publishing on one
    topic (every other grid place missing: no window of two samples whole)."""
    n = series.longest_clean_run
    if n >= MIN_FRAMES:
        return
    if series.excluded is None:
        raise TooFewFramesError(
            f"{rec.path}: the longest clean segment has {n} frames, too few for any "
            f"averaging time (need at least {MIN_FRAMES})"
        )
    frames = (
        f" Its messages carry header.frame_id {named_frames(rec)}" if len(rec.frame_ids) > 1 else ""
    )
    raise TooFewFramesError(
        f"{rec.path}: on the sample grid of {series.samples} samples at {series.rate_hz:.6g} Hz "
        f"the longest run of clean samples is {n}, too few for any averaging time (need at "
        f"least {MIN_FRAMES}): the stamps are not one uniformly sampled stream (several IMUs "
        f"publishing on one topic?{frames})"
    )


def interleaved_warning(
    source: ColumnSource, series: ConditionedSeries, rec: ImuRecording
) -> list[str]:
    """A warning when the analysed rows of a stream without a frame counter alternate between
    two sensors on some axis (:func:`imupipe.analysis.condition.two_sensors`): two IMUs
    publishing on one topic under one ``header.frame_id``, whose samples no stamp tells apart
    (with two frame ids they are told apart: :func:`check_frames`)."""
    if rec.frames["counter"].null_count() == 0:  # a device's frames, counted
        return []
    found = {
        name: why
        for name in AXES
        if name not in series.absent_axes
        and (why := two_sensors(source.column(name, series.rows)))  # (axes are never null)
    }
    if not found:
        return []
    return [
        "the even and odd messages differ as two sensors' would ("
        + "; ".join(f"{a}: {why}" for a, why in found.items())
        + "; one sensor's are alike): several IMUs publishing on one topic under one "
        "header.frame_id? Their samples are analysed as one stream"
    ]


def axis_result(
    name: str,
    y: np.ndarray,
    curve: AllanCurve,
    tau0_s: float,
    temp_d: np.ndarray | None,
    supply_d: np.ndarray | None,
    loop: bool,
    excluded: np.ndarray | None = None,
    searched: OutlierSearch | None = None,
    bridged: np.ndarray | None = None,
) -> AxisResult:
    """Stage 4 (+ loop) of one axis: outliers excised (:func:`excise_outliers`), mean, rms, the
    closed loop and the final model (the loop's, or the IEEE 952 fit without the loop), both
    fitted on ``curve`` (up to T/2, :data:`FIT_MIN_TERMS`) and published up to T/4
    (``temp_d``, ``supply_d``: the segment's temperature and supply as
    :func:`imupipe.model.loop.aux_block_means`; ``excluded``: the samples masked by the
    ``"mask"`` gap policy, left out of mean and rms too, as the ``bridged`` ones are;
    ``searched``: the outlier search already made on this very ``y``, else it is made here)."""
    sensor = sensor_of(name)
    masked = excluded if bridged is None else bridged if excluded is None else excluded | bridged
    usable = None if masked is None else ~masked
    found = spike_candidate(y, tau0_s, excluded) if searched is None else searched.found
    y, curve, outliers = excise_outliers(y, tau0_s, curve, excluded, found, bridged)
    signals = AxisSignals(
        name, sensor, y, tau0_s, temp_d, supply_d, excluded, spike_free=outliers is None
    )
    looped = close_loop(signals, curve) if loop else None
    published = curve.up_to(tau0_s * (len(y) // 4))  # Stable32's T/4 (the fit's reaches T/2)
    return AxisResult(
        name=name,
        sensor=sensor,
        unit="rad/s" if sensor == "gyro" else "m/s^2",
        mean=float(y.mean(where=usable) if usable is not None else y.mean()),
        rms=float(y.std(where=usable) if usable is not None else y.std()),
        curve=published,
        terms=fit_noise_terms(curve, sensor, tau0_s) if looped is None else looped.terms_after,
        loop=None if looped is None else looped.up_to(len(published.tau_s)),
        outliers=outliers,
    )


@dataclass(frozen=True)
class OutlierSearch:
    """:func:`imupipe.model.effects.spike_candidate` of an axis' series, made once by the event
    pass and handed to :func:`axis_result` when the series it analyses is the same."""

    found: Candidate | None  # None: no outlier


def excise_outliers(
    y: np.ndarray,
    tau0_s: float,
    curve: AllanCurve,
    excluded: np.ndarray | None,
    found: Candidate | None,
    bridged: np.ndarray | None = None,
) -> tuple[np.ndarray, AllanCurve, dict | None]:
    """Outliers ``found`` in ``y`` (:func:`imupipe.model.effects.spike_candidate`: beyond a
    family-wise, LSB- and tail-aware limit from the local median) replaced by their local
    median before the noise fit and the loop, and the Allan curve recomputed without them.
    Returns the series (a corrected copy when any was found), its curve and what was excised
    (SI units), or the inputs and None."""
    if found is None:
        return y, curve, None
    fix = found.spikes
    y = y.copy()
    y[fix.index] -= fix.value
    m = np.round(curve.tau_s / tau0_s).astype(np.int64)
    (curve,) = allan_curves([y], tau0_s, m, excluded=excluded, bridged=bridged)
    ev = found.evidence
    return (
        y,
        curve,
        {
            "count": int(fix.index.size),
            "max_size": ev["max_size"],
            "median_size": found.params["size"],
            "limit": ev["limit"],
            "threshold_z": ev["threshold_z"],
            "sigma": found.params["sigma"],
            "lsb": ev["lsb"],
            "first_times_s": ev["first_times_s"],
        },
    )


def outlier_warnings(results: dict[str, AxisResult]) -> list[str]:
    """One warning per axis whose outliers were excised."""
    return [
        f"{name}: {o['count']} outlier sample(s) up to {o['max_size']:.3g} {res.unit} from the "
        f"local median excised (limit {o['limit']:.3g} {res.unit} = {o['threshold_z']:.1f} "
        f"sigma + LSB/2; replaced by the local median, first at {o['first_times_s'][0]:.2f} s)"
        for name, res in results.items()
        if (o := res.outliers) is not None
    ]


def input_summary(
    rec: ImuRecording, series: ConditionedSeries, warnings: list[str], label: str | None = None
) -> InputSummary:
    """The report's ``input`` section for the chosen segment (or masked grid); ``label`` names
    the input instead of its local path (a fleet unit read from a URL)."""
    n = series.samples
    return InputSummary(
        path=str(rec.path) if label is None else label,
        topic=rec.topic,
        frames=series.usable_samples,
        rate_hz=series.rate_hz,
        duration_s=n * series.tau0_s,
        segments=[s.as_dict() for s in series.segments],
        warnings=warnings,
        source=rec.source,
        time_source=rec.time_source,
        counts=series.counts,
        temperature_topic=rec.temperature_topic,
        window_s=series.window_s,
    )


def find_axis_events(
    axis: AxisReader, series: ConditionedSeries, t0_stamp_s: float, run: AxisMap
) -> tuple[EventsFound | None, dict[str, str], dict[str, OutlierSearch]]:
    """First pass over the axes (``run``: :func:`imupipe.analysis.workers.axis_pool`'s map):
    the disturbance events found jointly on every analysable axis
    (:mod:`imupipe.analysis.events`; None with fewer than one such axis), the axes found
    stuck, and each analysable axis' outlier search (the detector's input leaves them out)."""

    def first_pass(name: str) -> tuple[np.ndarray, OutlierSearch] | str:
        if name in series.absent_axes:
            return ABSENT
        y = series.on_grid(axis(name))  # excluded samples (NaN/inf frames, gaps) filled
        if why := unanalysable(y):
            return why
        searched = OutlierSearch(spike_candidate(y, series.tau0_s, series.excluded))
        return fine_means(y, series.tau0_s, searched.found), searched

    means: dict[str, np.ndarray] = {}
    stuck: dict[str, str] = {}
    searched: dict[str, OutlierSearch] = {}
    for name, out in zip(AXES, run(first_pass, AXES), strict=True):
        if isinstance(out, str):
            stuck[name] = out
        else:
            means[name], searched[name] = out
    if not means:
        return None, stuck, searched
    units = {a: "rad/s" if sensor_of(a) == "gyro" else "m/s^2" for a in means}
    found = detect(means, series.tau0_s, series.samples, units, t0_stamp_s, series.excluded)
    return found, stuck, searched


def analyze_axes(
    source: ColumnSource,
    series: ConditionedSeries,
    options: AnalyzeOptions,
    progress: StageProgress,
    t0_stamp_s: float = 0.0,
    at_once: int = 1,
    kernels_ready: Callable[[], None] = lambda: None,
) -> tuple[dict[str, AxisResult], dict[str, str], EventsFound | None]:
    """Stages 3–4 (+ loop) on the chosen segment (or, policy ``"mask"``, the whole recording
    on its sample grid), ``at_once`` axes at a time on as many threads (the same results in
    the same order as one at a time: :mod:`imupipe.analysis.workers`); returns the results of
    the analysed axes, the axes found stuck (constant: nothing to analyse) and the disturbance
    events (option ``events``: found jointly on all axes first, their intervals excluded on
    every axis and filled for the time-domain steps,
    :func:`imupipe.analysis.events.fill_excised`).  ``kernels_ready`` is called before each
    axis' outliers and noise fit (:meth:`imupipe.model.ahead.Ahead.wait`)."""
    rows, tau0 = series.rows, series.tau0_s
    aux: dict[str, np.ndarray | None] = {}
    for name in HOUSEKEEPING:
        x = source.column(name, rows)
        aux[name] = aux_block_means(None if x is None else series.on_grid(x), tau0)
    m = tau_factors(series.samples, options.taus_per_decade, FIT_MIN_TERMS)  # T/2: the fit's
    reading = threading.Lock()  # the spilled source maps one column at a time

    def axis(name: str) -> np.ndarray:
        with reading:
            y = source.column(name, rows)
        assert y is not None  # axes are never null
        return y

    with axis_pool(at_once) as run:
        found, stuck, searched = (
            find_axis_events(axis, series, t0_stamp_s, run) if options.events else (None, {}, {})
        )
        excluded = series.excluded
        cut = None if found is None else event_mask(list(found.events), series.samples)
        if cut is not None:
            excluded = cut if excluded is None else excluded | cut

        def analyse(name: str) -> AxisResult | str:
            if name in series.absent_axes:
                return ABSENT
            y = series.on_grid(axis(name))
            why = stuck.get(name) or (None if found is not None else unanalysable(y))
            if why is not None:
                return why
            filled = y if found is None else fill_excised(y, found)
            curve = allan_curves([filled], tau0, m, excluded=excluded, bridged=series.bridged)[0]
            kernels_ready()
            return axis_result(
                name, filled, curve, tau0, aux["temp_c"], aux["supply_v"], options.loop,
                excluded, searched.get(name) if filled is y else None, series.bridged,
            )  # fmt: skip

        results: dict[str, AxisResult] = {}
        with progress.stage("analyse", len(AXES), "axes") as advance:
            for i, (name, out) in enumerate(zip(AXES, run(analyse, AXES), strict=True)):
                if isinstance(out, str):
                    stuck[name] = out
                else:
                    results[name] = out
                del out  # the spilled source's axis leaves before the next one comes
                advance(i + 1)
    return results, stuck, found


def analyze(
    path: Path,
    options: AnalyzeOptions,
    progress: StageProgress,
    outputs: Outputs,
    label: str | None = None,
) -> AnalysisResult:
    """Analyse the recording at ``path`` and hand the result to ``outputs``; every output names
    the input ``label`` (default: ``path``).

    The raw signals go to ``outputs.begin`` as soon as the segment is known (the Rerun
    recording encodes them while the axes are analysed).  A recording whose estimated peak
    exceeds ``options.memory_budget_bytes`` is read through the spilled column source, with
    the same numbers; the report's warnings say so.  On a cold numba cache the fit's and the
    loop's kernels compile in a child meanwhile (``options.compile_ahead``,
    :mod:`imupipe.model.ahead`).
    """
    with (
        small_pages(),
        compile_ahead(options.loop, options.compile_ahead) as ahead,
        open_columns(
            Path(path),
            options.topic,
            progress,
            options.memory_budget_bytes,
            options.tmp_dir,
            options.temperature_topic,
        ) as source,
    ):
        if source.spilled:
            ahead.wait(take_loop=False)  # the child compiles the loop's too; load_kernels the rest
            with progress.stage("compile", 1, "step"):
                load_kernels(options.loop)
        rec = source.conditioning()
        series = condition(rec, options.gaps, options.start_s, options.end_s)
        check_frames(rec, series)
        alternating = interleaved_warning(source, series, rec)
        t0_stamp_s = float(rec.frames["t_s"][series.rows.start])  # the first analysed sample
        frames = rec.frames.height
        about = replace(rec, frames=rec.frames.clear())
        del rec  # the spilled source's conditioning columns (t_s: 691 MB at 24 h / 1 kHz)
        if options.rrd:
            outputs.begin(source.signals(series.rows))
        try:
            at_once = axis_concurrency(options, source.peak_bytes(frames), series.samples)
            with threadpool_limits(BLAS_THREADS, user_api="blas"):
                results, stuck, found = analyze_axes(
                    source, series, options, progress, t0_stamp_s, at_once, ahead.wait
                )
            if not results:
                raise no_axis_error(about, [stuck_warning(a, w) for a, w in stuck.items()])
        except BaseException:
            outputs.discard()
            raise
        warnings = [
            *series.warnings,
            *alternating,
            *(stuck_warning(a, why) for a, why in stuck.items()),
            *outlier_warnings(results),
            *filter(None, [specific_force_warning(results)]),
            *coincident_step_warnings(results, series.samples * series.tau0_s, t0_stamp_s),
            *(found.warnings() if found is not None else []),
            *source.notes(series.segment.frames, options.rrd, at_once),
        ]
    result = AnalysisResult(
        input=input_summary(about, series, warnings, label),
        axes=results,
        device=about.device,
        events=found,
    )
    outputs.finish(result, progress)
    return result


AXIS_BYTES_PER_SAMPLE = 40
"""Peak memory one more axis analysed at once adds, per analysed sample (measured: 12 h /
100 Hz, 4.32 M samples: peak RSS 0.78 GB with one axis at a time, 0.92 GB with two, i.e. 32 B
per sample; rounded up)."""


def axis_concurrency(options: AnalyzeOptions, peak_bytes: int, samples: int) -> int:
    """Axes to analyse at once (:func:`imupipe.analysis.workers.axes_at_once`): ``workers``
    (default: the usable cores), as many as the memory budget leaves room for beyond the
    estimated one-axis-at-a-time ``peak_bytes``."""
    if options.workers is not None and options.workers < 1:
        raise ImupipeError(f"workers must be at least 1, not {options.workers}")
    return axes_at_once(
        options.workers,
        len(AXES),
        AXIS_BYTES_PER_SAMPLE * samples,
        options.memory_budget_bytes - peak_bytes,
    )


def compile_kernels(loop: bool = True) -> None:
    """Compile the numba kernels (or load them from numba's disk cache) on a few thousand
    synthetic samples: every kernel the analysis calls, with the types it calls them with —
    those only a record with gaps reaches included (the gap-tolerant Allan sums, the masked
    whitener), or :func:`load_kernels` would start its child on every run until one came."""
    rng = np.random.default_rng(0)
    white = rng.standard_normal(4096)
    axis_result("gyro_x", white, allan_curves([white], 0.01)[0], 0.01, None, None, loop)
    b1_noise_id(white, 100)  # white phase: the R(n) branch
    long = np.cumsum(rng.standard_normal(ACF_WINDOW + 2))
    noise_ids(long, np.array([1]), window=True)  # a record's window of averages (its p)
    psd_line(
        white, 0.01, 10.0, 20.0, spike_candidate(white + 50.0 * (np.arange(4096) == 7), 0.01).spikes
    )
    robust.compile_long_record_kernels()  # the event detector's running median among them
    gap = np.arange(white.size) % 1000 == 7
    allan_curves([white], 0.01, excluded=gap)  # the gap-tolerant sums
    Whitener(NoisePsd(1.0, 0.0, np.inf, 0.0), white.size, 0.01, gap)  # blocks left out


DECODE_MODULES = ("imupipe.io.", "imupipe.device.")
"""Modules whose kernels decode a recording (MCAP records, ADIS16364 bursts)."""


def decoding_kernel(kernel: Dispatcher) -> bool:
    """Whether ``kernel`` is a decoder's (:data:`DECODE_MODULES`): an ADIS16364 burst decoder is
    never compiled when analysing a ROS 2 Imu bag, so it may stay out of numba's cache."""
    return kernel.__module__.startswith(DECODE_MODULES)


def load_kernels(loop: bool) -> None:
    """Have the kernels compiled into numba's disk cache by a child process, then load them.

    Compiling in this process on a first run after installing keeps ~0.2 GB of LLVM's memory
    resident under the data (24 h / 1 kHz, cold cache: peak 2.02 GB against 1.81 GB warm);
    a child's memory leaves with it.  Loading from the cache costs this process little.  If the
    child fails (e.g. a read-only cache), the kernels are compiled here as before.  No child
    when the cache already holds every kernel of the stages after decoding (it cost ~2-6 s of a
    24 h / 1 kHz run: a Python start, the imports and the loading); the decoders' kernels
    (:data:`DECODE_MODULES`) have run or are not needed by then, and the child never compiles
    them."""
    if not all(disk_cached(k) for k in imported_kernels() if not decoding_kernel(k)):
        code = f"from imupipe.analysis.analyze import compile_kernels; compile_kernels({loop})"
        subprocess.run([sys.executable, "-c", code], capture_output=True, check=False)
    compile_kernels(loop)
