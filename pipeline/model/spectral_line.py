"""The spectrum's view of a spread line's centre: a Whittle fit of the damped oscillator's PSD.

A narrowband vibration (:func:`imupipe.model.effects.oscillator_avar`) is a random process, not
a tone: its periodogram's strongest bin scatters over about half the line's width from one
record to the next, so the Cramér–Rao interval of a sinusoid (:func:`effects.psd_line`, a
fraction of a bin wide) does not hold for it.  Its centre is estimated here from the line's
whole shape: the periodogram ordinates I_k (every second Hann bin,
:func:`effects.hann_periodogram`, nearly independent, each ~ S(f_k) χ²₂/2) against

    S(f) = c_white + c_flicker / f + P · S_osc(f; f0, w),   c_white, c_flicker, P ≥ 0,

by the Whittle likelihood (Whittle 1953), whose deviance is the gamma deviance with ν = 2 per
ordinate — :func:`ieee952.fit_nonneg_gamma` with the three linear coefficients free.  The 95 %
interval of f0 is the profile interval over the width: {f0 : min_w D(f0, w) − D_min ≤
φ χ²₁(0.95)}, φ = max(1, D_min / dof) (a misfit of the shape widens it).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from imupipe.model import ieee952
from imupipe.model.effects import oscillator_psd
from imupipe.vocab import CHI2_95

CENTRE_SPAN = 8.0  # an interval edge beyond the estimate ± this many widths is censored there
WIDTH_SPAN = 8.0  # the profile's width: within the estimate / … × this factor
FINE_BAND = 15.0  # the profile's ordinates: within this many best widths of the best centre
WHITTLE_EDF = 2.0  # a periodogram ordinate is S χ²₂ / 2
COARSE_ORDINATES = 2048
"""The coarse search reads a band of more ordinates than this as means of consecutive ones."""
POOLS_PER_WIDTH = 32
"""The fine fit pools consecutive ordinates spanning at most the coarse width / this."""
REFIT_DEVIANCE = 1.0
"""A width at the fitted centre whose deviance is lower than the joint (Nelder–Mead) fit's by
more than this restarts the fit from there: the estimate must lie inside its own 95 % intervals
(χ²₁ 3.84), so it may not stop short by more than a quarter of that.  On the real recordings
Nelder–Mead stops within 0.02 of it."""
MAX_REFITS = 4
"""Restarts after which a fit whose deviance still falls with the width has no line."""


@dataclass(frozen=True)
class _Pooled:
    """Periodogram ordinates pooled ``size`` at a time (the last pool may be smaller): each
    pool's mean ordinate is S̄ χ²₂ₖ / 2k for k members, S̄ their mean PSD — the Whittle
    likelihood of pooled ordinates is the gamma deviance with ν = 2k (exact in the mean; the
    gamma law holds where S is flat over a pool).  Pools of one ordinate are the ordinates
    themselves, bit for bit."""

    freqs: np.ndarray  # Hz, every member ordinate
    start: np.ndarray  # first member of each pool (np.add.reduceat)
    count: np.ndarray  # members of each pool
    power: np.ndarray  # mean ordinate of each pool
    floor: np.ndarray  # (pools, 2) mean floor columns (1, 1/f)
    centre: np.ndarray  # Hz, mean frequency of each pool
    line_mean: bool  # the line's PSD averaged over each pool's members, else read at its centre

    @classmethod
    def of(cls, freqs: np.ndarray, power: np.ndarray, size: int, line_mean: bool) -> _Pooled:
        start = np.arange(0, power.size, max(1, size))
        count = np.diff(np.append(start, power.size))
        floor = np.column_stack([np.ones_like(freqs), 1.0 / freqs])
        return cls(
            freqs, start, count, cls._mean(start, count, power), cls._mean(start, count, floor),
            cls._mean(start, count, freqs), line_mean,
        )  # fmt: skip

    @staticmethod
    def _mean(start: np.ndarray, count: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Mean of ``x`` (each column of it) over each pool; ``x`` itself for pools of one."""
        if count.size == x.shape[0]:
            return x
        sums = np.add.reduceat(x, start, axis=0)
        return sums / (count if x.ndim == 1 else count[:, None])

    def fit(self, f0: float, w: float, start: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """Whittle fit of the pools to the floor columns plus the line at (f0, w): the linear
        coefficients (white, flicker, line) and the deviance; ``start``: the coefficients to
        begin from (:func:`ieee952.fit_nonneg_gamma`), default 0."""
        if self.line_mean:
            line = self._mean(self.start, self.count, oscillator_psd(self.freqs, f0, w))
        else:
            line = oscillator_psd(self.centre, f0, w)
        design = np.column_stack([self.floor, line])
        return ieee952.fit_nonneg_gamma(design, self.power, WHITTLE_EDF * self.count, start=start)

    def deviance(self, f0: float, w: float) -> float:
        """Whittle deviance of the pools against the floor columns plus the line at (f0, w)."""
        return self.fit(f0, w)[1]


@dataclass(frozen=True)
class LineCentre:
    """A spread line's centre (Hz) with its 95 % Whittle profile interval, the width (Hz) at
    the best centre, the dispersion φ and the number of periodogram ordinates the fine fit read
    (pooled when they are many); :meth:`width_interval`, the width's own (computed on demand:
    ~30 ms of profile fits, wasted where the width is not used)."""

    frequency_hz: float
    lo: float
    hi: float
    width_hz: float
    dispersion: float
    ordinates: int
    _width_interval: Callable[[], tuple[float, float]] = field(repr=False, compare=False)

    @functools.cached_property
    def width_interval(self) -> tuple[float, float]:
        """The width's 95 % Whittle profile interval (Hz): the profile over the centre."""
        return self._width_interval()

    def as_evidence(self) -> dict[str, float]:
        """The fit as report.json evidence (SI: Hz)."""
        return {
            "frequency_hz": self.frequency_hz,
            "frequency_lo": self.lo,
            "frequency_hi": self.hi,
            "width_hz": self.width_hz,
            "dispersion": self.dispersion,
            "ordinates": self.ordinates,
        }


def line_centre(
    freqs: np.ndarray, power: np.ndarray, seed_hz: float, widths: np.ndarray
) -> LineCentre | None:
    """Centre of the spread line near ``seed_hz`` (Hz) in the periodogram ordinates
    (``freqs`` Hz, ``power``): a coarse search over ``widths`` (Hz) × centres ``seed_hz`` ± two
    widths; then, on the ordinates within :data:`FINE_BAND` widths of it, the Whittle estimate
    of (centre, width) (Nelder–Mead) and the centre's profile interval — the width minimised
    (bounded, within a factor :data:`WIDTH_SPAN` of the estimate) at each centre, each edge found
    by bracketing and Brent's root finder.  ``None`` when the band holds fewer than 8 ordinates,
    an ordinate of exactly 0 (a constant stretch of a series: its Whittle deviance is
    infinite), no width minimum (the deviance still falls :data:`MAX_REFITS` restarts
    wider: a smooth spectrum, no line), or a centre outside ``freqs`` (a low-pass's smooth fall
    is an oscillator's spectrum centred at 0 Hz, as wide as the filter's bandwidth: measured,
    a first-order low-pass of 13.5 Hz at 200 Hz gave a centre of −5.5e-5 Hz for a band of
    4.3–11 Hz, and the line's width grid, up to half its centre, crashed the analysis).
    """
    if power.size < 8 or not np.all(power > 0):
        return None
    band = (freqs[0], freqs[-1])
    coarse = [
        (c, w)
        for w in widths
        for c in seed_hz + w * np.linspace(-2, 2, 9)
        if freqs[0] < c < freqs[-1]
    ]
    pooled = _Pooled.of(freqs, power, -(-power.size // COARSE_ORDINATES), line_mean=True)
    # each width's centres in turn, each fit begun from the previous centre's coefficients:
    # the same minima in ~half the scoring iterations (a real ADIS16405's 10 Hz line: 11 →
    # 4–5 on 2,041 pools), and a fit that would stop at its iteration cap from 0 gets nearer
    # its minimum (scratch: deviances up to 230 lower on a line's far side)
    best, coef, width = None, None, None
    for c, w in coarse:
        coef, dev = pooled.fit(c, w, coef if w == width else None)
        width = w
        if best is None or dev < best:  # the first of equal minima, as min() keeps
            best, c1, w1 = dev, c, w
    near = np.abs(freqs - c1) <= FINE_BAND * w1  # the line and its shoulders
    if near.sum() >= 8:
        freqs, power = freqs[near], power[near]
    spacing = (freqs[-1] - freqs[0]) / (freqs.size - 1)
    fine = _Pooled.of(freqs, power, int(w1 / (POOLS_PER_WIDTH * spacing)), line_mean=False)

    def joint(p: np.ndarray) -> float:  # (centre offset in units of w1, ln(width / w1))
        return fine.deviance(c1 + p[0] * w1, w1 * np.exp(p[1]))

    def best_width(c: float, w: float) -> optimize.OptimizeResult:  # at centre c, near w
        return optimize.minimize_scalar(
            lambda lw: fine.deviance(c, w * np.exp(lw)),
            bounds=(-np.log(WIDTH_SPAN), np.log(WIDTH_SPAN)),
            method="bounded",
            options={"xatol": 1e-3},
        )

    x0 = np.zeros(2)
    for _ in range(MAX_REFITS):
        start = optimize.minimize(joint, x0, method="Nelder-Mead",
                                  options={"xatol": 1e-3, "fatol": 1e-4})  # fmt: skip
        c_hat, w_hat = c1 + start.x[0] * w1, w1 * float(np.exp(start.x[1]))
        at_centre = best_width(c_hat, w_hat)
        if at_centre.fun > start.fun - REFIT_DEVIANCE:
            break
        x0 = start.x + np.array([0.0, at_centre.x])  # Nelder–Mead stopped short of the width
    else:
        return None  # the deviance still falls at ever wider widths: no line to centre
    if not band[0] <= c_hat <= band[1]:
        return None  # the Whittle fit's centre ran out of the band: no line in it

    def profile(c: float) -> float:  # min over the width of the deviance at centre c
        res = at_centre if c == c_hat else best_width(c, w_hat)
        return min(float(res.fun), fine.deviance(c, w_hat))

    d_min = min(profile(c_hat), float(start.fun))
    dof = max(fine.power.size - 5, 1)  # three linear coefficients, centre and width
    phi = max(1.0, d_min / dof)

    def excess(c: float) -> float:  # > 0 outside the centre's 95 % interval
        return (profile(c) - d_min) / phi - CHI2_95

    def width_profile(lw: float) -> float:  # min over the centre of the deviance at a width
        res = optimize.minimize_scalar(
            lambda dc: fine.deviance(c_hat + dc * w_hat, w_hat * np.exp(lw)),
            bounds=(-2.0, 2.0),
            method="bounded",
            options={"xatol": 1e-3},
        )
        return min(float(res.fun), fine.deviance(c_hat, w_hat * np.exp(lw)))

    def width_excess(lw: float) -> float:  # > 0 outside ln(width / w_hat)'s 95 % interval
        return (width_profile(lw) - d_min) / phi - CHI2_95

    def width_interval() -> tuple[float, float]:
        lo, hi = (w_hat * np.exp(_edge(width_excess, 0.0, s, np.log(WIDTH_SPAN))) for s in (-1, 1))
        return float(lo), float(hi)

    c_lo, c_hi = (
        _edge(excess, c_hat, s * w_hat, CENTRE_SPAN * w_hat, floor=0.0) for s in (-1.0, 1.0)
    )
    return LineCentre(float(c_hat), c_lo, c_hi, w_hat, phi, int(power.size), width_interval)


def _edge(
    excess: Callable[[float], float], start: float, unit: float, span: float,
    floor: float = -np.inf,
) -> float:  # fmt: skip
    """Where ``excess`` (≤ 0 at ``start``) crosses 0 going from ``start`` in the direction and
    scale of ``unit``: steps of 0.05, 0.1, 0.2 … × ``unit`` bracket it, Brent's root finder
    (to 1e-4 × |unit|) finds it; censored at ``span`` from ``start`` and at ``floor`` (a line's
    centre is never below 0 Hz: the oscillator's PSD depends on the centre's square, so its
    profile below 0 mirrors the one above and an edge there is no frequency), the censored
    edge being that limit itself (a real ADIS16405's broad candidate line at 28.6 Hz read
    [−40.8, 40.8] Hz before)."""
    limit = span if unit > 0 else min(span, start - floor)
    inner, step = start, 0.05
    while True:
        reach = min(step * abs(unit), limit)
        outer = start + float(np.copysign(reach, unit))
        inside = excess(outer) <= 0  # each call a profile fit: read once
        if not inside or reach >= limit:
            break
        inner, step = outer, 2 * step
    if inside:  # censored
        return float(outer)
    a, b = sorted((inner, outer))
    return float(optimize.brentq(excess, a, b, xtol=1e-4 * abs(unit)))
