"""IEEE Std 952 noise terms fitted to an Allan variance curve with the estimator's statistics.

Composite Allan variance model (IEEE Std 952-1997, Annex C, Table C.2 and eq. C.x for bias
instability), rate units u (rad/s or m/s²):

* quantisation     3 Q² / τ²                          Q in u·s (rad or m/s)
* random walk      N² / τ                             N in u/√Hz
* bias instability (2 B² / π) · F(π f0 τ)             B in u, f0 the flicker cut-off (Hz)
  with F(x) = ln 2 − sin³x (sin x + 4x cos x) / (2x²) + Ci(2x) − Ci(4x)   (exact Annex C form;
  F → ln 2 for x → ∞, hence the plateau √(2 ln2 / π) B = 0.664 B)
* rate random walk K² τ / 3                           K in u/s/√Hz
* rate ramp        R² τ² / 2                          R in u/s

The model is linear in the squared coefficients, so for a fixed cut-off f0 it is a gamma GLM
with identity link and non-negative coefficients.  Each AVAR estimate is ~ σ²·χ²_ν/ν with ν
the curve's equivalent degrees of freedom (Greenhall), i.e. gamma with shape ν/2; we minimise
the gamma deviance D = Σ ν (â/a − ln(â/a) − 1) by iteratively re-weighted non-negative least
squares, on octave-spaced τ (neighbouring overlapping-AVAR points are strongly correlated, so a
dense grid would over-count the evidence) — and on a curve beyond T/4 on every τ of its last
two octaves, where the long-τ terms live and each point's small edf keeps its weight small
(:func:`fit_index`).  Intervals are profile-likelihood intervals
(ΔD ≤ φ·c·χ²₁(0.95), quasi-likelihood dispersion φ = max(1, D/dof), c the sandwich factor of
the fitted points' correlation for :data:`CORRELATED_TERMS` and the effects, else 1).

Short τ and the sensor's prefilter.  A rate series with autocovariance r(k) = 0 for k ≥ L (white
noise through an L-tap FIR such as the ADIS Bartlett filter, then sampled) has, for m ≥ L − 1,
exactly (sum of m samples and the covariance of adjacent sums, cf. IEEE Std 1139 / Allan 1966)

    σ²(mτ0) = τ0 S / τ − 3 τ0² Σₖ k r(k) / τ²,   S = r(0) + 2 Σₖ r(k)  (long-run variance)

i.e. the IEEE 952 random-walk term with N² = τ0 S plus a 1/τ² term whose sign is that of
−Σ k r(k): negative for a low-pass prefilter.  The quantisation column 3/τ² therefore may take
either sign (``prefilter=True``, as :func:`fit_noise_terms` fits: the better sign is kept); a
resolved negative term is reported as the prefilter's, not as Q, which is then unresolvable; an
unresolved one (0 in its interval) leaves Q a bound, profiled over the column's sign.  Below
m = L − 1 the shape is filter-specific, so the fit starts at the first octave τ that a
sequential deletion test (:func:`fit_start`) accepts.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from functools import partial
from typing import TYPE_CHECKING, Literal

import numba
import numpy as np
from scipy import optimize, special

from imupipe.model.effects import (
    gauss_markov_avar,
    oscillator_avar,
    prefilter_avar,
    sinusoid_avar,
)
from imupipe.stats.avar_covariance import avar_correlation
from imupipe.vocab import TERM_NAMES, TERM_UNITS, chi2_ppf_1dof

if TYPE_CHECKING:
    from imupipe.stats.allan import AllanCurve

_PLATEAU = 2.0 * np.log(2.0) / np.pi


def flicker_shape(tau: np.ndarray, cutoff_hz: float | np.ndarray = np.inf) -> np.ndarray:
    """AVAR of bias instability with B = 1 (IEEE 952-1997 Annex C): (2/π)·F(π f0 τ).

    ``cutoff_hz`` = ∞ gives the plateau 2 ln2 / π at every τ; ``tau`` and ``cutoff_hz``
    broadcast (e.g. (n_tau, 1) × (n_cutoff,) for a whole cut-off grid in one call).
    """
    tau, cutoff_hz = np.asarray(tau, dtype=float), np.asarray(cutoff_hz, dtype=float)
    if np.isinf(cutoff_hz).all():
        return np.full(np.broadcast_shapes(tau.shape, cutoff_hz.shape), _PLATEAU)
    x = np.pi * cutoff_hz * tau
    _, ci2 = special.sici(2 * x)
    _, ci4 = special.sici(4 * x)
    with np.errstate(divide="ignore", invalid="ignore"):
        exact = (
            np.log(2.0) - np.sin(x) ** 3 * (np.sin(x) + 4 * x * np.cos(x)) / (2 * x**2) + ci2 - ci4
        )
        small = x**2 / 2 - x**4 / 6  # series of ∫0^x sin⁴u/u³ du, avoids cancellation
    shape = (2.0 / np.pi) * np.where(x < 1e-2, small, exact)
    return np.where(np.isinf(cutoff_hz), _PLATEAU, shape)


@functools.lru_cache(maxsize=256)
def _flicker_table(tau_key: bytes, cutoff_key: bytes) -> np.ndarray:
    """:func:`flicker_shape` (n_tau, n_cutoff) of the float64 buffers ``tau_key`` and
    ``cutoff_key`` (read-only): one scipy.special.sici pass per τ grid and cut-off set, reused by
    every fit on that grid."""
    tau, cutoffs = np.frombuffer(tau_key), np.frombuffer(cutoff_key)
    table = flicker_shape(tau[:, None], cutoffs)
    table.flags.writeable = False
    return table


@functools.lru_cache(maxsize=256)
def _fit_points(
    tau_key: bytes, first: int, dense_from: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(:func:`fit_index`, :func:`evidence_weights`, :func:`design_columns`) of the float64
    buffer ``tau_key`` from index ``first`` (read-only): computed once per τ grid and fit start,
    reused by every :func:`fit_composite` on them (a real ADIS16405 unit's loops fit 11,141
    times on a few dozen; their Python loop, sort and column stacking held the GIL ~0.8 s)."""
    tau = np.frombuffer(tau_key)
    idx = fit_index(tau, first, dense_from)
    points = (idx, evidence_weights(tau, idx, dense_from), design_columns(tau))
    for a in points:
        a.flags.writeable = False
    return points


@functools.lru_cache(maxsize=64)  # a real ADIS16405 unit's analysis makes 44 (~100 kB each)
def _profile_designs(
    tau_key: bytes, first: int, dense_from: float, cutoff_key: bytes, signs: tuple[int, ...]
) -> np.ndarray:
    """The IEEE 952 columns at the fitted τ (:func:`_fit_points`) for every (sign of the 3/τ²
    column, flicker cut-off) of :func:`fit_composite`'s profile, signs outer: (n_sign ·
    n_cutoff, n_fit, 5), read-only; each fit adds its own extra columns to a copy."""
    idx, _, columns = _fit_points(tau_key, first, dense_from)
    flicker = _flicker_table(tau_key, cutoff_key)
    n_cutoff = flicker.shape[1]
    designs = np.repeat(columns[idx][None], len(signs) * n_cutoff, axis=0)
    designs[:, :, 0] *= np.repeat(signs, n_cutoff)[:, None]
    designs[:, :, 2] = np.tile(flicker[idx].T, (len(signs), 1))
    designs.flags.writeable = False
    return designs


@functools.lru_cache(maxsize=256)
def _cutoff_grid(tau_key: bytes) -> np.ndarray:
    """:func:`cutoff_grid` of the float64 buffer ``tau_key``, read-only."""
    grid = cutoff_grid(np.frombuffer(tau_key))
    grid.flags.writeable = False
    return grid


def design_columns(tau: np.ndarray, cutoff_hz: float = np.inf) -> np.ndarray:
    """Columns (n_tau, 5) of the AVAR model per unit squared coefficient (Q², N², B², K², R²)."""
    tau = np.asarray(tau, dtype=float)
    return np.column_stack(
        [3.0 / tau**2, 1.0 / tau, flicker_shape(tau, cutoff_hz), tau / 3.0, tau**2 / 2.0]
    )


def avar_model(
    tau: np.ndarray,
    quantization: float = 0.0,
    random_walk: float = 0.0,
    bias_instability: float = 0.0,
    rate_random_walk: float = 0.0,
    rate_ramp: float = 0.0,
    cutoff_hz: float = np.inf,
) -> np.ndarray:
    """IEEE 952 composite Allan variance (u²) at ``tau`` (s); term units as in the module doc."""
    coef = np.array([quantization, random_walk, bias_instability, rate_random_walk, rate_ramp])
    return design_columns(tau, cutoff_hz) @ coef**2


def gamma_deviance(avar: np.ndarray, model: np.ndarray, edf: np.ndarray) -> np.ndarray:
    """Per-point gamma deviance ν (â/a − ln(â/a) − 1) of AVAR estimates ``avar`` vs ``model``."""
    ratio = avar / model
    return edf * (ratio - np.log(ratio) - 1.0)


def octave_index(tau: np.ndarray) -> np.ndarray:
    """Indices of an octave-spaced subset of the increasing ``tau`` grid (ratio ≥ 2)."""
    keep = [0]
    for i in range(1, len(tau)):
        if tau[i] >= 2.0 * tau[keep[-1]] * (1 - 1e-9):
            keep.append(i)
    return np.asarray(keep)


LONG_TAU_OCTAVES = 2.0
"""A curve beyond Stable32's T/4 (the analysis' fit curve reaches T/2, ``FIT_MIN_TERMS`` of
:mod:`imupipe.stats.allan`) is fitted at every τ of its last this many octaves: from T/8."""


def long_tau_start(curve: AllanCurve) -> float:
    """τ (s) from which the fit reads every τ of ``curve`` (:func:`fit_index`): T/8 when the
    curve reaches beyond T/4 — its last τ holds fewer than 45 % of the first τ's terms (N − 2m
    against N − 2: m > 0.275 N) — else ∞ (octave points only, the fit of a T/4 curve)."""
    terms = np.asarray(curve.n_terms, dtype=float)
    if terms.size < 2 or terms[-1] >= 0.45 * terms[0]:
        return np.inf
    return float(curve.tau_s[-1]) / 2.0**LONG_TAU_OCTAVES


def fit_index(tau: np.ndarray, first: int = 0, dense_from: float = np.inf) -> np.ndarray:
    """Indices of the fitted τ from index ``first``: the octave-spaced subset, and every τ ≥
    ``dense_from`` (s; :func:`long_tau_start`).

    At short τ the overlapping-AVAR points of a dense grid are strongly correlated and have
    large edf, so the octave subset keeps the evidence honest.  At the long end the rate random
    walk K and the rate ramp R live: a ramp is a slope +1 rise of the ADEV over the longest τ,
    which one or two octave points (where they happen to fall) barely show.  There every τ up
    to T/2 is fitted, each weighted by its own Greenhall edf in the gamma deviance — a τ with
    edf ~1 (T/2) counts little (issue 13, item 6)."""
    idx = first + octave_index(tau[first:])
    tail = np.flatnonzero(tau >= dense_from * (1 - 1e-9))
    return np.union1d(idx, tail[tail >= first])


def evidence_weights(tau: np.ndarray, idx: np.ndarray, dense_from: float) -> np.ndarray:
    """Weight of each fitted τ's deviance (``idx`` from :func:`fit_index`): 1 on the octave
    subset; in the dense tail (τ ≥ ``dense_from``) the share of an octave each τ spans,
    log2(τ_i / τ_(i-1)) (0.33 on a grid of 10 a decade), so that an octave of the tail weighs
    what one octave point weighs.  Neighbouring overlapping-AVAR estimates are strongly
    correlated; counted as independent, the tail's few averages gave the long-τ terms
    intervals far too narrow (the paper's accelerometer noise with K on its plateau at T/2, 60
    records of 2.9 h: the 95 % upper bound of an unresolved K below the truth on 18/60 with
    every τ at full weight, 3/60 with these weights, 3/60 on octave points only)."""
    w = np.ones(idx.size)
    tail = (tau[idx] >= dense_from * (1 - 1e-9)) & (idx > 0)
    j = idx[tail]
    w[tail] = np.minimum(np.log2(tau[j] / tau[j - 1]), 1.0)
    return w


@numba.njit(cache=True, nogil=True)
def _passive_lstsq(
    a: np.ndarray, b: np.ndarray, passive: np.ndarray
) -> np.ndarray:  # pragma: no cover (JIT)
    """Least-squares solution of a[:, passive] z = b by Householder QR (Golub & Van Loan,
    *Matrix Computations*, alg. 5.3.2), zero outside ``passive``; a column numerically dependent
    on the earlier ones (|r_kk| ≤ 1e-13 ‖a_k‖), or beyond the m-th of m rows, gets z = 0.  (Before
    session 41 more passive columns than rows read r_kk outside the array: no bounds check in
    compiled code, a garbage solution of ~1e304 now and then.)"""
    m, n = a.shape
    cols = np.empty(n, dtype=np.int64)
    k = 0
    for j in range(n):
        if passive[j]:
            cols[k] = j
            k += 1
    rt = np.empty((k + 1, m))  # transposed columns (rows contiguous), then b
    size = np.zeros(k)
    for c in range(k):
        for i in range(m):
            rt[c, i] = a[i, cols[c]]
            size[c] += rt[c, i] ** 2
    for i in range(m):  # element by element, not slice assignments: see imupipe.jit
        rt[k, i] = b[i]
    v = np.empty(m)
    for c in range(k):
        norm = 0.0
        for i in range(c, m):
            norm += rt[c, i] ** 2
        norm = np.sqrt(norm)
        if norm == 0.0:
            continue
        for i in range(m - c):
            v[i] = rt[c, c + i]
        v[0] += norm if v[0] >= 0 else -norm
        vnorm = 0.0
        for i in range(m - c):
            vnorm += v[i] ** 2
        vnorm = np.sqrt(vnorm)
        for i in range(m - c):
            v[i] /= vnorm
        for cc in range(c, k + 1):  # reflect the remaining columns and b
            proj = 0.0
            for i in range(m - c):
                proj += v[i] * rt[cc, c + i]
            for i in range(m - c):
                rt[cc, c + i] -= 2.0 * proj * v[i]
    z = np.zeros(n)
    for c in range(min(k, m) - 1, -1, -1):  # columns beyond the m-th: dependent, z = 0
        if abs(rt[c, c]) > 1e-13 * np.sqrt(size[c]):
            acc = rt[k, c]
            for cc in range(c + 1, k):
                acc -= rt[cc, c] * z[cols[cc]]
            z[cols[c]] = acc / rt[c, c]
    return z


@numba.njit(cache=True, nogil=True)
def _gradient(a: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:  # pragma: no cover (JIT)
    """aᵀ(b − a x): the negative gradient of ½‖a x − b‖², the dual vector of the NNLS KKT
    conditions (loops: no BLAS call overhead on these tiny systems)."""
    m, n = a.shape
    w = np.zeros(n)
    for i in range(m):
        r = b[i]
        for k in range(n):
            r -= a[i, k] * x[k]
        for k in range(n):
            w[k] += a[i, k] * r
    return w


@numba.njit(cache=True, nogil=True)
def _nnls(
    a: np.ndarray, b: np.ndarray, maxiter: int, guess: np.ndarray
) -> np.ndarray:  # pragma: no cover (JIT)
    """argmin ‖a x − b‖₂ over x ≥ 0: the active-set algorithm NNLS of Lawson & Hanson, *Solving
    Least Squares Problems* (1974), ch. 23 — the algorithm of ``scipy.optimize.nnls``, compiled
    for the tiny (n_tau ≲ 30, p ≲ 8) systems of the IRLS (no per-call Python overhead).

    ``guess``: a candidate set of positive coefficients (the previous IRLS iteration's).  If the
    least-squares solution on it is positive and satisfies the KKT conditions (no other column
    with gradient above the tolerance: LH's own stopping rule) it is the solution — the same
    point LH reaches, in one solve instead of one per column; otherwise LH runs from x = 0.
    """
    m, n = a.shape
    tol = 0.0
    any_guess = False
    for k in range(n):
        column = 0.0
        for i in range(m):
            column += abs(a[i, k])
        tol = max(tol, column)
        any_guess = any_guess or guess[k]
    tol *= 10.0 * 2.220446049250313e-16 * max(m, n)
    if any_guess:
        z = _passive_lstsq(a, b, guess)
        w = _gradient(a, b, z)
        optimal = True
        for k in range(n):
            if (guess[k] and z[k] <= 0) or (not guess[k] and w[k] > tol):
                optimal = False
        if optimal:
            return z
    x = np.zeros(n)
    passive = np.zeros(n, dtype=np.bool_)
    for _ in range(maxiter):
        w = _gradient(a, b, x)
        blocked = np.empty(n, dtype=np.bool_)
        for k in range(n):
            blocked[k] = passive[k]
        z = x
        while True:  # the most promising free column whose unconstrained solve stays positive
            j, top = -1, tol
            for k in range(n):
                if not blocked[k] and w[k] > top:
                    j, top = k, w[k]
            if j < 0:
                return x
            passive[j] = True
            z = _passive_lstsq(a, b, passive)
            if z[j] > 0:
                break
            passive[j] = False
            blocked[j] = True
        while True:  # move towards z until feasible, dropping columns that reach zero
            alpha, stop = np.inf, -1
            for k in range(n):
                if passive[k] and z[k] <= 0 and x[k] / (x[k] - z[k]) < alpha:
                    alpha, stop = x[k] / (x[k] - z[k]), k
            if stop < 0:
                break
            moved = np.empty(n)
            for k in range(n):
                moved[k] = x[k] + alpha * (z[k] - x[k])
            x = moved
            x[stop] = 0.0
            for k in range(n):
                if passive[k] and x[k] <= 0:
                    passive[k] = False
                    x[k] = 0.0
            z = _passive_lstsq(a, b, passive)
        x = z
    return x


@numba.njit(cache=True, nogil=True)
def _deviance(
    avar: np.ndarray, model: np.ndarray, edf: np.ndarray
) -> float:  # pragma: no cover (JIT)
    """Σ :func:`gamma_deviance` in one compiled pass."""
    total = 0.0
    for i in range(avar.size):
        ratio = avar[i] / model[i]
        total += edf[i] * (ratio - np.log(ratio) - 1.0)
    return total


@numba.njit(cache=True, nogil=True)
def _fit_gamma(
    design: np.ndarray, avar: np.ndarray, edf: np.ndarray, offset: np.ndarray, start: np.ndarray
) -> tuple[np.ndarray, float]:  # pragma: no cover (JIT)
    """:func:`fit_nonneg_gamma` compiled: Fisher scoring on unit-norm columns, from ``start``
    (all zero: from nothing, the first step taken whatever its deviance).  Written in loops
    rather than numpy functions, which compile with each kernel that uses them (``avar.max()``
    ~1 s of CPU on a first run); the model's ``xs @ coef`` stays a BLAS product, whose rounding
    the fits' results are pinned to."""
    n, p = design.shape
    scale = np.zeros(p)
    for i in range(n):  # row by row, as numpy's reduction over axis 0
        for k in range(p):
            scale[k] += design[i, k] ** 2
    for k in range(p):
        scale[k] = np.sqrt(scale[k]) if scale[k] > 0 else 1.0
    xs = np.empty((n, p))
    for i in range(n):
        for k in range(p):
            xs[i, k] = design[i, k] / scale[k]
    top = avar[0]
    for i in range(n):
        top = max(top, avar[i])
    floor = 1e-12 * top
    mu = np.empty(n)
    target = np.empty(n)
    for i in range(n):
        mu[i] = avar[i]
        target[i] = avar[i] - offset[i]
    coef = np.empty(p)
    warm = False
    for k in range(p):
        coef[k] = start[k] * scale[k]
        warm = warm or start[k] > 0
    dev = np.inf
    if warm:  # a warm start: no step may leave it for a worse deviance
        mu = np.maximum(offset + xs @ coef, floor)
        dev = _deviance(avar, mu, edf)
    weighted = np.empty((n, p))
    rhs = np.empty(n)
    positive = np.empty(p, dtype=np.bool_)
    step = np.empty(p)
    new, trial, mu_t, dev_t = coef, coef, mu, dev
    for _ in range(100):
        for i in range(n):
            w = np.sqrt(edf[i]) / mu[i]
            rhs[i] = target[i] * w
            for k in range(p):
                weighted[i, k] = xs[i, k] * w
        for k in range(p):
            positive[k] = new[k] > 0
        new = _nnls(weighted, rhs, 50 * p, positive)
        for k in range(p):
            step[k] = new[k] - coef[k]
        for _ in range(30):
            trial = np.empty(p)
            for k in range(p):
                trial[k] = coef[k] + step[k]
            mu_t = np.maximum(offset + xs @ trial, floor)
            dev_t = _deviance(avar, mu_t, edf)
            if dev_t <= dev or not np.isfinite(dev):
                break
            for k in range(p):
                step[k] /= 2
        converged = np.isfinite(dev) and dev - dev_t <= 1e-10 * max(dev_t, 1.0)
        coef, mu, dev = trial, mu_t, dev_t
        if converged:
            break
    out = np.empty(p)
    for k in range(p):
        out[k] = coef[k] / scale[k]
    return out, dev


def _fit_designs(
    designs: np.ndarray, avar: np.ndarray, edf: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_nonneg_gamma` of every design (n_fit, n_tau, p) to the same data, from zero:
    the cut-off × sign profile of :func:`fit_composite`.  A loop here, not a kernel: a kernel
    calling :func:`_fit_gamma` would compile (re-optimise) the whole fit once more, ~2 s of CPU
    on a first run, to save one Python call per design (a few µs against ~17 µs of fitting)."""
    offset = np.zeros(avar.size)
    start = np.zeros(designs.shape[2])
    fits = [_fit_gamma(design, avar, edf, offset, start) for design in designs]
    return np.array([coef for coef, _ in fits]), np.array([dev for _, dev in fits])


def fit_nonneg_gamma(
    design: np.ndarray,
    avar: np.ndarray,
    edf: np.ndarray,
    offset: np.ndarray | float = 0.0,
    start: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Minimise the gamma deviance of ``avar`` ~ offset + design @ c over c ≥ 0.

    Fisher scoring for the identity link is a weighted NNLS with weights ν/μ² (IRLS) — one
    small solve per iteration — with step halving so the deviance never increases.  ``start``
    (c ≥ 0): begin there instead of at 0 — the deviance is not convex in c, and from 0 a first
    step that drives the model to its floor at a null of an offset column (a sinusoid's AVAR
    vanishes at τ = k/f) can leave the iteration stuck far from the optimum.
    Returns (c, deviance).
    """
    # writable C-contiguous copies (tiny): the arrays' types of _fit_designs' call, so that
    # _fit_gamma compiles once whoever calls it
    design, avar, edf = (np.array(a, dtype=float, order="C") for a in (design, avar, edf))
    offset_at = np.empty(avar.shape)
    offset_at[...] = offset  # a scalar or per-τ offset, broadcast into its own array
    start = np.zeros(design.shape[1]) if start is None else np.array(start, dtype=float)
    coef, dev = _fit_gamma(design, avar, edf, offset_at, start)
    return coef, float(dev)


@dataclass(frozen=True)
class CompositeFit:
    """Gamma-deviance fit of the composite AVAR model on the octave subset of a τ grid (and its
    dense tail, each τ weighted by :func:`evidence_weights`)."""

    names: tuple[str, ...]
    coef: np.ndarray  # non-negative coefficients of ``design`` columns (AVAR units)
    design: np.ndarray  # (n_tau, p) columns at every τ of the curve
    fit_index: np.ndarray  # τ indices used in the fit
    deviance: float
    dof: int  # fitted points − parameters (each point counted once, whatever its weight)
    cutoff_hz: float  # flicker cut-off f0 of the bias-instability column
    short_sign: int = 1  # sign of the 3/τ² column: +1 quantisation, −1 prefilter correlation
    weight: np.ndarray | None = None  # evidence weight per fit_index (None: all 1)
    # this fit holds the rate ramp R at 0 (its design column zero); R's bound is read from
    # the fit with R free, kept here (:func:`release_rate_ramp`)
    rate_ramp_fit: CompositeFit | None = None

    @property
    def with_rate_ramp(self) -> CompositeFit:
        """This fit with R free: itself, or the fit it holds R at 0 against."""
        return self if self.rate_ramp_fit is None else self.rate_ramp_fit

    def nu(self, edf: np.ndarray) -> np.ndarray:
        """The gamma shapes ×2 the fit gives its points: ``edf`` at fit_index × weight."""
        nu = np.asarray(edf, dtype=float)[self.fit_index]
        return nu if self.weight is None else nu * self.weight

    @property
    def tau_range(self) -> tuple[float, float]:
        """Smallest and largest τ (s) of the fitted points (column 1 of the design is 1/τ)."""
        inv_tau = self.design[self.fit_index, 1]
        return float(1.0 / inv_tau.max()), float(1.0 / inv_tau.min())

    @property
    def p_value(self) -> float:
        """P(χ²_dof ≥ D): goodness of fit of the model over the fitted points."""
        return float(special.chdtrc(self.dof, self.deviance))  # scipy.stats.chi2.sf

    @property
    def dispersion(self) -> float:
        """Quasi-likelihood dispersion φ = max(1, D/dof)."""
        return max(1.0, self.deviance / max(self.dof, 1))

    def avar(self) -> np.ndarray:
        """Model AVAR at every τ of the curve; NaN where it is not positive — below the fitted
        range, where the signed prefilter term −P/τ² outgrows the others (at 819.2 SPS: the two
        shortest τ), the model does not apply and has no deviation or residual."""
        model = self.design @ self.coef
        return np.where(model > 0, model, np.nan)

    def sandwich_factor(self, edf: np.ndarray, correlation: np.ndarray, j: int) -> float:
        """c_j = (H⁻¹ J H⁻¹)_jj / (H⁻¹)_jj: how much larger the variance of coefficient ``j``
        is than the fit's deviance assumes, its fitted points being correlated by
        ``correlation`` (ρ of the AVAR estimates at ``fit_index``,
        :func:`fit_correlation`) rather than independent.

        The fit maximises the independence (working) likelihood of gamma points with shapes
        ν_i/2 (:meth:`nu`); its score s = Σ ν_i (â_i − μ_i) x_i / (2 μ_i²) has Fisher matrix
        H = ½ Σ ν_i u_i u_iᵀ (u_i = x_i / μ_i) and, with Var â_i = 2 μ_i² / edf_i and
        correlations ρ, variance J = ½ Σ_ik ν_i ν_k ρ_ik u_i u_kᵀ / √(edf_i edf_k) (= H when
        ρ = I and every weight is 1).  The profile deviance difference of a scalar parameter
        divided by c_j is again ~ χ²₁ (the moment-matched adjustment of the independence
        likelihood: Rotnitzky & Jewell 1990; Chandler & Bate 2007, Biometrika 94(1) §3.4).
        H and J are taken on the fit's positive coefficients and ``j``; 1 when H is
        singular (or so ill-conditioned that c is not a positive number)."""
        idx = self.fit_index
        active = self.coef > 0
        active[j] = True
        model = np.maximum(self.design[idx] @ self.coef, 1e-300)
        u = self.design[idx][:, active] / model[:, None]
        u = u / np.maximum(np.linalg.norm(u, axis=0), 1e-300)  # c_j is scale-free
        nu, e = self.nu(edf), np.asarray(edf, dtype=float)[idx]
        fisher = 0.5 * (u.T * nu) @ u
        v = nu[:, None] * u
        score_var = 0.5 * v.T @ (np.asarray(correlation) / np.sqrt(np.outer(e, e))) @ v
        k = int(np.count_nonzero(active[:j]))
        try:
            naive = np.linalg.inv(fisher)
        except np.linalg.LinAlgError:
            return 1.0
        factor = float((naive @ score_var @ naive)[k, k] / naive[k, k])
        return factor if np.isfinite(factor) and factor > 0 else 1.0

    def deviance_scale(self, edf: np.ndarray, j: int, correlation: np.ndarray | None) -> float:
        """φ·c_j, the unit of coefficient ``j``'s profile deviance: φ the dispersion, c_j the
        :meth:`sandwich_factor` of the fitted points' ``correlation`` (1 without one)."""
        adjust = 1.0 if correlation is None else self.sandwich_factor(edf, correlation, j)
        return self.dispersion * adjust

    def interval_within(
        self,
        avar: np.ndarray,
        edf: np.ndarray,
        j: int,
        room: float,
        correlation: np.ndarray | None = None,
        known: tuple[float, float] | None = None,
    ) -> tuple[float, float]:
        """The :meth:`profile_interval` of coefficient ``j`` whose deviance may rise by ``room``
        (deviance units) over this fit's: at the level whose φ·c_j·χ²₁ is ``room`` (at least
        1e-9) — a fit at another non-linear shape, which has used part of the room already.
        ``known``: see :meth:`profile_interval`."""
        scale = self.deviance_scale(edf, j, correlation)
        level = float(special.gammainc(0.5, room / scale / 2))  # χ²₁'s cdf
        return self.profile_interval(avar, edf, j, max(level, 1e-9), correlation, known)

    def as_quantization(self, avar: np.ndarray, edf: np.ndarray) -> CompositeFit:
        """This fit with its 3/τ² column read as quantisation (sign +1) and refitted at the
        same flicker cut-off and effect shapes: the fit a Q bound is profiled in when the
        column fits best negative but not significantly (:func:`terms_from_fit`)."""
        if self.short_sign > 0:
            return self
        design = self.design.copy()
        design[:, 0] = -design[:, 0]
        start = self.coef.copy()
        start[0] = 0.0
        coef, deviance = fit_nonneg_gamma(
            design[self.fit_index], avar[self.fit_index], self.nu(edf), 0.0, start
        )
        return replace(self, coef=coef, design=design, deviance=deviance, short_sign=1)

    def profile_interval(
        self,
        avar: np.ndarray,
        edf: np.ndarray,
        j: int,
        level: float = 0.95,
        correlation: np.ndarray | None = None,
        known: tuple[float, float] | None = None,
    ) -> tuple[float, float]:
        """Profile-likelihood interval (lo, hi) of coefficient ``j`` (lo = 0: not resolved;
        hi = inf: the deviance never rises past the limit, the data do not bound it).  The
        deviance may rise by φ·c_j·χ²₁(level): φ the dispersion, c_j the
        :meth:`sandwich_factor` of the fitted points' ``correlation`` (1 without one).

        ``known``: an interval (lo > 0) this one is to be united with
        (:func:`over_alternatives`).  An end of it that lies beyond this fit's coefficient and
        where the deviance is already past the limit holds this interval's end on its side
        (the deviance crosses the limit between them): that end is returned as it is, one
        refit instead of the walk to the crossing."""
        idx = self.fit_index
        x, a, nu = self.design[idx], avar[idx], self.nu(edf)
        others = np.delete(x, j, axis=1)
        at_best = np.delete(self.coef, j)
        limit = self.deviance_scale(edf, j, correlation) * chi2_ppf_1dof(level)
        solved: list[tuple[float, np.ndarray]] = [(float(self.coef[j]), at_best)]

        def excess(c: float) -> float:
            # The profile deviance is the least over the other coefficients, and the gamma
            # deviance is not convex in them: a fit from one start can stop on a higher branch
            # or stall at the model's floor (deviance ~1e12), and the interval would end
            # there, too short.  So each profile fit starts both from the fit's optimum and
            # from the solution at the nearest c solved so far (a continuation along the
            # profile), and the lesser deviance counts.
            nearest = min(solved, key=lambda done: abs(done[0] - c))[1]
            starts = (at_best,) if nearest is at_best else (at_best, nearest)
            with np.errstate(invalid="ignore"):  # c = inf on an all-zero column: no bound
                offset = c * x[:, j]
            coef, dev = min(
                (fit_nonneg_gamma(others, a, nu, offset, start) for start in starts),
                key=lambda fit: fit[1],
            )
            solved.append((c, coef))
            return dev - self.deviance - limit

        best = float(self.coef[j])
        known_lo, known_hi = known or (np.nan, np.nan)

        def crossing(a: float, b: float, xtol: float) -> float | None:
            """The limit's crossing between the walk's last c within it and its first past
            it (``a``, ``b`` in either order); ``None`` when the one past it, fitted again
            from its own solution (brentq evaluates the ends anew), lies within the limit
            after all: the walk goes on.  Measured on a 2 h recording of the independent
            generator with a strong sinusoid and its third harmonic, where brentq raised
            "f(a) and f(b) must have different signs" (an internal error, exit 1)."""
            try:
                return optimize.brentq(excess, a, b, xtol=xtol, rtol=1e-6)
            except ValueError:
                return None

        # Each end is bracketed by walking away from the fit in steps, so that every fit has
        # a near neighbour to continue from, up to the first c past the limit; brentq then
        # solves inside that step.
        lo = 0.0
        inner = best
        if 0 < known_lo <= best and excess(known_lo) > 0:
            lo = known_lo
        for c in best * np.linspace(0.9, 0.0, 10) if best > 0 and not lo else ():
            if excess(c) > 0:  # a coefficient at its bound 0 has lo = 0
                root = crossing(c, inner, 1e-6 * best)
                if root is not None:
                    lo = root
                    break
            inner = c
        # upper end: 10 % steps up to 4x the fit (or from a tiny fraction of the data's
        # level), doubling beyond, until the deviance rises past the limit
        if best <= known_hi < np.inf and excess(known_hi) > 0:
            return lo, known_hi
        with np.errstate(over="ignore"):  # an all-zero column: inf, the search finds no end
            tiny = 1e-6 * float(np.min(a / np.maximum(np.abs(x[:, j]), 1e-300)))
        inner, c = best, max(1.1 * best, tiny)
        for _ in range(400):
            if excess(c) > 0:
                root = crossing(inner, c, 1e-6 * c)
                if root is not None:
                    return lo, root
            if not np.isfinite(2.0 * c):  # the data do not bound it (e.g. a null column)
                break
            inner, c = c, c * (1.1 if c < 4.0 * best else 2.0)
        return lo, np.inf


CORRELATED_TERMS = ("quantization", "random_walk", "bias_instability", "rate_random_walk")
"""The IEEE 952 terms whose interval :func:`terms_from_fit` widens for the correlation of the
fitted τ points (:meth:`CompositeFit.sandwich_factor`), as do the loop's AVAR effects.  Measured
(session 14, docs/validation.md): on the paper's gyro noise N's 95 % interval held the truth on
81 % of 200 records of 43 min without it, 93.5 % with it (white noise, 12 h: 85 % → 97.5 %), B's
on 87 % → 95 %.  K since session 28, with R held at 0 unless the data ask for it
(:func:`release_rate_ramp`): on 60 records of 12 h where K shows (``benchmarks/interval_coverage.py
k_coverage``) the truth lay above the upper end of K's 68 % interval on 52 % of records with R
free and no factor, on 33 % with R held unless significant and the factor (95 %: 17 → 7 %; on
records of the independent generator, R always held: 33 % without the factor, 17 % with it).
Where K is mostly unresolved (4 h records) nothing changed (47 %): there the flicker cut-off's
profile lets B's column take the tail's rise (docs/validation.md, session 28).  R is read from the
long-τ tail's evidence weights (:func:`evidence_weights`), set for the tail's correlation on
measured coverage; the factor only widened its interval (a size-3 ramp resolved on 2 of 60
records instead of 17, none falsely on 60 clean records either way), so R keeps the weighted
likelihood's interval.  Where the fit holds K at 0 (hidden under B) its bound keeps the weighted
likelihood's too (:func:`interval_correlation`; the factor is a local correction of the
likelihood's curvature, for a coefficient inside its range): on 60 records of the paper's
accel_z noise with K's AVAR at T/2 on the flicker plateau (2.9 h at 100 Hz) K's bound lay above
the truth on 60 of 60 with R free and no factor (median 2.33 × the truth), with the factor on
every K 60 of 60 (3.07 ×), on K above 0 only 60 of 60 (3.03 ×; lowest decile 1.88 → 1.33 ×)."""


def interval_correlation(fit: CompositeFit, j: int, rho: np.ndarray | None) -> np.ndarray | None:
    """The correlation ``rho`` of the fitted points (:func:`fit_correlation`) that term ``j``'s
    interval accounts for: for :data:`CORRELATED_TERMS`, except K where the fit holds it at 0
    (its bound then the weighted likelihood's), else None (points counted as independent)."""
    if TERM_NAMES[j] not in CORRELATED_TERMS or (j == 3 and fit.coef[j] <= 0):
        return None
    return rho


def fit_correlation(fit: CompositeFit, tau0_s: float, n_terms: np.ndarray) -> np.ndarray:
    """Correlation of the AVAR estimates at ``fit.fit_index`` under the fitted noise
    (:func:`imupipe.stats.avar_covariance.avar_correlation` of the fit's Q², N², B², K²;
    ``n_terms`` the curve's terms per τ, ``tau0_s`` its sample interval).  A negative 1/τ²
    column (the prefilter's correlation, not a noise) and the flicker cut-off are left out:
    the white and flicker parts it adjusts dominate every τ it touches."""
    idx = fit.fit_index
    tau = 1.0 / fit.design[idx, 1]
    m = np.maximum(np.rint(tau / tau0_s), 1).astype(np.int64)
    q2 = float(fit.coef[0]) if fit.short_sign > 0 else 0.0
    coef = (q2, float(fit.coef[1]), float(fit.coef[2]), float(fit.coef[3]))
    return avar_correlation(m, np.asarray(n_terms)[idx], tau0_s, coef)


def cutoff_grid(tau: np.ndarray) -> np.ndarray:
    """Flicker cut-off frequencies f0 (Hz) worth trying: where F(π f0 τ) changes within the grid."""
    return np.concatenate([np.geomspace(0.05 / tau[-1], 10.0 / tau[0], 25), [np.inf]])


def avar_upper(avar: np.ndarray, edf: np.ndarray, level: float = 0.95) -> np.ndarray:
    """Upper end of the two-sided ``level`` chi-square interval of AVAR estimates ``avar`` with
    ``edf`` degrees of freedom: avar·ν/χ²_ν((1 − level)/2) (u²; NaN where ν is unknown).  The
    bound every noise term's asymptote is held below (:func:`asymptote_caps`,
    :func:`flicker_limit`): a 95 % bound, not the curve's 68.3 % error bars, since the lowest of
    some 50 correlated points is compared."""
    nu = np.asarray(edf, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.asarray(avar, dtype=float) * nu / special.chdtri(nu, 0.5 + level / 2)


def flicker_limit(avar_hi: np.ndarray) -> float:
    """Largest B² (u²) whose plateau (2 ln2/π) B² stays below the lowest upper confidence
    bound ``avar_hi`` of the measured AVAR (non-finite bounds ignored)."""
    hi = np.asarray(avar_hi, dtype=float)
    hi = hi[np.isfinite(hi)]
    return float(hi.min() / _PLATEAU) if hi.size else np.inf


def asymptote_caps(tau: np.ndarray, avar_hi: np.ndarray, tau_min: float) -> np.ndarray:
    """Per IEEE 952 term, the largest squared coefficient (Q², N², B², K², R²) whose own
    asymptote (Annex C: 3Q²/τ², N²/τ, the plateau (2 ln2/π) B², K²τ/3, R²τ²/2) stays at or
    below the measured AVAR's upper confidence bound ``avar_hi`` at every τ ≥ ``tau_min`` (s):
    a noise term cannot exceed the measured deviation anywhere in the model's range."""
    tau, hi = np.asarray(tau, dtype=float), np.asarray(avar_hi, dtype=float)
    keep = (tau >= tau_min * (1 - 1e-9)) & np.isfinite(hi)
    if not keep.any():
        return np.full(len(TERM_NAMES), np.inf)
    return np.min(hi[keep, None] / design_columns(tau[keep]), axis=0)


ADEQUATE_P = 0.001
"""Goodness-of-fit p-value below which a fit is rejected on its range (:func:`_adequacy`)."""


def fit_composite(
    tau: np.ndarray,
    avar: np.ndarray,
    edf: np.ndarray,
    extra: dict[str, np.ndarray] | None = None,
    cutoff_hz: float | None = None,
    n_nonlinear: int = 0,
    tau_min: float = 0.0,
    prefilter: bool = False,
    flicker_max: float = np.inf,
    dense_from: float = np.inf,
    rate_ramp: bool = True,
) -> CompositeFit:
    """Fit the IEEE 952 model (+ ``extra`` AVAR columns) on octave-spaced τ ≥ ``tau_min`` (s)
    and every τ ≥ ``dense_from`` (s, :func:`fit_index`); ``rate_ramp=False`` holds R at 0 (its
    column zero, one parameter fewer: :func:`release_rate_ramp`).

    The flicker cut-off f0 is profiled over :func:`cutoff_grid` unless given; with
    ``prefilter`` also the sign of the 3/τ² column over ±1 (quantisation or the prefilter's
    correlation, module doc).  ``n_nonlinear`` counts nonlinear parameters of the extra
    columns (for the degrees of freedom).  ``flicker_max`` (u²) bounds B² over that profile:
    with a low cut-off the flicker column is small on the grid and B may grow without bound
    while contributing little; a B whose plateau 0.664 B lies above the measured curve
    (:func:`flicker_limit`) is physically impossible, so such (f0, sign) fits are passed over
    while a possible one exists — unless the free fit is adequate (p ≥ :data:`ADEQUATE_P`): its
    B then agrees with the curve and the lowest points dipped by chance.
    """
    extra = extra or {}
    tau = np.ascontiguousarray(tau, dtype=float)
    first = int(np.searchsorted(tau, tau_min * (1 - 1e-9)))
    tau_key = tau.tobytes()
    idx, weight, columns = _fit_points(tau_key, first, float(dense_from))
    names = TERM_NAMES + tuple(extra)
    grid = _cutoff_grid(tau_key) if cutoff_hz is None else np.array([cutoff_hz], dtype=float)
    flicker = _flicker_table(tau_key, grid.tobytes())
    base = np.column_stack([columns, *extra.values()])
    base[:, 4] *= rate_ramp
    signs = (1, -1) if prefilter else (1,)
    profiled = _profile_designs(tau_key, first, float(dense_from), grid.tobytes(), signs)
    designs = np.empty((*profiled.shape[:2], base.shape[1]))
    designs[:, :, :4] = profiled[:, :, :4]  # Q, N, B, K by sign and cut-off; R and the extras
    designs[:, :, 4:] = base[idx, 4:]
    a = np.ascontiguousarray(avar[idx], dtype=float)
    coefs, devs = _fit_designs(designs, a, np.ascontiguousarray(edf[idx] * weight, dtype=float))

    def composite(k: int) -> CompositeFit:
        sign, f0 = signs[k // len(grid)], grid[k % len(grid)]
        design = base.copy()
        design[:, 0] *= sign
        design[:, 2] = flicker[:, k % len(grid)]
        n_par = design.shape[1] - (not rate_ramp) + n_nonlinear
        n_par += cutoff_hz is None and np.isfinite(f0)
        dof = max(len(idx) - int(n_par), 1)
        return CompositeFit(
            names, coefs[k], design, idx, float(devs[k]), dof, float(f0), sign, weight
        )

    def lowest(ks: np.ndarray | None = None) -> int:  # the first of the least deviances (1e-9)
        among = devs if ks is None else devs[ks]
        at = int(np.argmax(among < among.min() + 1e-9))
        return at if ks is None else int(ks[at])

    best = composite(lowest())
    if best.coef[2] <= flicker_max:
        return best
    possible = np.flatnonzero(coefs[:, 2] <= flicker_max)
    if not possible.size:
        return best
    # an adequate free fit keeps its B: a clean record whose correlated long-τ points dip by
    # chance under the plateau (measured: the default 12 h simulation's accel_z, capped to 55 %
    # of its true B with K inflated 30-fold and D/dof 240) is no impossible model; a misfit
    # that inflates B (an unmodelled effect) is rejected and loses it
    return best if best.p_value >= ADEQUATE_P else composite(lowest(possible))


RATE_RAMP_LEVEL = 0.05
"""Level of the likelihood-ratio test that releases the rate ramp R in a reported fit
(:func:`release_rate_ramp`)."""


def release_rate_ramp(free: CompositeFit, held: CompositeFit) -> CompositeFit:
    """The fit to report: ``free`` (R fitted) where the data ask for R, else ``held`` (the same
    fit with R held at 0, ``fit_composite(..., rate_ramp=False)``) carrying ``free`` for R's bound.

    R asks for itself when the deviance falls by more than φ·χ²₁(1 − 2·:data:`RATE_RAMP_LEVEL`)
    (R ≥ 0 sits on its boundary under the null: ΔD ~ ½χ²₀ + ½χ²₁, Self & Liang 1987, JASA 82,
    605; φ the free fit's dispersion).  Left free, R takes the last τ points' chance rise and K
    loses it: measured on 60 records of white, flicker and rate random walk noise (12 h at
    100 Hz, K's AVAR at T/2 ten times the flicker plateau; ``benchmarks/interval_coverage.py
    k_coverage``) K came out at a median 0.61 of the truth and above the upper end of its 68 %
    interval on 52 % of records instead of 16 %; with R released by this test (on 2 of the 60)
    at 0.74 and 33 % (with the sandwich factor, :data:`CORRELATED_TERMS`)."""
    fall, limit = rate_ramp_test(free, held)
    if fall > limit:
        return free
    return replace(held, rate_ramp_fit=free)


def rate_ramp_test(free: CompositeFit, held: CompositeFit) -> tuple[float, float]:
    """(ΔD, limit) of :func:`release_rate_ramp`'s test: how much the deviance falls with R
    free, and φ·χ²₁(1 − 2·:data:`RATE_RAMP_LEVEL`) it must exceed."""
    limit = free.dispersion * chi2_ppf_1dof(1.0 - 2.0 * RATE_RAMP_LEVEL)
    return held.deviance - free.deviance, limit


def fit_start(
    tau: np.ndarray,
    avar: np.ndarray,
    edf: np.ndarray,
    extra: dict[str, np.ndarray] | None = None,
    level: float = 0.999,
    prefilter: bool = True,
    flicker_max: float = np.inf,
    dense_from: float = np.inf,
) -> tuple[float, str]:
    """Smallest τ (s) from which the composite model holds, and why (deletion tests).

    The model is exact for prefiltered white noise only from m = L − 1 (module doc), L unknown,
    and a sensor resonance can bend the curve over several short octaves.  Fits start at each of
    the first third of the octave points (keeping ≥ 3 residual degrees of freedom); point s
    contributes ΔD_s = D(from s) − D(from s + 1).  The fit starts just after the LAST point whose
    ΔD_s exceeds φ·χ²₁(``level``), φ the dispersion of the fit from the latest start (so a
    resonance at short τ does not inflate the yardstick, and a misfit at long τ that the loop
    treats inflates it for every point alike; ΔD ~ φ χ²₁ under the model, the quasi-likelihood
    deletion test of McCullagh & Nelder, §9.2).  Whatever lies below that start is left out;
    the fitted range is the one where the model holds point by point.  ``prefilter``,
    ``flicker_max`` and ``dense_from`` as in :func:`fit_composite`.  Returns (tau_min, note).
    """
    fit, note = _start_fit(tau, avar, edf, extra, level, prefilter, flicker_max, dense_from)
    return float(tau[fit.fit_index[0]]), note


def _start_fit(
    tau: np.ndarray,
    avar: np.ndarray,
    edf: np.ndarray,
    extra: dict[str, np.ndarray] | None,
    level: float,
    prefilter: bool,
    flicker_max: float = np.inf,
    dense_from: float = np.inf,
) -> tuple[CompositeFit, str]:
    """:func:`fit_start`, returning the fit from the chosen τ (= ``fit_composite`` with that
    ``tau_min``) instead of only its first τ."""
    limit = chi2_ppf_1dof(level)
    idx = octave_index(tau)
    policy = {"prefilter": prefilter, "flicker_max": flicker_max, "dense_from": dense_from}
    fits = [fit_composite(tau, avar, edf, extra, **policy)]
    for s in range(1, max(len(idx) // 3, 1) + 1):
        rest = fit_composite(tau, avar, edf, extra, tau_min=tau[idx[s]], **policy)
        if rest.dof < 3:
            break
        fits.append(rest)
    reference = fits[-1].dispersion
    delta = np.array([a.deviance - b.deviance for a, b in itertools.pairwise(fits)])
    significant = np.flatnonzero(delta > reference * limit)
    start = int(significant[-1]) + 1 if significant.size else 0
    fit = fits[start]
    if start == 0:
        return fit, "fit from the first tau: the shortest tau agrees with the model"
    tau_min = float(tau[fit.fit_index[0]])
    dropped = ", ".join(f"{t:.3g}" for t in tau[idx[:start]])
    worst = ", ".join(f"{tau[idx[j]]:.3g} s" for j in significant)
    return fit, (
        f"fit from tau = {tau_min:.3g} s: below it the model does not hold (tau = {dropped} s "
        f"left out; deviance contribution above phi*chi2_1({level}) at {worst}, phi = "
        f"{reference:.3g} from the fit from tau = {tau[idx[len(fits) - 1]]:.3g} s), i.e. samples "
        "correlated over more lags than the white + prefilter model holds for (sensor filter, "
        "aliasing or a short-period resonance)"
    )


def deviance_residuals(avar: np.ndarray, model: np.ndarray, edf: np.ndarray) -> np.ndarray:
    """Signed deviance residuals z = sign(â − a) √d per τ (≈ N(0, 1) when the model holds)."""
    return np.sign(avar - model) * np.sqrt(np.maximum(gamma_deviance(avar, model, edf), 0.0))


@dataclass(frozen=True)
class NoiseTerm:
    """One IEEE 952 coefficient with its 95 % interval, or ``value=None`` and a ``reason``."""

    value: float | None
    lo: float | None
    hi: float | None
    unit: str
    reason: str | None


def effect_shape(kind: str, shape: tuple, tau0: float) -> Callable[[np.ndarray], np.ndarray]:
    """The AVAR column (per unit squared ``value``) of an effect of ``kind`` with ``shape``
    parameters in a series sampled every ``tau0`` s, as a function of τ (s)
    (:mod:`imupipe.model.effects`; exact for the samples, not the continuous-time limit):

    * sinusoid (frequency Hz,): amplitude² · :func:`effects.sinusoid_avar`;
    * gauss_markov (Tc s,): σ² · :func:`effects.gauss_markov_avar`;
    * narrowband (centre Hz, line width Hz): σ² · :func:`effects.oscillator_avar`;
    * prefilter (filter family, length s, the τ0 s it was searched at): N_f² ·
      (:func:`effects.prefilter_avar` − 1/τ),
      the part of the white noise N² that passed the sensor's prefilter loses its short-τ
      variance (≤ 0; the IEEE 952 N² keeps the whole white level).
    """
    if kind == "sinusoid":
        return partial(sinusoid_avar, f0=shape[0], tau0=tau0)
    if kind == "gauss_markov":
        return partial(gauss_markov_avar, tc=shape[0], tau0=tau0)
    if kind == "narrowband":
        return partial(oscillator_avar, f0=shape[0], width_hz=shape[1], tau0=tau0)
    if kind == "prefilter":
        family, length_s, _ = shape

        def deficit(tau: np.ndarray) -> np.ndarray:
            return prefilter_avar(tau, tau0, family, length_s) - 1.0 / tau

        return deficit
    raise ValueError(f"no AVAR shape for effect kind {kind!r}")


@dataclass(frozen=True)
class EffectTerm:
    """An AVAR effect the closed loop added to the model, with the 95 % profile interval of
    ``value`` in ``unit``: a sinusoid (``value`` its amplitude, ``parameter`` its frequency, Hz),
    a Gauss–Markov process (σ; correlation time Tc, s), a narrowband vibration (σ, its rms;
    centre frequency, Hz, and ``width_hz``), or the sensor's prefilter (N_f, the filtered part
    of the white noise; filter length, s, of the family ``filter``), in a series sampled every
    ``tau0_s`` s.  ``label``: its key in report.json ``model.terms`` (the kind, numbered when a
    kind occurs more than once)."""

    kind: str
    value: float
    lo: float
    hi: float
    unit: str
    parameter: float
    tau0_s: float
    width_hz: float = 0.0
    filter: str = ""
    label: str = ""

    def avar(self, tau: np.ndarray) -> np.ndarray:
        """Its Allan variance (u²) at ``tau`` (s) (:func:`effect_shape`)."""
        shape = {
            "narrowband": (self.parameter, self.width_hz),
            "prefilter": (self.filter, self.parameter, self.tau0_s),
        }.get(self.kind, (self.parameter,))
        tau = np.asarray(tau, dtype=float)
        return self.value**2 * effect_shape(self.kind, shape, self.tau0_s)(tau)

    def as_model_term(self) -> dict:
        """The report.json ``model.terms`` entry: value, lo, hi, unit (and the shape: centre
        and width of a narrowband line, family and length of a prefilter)."""
        out = {"value": self.value, "lo": self.lo, "hi": self.hi, "unit": self.unit}
        if self.kind == "narrowband":
            out |= {"frequency_hz": self.parameter, "width_hz": self.width_hz}
        if self.kind == "prefilter":
            out |= {"filter": self.filter, "length_s": self.parameter}
        return out


@dataclass(frozen=True)
class NoiseTerms:
    """The five IEEE 952 terms of one axis (see module doc for units) and how they were fitted."""

    quantization: NoiseTerm
    random_walk: NoiseTerm
    bias_instability: NoiseTerm
    rate_random_walk: NoiseTerm
    rate_ramp: NoiseTerm
    cutoff_hz: float = np.inf  # flicker cut-off f0 of the bias-instability term (Hz)
    fit_tau_min_s: float = 0.0  # fitted τ range (s)
    fit_tau_max_s: float = np.inf
    deviance_per_dof: float = np.nan  # D/dof of the fit (≈ 1 when the model is adequate)
    prefilter_avar_s2: float = 0.0  # C of the −C/τ² prefilter term (u²·s², module doc)
    fit_note: str = ""  # where the fit starts and why; adequacy of the model
    effects: tuple[EffectTerm, ...] = ()  # AVAR effects of the final model (closed loop)

    def as_dict(self) -> dict:
        """The report.json ``ieee952`` block: {term: {value, lo, hi, unit, reason}}."""
        return {name: asdict(getattr(self, name)) for name in TERM_NAMES}

    def avar(self, tau: np.ndarray) -> np.ndarray:
        """The model's Allan variance at ``tau`` (s), exactly the reported terms: the resolved
        terms of :func:`avar_model` (an unresolved term contributes nothing), the effects,
        minus the prefilter term C/τ² (u²); NaN where that is not positive (below the fitted
        range, where the model does not apply)."""
        values = {n: getattr(self, n).value or 0.0 for n in TERM_NAMES}
        tau = np.asarray(tau, dtype=float)
        model = avar_model(tau, **values, cutoff_hz=self.cutoff_hz)
        model = model - self.prefilter_avar_s2 / tau**2 + sum(e.avar(tau) for e in self.effects)
        return np.where(model > 0, model, np.nan)

    def adev(self, tau: np.ndarray) -> np.ndarray:
        """√ :meth:`avar`: the model's Allan deviation (u) at ``tau`` (s)."""
        return np.sqrt(self.avar(tau))

    def fit_summary(self) -> dict:
        """How the terms were fitted: τ range (s), D/dof, prefilter term C (u²·s²), note."""
        return {
            "tau_min_s": self.fit_tau_min_s,
            "tau_max_s": self.fit_tau_max_s,
            "deviance_per_dof": self.deviance_per_dof,
            "cutoff_hz": None if np.isinf(self.cutoff_hz) else self.cutoff_hz,
            "prefilter_avar_s2": self.prefilter_avar_s2,
            "note": self.fit_note,
        }


def _adequacy(fit: CompositeFit, level: float = ADEQUATE_P) -> str | None:
    """Warning text when the model is rejected on its fitted range (P(χ²_dof ≥ D) < level)."""
    if fit.p_value >= level:
        return None
    return (
        f"model rejected on the fitted range (D/dof = {fit.deviance / fit.dof:.3g}, "
        f"p = {fit.p_value:.2g}): an effect the IEEE 952 terms do not describe; "
        f"interval widened by sqrt(D/dof) = {np.sqrt(fit.dispersion):.3g} (quasi-likelihood)"
    )


def over_alternatives(
    fit: CompositeFit,
    alternatives: Sequence[CompositeFit],
    avar: np.ndarray,
    edf: np.ndarray,
    j: int,
    correlation: np.ndarray | None,
    interval: tuple[float, float],
) -> tuple[float, float]:
    """The 95 % profile interval ``interval`` of ``fit``'s coefficient ``j`` widened over
    ``alternatives`` (fits of the same points with a non-linear shape elsewhere): the profile
    deviance of the coefficient is the least over the shape, so its interval is the union over
    the alternatives within ΔD = D − D_min ≤ φ c_j χ²₁(0.95) of each one's interval at the
    remaining room (φ the dispersion and c_j the :meth:`CompositeFit.sandwich_factor` of
    ``fit``; :meth:`CompositeFit.interval_within`, as the effects' own values are).  An
    alternative on which the coefficient is not resolved widens only the upper end: the term
    stays reported as resolved, its lower end the least resolved one."""
    lo, hi = interval
    phi = fit.deviance_scale(edf, j, correlation)
    for alt in alternatives:
        room = chi2_ppf_1dof(0.95) - (alt.deviance - fit.deviance) / phi
        if room <= 0:
            continue
        a_lo, a_hi = alt.interval_within(avar, edf, j, room * phi, correlation, (lo, hi))
        lo = min(lo, a_lo) if a_lo > 0 else lo
        hi = max(hi, a_hi)
    return lo, hi


def cutoff_alternatives(
    fit: CompositeFit, refit: Callable[[float, bool], CompositeFit], flicker_max: float = np.inf
) -> list[CompositeFit]:
    """``fit`` at every other flicker cut-off f0 of its :func:`cutoff_grid` (``refit(f0,
    rate_ramp)``: the same points and columns at that f0, R free or held at 0 as in ``fit``,
    :func:`release_rate_ramp`), for :func:`terms_from_fit`'s
    ``alternatives``: f0 is profiled, so the noise terms' intervals are their profiles over it
    too (:func:`over_alternatives` keeps those within the deviance's room).  An alternative
    whose B is impossible (over ``flicker_max``, :func:`flicker_limit`) is left out unless it
    is adequate, as :func:`fit_composite` chooses.  Each keeps ``fit``'s degrees of freedom: one
    model, its f0 counted once.

    Measured (session 49, ``benchmarks/interval_coverage.py coverage``): on 40 records of 4 h
    at 100 Hz with flicker of half the white noise at 1 s (N 2.7e-3, B 1.3e-3, an
    accelerometer's), N's 95 % interval at the chosen f0 alone held the truth on 62.5 %
    (half-width 0.20 % of N against a spread of 0.17 %: the f0 chosen trades with N); over the
    cut-offs on 87.5 % (half-width 0.34 %).  On the paper's gyro (43 min, 80 records) 95.0 →
    96.3 %, the half-width 0.46 → 0.49 %."""
    tau = 1.0 / fit.design[:, 1]
    free_r = fit.rate_ramp_fit is None
    others = (
        replace(refit(float(f0), free_r), dof=fit.dof)
        for f0 in cutoff_grid(tau)
        if f0 != fit.cutoff_hz
    )
    return [alt for alt in others if alt.coef[2] <= flicker_max or alt.p_value >= ADEQUATE_P]


def _quantization_bound(
    fit: CompositeFit, avar: np.ndarray, edf: np.ndarray, correlation: np.ndarray | None
) -> float:
    """Q²'s 95 % upper bound (u² s²) where the 3/τ² column of ``fit`` fits best negative with 0
    in its interval: the largest Q² ≥ 0 whose profile deviance (the column read as
    quantisation, :meth:`CompositeFit.as_quantization`) lies within φ·c·χ²₁(0.95) of the
    signed column's best ``fit`` — one profile over the signed coefficient, −P … +Q², cut at
    the same deviance as every other term's interval."""
    positive = fit.as_quantization(avar, edf)
    limit = fit.deviance_scale(edf, 0, correlation) * chi2_ppf_1dof(0.95)
    room = limit - (positive.deviance - fit.deviance)
    return positive.interval_within(avar, edf, 0, room, correlation)[1]


def terms_from_fit(
    fit: CompositeFit,
    avar: np.ndarray,
    edf: np.ndarray,
    sensor: Literal["gyro", "accel"],
    note: str = "",
    avar_hi: np.ndarray | None = None,
    effect_parameters: dict[str, tuple[str, tuple]] | None = None,
    sampling: tuple[float, np.ndarray] | None = None,
    alternatives: Sequence[CompositeFit] = (),
) -> NoiseTerms:
    """Convert the squared coefficients of ``fit`` to IEEE 952 terms with profile intervals.

    A resolved term carries a ``reason`` only when the model is rejected on the fitted range
    (its interval is then inflated by the dispersion, and says so).  ``note`` (e.g. from
    :func:`fit_start`) is prepended to ``fit_note``.  ``avar_hi``: the measured AVAR's upper
    confidence bound at every τ; an upper bound (of an unresolved term, or of an interval) is
    then never one whose asymptote lies above it (:func:`asymptote_caps`).  Extra columns of
    ``fit`` become :class:`EffectTerm` s: ``effect_parameters[name]`` = (kind, shape parameters
    of :func:`effect_shape`; they need ``sampling``).  ``sampling`` = (τ0 s, the curve's terms
    per τ): the intervals of
    :data:`CORRELATED_TERMS` and of the effects then account for the correlation of the fitted
    τ points (:func:`fit_correlation`, :meth:`CompositeFit.sandwich_factor`); without it, and
    for K and R always, the points are counted as independent (K, R: with their evidence
    weights).  ``alternatives``: fits of the same curve with an effect's shape elsewhere in its
    interval; a resolved term's interval is then its profile over them too
    (:func:`over_alternatives`).
    """
    rho = None if sampling is None else fit_correlation(fit, *sampling)
    tau_lo, tau_hi = fit.tau_range
    misfit = _adequacy(fit)
    tau = 1.0 / fit.design[:, 1]
    caps = (
        np.full(len(TERM_NAMES), np.inf)
        if avar_hi is None
        else asymptote_caps(tau, avar_hi, tau_lo)
    )
    terms, prefilter = {}, 0.0
    for j, (name, unit) in enumerate(zip(TERM_NAMES, TERM_UNITS[sensor], strict=True)):
        correlated = interval_correlation(fit, j, rho)
        profiled = fit.with_rate_ramp if j == 4 else fit
        lo, hi_profile = profiled.profile_interval(avar, edf, j, correlation=correlated)
        if profiled is not fit:  # R held at 0 in the model is reported by its bound
            lo = 0.0
        elif lo > 0:
            lo, hi_profile = over_alternatives(
                fit, alternatives, avar, edf, j, correlated, (lo, hi_profile)
            )
        signed = ""  # Q's bound where the 1/τ² column fits best negative, 0 in its interval
        if j == 0 and fit.short_sign < 0:
            prefilter = float(3.0 * fit.coef[0])
            if lo == 0:
                signed = (
                    f"; the term fits best negative, -{prefilter:.3g}/tau^2, with 0 in its 95 % "
                    f"interval [-{3 * hi_profile:.3g}, 0], so no prefilter's correlation of "
                    "neighbouring samples is resolved either"
                )
                hi_profile = _quantization_bound(fit, avar, edf, correlated)
        capped = caps[j] < hi_profile
        hi = min(hi_profile, caps[j])  # an unresolved term: at most what the curve allows
        if j == 0 and fit.short_sign < 0 and lo > 0:
            reason = (
                f"masked: the 1/tau^2 AVAR term is negative (-{prefilter:.3g}/tau^2, 95 % "
                f"[-{3 * hi:.3g}, -{3 * lo:.3g}]), the signature of neighbouring samples "
                "correlated by the sensor's prefilter; quantisation cannot be separated from it"
            )
            terms[name] = NoiseTerm(None, None, None, unit, reason)
        elif lo > 0:
            # a resolved term's interval: the profile's; B's is also held to a possible plateau
            # (others may lie above the curve where the negative prefilter term offsets them),
            # unless the fit kept a B above it because the data rejected the limit
            # (:func:`fit_composite`)
            value = float(np.sqrt(fit.coef[j]))
            if j == 2 and fit.coef[j] <= caps[j]:
                hi_profile = max(hi, float(fit.coef[j]))
            hi = float(np.sqrt(hi_profile))
            terms[name] = NoiseTerm(value, float(np.sqrt(lo)), hi, unit, misfit)
        else:
            how = (
                "its asymptote reaches the measured deviation's upper confidence bound"
                if capped
                else "profile likelihood" + (" over the 1/tau^2 term's sign" if signed else "")
            )
            reason = (
                f"not resolved for {tau_lo:.4g} s <= tau <= {tau_hi:.4g} s: 95 % upper bound "
                f"{np.sqrt(hi):.3g} {unit} ({how}{signed})"
            )
            if profiled is not fit and profiled.coef[j] > 0:  # the test held a fitted R at 0
                fall, limit = rate_ramp_test(profiled, fit)
                reason += (
                    f"; held at 0 in the model: with R fitted the deviance falls by {fall:.3g}, "
                    f"under phi*chi2_1({1 - 2 * RATE_RAMP_LEVEL:.2f}) = {limit:.3g} "
                    f"(likelihood-ratio test at {100 * RATE_RAMP_LEVEL:g} %)"
                )
            if misfit:
                reason += f"; {misfit}"
            terms[name] = NoiseTerm(None, None, float(np.sqrt(hi)), unit, reason)
    effects = []
    for name, (kind, shape) in (effect_parameters or {}).items():
        j = fit.names.index(name)
        lo, hi = fit.profile_interval(avar, edf, j, correlation=rho)
        value, lo, hi = (float(np.sqrt(c)) for c in (fit.coef[j], lo, hi))
        unit = TERM_UNITS[sensor][1 if kind == "prefilter" else 2]
        if kind == "prefilter":
            family, length_s, tau0 = shape
            term = EffectTerm(kind, value, lo, hi, unit, length_s, tau0, 0.0, family, name)
        else:
            width = shape[1] if kind == "narrowband" else 0.0
            term = EffectTerm(kind, value, lo, hi, unit, shape[0], sampling[0], width, label=name)
        effects.append(term)
    held = fit.rate_ramp_fit is not None and (
        "rate ramp R held at 0 by the likelihood-ratio test: D/dof with one parameter fewer "
        "than the closed loop's error, whose fits keep R free"
    )
    fit_note = "; ".join(
        t for t in (note, held, misfit or "model adequate on the fitted range") if t
    )
    return NoiseTerms(
        **terms,
        cutoff_hz=fit.cutoff_hz,
        fit_tau_min_s=tau_lo,
        fit_tau_max_s=tau_hi,
        deviance_per_dof=fit.deviance / fit.dof,
        prefilter_avar_s2=prefilter,
        fit_note=fit_note,
        effects=tuple(effects),
    )


def monotone_edf(edf: np.ndarray) -> np.ndarray:
    """Equivalent degrees of freedom made non-increasing in τ (running minimum).

    For any fixed power-law noise Greenhall's edf of the overlapping AVAR falls with m, and the
    noise only gets redder with τ; an edf that rises again (lag-1 noise identification reading
    a periodic signal's negative autocorrelation as white PM at mid τ) would give one point the
    weight of the shortest τ.  The running minimum caps it at the evidence of shorter τ.
    """
    return np.minimum.accumulate(np.asarray(edf, dtype=float))


@dataclass(frozen=True)
class CurveFit:
    """The IEEE 952 fit of one Allan curve (:func:`fit_curve`) and what it read: ``avar`` (u²)
    and ``edf`` (:func:`monotone_edf`) at every τ of the curve, ``avar_hi`` their 95 % upper
    bounds (:func:`avar_upper`), ``note`` why the fit starts where it does."""

    fit: CompositeFit
    note: str
    avar: np.ndarray
    edf: np.ndarray
    avar_hi: np.ndarray
    alternatives: tuple[CompositeFit, ...] = ()
    """``fit`` at the other flicker cut-offs (:func:`cutoff_alternatives`)."""


def fit_curve(curve: AllanCurve) -> CurveFit:
    """The composite fit of ``curve`` that :func:`fit_noise_terms` reports: weights from
    :func:`monotone_edf`, the start chosen by :func:`fit_start`, B kept possible
    (:func:`flicker_limit`), every τ from :func:`long_tau_start` on read for the long-τ terms,
    R released only where the data ask for it (:func:`release_rate_ramp`)."""
    avar = np.asarray(curve.adev, dtype=float) ** 2
    tau = np.asarray(curve.tau_s, dtype=float)
    edf = monotone_edf(curve.edf)
    avar_hi = avar_upper(avar, edf)
    policy = {
        "prefilter": True,
        "flicker_max": flicker_limit(avar_hi),
        "dense_from": long_tau_start(curve),
    }
    fit, note = _start_fit(tau, avar, edf, None, 0.999, **policy)
    tau_min = float(tau[fit.fit_index[0]])
    held = fit_composite(tau, avar, edf, tau_min=tau_min, rate_ramp=False, **policy)
    reported = release_rate_ramp(fit, held)
    alternatives = cutoff_alternatives(
        reported,
        lambda f0, rate_ramp: fit_composite(
            tau, avar, edf, cutoff_hz=f0, tau_min=tau_min, rate_ramp=rate_ramp, **policy
        ),
        policy["flicker_max"],
    )
    return CurveFit(reported, note, avar, edf, avar_hi, tuple(alternatives))


def fit_noise_terms(
    curve: AllanCurve, sensor: Literal["gyro", "accel"], tau0_s: float, correlated: bool = True
) -> NoiseTerms:
    """IEEE 952 terms of one axis from its Allan curve of samples every ``tau0_s`` s (SI rate
    units, see module doc).

    Weights from :func:`monotone_edf`; the fit starts at the τ chosen by :func:`fit_start`
    (reported in ``fit_tau_min_s`` and ``fit_note``); B is kept possible
    (:func:`flicker_limit`) and every upper bound below the measured curve's 95 % upper bound
    (:func:`asymptote_caps`); the intervals account for the correlation of the fitted τ
    (``correlated=False``: counted as independent, as before session 14 — for comparisons,
    ``benchmarks/interval_coverage.py``) and are profiled over the flicker cut-off
    (:func:`cutoff_alternatives`).
    """
    done = fit_curve(curve)
    sampling = (tau0_s, np.asarray(curve.n_terms)) if correlated else None
    return terms_from_fit(
        done.fit,
        done.avar,
        done.edf,
        sensor,
        done.note,
        done.avar_hi,
        sampling=sampling,
        alternatives=done.alternatives,
    )
