"""Pass-wise analysis of recordings too large to decode whole (e.g. 24 h at 1 kHz, 86.4 M frames).

The normal path (:func:`imupipe.analysis.analyze.analyze`) decodes one frame of every column
(~85 bytes a frame) and peaks near :data:`PEAK_BYTES_PER_FRAME`.  Here the file is read several
times, each pass decoding only what one step needs (:func:`imupipe.io.decode.decode`, ``columns``):

1. conditioning: ``t_s``, counter, flags and a 1-byte ``nonfinite`` flag per frame →
   :func:`imupipe.analysis.condition.condition` chooses the segment, exactly as on the whole frame;
2. temperature and supply, cut to the segment (the loop's regressors);
3. one pass per axis: that axis' float64 column, cut to the segment → Allan deviation, IEEE 952
   terms and the loop (:func:`imupipe.analysis.analyze.axis_result`) → freed before the next axis.

The numbers equal the normal path's (same functions on the same float64 samples); only
``recording.rrd`` differs: its raw signals are a min/max envelope of :data:`ENVELOPE_BINS`
bins (two points per bin: the minimum at the bin's first stamp, the maximum at its middle),
stated in the report's warnings.
"""

from __future__ import annotations

import ctypes
import subprocess
import sys
from pathlib import Path

import numpy as np
import polars as pl
from mcap.reader import make_reader

from imupipe.analysis.analyze import (
    AnalyzeOptions,
    axis_result,
    check_frames,
    housekeeping,
    input_summary,
    write_outputs,
)
from imupipe.analysis.condition import (
    Segment,
    condition,
    no_axis_error,
    stuck_warning,
    unanalysable,
)
from imupipe.analysis.results import AnalysisResult, AxisResult
from imupipe.io.decode import decode, mcap_files
from imupipe.io.mcap_scan import chunk_limit
from imupipe.model.effects import psd_line, spike_candidate
from imupipe.model.loop import aux_block_means
from imupipe.progress import StageProgress
from imupipe.stats import robust
from imupipe.stats.allan import allan_curves, tau_factors
from imupipe.stats.edf import b1_noise_id
from imupipe.vocab import AXES

PEAK_BYTES_PER_FRAME = 210
"""Peak RSS of the normal path per decoded frame (measured: 12 h / 100 Hz, 4.32 M frames,
0.87-0.91 GB, README "Speed and memory")."""
FALLBACK_BYTES_PER_FRAME = 40
"""Without a readable MCAP summary, frames are estimated as file bytes / this (a ROS Imu message
is ~350 bytes and our ADIS frame ~60 before compression; zstd shrinks them at most ~8×)."""
ENVELOPE_BINS = 100_000
"""Bins of the min/max envelope sent to Rerun for the raw signals (2 points each)."""
CONDITION_COLUMNS = frozenset({"t_s", "counter", "flag_nd", "flag_ea", "saturated", "nonfinite"})
HOUSEKEEPING_COLUMNS = frozenset({"temp_c", "supply_v"})


def message_count(file: Path) -> int:
    """Messages in ``file`` from its MCAP summary statistics, else estimated from its size."""
    try:
        with open(file, "rb") as f:
            stats = make_reader(f).get_summary().statistics
        return int(stats.message_count)
    except Exception:  # damaged or summary-less file: estimate from its size
        return file.stat().st_size // FALLBACK_BYTES_PER_FRAME


def peak_estimate(files: list[Path]) -> int:
    """Estimated peak bytes of the normal path on a recording made of ``files``."""
    return PEAK_BYTES_PER_FRAME * sum(message_count(f) for f in files)


def envelope(y: np.ndarray, bins: int = ENVELOPE_BINS) -> np.ndarray:
    """Min/max of ``y`` over consecutive bins of ceil(len/bins) samples, interleaved
    (min_0, max_0, min_1, ...); ``y`` itself when it has no more than ``2 * bins`` samples."""
    if len(y) <= 2 * bins:
        return y
    starts = np.arange(0, len(y), -(-len(y) // bins))
    return np.column_stack([np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts)]).ravel()


def envelope_times(t_s: np.ndarray, bins: int = ENVELOPE_BINS) -> np.ndarray:
    """Stamps for :func:`envelope`: each bin's first stamp (min) and middle stamp (max)."""
    if len(t_s) <= 2 * bins:
        return t_s
    step = -(-len(t_s) // bins)
    starts = np.arange(0, len(t_s), step)
    middles = np.minimum(starts + step // 2, len(t_s) - 1)
    return np.column_stack([t_s[starts], t_s[middles]]).ravel()


M_MMAP_THRESHOLD = -3
"""glibc ``mallopt`` parameter: allocations at least this large are mmapped (malloc.h)."""


def _release_freed_memory() -> None:
    """Make freed arrays leave the process (glibc only; elsewhere nothing is done).

    The runs' per-chunk arrays (~0.5 MB) come from the C heap once glibc's dynamic mmap
    threshold has risen, and their free space stays resident: measured on 24 h / 1 kHz, the
    conditioning pass peaked at 3.5 GB with ~1.7 GB of live arrays.  A fixed 128 kB threshold
    mmaps them (returned on free), and ``malloc_trim`` hands back what the heap already holds.
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(M_MMAP_THRESHOLD, 128 * 1024)
        libc.malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def compile_kernels(loop: bool = True) -> None:
    """Compile the numba kernels (or load them from numba's disk cache) on a few thousand
    synthetic samples: every kernel the passes call, with the types they call it with."""
    rng = np.random.default_rng(0)
    white = rng.standard_normal(4096)
    axis_result("gyro_x", white, allan_curves([white], 0.01)[0], 0.01, None, None, loop)
    b1_noise_id(white, 100)  # white phase: the R(n) branch
    psd_line(
        white, 0.01, 10.0, 20.0, spike_candidate(white + 50.0 * (np.arange(4096) == 7), 0.01).spikes
    )
    robust.median_positive(np.cumsum(white), differences=True)
    robust.mad(np.cumsum(white), differences=True)


def _load_kernels(loop: bool) -> None:
    """Have the kernels compiled into numba's disk cache by a child process, then load them.

    Compiling in this process on a first run after installing keeps ~0.2 GB of LLVM's memory
    resident under the data (24 h / 1 kHz, cold cache: peak 2.02 GB against 1.81 GB warm);
    a child's memory leaves with it.  Loading from the cache costs this process little.  If the
    child fails (e.g. a read-only cache), the kernels are compiled here as before."""
    code = f"from imupipe.analysis.lowmem import compile_kernels; compile_kernels({loop})"
    subprocess.run([sys.executable, "-c", code], capture_output=True, check=False)
    compile_kernels(loop)


def _segment(frames: pl.DataFrame, name: str, seg: Segment) -> np.ndarray | None:
    """Column ``name`` of the segment's rows (housekeeping nulls filled as on the normal path),
    as an array that owns only those rows: no view keeping the whole recording's column alive."""
    x = housekeeping(frames.slice(seg.start, seg.frames), name)
    return x if x is None or seg.frames == frames.height else x.copy()


def analyze_low_memory(
    path: Path,
    out_dir: Path,
    options: AnalyzeOptions,
    progress: StageProgress,
) -> AnalysisResult:
    """:func:`imupipe.analysis.analyze.analyze` in 2 + 6 decoding passes (module docstring)."""
    from imupipe.report.rerun_view import RrdWriter

    path = Path(path)
    size = sum(f.stat().st_size for f in mcap_files(path))
    passes = 2 + len(AXES)

    def decode_pass(k: int, what: str, columns: frozenset[str]):
        _release_freed_memory()
        with progress.stage(f"decode {k}/{passes} {what}", size, "bytes") as advance:
            return decode(
                path,
                options.topic,
                advance,
                columns,
                keep_one_time_base=True,
                max_chunk_bytes=chunk_limit(options.memory_budget_bytes),
                temperature_topic=options.temperature_topic,
            )

    with progress.stage("compile", 1, "step"):
        _load_kernels(options.loop)
    rec = decode_pass(1, "stamps", CONDITION_COLUMNS)
    series = condition(rec, gaps=options.gaps)
    n = series.frames.height
    check_frames(rec, n)
    seg = series.segments[series.chosen]
    shown: dict[str, np.ndarray] = {"t_s": envelope_times(series.frames["t_s"].to_numpy())}
    rec.frames = series.frames = rec.frames.clear()  # frees the pass's columns
    series.warnings.append(
        f"low-memory path: the whole frame would need ~{peak_estimate(mcap_files(path)) / 1e9:.2f}"
        f" GB (budget {options.memory_budget_bytes / 1e9:.2f} GB); decoded in {passes} passes"
    )
    house = decode_pass(2, "temp/supply", HOUSEKEEPING_COLUMNS).frames
    aux: dict[str, np.ndarray | None] = {}
    for name in ("temp_c", "supply_v"):  # kept as the loop's block means only
        x = _segment(house, name, seg)
        if x is not None:
            shown[name] = envelope(x)
        aux[name] = aux_block_means(x, series.tau0_s)
    del house, x
    m = tau_factors(n, per_decade=options.taus_per_decade)
    results: dict[str, AxisResult] = {}
    for k, name in enumerate(AXES, start=3):
        y = _segment(decode_pass(k, name, frozenset({name})).frames, name, seg)
        reason = unanalysable(y)
        if reason is not None:
            series.stuck_axes.append(name)
            series.warnings.append(stuck_warning(name, reason))
            continue
        with progress.stage(f"analyse {name}", 1, "axis") as advance:
            curve = allan_curves([y], series.tau0_s, m)[0]
            results[name] = axis_result(
                name, y, curve, series.tau0_s, aux["temp_c"], aux["supply_v"], options.loop
            )
            advance(1)
        shown[name] = envelope(y)
        del y
    if not results:
        raise no_axis_error(rec, series.warnings[-len(AXES) :])
    if options.rrd and n > 2 * ENVELOPE_BINS:
        series.warnings.append(
            f"recording.rrd shows the raw signals as a min/max envelope of {ENVELOPE_BINS} bins "
            f"({-(-n // ENVELOPE_BINS)} samples each) (low-memory path)"
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    rrd = RrdWriter(out_dir / "recording.rrd", pl.DataFrame(shown)) if options.rrd else None
    result = AnalysisResult(input=input_summary(rec, series, n), axes=results, device=rec.device)
    write_outputs(result, out_dir, options, progress, rrd)
    return result
