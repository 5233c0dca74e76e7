"""Stage 2 — condition: a uniform time base, and the segments the Allan variance may use.

The Allan variance assumes equally spaced samples with no gaps.  This stage never interpolates:
it finds every place where that assumption breaks — a gap in time or in the frame counter,
a non-increasing stamp, a non-finite or saturated sample — cuts the recording there into
segments, and hands the longest clean segment on (policy ``"longest"``), refuses
(policy ``"fail"``), or keeps the whole recording with the breaks masked (policy ``"mask"``).
The default, ``"auto"``, masks when no gap is longer than :data:`AUTO_MAX_GAP_S` (lost frames,
a NaN row, a pause of the recorder: the whole recording is analysed) and otherwise analyses the
longest clean segment: 1 h is the longest gap the closed loop was validated across
(docs/gaps_and_outliers.md).  Everything it found is counted and stated as a warning.

Policy ``"mask"``: every row gets its place on the uniform sample grid (the frame counter's
step where it agrees with the stamps to within a sample, else the stamp step in periods);
missing frames are grid places without a row, and they, non-finite or saturated rows and rows
after a duplicate, backwards or disagreeing stamp are *excluded*.  The gap-tolerant Allan
variance (:mod:`imupipe.stats.allan`, ``excluded``) skips every term that touches one, so a
missing frame costs the terms around it, not half the recording.  When more than
:data:`MAX_MASKED_FRACTION` of the grid would be excluded (e.g. a clock jumping by days), the
longest clean segment is analysed instead, with a warning.

Contract: :class:`ConditionedSeries` — the segments found, the chosen one (rows of the decoded
frame; with ``"mask"`` every row, ``grid_index``/``excluded`` saying where each row sits on the
sample grid and which grid samples are excluded), ``tau0_s`` the sampling interval estimated as
the mean stamp step, what was counted and the warnings.  The decoded frame is only read, never
changed or kept.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from imupipe.errors import ImupipeError
from imupipe.io.decode import CLOCK_RESET_NS, FRAME_ID_SAMPLE, ImuRecording, nonfinite_bits
from imupipe.stats import robust
from imupipe.stats.allan import clean_runs, run_offsets
from imupipe.vocab import AXES

GAP_FACTOR = 1.5
"""With steady stamps, a step longer than this many nominal periods is a gap."""
JITTER_SIGMAS = 6.0
"""With jittery stamps, a step must also exceed the period by this many robust sigmas of the
step (1.4826 × median absolute deviation) to count as a gap."""
JITTER_WARN = 0.1
"""Warn when the rms stamp jitter exceeds this fraction of the period."""
SPAN_ROWS = 240
"""Jittery stamps: the sample period is the median of their steps over spans of this many rows.
Samples stamped together in bursts (two or three a USB frame, …) still span whole periods
there, where single steps read ~0 or a few periods: 240 is a multiple of every burst length up
to 6 and of 8, 10, 12, 15 and 16, so such spans hold whole bursts."""
SCATTER_STRIDE = 16
"""Every this many-th single stamp step is read for how much the steps scatter."""
BURST_ROWS = 16
"""Longest burst of samples stamped together that a lost frame is placed across
(:func:`_envelope_places`)."""
ENVELOPE_ROWS = 64
"""Jittery stamps without a frame counter: rows per block whose low quantile of lateness (the
stamp minus its place on a uniform grid) tells the block's level; a lost frame raises the level
of every later block by one period."""
ENVELOPE_QUANTILE = 0.04
"""The quantile of a block's lateness that is its level: below the late tail (a stamp held up by
the host, the later samples of a burst) and above the few stamps that came early.  0.04 of 64
rows lies between the 3rd and 4th lowest, so a block holding 4 bursts' last samples (bursts of
up to :data:`BURST_ROWS`) reads their level; at 0.1 (the 7th–8th lowest, before session 41)
bursts of 10 put 6 or 7 ends in a block and its level jumped a period between blocks: 7 frames
"lost" in 5 min at 200 Hz that were all there."""
DRIFT_BLOCKS = 32
"""Blocks either side whose median level change is the clock's drift (the host's and the
sensor's clocks differ by ppm; a rate drifting by a few % in a slow host timer), told apart
from a lost frame's one-period step in one block."""
MAX_MASKED_FRACTION = 0.5
"""Policy ``"mask"``: beyond this excluded fraction of the grid, the longest segment is used."""

BRIDGE_RUN = 5
"""Runs of at most this many masked samples (lost messages, a NaN frame) that the Allan variance
reads as their fill at the τ where skipping them would leave fewer than half its terms, when
skipping them leaves no term of τ ≥ T/8 (frames lost every few seconds: a busy recorder
dropping messages; :func:`imupipe.stats.allan.allan_curves`, ``bridged``)."""
BRIDGE_MAX_FRACTION = 0.02
"""Most of the grid that is bridged so: the fill carries no noise, so at those τ a white
noise' Allan variance reads low by about the bridged fraction (measured:
docs/gaps_and_outliers.md)."""
AUTO_MAX_GAP_S = 3600.0
"""Policy ``"auto"``: the longest gap (run of excluded grid samples, s) it masks; a longer one
makes it analyse the longest clean segment.  Measured on independent-generator recordings of
4 h at 100 Hz, clean, 8 seeds each (docs/gaps_and_outliers.md): with the whole recording
masked, no false effect with 20 gaps of up to 5 s, three of 2 min, one of 10 min or one of
1 h, and one false bias step with ten of 30 s (of 8 recordings), since the loop's time-domain
tests leave the masked blocks out (:class:`imupipe.model.effects.Whitener`; before that, a 1 h
gap's fill made false steps or warm-ups on 4 of 8).  Longer gaps were not measured."""

GapPolicy = Literal["auto", "longest", "fail", "mask"]


@dataclass(frozen=True)
class Segment:
    """Rows ``[start, stop)`` of the decoded frame with uniform sampling."""

    start: int
    stop: int
    t_start_s: float
    t_stop_s: float

    @property
    def frames(self) -> int:
        return self.stop - self.start

    def as_dict(self) -> dict[str, float | int]:
        return {
            "start_frame": self.start,
            "stop_frame": self.stop,
            "frames": self.frames,
            "t_start_s": self.t_start_s,
            "t_stop_s": self.t_stop_s,
        }


@dataclass(frozen=True)
class ConditionedSeries:
    """The segment to analyse and what conditioning found."""

    tau0_s: float
    nominal_rate_hz: float
    segments: tuple[Segment, ...]
    chosen: int
    counts: dict[str, int] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    grid_index: np.ndarray | None = None
    """Policy ``"mask"``: int64 (rows,) place of each row on the sample grid, from row
    ``grid_start`` of the recording on."""
    grid_start: int = 0
    """Policy ``"mask"``: the recording's first row on the grid (the first of the part at one
    rate the analysis keeps, :func:`rate_regimes`)."""
    excluded: np.ndarray | None = None
    """Policy ``"mask"``: bool (grid samples,) True where no usable sample exists and no term
    of the Allan variance may reach (all of them but the :attr:`bridged` ones)."""
    bridged: np.ndarray | None = None
    """Policy ``"mask"``: bool (grid samples,) the short runs without a usable sample that the
    Allan variance reads as their fill (:data:`BRIDGE_RUN`), or None."""
    absent_axes: tuple[str, ...] = ()
    """Axes NaN/inf in every frame, which the sensor does not provide: not analysed
    (:data:`ABSENT`), and their NaN/inf does not make a frame bad."""
    window_s: tuple[float, float | None] = (0.0, None)
    """The time window the segments were cut from (:func:`window_rows`)."""

    @property
    def rate_hz(self) -> float:
        return 1.0 / self.tau0_s

    @property
    def segment(self) -> Segment:
        """The chosen segment."""
        return self.segments[self.chosen]

    @property
    def rows(self) -> slice:
        """The rows of the decoded frame to analyse: the chosen segment's, or (``"mask"``)
        every row of the recording's part at one rate."""
        if self.grid_index is not None:
            return slice(self.grid_start, self.grid_start + len(self.grid_index))
        return slice(self.segment.start, self.segment.stop)

    @property
    def samples(self) -> int:
        """Samples of the analysed series: grid places (``"mask"``), else the segment's rows."""
        return self.segment.frames if self.excluded is None else len(self.excluded)

    @property
    def longest_clean_run(self) -> int:
        """Consecutive usable samples in the longest clean stretch: the chosen segment's frames,
        or (policy ``"mask"``) the longest run of grid samples of which none is excluded."""
        return self.segment.frames if self.excluded is None else _longest_run(~self.excluded)

    @property
    def usable_samples(self) -> int:
        """Samples that carry data (the grid places not excluded)."""
        return self.samples - (0 if self.excluded is None else int(self.excluded.sum()))

    def on_grid(self, values: np.ndarray) -> np.ndarray:
        """A column of :attr:`rows` as the analysed series: itself (no mask), else float64 on
        the grid, excluded and bridged samples filled by :func:`fill_runs` over
        :data:`FILL_SPAN_S` (the Allan variance reads only the bridged ones' fill)."""
        if self.excluded is None or self.grid_index is None:
            return values
        out = np.empty(len(self.excluded))
        out[self.grid_index] = values
        holes = self.excluded if self.bridged is None else self.excluded | self.bridged
        fill_runs(out, holes, max(1, round(FILL_SPAN_S / self.tau0_s)))
        return out


FILL_SPAN_S = 0.5
"""Span either side of a run of excluded samples whose mean its fill starts and ends at (s)."""
_FILL_RUNS = 1 << 14
"""Runs filled at a time (bounds the (runs, span) gathers)."""


def fill_runs(y: np.ndarray, holes: np.ndarray, span: int) -> None:
    """Replace, in place, every run of ``holes`` (bool, len(y)) in ``y`` by the straight line
    from the mean of the usable samples among the ``span`` before the run to the mean of those
    among the ``span`` after it (one side's mean alone at either end of the record).

    The line starts and ends at a level known to a fraction 1/√span of the sample noise: from
    the two neighbouring samples alone, a gap's fill sat a whole sample-noise σ off, a level
    shift of σ√(block) in any block mean — on every axis at once, a disturbance event at
    every gap.  The fill carries no noise; it is what the time-domain steps read where there
    is no data (the Allan variance never reads it)."""
    usable = ~holes
    starts, stops = clean_runs(usable).T  # the runs of holes
    offsets = np.arange(span)
    sides = []
    for k in range(0, len(starts), _FILL_RUNS):
        a, b = starts[k : k + _FILL_RUNS], stops[k : k + _FILL_RUNS]
        side = []
        for idx in (a[:, None] - span + offsets, b[:, None] + offsets):
            inside = (idx >= 0) & (idx < len(y))
            idx = np.clip(idx, 0, len(y) - 1)
            w = inside & usable[idx]
            count = w.sum(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                side.append(np.where(w, y[idx], 0.0).sum(axis=1) / count)
        left, right = side
        sides.append(
            (np.where(np.isnan(left), right, left), np.where(np.isnan(right), left, right))
        )
    if not sides:
        return
    left = np.concatenate([s[0] for s in sides])
    right = np.concatenate([s[1] for s in sides])
    length = stops - starts
    run = np.repeat(np.arange(len(starts)), length)
    step = run_offsets(length) + 1
    y[holes] = left[run] + (right - left)[run] * (step / (length + 1)[run])


FLOAT_RANGE = (1e-100, 1e100)
"""Spread and magnitude an axis may have: the Allan variance squares differences of the phase
(sums of n values), which leave float64 (1e±308, denormals from 2.2e-308) well outside this."""
GLITCH_FRACTION = 1e-3
"""A channel equal to one value but for fewer than this fraction of its samples is treated as
stuck: its few glitches are no noise a fitted N could describe."""
_SCAN = 1 << 22
"""Samples compared at a time (4 MB of booleans, not a record-length temporary)."""


def _count(y: np.ndarray, differs: Callable[[int], np.ndarray]) -> int:
    """How many booleans ``differs(start)`` marks true over ``y``, :data:`_SCAN` at a time."""
    return sum(int(np.count_nonzero(differs(i))) for i in range(0, len(y), _SCAN))


CLOCK_RESET_S = CLOCK_RESET_NS / 1e9
"""A stamp step back this long (s) is a reset of the stamping clock (:mod:`imupipe.io.decode`
places resets by the log time where it can; those left are not steps of the sampling)."""

ALTERNATION_ROWS = 4096
"""Rows of each block whose even and odd rows :func:`two_sensors` compares."""
ALTERNATION_BLOCKS = 16
"""Blocks, spread evenly over the record, that :func:`two_sensors` compares."""
ALTERNATION_Z = 20.0
"""Even and odd rows' means this many standard errors apart (median over the blocks) read as
two sensors' biases: one sensor's are |N(0, 1)| apart (median 0.67)."""
ALTERNATION_RATIO = 1.5
"""Even and odd rows' noise this many times apart (median over the blocks) reads as two
sensors': one sensor's agree to ~2 % over a block."""


def two_sensors(y: np.ndarray) -> str | None:
    """Why the even and odd rows of ``y`` look like two sensors' samples, interleaved as two
    IMUs publishing alternately on one topic would be (None when they look like one sensor's).

    Over up to :data:`ALTERNATION_BLOCKS` blocks of :data:`ALTERNATION_ROWS` rows spread over
    ``y``: the even rows' mean minus the odd rows', in standard errors from each half's rms of
    successive differences (whose slow components cancel, as they do between the halves), and
    the ratio of those rms.  A tone at exactly half the sample rate alternates too: the
    caller warns, it does not refuse."""
    blocks = len(y) // ALTERNATION_ROWS
    if blocks == 0:
        return None
    starts = np.linspace(0, len(y) - ALTERNATION_ROWS, min(blocks, ALTERNATION_BLOCKS))
    rows = y[starts.astype(np.int64)[:, None] + np.arange(ALTERNATION_ROWS)]
    even, odd = rows[:, 0::2], rows[:, 1::2]
    with np.errstate(all="ignore"):  # blocks without noise, with NaN or huge values: left out
        noise = np.stack([np.diff(even, axis=1).std(axis=1), np.diff(odd, axis=1).std(axis=1)])
        stderr = np.sqrt((noise**2).sum(axis=0) / ALTERNATION_ROWS)  # var of a diff: 2 σ²
        z = np.abs(even.mean(axis=1) - odd.mean(axis=1)) / stderr
        ratio = noise.max(axis=0) / noise.min(axis=0)
    usable = np.isfinite(z) & np.isfinite(ratio)
    if not usable.any():
        return None
    z, ratio = float(np.median(z[usable])), float(np.median(ratio[usable]))
    if not (z > ALTERNATION_Z or ratio > ALTERNATION_RATIO):
        return None
    return f"means {z:.3g} standard errors apart, noise {ratio:.3g}× apart"


def unanalysable(y: np.ndarray) -> str | None:
    """Why an axis holds no noise the Allan variance can analyse (None when it can): 0 throughout
    (a field the sensor does not measure), constant (stuck), beyond :data:`FLOAT_RANGE` (values
    ×1e200, denormals), constant but for a few glitches (:data:`GLITCH_FRACTION`), or a pattern
    repeating every 2 samples (a 1-LSB channel alternating 0/1: its Allan variance is exactly 0
    at every even m)."""
    lo, hi = float(y.min()), float(y.max())
    if lo == hi == 0.0:  # a field not measured, published as 0 (not marked: io.decode.NO_ESTIMATE)
        return "is 0 in every sample over the segment (not measured by this sensor?)"
    if lo == hi:
        return "is constant over the segment (stuck channel?)"
    if max(-lo, hi) > FLOAT_RANGE[1]:
        return f"reaches {max(-lo, hi):.3g}, beyond what float64 Allan sums hold (1e100)"
    if hi - lo < FLOAT_RANGE[0]:
        return f"varies by only {hi - lo:.3g}, below what float64 Allan sums resolve (1e-100)"
    usual = float(np.median(y[:3]))
    others = _count(y, lambda i: y[i : i + _SCAN] != usual)
    if others < GLITCH_FRACTION * len(y):
        return f"is constant but for {others} sample(s) (glitches?)"
    later, earlier = y[2:], y[:-2]
    if _count(later, lambda i: later[i : i + _SCAN] != earlier[i : i + _SCAN]) == 0:
        return "repeats every 2 samples (a deterministic alternation, no noise)"
    return None


def named_frames(rec: ImuRecording) -> str:
    """The ``header.frame_id`` values of ``rec``'s first messages, quoted, at most four."""
    shown = ", ".join(f"'{f}'" for f in rec.frame_ids[:4])
    return shown + (", ..." if len(rec.frame_ids) > 4 else "")


ABSENT = "is NaN/inf in every frame (an axis the sensor does not provide?)"
"""Why an axis of :attr:`ConditionedSeries.absent_axes` is not analysed."""


def stuck_warning(axis: str, reason: str) -> str:
    return f"{axis} {reason}: it is not analysed"


def no_axis_error(rec: ImuRecording, why: list[str]) -> ImupipeError:
    """The error refusing a recording none of whose axes can be analysed (``why``: one
    :func:`stuck_warning` per axis)."""
    return ImupipeError(f"{rec.path}: no axis can be analysed: " + "; ".join(why))


_CHUNK = 1 << 22
"""Stamp steps examined at a time: the steps of a 24 h / 1 kHz record are never held whole
(their float64 array alone would be 691 MB)."""


def _nominal_rate(rec: ImuRecording, t: np.ndarray) -> float:
    """The device's configured rate, else 1 / the median of the increasing stamp steps."""
    if "output_rate_hz" in rec.device:
        return float(rec.device["output_rate_hz"])
    step = robust.median_positive(t, differences=True)
    if not step > 0:
        raise ImupipeError(f"{rec.path}: cannot tell the sample rate (no increasing stamps)")
    return 1.0 / step


RATE_BLOCK = 256
"""Stamp steps per block whose median follows the sample rate (a gap or a bad stamp in a block
does not move its median)."""
RATE_SPANS = 16
"""Spans of :data:`SPAN_ROWS` rows whose median step follows the rate of jittery stamps."""
RATE_CHANGE = 0.1
"""Blocks whose median steps differ by more than this fraction are at different rates."""


def _block_median_steps(t: np.ndarray, spans: bool = False) -> np.ndarray:
    """Median stamp step of each block of :data:`RATE_BLOCK` steps (the last partial block
    left out), :data:`_CHUNK` steps at a time (a multiple of the block); with ``spans``, the
    median step over each :data:`RATE_SPANS` spans of :data:`SPAN_ROWS` rows (jittery or
    bursty stamps, whose single steps tell no rate)."""
    if spans:  # RATE_SPANS spans a block
        steps = np.diff(t[::SPAN_ROWS]) / SPAN_ROWS
        per = RATE_SPANS
        k = len(steps) // per
        return robust.row_medians(steps[: k * per].reshape(k, per))
    parts = []
    for i in range(0, len(t) - 1, _CHUNK):
        steps = np.diff(t[i : min(i + _CHUNK, len(t) - 1) + 1])
        k = len(steps) // RATE_BLOCK
        parts.append(robust.row_medians(steps[: k * RATE_BLOCK].reshape(k, RATE_BLOCK)))
    return np.concatenate(parts) if parts else np.empty(0)


def rate_regimes(t: np.ndarray, spans: bool = False) -> list[tuple[int, int, float]]:
    """The parts of a recording at one sample rate: (first row, stop row, median step in s)
    each, in order; one part unless the block median step (:func:`_block_median_steps`) jumps
    by more than :data:`RATE_CHANGE` between neighbouring blocks and stays there for at least
    two blocks (a rate switched from 200 to 100 Hz); ``spans``: steps read over spans
    (:func:`_block_median_steps`).  A slow drift of the rate is one part.
    A block whose median step is not positive (stamps repeated or going back) tells no rate:
    it takes its predecessor's (the first positive one's at the start), and the stamps
    themselves are left to the segment cuts (:func:`condition`)."""
    medians = _block_median_steps(t, spans)
    told = np.flatnonzero(medians > 0)
    if len(medians) < 4 or not told.size:
        return [(0, len(t), float(np.median(np.diff(t))) if len(t) > 1 else np.nan)]
    last_told = np.maximum.accumulate(np.where(medians > 0, np.arange(len(medians)), told[0]))
    medians = medians[last_told]
    with np.errstate(divide="ignore", invalid="ignore"):
        jump = np.abs(np.log(medians[1:] / medians[:-1])) > np.log1p(RATE_CHANGE)
    lasting = jump.copy()
    lasting[:-1] &= ~jump[1:]  # the next block stays at the new rate (not a one-block spike)
    lasting[-1] = False
    blocks = [0, *(np.flatnonzero(lasting) + 1).tolist(), len(medians)]
    steps = [float(np.median(medians[a:b])) for a, b in itertools.pairwise(blocks)]
    switches = zip(blocks[1:-1], steps[:-1], strict=True)
    rows = [0, *(_switch_row(t, k, step) for k, step in switches), len(t)]
    return [(a, b, step) for (a, b), step in zip(itertools.pairwise(rows), steps, strict=True)]


def _switch_row(t: np.ndarray, block: int, step: float) -> int:
    """The first row of the new rate at the switch found before ``block``: the row after the
    last one, in the two blocks around it, that follows its predecessor by about the old
    ``step`` (s).  (Block-aligned, up to a block of the new rate's rows stayed in the old part,
    where the gap policy "auto" masked them as missing frames of the old rate.)"""
    lo, hi = (block - 1) * RATE_BLOCK, min((block + 1) * RATE_BLOCK, len(t) - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        old = np.abs(np.log(np.diff(t[lo : hi + 1]) / step)) <= np.log1p(RATE_CHANGE)
    last = np.flatnonzero(old)
    return lo + int(last[-1]) + 2 if last.size else block * RATE_BLOCK


def _breaks(
    t: np.ndarray, counter: np.ndarray | None, threshold: float, period: float
) -> tuple[np.ndarray, dict[str, int]]:
    """Where the uniform sampling breaks, (n + 1,) bool (True at 0, n and before every row that
    does not follow its predecessor by one period), and the counts of each kind of break.

    A step of the stamps ``t`` (s) is a break when it is zero (duplicate stamp), negative
    (stamp going backwards), longer than ``threshold`` (a gap; not the long step right after a
    bad stamp, which makes up for it) or when the u32 frame ``counter`` (if any) does not step
    by one modulo 2**32.  Missed frames: from the counter, else from the gap lengths in
    ``period`` units.  The steps are examined :data:`_CHUNK` at a time.
    """
    n = len(t)
    breaks = np.zeros(n + 1, dtype=bool)
    breaks[0] = breaks[n] = True
    counts = dict.fromkeys(("gaps", "missed_frames", "duplicate_stamps", "non_monotonic_stamps"), 0)
    if counter is not None:
        counts["counter_wraps"] = 0
    after_bad = False  # the previous chunk ended on a duplicate or backwards stamp
    for i in range(0, n - 1, _CHUNK):
        j = min(i + _CHUNK, n - 1)
        d = np.diff(t[i : j + 1])
        duplicate, backwards = d == 0, d < 0
        gap = d > threshold
        gap[0] &= not after_bad
        gap[1:] &= ~(duplicate | backwards)[:-1]
        after_bad = bool(duplicate[-1] or backwards[-1])
        brk = duplicate | backwards | gap
        counts["duplicate_stamps"] += int(np.count_nonzero(duplicate))
        counts["non_monotonic_stamps"] += int(np.count_nonzero(backwards))
        if counter is None:
            counts["gaps"] += int(np.count_nonzero(gap))
            counts["missed_frames"] += int(np.sum(np.round(d[gap] / period) - 1))
        else:
            c = counter[i : j + 1].astype(np.uint32, copy=False)
            step = np.diff(c)  # uint32 arithmetic wraps as the counter does
            jump = step != 1
            counts["counter_wraps"] += int(np.count_nonzero(c[1:] < c[:-1]))
            counts["missed_frames"] += int(np.sum(step[jump & (step > 1)] - np.int64(1)))
            counts["gaps"] += int(np.count_nonzero(gap | (jump & ~duplicate)))
            brk |= jump
        breaks[i + 1 : j + 1] = brk
    return breaks, counts


def _step_jitter(t: np.ndarray, mean: float) -> float:
    """Standard deviation of the stamp steps np.diff(t) about their ``mean`` (s), :data:`_CHUNK`
    at a time; steps back of more than :data:`imupipe.io.decode.CLOCK_RESET_NS` (resets of the
    stamping clock, :func:`_time_and_places`) are not steps of the sampling."""
    total, steps = 0.0, 0
    for i in range(0, len(t) - 1, _CHUNK):
        d = np.diff(t[i : i + _CHUNK + 1])
        d = d[d >= -CLOCK_RESET_S]
        total += float(np.sum((d - mean) ** 2))
        steps += len(d)
    return float(np.sqrt(total / steps))


def _grid_places(
    t: np.ndarray, counter: np.ndarray | None, period: float
) -> tuple[np.ndarray, np.ndarray]:
    """(grid place of each row (int64, first row 0), rows whose place is uncertain (bool)).

    A row's step from its predecessor is the counter's step (modulo 2**32) where that agrees
    with the stamp step rounded to periods within one sample (or 1 %), else the stamp step
    (at least 1).  One wrong stamp breaks two steps, into its row and out of it: where a step
    disagrees but the span over it and a neighbouring bad step (stamp not increasing, or
    disagreeing) agrees with the counter's two steps, the counter places the row, so the grid
    does not shift.  Uncertain: a zero or negative stamp step, a counter that disagrees, or the
    row whose own stamp was the wrong one."""
    d = np.diff(t)
    step = np.maximum(np.rint(d / period), 1).astype(np.int64)
    uncertain = np.concatenate(([False], d <= 0))
    if counter is not None:
        by_counter = np.diff(counter.astype(np.uint32)).astype(np.int64)
        agree = (by_counter >= 1) & _within(by_counter, step)
        bad = (d <= 0) | ~agree
        span_t = np.rint((t[2:] - t[:-2]) / period).astype(np.int64)
        span_ok = (
            (by_counter[1:] >= 1)
            & (by_counter[:-1] >= 1)
            & _within(by_counter[1:] + by_counter[:-1], span_t)
        )
        after_bad = np.concatenate(([False], ~agree[1:] & bad[:-1] & span_ok))
        before_bad = np.concatenate((~agree[:-1] & bad[1:] & span_ok, [False]))
        step = np.where(agree | after_bad | before_bad, by_counter, step)
        uncertain[1:] |= ~(agree | after_bad)  # a row bridged to the next has the wrong stamp
    return np.concatenate(([0], np.cumsum(step))), uncertain


def _scatter(t: np.ndarray) -> tuple[float, float]:
    """(the median stamp step over spans of :data:`SPAN_ROWS` rows, s (the mean step with fewer
    than three spans); the robust sigma of every :data:`SCATTER_STRIDE`-th single step about it,
    1.4826 × the median absolute deviation, over it): the sample period of stamps that jitter
    or come in bursts (one span a gap touches does not move the median), and how much they
    scatter (a host's receive times: tens of %; samples stamped together in bursts: steps of ~0
    and a few periods, over 100 %)."""
    spans = np.diff(t[::SPAN_ROWS]) / SPAN_ROWS
    period = float(np.median(spans)) if spans.size >= 3 else (t[-1] - t[0]) / (len(t) - 1)
    if not period > 0:
        return period, 0.0
    steps = t[1::SCATTER_STRIDE] - t[: len(t) - 1 : SCATTER_STRIDE]  # a step in 16 tells it
    return period, robust.MAD_TO_SIGMA * float(np.median(np.abs(steps - period))) / period


def _lateness(
    t: np.ndarray, period: float, start: int, stop: int, drift: np.ndarray | None = None
) -> np.ndarray:
    """Rows ``start:stop``: how late each stamp is against a uniform grid from the first row,
    in periods, ``(t[k] − t[0]) / period − k``; less the clock's drift if given (``drift[b]``:
    the level change from block b to b + 1 of :data:`ENVELOPE_ROWS` rows, a line through
    their centres)."""
    rows = np.arange(start, stop)
    late = (t[start:stop] - t[0]) / period - rows
    if drift is not None:
        w = ENVELOPE_ROWS
        block = rows // w
        at_centre = np.concatenate(([0.0], np.cumsum(drift[:-1])))
        late -= at_centre[block] + drift[block] * (rows - block * w - w / 2) / w
    return late


def _block_levels(t: np.ndarray, period: float, drift: np.ndarray | None = None) -> np.ndarray:
    """Each block of :data:`ENVELOPE_ROWS` rows' :data:`ENVELOPE_QUANTILE` quantile of
    :func:`_lateness` (the last block may be short), :data:`_CHUNK` rows at a time."""
    w = ENVELOPE_ROWS
    levels = np.empty(-(-len(t) // w))
    for i in range(0, len(t), _CHUNK):  # _CHUNK is a multiple of the block
        u = _lateness(t, period, i, min(i + _CHUNK, len(t)), drift)
        full = len(u) // w
        levels[i // w : i // w + full] = np.quantile(
            u[: full * w].reshape(full, w), ENVELOPE_QUANTILE, axis=1
        )
        if full * w < len(u):
            levels[-1] = np.quantile(u[full * w :], ENVELOPE_QUANTILE)
    return levels


def _drift(levels: np.ndarray) -> np.ndarray:
    """Per block, the level change a drifting clock rate makes: the running median of the
    changes over :data:`DRIFT_BLOCKS` blocks either side (the last block: its predecessor's);
    within :data:`DRIFT_BLOCKS` of either end, the median of the first (last) whole window.
    The running median repeats the end values beyond the ends, so the first change alone was
    the majority of the first window: frames lost in the first block (or the last) read as
    drift, and were not found (3 frames lost in the first 64 rows: 0 counted)."""
    d = np.diff(levels)
    change = robust.running_median(d[:, None], DRIFT_BLOCKS)[:, 0]
    h, window = DRIFT_BLOCKS, 2 * DRIFT_BLOCKS + 1
    if len(d) > window:
        change[:h] = np.median(d[:window])
        change[-h:] = np.median(d[-window:])
    elif len(d):
        change[:] = np.median(d)
    return np.append(change, change[-1])


def _envelope_places(t: np.ndarray, period: float) -> np.ndarray:
    """Grid place of each row (int64, first row 0) of jittery stamps without a frame counter.

    Rounding each step to periods (:func:`_grid_places`) fails on such stamps: a late stamp
    followed by an early one reads as a lost frame and a duplicate, and the errors add up (a
    host's receive times, 30 % of a period of latency, put 360 000 frames on a grid of 370 000
    with 3 % of it masked).  Here the frames keep their order and the stamps only say where
    frames were lost: the level of each block's lateness (:func:`_block_levels`) steps up by m
    periods where m frames are missing, while latency, bursts and a drifting clock rate leave
    it in place (the clock's drift, :func:`_drift`, is taken out of the lateness before the
    levels are read again, and what is left of it is not counted).  A step is placed at the
    first row from which the lateness' forward minimum over :data:`BURST_ROWS` rows stays above
    the old level plus m − ½ (a frame at a time): the row before a lost frame may be placed
    late by one where stamps come in bursts (nothing tells the two apart).  A level falling
    (more frames than time: a clock stepped back, a message recorded twice) keeps the frames
    in order."""
    n, w = len(t), ENVELOPE_ROWS
    if n <= w:
        return np.arange(n, dtype=np.int64)
    drift = _drift(_block_levels(t, period))
    # the period the stamps keep on the whole: the spans' median is off by up to a burst a span
    # for bursts whose length does not divide SPAN_ROWS (bursts of 7: 0.8 %, a 5 s gap of 1000
    # frames counted 1008)
    scale = 1 + float(np.median(drift)) / w
    if 0.5 <= scale <= 2:  # a burst's rounding; not stamps that keep no time (a frozen clock)
        period *= scale
    drift = _drift(_block_levels(t, period))
    levels = _block_levels(t, period, drift)
    step = np.diff(levels) - _drift(levels)[:-1]
    # a loss inside a block moves that block's level part of the way: the changes of
    # neighbouring blocks that moved by a quarter period or more are one loss, their sum
    moved = np.abs(step) >= 0.25
    starts = np.flatnonzero(moved & ~np.concatenate(([False], moved[:-1])))
    stops = np.flatnonzero(moved & ~np.concatenate((moved[1:], [False]))) + 1
    missing = np.zeros(n + 1, dtype=np.int64)  # frames lost just before each row
    for b, e in zip(starts.tolist(), stops.tolist(), strict=True):  # blocks b..e, their changes
        lost = int(np.rint(step[b:e].sum()))
        if lost <= 0:
            continue
        lo, hi = max(b - 1, 0) * w, min((e + 1) * w, n)  # from the block before, all early
        excess = _lateness(t, period, lo, hi, drift) - levels[b]
        ahead = np.pad(excess, (0, BURST_ROWS - 1), mode="edge")
        floor = np.lib.stride_tricks.sliding_window_view(ahead, BURST_ROWS).min(axis=1)
        base = float(np.median(floor[: w // 2])) if b > 0 else 0.0
        split = -1  # each lost frame where the floor passes its level (one gap: a burst apart)
        for level in range(1, lost + 1):
            before = np.flatnonzero(floor < base + level - 0.5)
            row = int(before[-1]) + 1 if before.size else 0
            split = split if 0 <= split and row - split <= BURST_ROWS else row
            missing[lo + split] += 1
    return np.arange(n, dtype=np.int64) + np.cumsum(missing[:n])


def _within(by_counter: np.ndarray, by_stamps: np.ndarray) -> np.ndarray:
    """Counter steps that agree with stamp steps (both in periods) within one sample or 1 %."""
    return np.abs(by_counter - by_stamps) <= np.maximum(1, by_stamps // 100)


def _bridge(
    excluded: np.ndarray, clean: int, tau0: float, warnings: list[str]
) -> tuple[np.ndarray | None, int]:
    """The short runs of ``excluded`` (at most :data:`BRIDGE_RUN` samples) for the Allan variance
    to read as their fill, and the longest run of samples the rest leaves clean; (None,
    ``clean``) if they are over :data:`BRIDGE_MAX_FRACTION` of the grid or bridging them
    lengthens no run.  Says so in ``warnings``."""
    runs = clean_runs(~excluded)  # the runs of excluded samples, [start, stop)
    short = runs[runs[:, 1] - runs[:, 0] <= BRIDGE_RUN]
    count = int(np.sum(short[:, 1] - short[:, 0]))
    if count > BRIDGE_MAX_FRACTION * len(excluded) or not len(short):
        return None, clean
    bridged = np.zeros(len(excluded), dtype=bool)
    lengths = short[:, 1] - short[:, 0]
    bridged[np.repeat(short[:, 0], lengths) + run_offsets(lengths)] = True
    longest = _longest_run(~(excluded & ~bridged))
    if longest <= clean:
        return None, clean
    warnings.append(
        f"{count} masked samples in {len(short)} runs of at most {BRIDGE_RUN} "
        f"({100 * count / len(excluded):.3g} % of the grid) are read by the Allan variance as "
        f"their fill where skipping them would leave fewer than half its terms: skipped, no "
        f"term longer than {clean} samples ({clean * tau0:.4g} s) would be free of them, now "
        f"{longest} ({longest * tau0:.4g} s); the fill carries no noise, so there a white "
        f"noise' Allan variance reads low by about {100 * count / len(excluded):.2g} %"
    )
    return bridged, longest


def _mask_warning(series_samples: int, excluded: int, n: int) -> str:
    return (
        f"analysing the whole recording on a uniform grid of {series_samples} samples with "
        f"{excluded} masked ({100 * excluded / series_samples:.3g} %: missing frames and "
        f"excluded rows; {n} frames read); Allan variance terms touching them are skipped"
    )


def _longest_run(flags: np.ndarray) -> int:
    """Length of the longest run of True in ``flags``."""
    return int(np.max(np.diff(clean_runs(~flags), axis=1), initial=0))


def window_rows(t: np.ndarray, start_s: float = 0.0, end_s: float | None = None) -> slice:
    """The rows of the time window [``start_s``, ``end_s``] of stamps ``t`` (s from the first
    frame): from the first row stamped at or after ``start_s`` to the last stamped at or before
    ``end_s`` (None: the last frame's stamp; negative: that many seconds before it).  A slice of
    rows, so that a stamp going backwards inside the window stays for conditioning to find."""
    stop_s = t[-1] if end_s is None else (t[-1] + end_s if end_s < 0 else end_s)
    first = int(np.argmax(t >= start_s)) if t.size and t.max() >= start_s else t.size
    after = np.flatnonzero(t[first:] <= stop_s)
    return slice(first, first + int(after[-1]) + 1 if after.size else first)


def condition(
    rec: ImuRecording, gaps: GapPolicy = "auto", start_s: float = 0.0, end_s: float | None = None
) -> ConditionedSeries:
    """Cut ``rec`` into uniformly sampled segments and pick the one to analyse (``gaps``:
    ``"auto"``, ``"longest"``, ``"fail"`` or ``"mask"``, module docstring), within the time
    window [``start_s``, ``end_s``] (:func:`window_rows`; default: the whole recording)."""
    if not (np.isfinite(start_s) and start_s >= 0) or not (end_s is None or np.isfinite(end_s)):
        given = f"--start {start_s:g}" + ("" if end_s is None else f" --end {end_s:g}")
        raise ImupipeError(f"the time window needs a finite --start >= 0 and --end (s): {given}")
    df = rec.frames
    if df.height < 2:
        raise ImupipeError(f"{rec.path}: {df.height} frame(s), too few for any averaging time")
    offset = 0
    if start_s != 0.0 or end_s is not None:
        t = df["t_s"].to_numpy()
        rows = window_rows(t, start_s, end_s)
        if rows.stop - rows.start < 2:
            raise ImupipeError(
                f"{rec.path}: the window --start {start_s:g} --end "
                f"{'(last frame)' if end_s is None else f'{end_s:g}'} s holds "
                f"{rows.stop - rows.start} frame(s) of a recording stamped 0..{t.max():.6g} s"
            )
        offset = rows.start
        df = df.slice(offset, rows.stop - offset)
    n = df.height
    warnings = list(rec.warnings)
    if len(rec.frame_ids) > 1:
        warnings.append(
            f"topic {rec.topic} carries messages of {len(rec.frame_ids)} frames (header.frame_id "
            f"{named_frames(rec)}) among its first {FRAME_ID_SAMPLE}: if several IMUs publish on "
            "it, they are analysed as one stream (give each its own topic)"
        )
    # stamps that scatter (a host's receive times, bursts) and no frame counter to place them;
    # not messages of several frames (several IMUs on the topic stamp in pairs or sets too)
    maybe = df["counter"].null_count() > 0 and len(rec.frame_ids) <= 1 and n > 2 * ENVELOPE_ROWS
    span_period, scatter = _scatter(df["t_s"].to_numpy()) if maybe else (np.nan, 0.0)
    jittery = scatter > JITTER_WARN
    regimes = rate_regimes(df["t_s"].to_numpy(), spans=jittery)
    if len(regimes) > 1:  # analyse the longest part at one rate, as if the rest were a gap
        first, stop, step = max(regimes, key=lambda r: r[1] - r[0])
        rates = ", ".join(f"{1 / r[2]:.4g} Hz from frame {r[0] + offset}" for r in regimes)
        warnings.append(
            f"the sample rate changes {len(regimes) - 1} time(s) ({rates}): analysing the "
            f"longest part at one rate, frames {first + offset}..{stop - 1 + offset} "
            f"({1 / step:.4g} Hz)"
        )
        df = df.slice(first, stop - first)
        offset += first
        n = df.height
    t = df["t_s"].to_numpy()
    counter = df["counter"].to_numpy() if df["counter"].null_count() == 0 else None
    mad_sigma = robust.MAD_TO_SIGMA * robust.mad(t, differences=True)
    if jittery and len(regimes) > 1:  # the part at one rate, again
        span_period, scatter = _scatter(t)
        jittery = n > 2 * ENVELOPE_ROWS and scatter > JITTER_WARN
    if jittery and "output_rate_hz" not in rec.device:
        rate = 1.0 / span_period
    else:
        rate = _nominal_rate(rec, t)
    period = 1.0 / rate

    if "nonfinite" in df.columns:  # a frame decoded without its axes (imupipe.io.columns)
        bits = df["nonfinite"].to_numpy()
    else:
        bits = nonfinite_bits((df[a].to_numpy() for a in AXES), n)
    # an axis NaN/inf in every frame is one the sensor does not provide (a gyro-only unit's
    # accelerometers): not analysed, and no reason to drop the other axes' frames
    absent_bits = np.bitwise_and.reduce(bits)
    absent = tuple(a for i, a in enumerate(AXES) if absent_bits >> i & 1)
    nonfinite = (bits & ~absent_bits) != 0
    del bits
    saturated = df["saturated"].to_numpy()
    threshold = max(GAP_FACTOR * period, period + JITTER_SIGMAS * mad_sigma)
    breaks, counts = _breaks(t, counter, threshold, period)
    places = None
    if jittery:  # frames in order; breaks only where the stamps' envelope says frames were lost
        places = _envelope_places(t, period)
        if "output_rate_hz" not in rec.device:  # no rate but the stamps': theirs, now placed
            span, places_spanned = _time_and_places(t, places, 0, n - 1)
            rate = places_spanned / span
            period = 1.0 / rate
        lost = np.diff(places) - 1
        breaks[1:n] = lost > 0
        counts["gaps"] = int(np.count_nonzero(lost))
        counts["missed_frames"] = int(places[-1] - (n - 1))
        del lost
    counts.update(
        {
            "frames": n,
            "nonfinite_frames": int(np.count_nonzero(nonfinite)),
            "saturated_frames": int(np.count_nonzero(saturated)),
            "flagged_frames": int(np.count_nonzero(df["flag_ea"].to_numpy() & ~saturated)),
            "stale_frames": int(np.count_nonzero(~df["flag_nd"].to_numpy())),
        }
    )
    bad_row = nonfinite | saturated
    del nonfinite, saturated

    # Segment boundaries: a break between rows, and bad rows removed entirely.
    edges = np.flatnonzero(breaks)
    segments: list[Segment] = []
    for a, b in itertools.pairwise(edges):
        # split [a, b) further around bad rows: the runs of good rows
        for start, stop in (clean_runs(bad_row[a:b]) + a).tolist():
            segments.append(
                Segment(start + offset, stop + offset, float(t[start]), float(t[stop - 1]))
            )
    if not segments:
        raise ImupipeError(f"{rec.path}: no usable frames (all non-finite or saturated)")

    describe = {
        "gaps": "gap(s) in time or frame counter ({missed_frames} frames missing)",
        "duplicate_stamps": "duplicate stamp(s)",
        "non_monotonic_stamps": "stamp(s) going backwards",
        "nonfinite_frames": "frame(s) with NaN/inf values",
        "saturated_frames": "saturated (over-range) frame(s)",
        "flagged_frames": "frame(s) with the EA (error/alarm) flag set",
        "stale_frames": "frame(s) without the ND (new data) flag: the same sample read twice",
    }
    if jittery:
        unordered = counts["duplicate_stamps"] + counts["non_monotonic_stamps"]
        del describe["duplicate_stamps"], describe["non_monotonic_stamps"]
        warnings.append(
            f"stamps scatter by {100 * scatter:.0f} % of the sample period (a host's "
            f"receive times, or samples stamped in bursts; {unordered} not after the one "
            "before): frames are kept in their order on the mean period, and frames lost are "
            "found where the stamps' lower envelope steps up by whole periods"
        )
    for key, text in describe.items():
        if counts[key]:
            warnings.append(f"{counts[key]} " + text.format(**counts))

    chosen = int(np.argmax([s.frames for s in segments]))
    seg = segments[chosen]
    if gaps in ("mask", "auto") and len(segments) > 1:
        masked = _masked_series(
            t, counter, period, bad_row, segments, chosen, counts, offset, places
        )
        longest_gap_s = None if masked is None else _longest_run(masked.excluded) * masked.tau0_s
        if masked is not None and (gaps == "mask" or longest_gap_s <= AUTO_MAX_GAP_S):
            return replace(
                masked,
                warnings=(*warnings, *masked.warnings),
                absent_axes=absent,
                window_s=(start_s, end_s),
            )
        warnings.append(
            f"more than {100 * MAX_MASKED_FRACTION:.0f} % of the sample grid would be masked: "
            "the longest clean segment is analysed instead"
            if masked is None
            else f"a gap of {longest_gap_s:.4g} s, longer than the {AUTO_MAX_GAP_S:g} s the "
            "default gap policy masks: the longest clean segment is analysed instead "
            "(--gaps mask keeps the whole recording; its closed loop is not validated "
            "across gaps that long)"
        )
    if len(segments) > 1:
        if gaps == "fail":
            raise ImupipeError(
                f"{rec.path}: the recording has {len(segments)} segments separated by gaps or "
                "bad frames (use --gaps longest to analyse the longest one)"
            )
        warnings.append(
            f"analysing the longest clean segment: frames {seg.start}..{seg.stop - 1} "
            f"({seg.frames} of {n} frames, {seg.t_stop_s - seg.t_start_s:.1f} s) "
            f"out of {len(segments)} segments"
        )

    seg_t = t[seg.start - offset : seg.stop - offset]
    span, places_spanned = _time_and_places(t, None, seg.start - offset, seg.stop - offset - 1)
    tau0 = span / places_spanned if seg.frames > 1 else period
    if seg.frames > 2:
        jitter = _step_jitter(seg_t, tau0) / tau0
        counts["jitter_ppm"] = round(jitter * 1e6)
        if jitter > JITTER_WARN and not jittery:  # (jittery: said above)
            warnings.append(
                f"stamp jitter is {100 * jitter:.0f} % of the sample period: samples are treated "
                "as equally spaced at the mean period"
            )
        if abs(tau0 * rate - 1) > 1e-3:
            warnings.append(
                f"measured mean rate {1 / tau0:.4f} Hz differs from the nominal {rate:g} Hz; "
                "the measured rate is used"
            )

    return ConditionedSeries(
        tau0_s=float(tau0),
        nominal_rate_hz=rate,
        segments=tuple(segments),
        chosen=chosen,
        counts=counts,
        warnings=tuple(warnings),
        absent_axes=absent,
        window_s=(start_s, end_s),
    )


def _time_and_places(
    t: np.ndarray, place: np.ndarray | None, first: int, last: int
) -> tuple[float, int]:
    """The time (s) and the grid places (``place``; None: one per row) from row ``first`` to
    row ``last``, whose ratio is the mean sample period, summed over the runs between steps
    back of more than :data:`imupipe.io.decode.CLOCK_RESET_NS` (resets of the stamping clock
    that the log time could not place: across one, the end points' times say nothing)."""
    resets = first + 1 + np.flatnonzero(np.diff(t[first : last + 1]) < -CLOCK_RESET_S)
    pairs = list(zip([first, *resets.tolist()], [*(resets - 1).tolist(), last], strict=True))
    spanned = sum(b - a if place is None else int(place[b] - place[a]) for a, b in pairs)
    return sum(float(t[b] - t[a]) for a, b in pairs), spanned


def _masked_series(
    t: np.ndarray,
    counter: np.ndarray | None,
    period: float,
    bad_row: np.ndarray,
    segments: list[Segment],
    chosen: int,
    counts: dict[str, int],
    offset: int,
    places: np.ndarray | None = None,
) -> ConditionedSeries | None:
    """Policy ``"mask"``: the whole recording (its part at one rate, from row ``offset``: the
    rows of ``t``) on its sample grid, or None if more than :data:`MAX_MASKED_FRACTION` of the
    grid would be excluded.  ``places``: the rows' grid places when they were found already
    (jittery stamps, :func:`_envelope_places`; every row's place then certain)."""
    if places is None:
        place, uncertain = _grid_places(t, counter, period)
    else:
        place, uncertain = places, np.zeros(len(t), dtype=bool)
    usable_row = ~(bad_row | uncertain)
    grid = int(place[-1]) + 1
    if grid - int(usable_row.sum()) > MAX_MASKED_FRACTION * grid:  # told before allocating:
        return None  # a stamp damaged into the far future asks for billions of grid samples
    excluded = np.ones(grid, dtype=bool)
    excluded[place[usable_row]] = False
    n_excluded = int(excluded.sum())
    if n_excluded > MAX_MASKED_FRACTION * len(excluded) or usable_row.sum() < 2:
        return None
    first, last = np.flatnonzero(usable_row)[[0, -1]]
    span, places_spanned = _time_and_places(t, place, first, last)
    tau0 = span / places_spanned
    counts["masked_samples"] = n_excluded
    counts["grid_samples"] = len(excluded)
    warnings = [_mask_warning(len(excluded), n_excluded, len(t))]
    clean = _longest_run(~excluded)
    bridged = None
    if 8 * clean < len(excluded):  # no term of τ ≥ T/8 (the long-τ fit's) is free of them
        bridged, clean = _bridge(excluded, clean, tau0, warnings)
    if bridged is not None:
        warnings[0] += " (the short runs only where that leaves half the terms: below)"
    if 8 * clean < len(excluded):
        warnings.append(
            f"the longest run of samples with none masked is {clean} ({clean * tau0:.4g} s of "
            f"{len(excluded) * tau0:.4g} s): the Allan variance stops at τ = "
            f"{(clean - 1) // 2 * tau0:.4g} s, and noise terms that show only at longer τ "
            "(bias instability, rate random walk) cannot be told from this recording"
        )
    if abs(tau0 / period - 1) > 1e-3:
        warnings.append(
            f"measured mean rate {1 / tau0:.4f} Hz differs from the nominal {1 / period:g} Hz; "
            "the measured rate is used"
        )
    return ConditionedSeries(
        tau0_s=tau0,
        nominal_rate_hz=1.0 / period,
        segments=tuple(segments),
        chosen=chosen,
        counts=counts,
        warnings=tuple(warnings),
        grid_index=place,
        grid_start=offset,
        excluded=excluded if bridged is None else excluded & ~bridged,
        bridged=bridged,
    )
