"""Disturbance events found jointly on all axes (issue 13 item 1), handled by excision.

A bump of the table, a short transient or a tilt episode shows at the same instant on several
axes.  Found axis by axis it would be read as "bias steps" (often one edge only); here it is
found once, on all axes together, and its interval is *excluded* for every axis: the
gap-tolerant Allan variance (:mod:`imupipe.stats.allan`, ``excluded``) skips every term whose
window touches it, and the loop's time-domain steps see it filled by linear interpolation.

Detector (all on :data:`FINE_BLOCK_S` block means of each axis, spikes already removed):

1. At each dyadic scale L = 1, 2, 4, … fine blocks (0.5 s … :data:`MAX_SCALE_S`), means of
   windows of L blocks at a stride of L/2 (half-overlapping).  Residual r = window mean −
   median of the 2·:data:`NEIGHBOURS` + 1 window means around it (±8 L in time): the local
   level, robust against the event itself, following drift and wander slower than the window,
   and keeping edges (the window itself breaks the tie at a level change).
2. Per axis and scale, a robust z-score z = r / s.  The scale s is that of the residual
   r′ = window mean − median of the same neighbourhood *without the windows that share a
   block with it* (the window itself and, at L ≥ 2, its two half-overlapping neighbours): the
   larger of the winsorised standard deviation of r′ and the (1 − p) quantile of |r′| /
   Φ⁻¹(1 − p/2) (p = max(:data:`TAIL_P`, 10 / windows)), so a heavy-tailed or quantised core
   is not taken for events.  Why r′: a median that contains the window follows a small window
   mean part of the way but a large one hardly at all, so r is shrunk in its core and not in
   its tails, and r scaled by its own spread has tails heavier than Gaussian wherever the
   tail-quantile floor does not apply (fewer than 10 000 windows: every scale of a record
   shorter than 1.4 h).  On 60 clean 0.5 h recordings of the independent generator, pooled
   over the scales, |z| > 4.5 came 1.8× as often as Gaussian (at 0.5 s windows |z| > 5 5.7×):
   the α = 0.1 check of docs/events.md alarmed on 13/70.  r′ shares no sample with the window
   and is Gaussian on Gaussian noise (same recordings: 0.88–1.0× up to 4 σ), and in the tails
   |r| ≤ |r′| (adding the window to the median pulls it towards the window), so r / s has at
   most Gaussian tails (there 0.65× at 4 σ, 0.83× at 4.5 σ) while edges stay sharp.  Only
   windows with a full neighbourhood are tested (none within 8 L of either end).
3. A window is flagged when one axis has |z| > z₁ or at least two axes have |z| > z₂.  With M
   tests (windows summed over all scales) and A axes, z₁ and z₂ are chosen so that under
   Gaussian z each rule has a record-wide false-alarm probability of at most α/2 (Bonferroni
   over windows, scales and axes / axis pairs, valid under any dependence between them):
   A · 2Φ̄(z₁) = α / (2M) and Σ_{i<j} P(|Zᵢ| > z₂, |Zⱼ| > z₂; ρᵢⱼ) = α / (2M),
   α = :data:`FALSE_ALARM`, with ρᵢⱼ the correlation of the two axes' z measured at that scale
   (:func:`axis_correlation`): axes that share noise (one temperature, one mechanical
   disturbance) coincide more often, and z₂ rises.  For ρ = 0 the pair rule is
   C(A, 2) · (2Φ̄(z₂))² = α / (2M).
4. Flagged windows that overlap are one event.  Its start and end: the box [a, b) of fine blocks
   inside the flagged span that maximises the multi-axis box likelihood ratio
   Σ_axes (Σ_{k∈[a,b)} x_k − level)² / ((b − a) v) (v: the fine-block variance; level: the
   median outside the flagged span), on the axes that had |z| > z₂ in its flagged windows.
5. Size per axis: mean inside − mean of the levels before and after (each the median of the
   fine blocks over max(duration, :data:`LEVEL_SPAN_S`) next to the box).  **Step rule**: an
   event is a *step* (a real bias step: kept, left to the loop's per-axis ``bias_step``
   candidate) when, on its largest axis, the level after differs from the level before by
   more than z₂ standard errors of a difference of two such adjacent means (robust scale of
   the adjacent differences over the record) *and* by more than half the size inside the box.
   Otherwise it is a *transient*, excised on every axis over [a, b) widened by
   max(:data:`MARGIN_S`, :data:`MARGIN_FRACTION` × duration) each side.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from math import comb
from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy import optimize, special

from imupipe.analysis.common_mode import CommonMode, common_mode
from imupipe.analysis.condition import fill_runs
from imupipe.model.effects import Candidate, block_means
from imupipe.stats import robust

FINE_BLOCK_S = 0.5
"""Length of the block means the detector works on (at least one sample)."""
MAX_SCALE_S = 512.0
"""Longest window searched (s); a scale is searched only when at least :data:`MIN_WINDOWS`
windows have a full neighbourhood."""
NEIGHBOURS = 16
"""Strided windows each side whose median is the local level (16 half-window strides = 8 L)."""
MIN_WINDOWS = 40
TAIL_P = 1e-3
TAIL_WINDOWS = 10
"""The tail-quantile scale is used only at scales with at least this many windows beyond
its (1 − :data:`TAIL_P`) quantile (elsewhere the MAD alone: window means of many samples are
Gaussian, and a few long events would hold a larger share of the windows)."""
FALSE_ALARM = 1e-3
"""Record-wide false-alarm probability of the detector (Gaussian, independent axes)."""
LEVEL_SPAN_S = 60.0
"""Shortest span over which the levels before and after an event are measured."""
MARGIN_S = 1.0
MARGIN_FRACTION = 0.05
STEP_FRACTION = 0.5
MAX_BOX_POINTS = 1024
"""The box search of an event works on at most this many (merged) fine blocks."""

EventKind = Literal["transient", "step"]


@dataclass(frozen=True)
class EventDetector:
    """What the detector searched and its thresholds (report.json ``events.detector``)."""

    fine_block_s: float
    scales_s: tuple[float, ...]
    windows: tuple[int, ...]
    z_single: tuple[float, ...]
    z_joint: tuple[float, ...]
    axes: tuple[str, ...]
    pair_correlation: tuple[tuple[float, ...], ...]
    """Correlation of each axis pair's z at each scale (:func:`axis_correlation`: C(A, 2)
    values per scale, in :func:`np.triu_indices` order of ``axes``)."""
    false_alarm: float = FALSE_ALARM

    @property
    def correlation(self) -> tuple[float, ...]:
        """Largest |correlation| of an axis pair's z at each scale (0 with one axis)."""
        return tuple(float(np.max(np.abs(r), initial=0.0)) for r in self.pair_correlation)

    @property
    def dof(self) -> tuple[float, ...]:
        """Degrees of freedom of each scale's estimates (:func:`scale_dof`)."""
        return tuple(scale_dof(w) for w in self.windows)

    def as_dict(self) -> dict:
        return {
            "fine_block_s": self.fine_block_s,
            "tests": sum(self.windows),
            "axes": list(self.axes),
            "false_alarm": self.false_alarm,
            "scales": [
                {
                    "window_s": s,
                    "windows": w,
                    "z_single_axis": z1,
                    "z_two_axes": z2,
                    "max_abs_axis_correlation": r,
                }
                for s, w, z1, z2, r in zip(
                    self.scales_s,
                    self.windows,
                    self.z_single,
                    self.z_joint,
                    self.correlation,
                    strict=True,
                )
            ],
            "rule": (
                "a window is an event when one axis has |z| > z_single_axis or two or more "
                "axes have |z| > z_two_axes; each rule has a record-wide false-alarm "
                "probability <= false_alarm / 2 (Bonferroni over the tests of all scales and "
                "the axes / axis pairs; a pair's joint tail is that of a bivariate normal with "
                "the axes' correlation measured at the scale, so correlated axes raise "
                "z_two_axes; Student-t quantiles with the degrees of freedom of each "
                "scale's noise estimate); an event whose level after differs from the "
                "level before by more than z_two_axes standard errors and by more than half "
                "its size is a step (kept), otherwise a transient (excised on every axis)"
            ),
        }


@dataclass(frozen=True)
class DisturbanceEvent:
    """One event: where (fine blocks ``[first, stop)`` → seconds from the analysed record's
    start), the axes it touches with its size (SI, axis unit) and z per axis, and how it was
    handled (``excised``: samples ``[start, stop)`` excluded on every axis, or None)."""

    start_s: float
    duration_s: float
    axes: tuple[str, ...]
    size: dict[str, float]
    level_change: dict[str, float]
    z: dict[str, float]
    kind: EventKind
    excised: tuple[int, int] | None
    scale_s: float
    units: dict[str, str] = field(default_factory=dict)

    def as_dict(self, tau0: float, t0_stamp_s: float) -> dict:
        """report.json record (``t0_stamp_s``: the time of the analysed record's first sample
        on the recording's time base, s since its first frame)."""
        out = {
            "kind": self.kind,
            "start_s": self.start_s,
            "start_recording_s": t0_stamp_s + self.start_s,
            "duration_s": self.duration_s,
            "axes": list(self.axes),
            "size": {a: {"value": v, "unit": self.units.get(a, "")} for a, v in self.size.items()},
            "level_change": {
                a: {"value": v, "unit": self.units.get(a, "")} for a, v in self.level_change.items()
            },
            "z": self.z,
            "scale_s": self.scale_s,
            "handling": "excised on every axis"
            if self.excised is not None
            else "kept: a level change (bias step), left to the loop's per-axis bias_step",
        }
        if self.excised is not None:
            a, b = self.excised
            out["excised"] = {"start_s": a * tau0, "stop_s": b * tau0, "samples": b - a}
        return out


def fine_block(tau0: float) -> int:
    """Samples per fine block (:data:`FINE_BLOCK_S`, at least 1)."""
    return max(1, round(FINE_BLOCK_S / tau0))


def fine_means(y: np.ndarray, tau0: float, outliers: Candidate | None) -> np.ndarray:
    """Means of consecutive :func:`fine_block` blocks of ``y`` (an incomplete last one dropped),
    with ``outliers`` (:func:`imupipe.model.effects.spike_candidate` of ``y``, None: none
    found) removed first (a single gross outlier is no event): the detector's input, one axis
    at a time."""
    b = fine_block(tau0)
    n = len(y) // b
    means = np.asarray(y[: n * b], dtype=float).reshape(n, b).mean(axis=1)
    if outliers is not None:
        fix = outliers.spikes
        keep = fix.index < n * b
        np.subtract.at(means, fix.index[keep] // b, fix.value[keep] / b)
    return means


JOINT_NODES = 1024
"""Integration nodes of :func:`joint_tail` (composite trapezoid in u = x − t)."""
MAX_CORRELATION = 1 - 1e-9
"""|ρ| is capped here (ρ = ±1 makes the conditional normal a step)."""


def joint_tail(t: float, rho: np.ndarray) -> np.ndarray:
    """P(|X| > t and |Y| > t) of a standard bivariate normal pair with correlation ``rho`` (one
    value per pair): 2 [U(t, ρ) + U(t, −ρ)], U(t, ρ) = P(X > t, Y > t) =
    ∫_t^∞ φ(x) Φ̄((t − ρx) / √(1 − ρ²)) dx (the conditional law of Y given X; e.g. Genz 2004,
    Stat. Comput. 14, eq. 1), integrated over u = x − t ∈ [0, 40/t + 10] where φ(t + u) ≤
    φ(t)·e⁻⁴⁰.  No cancellation: every term is a positive tail, so tail probabilities of 1e-15
    keep their relative accuracy (ρ = 0 gives (2Φ̄(t))² to 0.1 %, from above)."""
    rho = np.clip(np.abs(np.asarray(rho, dtype=float)), 0.0, MAX_CORRELATION)[:, None]
    u = np.linspace(0.0, 40.0 / max(t, 1.0) + 10.0, JOINT_NODES)[None, :]
    x = t + u
    w = np.exp(-0.5 * x * x) / np.sqrt(2 * np.pi)
    s = np.sqrt(1 - rho * rho)
    inner = special.ndtr(-(t - rho * x) / s) + special.ndtr(-(t + rho * x) / s)
    return 2 * np.trapezoid(w * inner, u, axis=1)


def thresholds(
    tests: int, axes: int, dof: float = np.inf, correlation: np.ndarray | None = None,
    false_alarm: float = FALSE_ALARM,
) -> tuple[float, float]:  # fmt: skip
    """(z₁, z₂) of the module docstring, step 3, as Student-t quantiles with ``dof`` degrees
    of freedom of the scale estimate (normal quantiles when ``dof`` is inf); z₂ = inf with one
    axis.

    ``correlation``: the correlation of the z of each axis pair (C(A, 2) values, the order of
    :func:`np.triu_indices`); None or all 0: independent axes.  z₂ is then the Gaussian ζ with
    Σ_pairs P(|Zᵢ| > ζ, |Zⱼ| > ζ; ρᵢⱼ) = α / (2M) (:func:`joint_tail`), carried to the t law
    by its one-axis tail Φ̄(ζ) — for ρ = 0 exactly the independent rule.  Bonferroni over the
    pairs needs no independence between pairs; z₁ (a union over axes) never did."""

    def quantile(tail: float) -> float:  # upper quantile of t_dof (of N(0, 1): dof inf)
        return float(-special.ndtri(tail) if np.isinf(dof) else special.stdtrit(dof, 1 - tail))

    share = false_alarm / (2 * max(tests, 1))
    z1 = quantile(share / (2 * axes))
    if axes < 2:
        return z1, np.inf
    if correlation is None or not np.any(correlation):
        return z1, quantile(np.sqrt(share / comb(axes, 2)) / 2)
    rho = np.asarray(correlation, dtype=float)

    def excess(zeta: float) -> float:  # log of the pairs' summed tail over the share
        return float(np.log(np.sum(joint_tail(zeta, rho)) + 1e-320) - np.log(share))

    zeta = optimize.brentq(excess, 0.0, 40.0, xtol=1e-6)
    return z1, quantile(float(special.ndtr(-zeta)))


WINSOR_C = 3.0
WINSOR_VAR = float(
    special.erf(WINSOR_C / np.sqrt(2))
    - 2 * WINSOR_C * np.exp(-(WINSOR_C**2) / 2) / np.sqrt(2 * np.pi)
    + WINSOR_C**2 * special.erfc(WINSOR_C / np.sqrt(2))
)
"""E[min(Z², c²)] of a standard normal Z (c = :data:`WINSOR_C`): the winsorised variance's
Gaussian expectation, ≈ 0.995."""
WINSOR_EFFICIENCY = 0.95
"""Efficiency of the winsorised standard deviation against the sample one (Gaussian): the
scale of J half-overlapping windows has about 0.95 × J / 2 degrees of freedom."""


def scale_dof(windows: int) -> float:
    """Degrees of freedom of a scale's estimates from its ``windows`` half-overlapping windows
    (:data:`WINSOR_EFFICIENCY` × J / 2)."""
    return WINSOR_EFFICIENCY * windows / 2


DENSE_SPAN = 16
"""Windows of a span in which a sustained disturbance is recognised (:func:`_sustained`)."""
DENSE_FRACTION = 0.5
"""Share of a span's windows beyond ±:data:`WINSOR_C` robust sigmas that marks it sustained:
Gaussian noise puts 0.27 % of windows there (8 of 16 by chance: ~1e-17 a span), noise with
5 % there ~5e-7 a span."""


def _sustained(r: np.ndarray, limit: float) -> np.ndarray:
    """bool (J,): windows in a span of :data:`DENSE_SPAN` consecutive ones of which at least
    :data:`DENSE_FRACTION` have |r| > ``limit``: a sustained disturbance (a robot carried
    about, a vibration burst), not the scattered extremes of a heavy-tailed noise."""
    beyond = np.concatenate([[0], np.cumsum(np.abs(r) > limit)])
    span = min(DENSE_SPAN, len(r))
    dense = beyond[span:] - beyond[:-span] >= DENSE_FRACTION * span  # span starting at i
    starts = np.flatnonzero(dense)
    hit = np.zeros(len(r) + 1, dtype=np.int64)
    np.add.at(hit, starts, 1)
    np.add.at(hit, starts + span, -1)
    return np.cumsum(hit[:-1]) > 0


def _robust_scale(r: np.ndarray) -> float:
    """Scale of the residuals (module docstring, step 2): the standard deviation of r
    winsorised at ±:data:`WINSOR_C` × (1.4826 MAD) — a few event windows barely move it —
    and, where there are enough windows (:data:`TAIL_WINDOWS`), at least the tail-quantile
    scale, so a heavy-tailed or quantised core is not taken for events.  The tail quantile
    leaves out the windows of a sustained disturbance (:func:`_sustained`): over more than
    :data:`TAIL_P` of the windows (43 s of a 12 h record at 0.5 s) it would otherwise set
    the quantile itself and hide itself (a robot carried for its first minute: N 37× the
    truth on a 4 h record)."""
    r = np.ascontiguousarray(r)
    sigma0 = robust.MAD_TO_SIGMA * robust.mad(r, center=0.0)
    c = WINSOR_C * sigma0
    sigma = float(np.sqrt(np.mean(np.clip(r, -c, c) ** 2) / WINSOR_VAR))
    if len(r) * TAIL_P < TAIL_WINDOWS:
        return sigma
    quiet = r[~_sustained(r, c)] if c > 0 else r
    if len(quiet) * TAIL_P < TAIL_WINDOWS:
        return sigma
    tail = robust.abs_quantile(quiet, 1.0 - TAIL_P) / float(-special.ndtri(TAIL_P / 2))
    return max(sigma, tail)


def axis_correlation(z: np.ndarray) -> np.ndarray:
    """Correlation of the z of each axis pair over the windows of one scale (C(A, 2) values in
    :func:`np.triu_indices` order), from z clipped at ±:data:`WINSOR_C` so a few event windows
    barely move it; 0 where an axis' z is constant."""
    c = np.clip(z, -WINSOR_C, WINSOR_C)
    c = c - c.mean(axis=0)
    sd = np.sqrt(np.mean(c * c, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (c.T @ c) / len(c) / np.outer(sd, sd)
    return np.nan_to_num(r[np.triu_indices(z.shape[1], 1)], nan=0.0)


@dataclass(frozen=True)
class _Scale:
    """z-scores of one scale: windows ``[starts, starts + length)`` (fine blocks), (J, A), and
    the residual scale of each axis (its unit)."""

    length: int
    starts: np.ndarray
    z: np.ndarray
    sigma: np.ndarray

    @property
    def dof(self) -> float:
        """Degrees of freedom of its scale estimate (:func:`scale_dof`)."""
        return scale_dof(len(self.starts))


def _scales(x: np.ndarray, dt: float) -> list[_Scale]:
    """The tested windows and their z (steps 1–2) at every searchable scale."""
    n = len(x)
    c = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    out = []
    length = 1
    while length * dt <= MAX_SCALE_S * (1 + 1e-9):
        stride = max(1, length // 2)
        starts = np.arange(0, n - length + 1, stride)
        if len(starts) - 2 * NEIGHBOURS < MIN_WINDOWS:
            break
        m = (c[starts + length] - c[starts]) / length
        inner = slice(NEIGHBOURS, len(starts) - NEIGHBOURS)
        r = (m - robust.running_median(m, NEIGHBOURS))[inner]
        apart = (m - robust.running_median(m, NEIGHBOURS, -(-length // stride)))[inner]
        scale = np.array([_robust_scale(apart[:, a]) for a in range(r.shape[1])])
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(scale > 0, r / scale, 0.0)
        out.append(_Scale(length, starts[inner], z, scale))
        length *= 2
    return out


def overlapping_groups(lo: npt.ArrayLike, hi: npt.ArrayLike) -> list[np.ndarray]:
    """The intervals [lo, hi] merged where they overlap or touch, chained (an interval that
    reaches any of a group's joins it): each group's indices, in the order of ``lo`` (ties in
    the order given)."""
    order = np.argsort(lo, kind="stable")
    if not order.size:
        return []
    reach = np.maximum.accumulate(np.asarray(hi)[order])
    starts_group = np.asarray(lo)[order][1:] > reach[:-1]
    return np.split(order, np.flatnonzero(starts_group) + 1)


def _best_box(e: np.ndarray, v: np.ndarray) -> tuple[int, int]:
    """[a, b) of rows of ``e`` (residuals (L, A) from the level) maximising
    Σ_A (Σ_{[a,b)} e)² / ((b − a) v) (step 4); rows merged to ≤ :data:`MAX_BOX_POINTS`."""
    merge = -(-len(e) // MAX_BOX_POINTS)  # ≥ 1: an event spans at least one block
    k = len(e) // merge
    coarse = e[: k * merge].reshape(k, merge, -1).sum(axis=1)
    c = np.vstack([np.zeros((1, e.shape[1])), np.cumsum(coarse, axis=0)])
    stat = np.zeros((k + 1, k + 1))
    for j in range(e.shape[1]):
        d = c[None, :, j] - c[:, None, j]  # d[a, b] = sum over [a, b)
        stat += d * d / v[j]
    length = np.arange(k + 1)[None, :] - np.arange(k + 1)[:, None]
    stat = np.where(length > 0, stat / np.maximum(length, 1), -np.inf)
    a, b = np.unravel_index(int(np.argmax(stat)), stat.shape)
    return int(a) * merge, int(b) * merge


def _adjacent_difference_scale(x: np.ndarray, width: int) -> float:
    """Robust standard deviation of the difference of two adjacent means of ``width`` blocks
    of ``x`` over the record (1.4826 × MAD of consecutive non-overlapping window means)."""
    k = len(x) // width
    if k < 3:
        return np.inf
    m = x[: k * width].reshape(k, width).mean(axis=1)
    return robust.MAD_TO_SIGMA * robust.mad(np.diff(m))


def find_events(
    means: dict[str, np.ndarray], dt: float, samples_per_block: int, n_samples: int,
    units: dict[str, str] | None = None, false_alarm: float = FALSE_ALARM,
    blocks: np.ndarray | None = None,
) -> tuple[list[DisturbanceEvent], EventDetector]:  # fmt: skip
    """Events in the fine block means of the axes (``means``: {axis: (n_blocks,)}, equal
    lengths; ``dt`` s per block of ``samples_per_block`` samples; the record has ``n_samples``
    samples), found and classified as in the module docstring, at the record-wide
    ``false_alarm`` probability.  ``blocks``: the place on the record's block grid of each
    mean when some blocks were left out (:func:`detect`: blocks touching a gap); the events'
    times and excised samples are given on that grid."""
    names = tuple(means)
    x = np.column_stack([means[a] for a in names])
    scales = _scales(x, dt)
    tests = sum(len(s.starts) for s in scales)
    rho = [axis_correlation(s.z) for s in scales]
    limits = [
        thresholds(tests, len(names), s.dof, r, false_alarm)
        for s, r in zip(scales, rho, strict=True)
    ]
    detector = EventDetector(
        dt,
        tuple(s.length * dt for s in scales),
        tuple(len(s.starts) for s in scales),
        tuple(z for z, _ in limits),
        tuple(z for _, z in limits),
        names,
        tuple(tuple(float(v) for v in r) for r in rho),
        false_alarm,
    )
    spans, zs, ratios, lengths = [], [], [], []
    for s, (z1, z2) in zip(scales, limits, strict=True):
        a = np.abs(s.z)
        top = np.sort(a, axis=1)[:, ::-1]
        flag = top[:, 0] > z1
        if a.shape[1] > 1:
            flag |= top[:, 1] > z2
        for j in np.flatnonzero(flag):
            spans.append((s.starts[j], s.starts[j] + s.length))
            zs.append(s.z[j])
            ratios.append(a[j] / min(z1, z2))  # > 1: the axis takes part (step 4)
            lengths.append(s.length)
    if not spans:
        return [], detector
    spans_a, zs_a, ratios_a = np.array(spans), np.array(zs), np.array(ratios)
    fine_v = np.array([(robust.MAD_TO_SIGMA * robust.mad(x[:, j], differences=True)) ** 2 / 2
                       for j in range(len(names))])  # fmt: skip
    fine_v = np.where(fine_v > 0, fine_v, np.var(x, axis=0) + 1e-300)
    z_step = min(thresholds(tests, len(names)))
    lengths_a = np.array(lengths)
    tested = {s.length: (int(s.starts[0]), int(s.starts[-1]) + s.length) for s in scales}
    events = []
    for members in overlapping_groups(spans_a[:, 0], spans_a[:, 1]):
        first, stop = int(spans_a[members[0], 0]), int(spans_a[members, 1].max())
        zmax = np.max(np.abs(zs_a[members]), axis=0)
        touched = np.flatnonzero(np.max(ratios_a[members], axis=0) > 1)
        hull = _hull(spans_a[members], lengths_a[members], tested, len(x))
        events.append(
            _event(x, names, touched, first, stop, zmax, fine_v, dt, samples_per_block,
                   n_samples, z_step, units or {}, max(lengths[i] for i in members) * dt,
                   np.arange(len(x)) if blocks is None else blocks, hull)
        )  # fmt: skip
    return events, detector


HULL_MAX_BLOCKS = 8
"""Longest window (fine blocks: 4 s) whose flagged windows an event spans whole (:func:`_hull`)."""


def _hull(
    spans: np.ndarray, lengths: np.ndarray, tested: dict[int, tuple[int, int]], n: int
) -> tuple[int, int] | None:
    """The fine blocks an event spans whatever its best box: from the first to the last of its
    flagged windows ``spans`` (of ``lengths`` blocks) at the shortest length that flagged any,
    if that is at most :data:`HULL_MAX_BLOCKS` (None otherwise: a long window flagged for a
    short bump would overreach).  It reaches the record's start (end) when it begins (ends)
    with the first (last) window tested at that length (``tested``: length → (first window's
    start, last window's stop), the ends without a full neighbourhood untested): a disturbance
    flagged from the first tested window on is taken to have begun before it (a robot carried
    to its place, then left at rest).  ``n``: blocks in the record."""
    shortest = int(lengths.min())
    if shortest > HULL_MAX_BLOCKS:
        return None
    at = spans[lengths == shortest]
    first, stop = int(at[:, 0].min()), int(at[:, 1].max())
    start_tested, stop_tested = tested[shortest]
    return (0 if first <= start_tested else first), (n if stop >= stop_tested else stop)


def _level(x: np.ndarray, lo: int, hi: int) -> np.ndarray:
    lo, hi = max(lo, 0), min(hi, len(x))
    return np.median(x[lo:hi], axis=0) if hi > lo else np.full(x.shape[1], np.nan)


def _event(
    x: np.ndarray, names: tuple[str, ...], touched: np.ndarray, first: int, stop: int,
    zmax: np.ndarray, fine_v: np.ndarray, dt: float, per_block: int, n_samples: int,
    z_step: float, units: dict[str, str], scale_s: float, blocks: np.ndarray,
    hull: tuple[int, int] | None = None,
) -> DisturbanceEvent:  # fmt: skip
    """One merged component of flagged windows as an event (steps 4–5); ``blocks``: each
    row of ``x``'s place on the record's block grid (times and excision are on the grid);
    ``hull``: the blocks of its windows flagged at their shortest length (:func:`_hull`),
    which the event spans whatever its best box (an oscillation's box is one swing of it)."""
    span = max(stop - first, round(LEVEL_SPAN_S / dt))
    outside = np.concatenate([x[max(first - span, 0) : first], x[stop : stop + span]])
    level = np.median(outside, axis=0)  # never empty: windows start after their neighbours
    sub = x[first:stop][:, touched] - level[touched]
    a, b = _best_box(sub, fine_v[touched])
    a, b = first + a, first + b
    if hull is not None:
        a, b = min(a, hull[0]), max(b, hull[1])
    width = max(b - a, round(LEVEL_SPAN_S / dt))
    before, after = _level(x, a - width, a), _level(x, b, b + width)
    ends = np.nanmean(np.vstack([before, after]), axis=0)  # the level either side
    inside = x[a:b].mean(axis=0)
    size = inside - ends
    change = np.where(np.isnan(before) | np.isnan(after), 0.0, after - before)
    main = touched[int(np.argmax(np.abs(zmax[touched])))]
    se = _adjacent_difference_scale(x[:, main], width)
    is_step = bool(
        abs(change[main]) > z_step * se and abs(change[main]) > STEP_FRACTION * abs(size[main])
    )
    a, b = int(blocks[a]), int(blocks[b - 1]) + 1  # on the record's grid from here
    excised = None
    if not is_step:
        margin = max(MARGIN_S, MARGIN_FRACTION * (b - a) * dt)
        m = round(margin / dt)
        excised = (max(0, (a - m) * per_block), min(n_samples, (b + m) * per_block))
    axes = tuple(names[j] for j in touched)
    return DisturbanceEvent(
        start_s=a * dt,
        duration_s=(b - a) * dt,
        axes=axes,
        size={names[j]: float(size[j]) for j in touched},
        level_change={names[j]: float(change[j]) for j in touched},
        z={names[j]: float(zmax[j]) for j in touched},
        kind="step" if is_step else "transient",
        excised=excised,
        scale_s=scale_s,
        units={n: units[n] for n in axes if n in units},
    )


def event_mask(events: list[DisturbanceEvent], n: int) -> np.ndarray | None:
    """bool (n,) True on every excised event's samples, or None when none is excised."""
    cut = [e.excised for e in events if e.excised is not None]
    if not cut:
        return None
    mask = np.zeros(n, dtype=bool)
    for a, b in cut:
        mask[a:b] = True
    return mask


@dataclass(frozen=True)
class EventsFound:
    """The detector's result on one record (report.json ``events``): ``tau0_s`` the sampling
    interval and ``t0_stamp_s`` the time of the analysed record's first sample on the
    recording's time base (s since its first frame; not 0 when a later segment is analysed)."""

    detector: EventDetector
    events: tuple[DisturbanceEvent, ...]
    tau0_s: float
    t0_stamp_s: float

    @functools.cached_property
    def common_mode(self) -> CommonMode:
        """The axis pairs whose level fluctuations move together (:mod:`.common_mode`; tested
        once, then read by report.json, the warnings and the figure)."""
        return common_mode(self.detector)

    def as_dict(self) -> dict:
        excised = [e.excised for e in self.events if e.excised is not None]
        return {
            "detector": self.detector.as_dict(),
            "found": [e.as_dict(self.tau0_s, self.t0_stamp_s) for e in self.events],
            "excised_samples": int(sum(b - a for a, b in excised)),
            "common_mode": self.common_mode.as_dict(),
        }

    def warnings(self) -> list[str]:
        """One line per event for the report's warnings, and one for axes that move together."""
        moving = self.common_mode.warning()
        return [
            f"disturbance event ({e.kind}) at {e.start_s:.1f} s for {e.duration_s:.1f} s on "
            f"{', '.join(e.axes)}: "
            + (
                "excised on every axis"
                if e.excised is not None
                else "a lasting level change, left to the loop (bias step)"
            )
            for e in self.events
        ] + ([moving] if moving else [])


def detect(
    means: dict[str, np.ndarray], tau0: float, n_samples: int, units: dict[str, str],
    t0_stamp_s: float, excluded: np.ndarray | None = None,
) -> EventsFound:  # fmt: skip
    """:func:`find_events` on the :func:`fine_means` of the analysed axes.  ``excluded``
    (n_samples,) bool, the samples masked by the gap policy ``"mask"``: every fine block
    touching one is left out and the blocks either side of a gap are joined, so neither a
    gap's interpolated fill nor the gap itself is taken for an event (a level that differs
    across a gap shows as a step there)."""
    b = fine_block(tau0)
    blocks = None
    if excluded is not None and np.any(excluded):
        n_blocks = len(next(iter(means.values())))
        blocks = np.flatnonzero(block_means(excluded[: n_blocks * b], b) == 0)
        means = {a: m[blocks] for a, m in means.items()}
    events, detector = find_events(means, b * tau0, b, n_samples, units, blocks=blocks)
    return EventsFound(detector, tuple(events), tau0, t0_stamp_s)


def fill_excised(y: np.ndarray, events: EventsFound) -> np.ndarray:
    """``y`` with every excised event's samples replaced by the straight line between the
    means of the fine block before and after it (:func:`imupipe.analysis.condition.fill_runs`;
    a copy, ``y`` itself when none is excised): what the loop's time-domain steps see there
    (its Allan sums skip those samples)."""
    cut = event_mask(list(events.events), len(y))
    if cut is None:
        return y
    y = np.array(y, dtype=float)
    fill_runs(y, cut, fine_block(events.tau0_s))
    return y
