"""Overlapping Allan deviation on a log-spaced tau grid, with Stable32-grade confidence intervals.

The estimator is NIST SP 1065 eq. (11) on phase x (N = n + 1 points, x_0 = 0):

    sigma**2(m tau0) = sum_{i=0}^{N-2m-1} (x_{i+2m} - 2 x_{i+m} + x_i)**2 / (2 (m tau0)**2 (N - 2m))

with x = tau0 * cumsum(y - mean(y)) in float64 (removing the mean first keeps x a zero-drift
random walk, so the second differences do not lose digits to a large linear ramp).  The sums
of all m are one fused, vectorised pass per block of samples compiled by numba and spread over
the cores (:func:`_sum_sq_second_diff`): numpy would need three passes that write memory per m
(measured 3-4x slower), and the phase is the only large allocation (bounded by
:data:`PHASE_BUDGET_BYTES`).
Intervals: :mod:`imupipe.stats.edf`.

Gaps: with a boolean ``excluded`` mask (missing frames, NaN or saturated rows, excised events),
the sum skips every term whose window of 2m samples touches an excluded sample, and divides by
the number of terms actually summed — i.e. the terms of eq. (11) evaluated on each clean run
[s, e) of samples (L = e - s samples, L + 1 - 2m terms) and pooled.  The equivalent degrees of
freedom are the sum of Greenhall's edf of each run (runs treated as independent records).
Without an excluded sample the computation is the gap-free one, unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numba
import numpy as np

from imupipe.jit import kernel_input, spread
from imupipe.stats.edf import chi2_interval, edf_oadev, noise_ids

FIT_MIN_TERMS = 2
"""``min_terms`` of the τ grid the noise fit reads (:func:`tau_factors`: up to T/2); the curve
users read (allan.parquet, figures) stops at Stable32's T/4 (the default ``min_terms`` 4)."""

PHASE_BUDGET_BYTES = 64 << 20
"""Phase memory for axes processed together; longer records are processed axis by axis.  Axis
by axis costs nothing in speed (the sums are spread over the cores per tau): 12 h at 100 Hz,
6 axes, same process: 1 GB budget (all axes at once) 2.89 s, +0.25 GB; 64 MB (one 35 MB axis
at a time) 2.54 s, +0.12 GB, bit-identical."""


def tau_factors(n: int, per_decade: int = 10, min_terms: int = 4) -> np.ndarray:
    """Averaging factors m (int64, strictly increasing) for ``n`` rate samples.

    Grid: m_k = max(round(10**(k / per_decade)), k + 1), k = 0, 1, ..., i.e. every integer
    while the geometric grid is denser than 1, then geometric: at least ``per_decade`` factors
    per decade wherever a decade holds that many integers.  Longest m: the record must hold
    at least ``min_terms`` non-overlapping intervals of length m, m <= n // min_terms.  The
    default 4 is Stable32's limit (tau <= T/4), where the overlapping ADEV still has a few
    equivalent degrees of freedom (>= ~2 for white FM, Greenhall & Riley 2003); 2 reaches
    T/2, the longest τ with a term (edf ~1), which the noise fit reads for its long-τ terms
    (:data:`FIT_MIN_TERMS`).  The grid of a smaller ``min_terms`` extends the larger one's.
    """
    m_max = n // min_terms
    if m_max < 1:
        raise ValueError(f"{n} samples are too few for any tau (need >= {min_terms})")
    k = np.arange(int(np.ceil(np.log10(m_max) * per_decade)) + per_decade + 1)
    m = np.maximum(np.rint(10.0 ** (k / per_decade)), k + 1).astype(np.int64)
    return np.unique(m[m <= m_max])


Rates = np.ndarray | Sequence[np.ndarray]
"""Rate samples: an (n,) or (n, k) array, or a sequence of k equally long 1-D arrays (the
columns of a polars frame, without copying them into one matrix)."""


@dataclass(frozen=True)
class SparseCorrection:
    """Values to subtract from a 1-D rate series at a few samples (e.g. spikes replaced by the
    median), applied on the fly: a corrected 24 h / 1 kHz copy would cost 691 MB.

    ``index``: int64 sample indices, strictly increasing; ``value``: float64, unit of the rate.
    """

    index: np.ndarray
    value: np.ndarray

    def within(self, start: int, stop: int) -> SparseCorrection:
        """The corrections of samples ``[start, stop)``, indexed from ``start``."""
        lo, hi = np.searchsorted(self.index, [start, stop])
        return SparseCorrection(self.index[lo:hi] - start, self.value[lo:hi])


NO_CORRECTION = SparseCorrection(np.empty(0, np.int64), np.empty(0))
"""The empty correction (nothing subtracted)."""


def _columns(y: Rates) -> list[np.ndarray]:
    if isinstance(y, np.ndarray):
        return [y] if y.ndim == 1 else [y[:, a] for a in range(y.shape[1])]
    return list(y)


def _single(cols: list[np.ndarray], correction: SparseCorrection | None) -> SparseCorrection:
    if correction is None:
        return NO_CORRECTION
    if len(cols) != 1:
        raise ValueError("a SparseCorrection applies to one 1-D rate series")
    return correction


def clean_runs(excluded: np.ndarray) -> np.ndarray:
    """(k, 2) int64 ``[start, stop)``: the maximal runs of samples not ``excluded`` (bool (n,))."""
    padded = np.concatenate(([True], np.asarray(excluded, dtype=bool), [True]))
    return np.flatnonzero(padded[1:] != padded[:-1]).astype(np.int64).reshape(-1, 2)


def run_offsets(lengths: np.ndarray) -> np.ndarray:
    """0, 1, …, L − 1 for each length L of ``lengths`` (int), concatenated: each sample's place
    within its run."""
    lengths = np.asarray(lengths, dtype=np.int64)
    return np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)


def run_terms(runs: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Terms of eq. (11) that lie inside one clean run, per factor m: sum_r max(0, L_r + 1 - 2m)."""
    lengths = runs[:, 1] - runs[:, 0]
    m = np.asarray(m, dtype=np.int64)
    return np.maximum(lengths[None, :] + 1 - 2 * m[:, None], 0).sum(axis=1)


def _runs_of(excluded: np.ndarray | None, n: int) -> np.ndarray | None:
    """The clean runs of a mask of ``n`` samples, or None when nothing is excluded."""
    if excluded is None:
        return None
    excluded = np.asarray(excluded, dtype=bool)
    if excluded.shape != (n,):
        raise ValueError(f"the excluded mask has shape {excluded.shape}, the series ({n},)")
    if not excluded.any():
        return None
    if excluded.all():
        raise ValueError("every sample is excluded")
    return clean_runs(excluded)


def phase(
    y: Rates,
    tau0: float,
    correction: SparseCorrection | None = None,
    excluded: np.ndarray | None = None,
) -> np.ndarray:
    """Phase of rate samples ``y``: x = tau0*cumsum(y - mean), x_0 = 0.

    Returned axis-major, shape (k, n + 1) (or (n + 1,) for 1-D input), C-contiguous so each
    axis' phase is one contiguous row for :func:`_sum_sq_second_diff`.  Units: those of y times
    seconds (e.g. rad for a gyro in rad/s).  NIST SP 1065 eq. (1).  ``correction`` (1-D ``y``
    only) is subtracted from y first.  ``excluded`` (bool (n,)): those samples are never read
    (they may be NaN); the mean is that of the others and the phase stays flat across them.
    """
    cols = _columns(y)
    fix = _single(cols, correction)
    x = np.empty((len(cols), len(cols[0]) + 1))
    skip = None if _runs_of(excluded, len(cols[0])) is None else np.asarray(excluded, dtype=bool)
    for row, col in zip(x, cols, strict=True):
        col = kernel_input(col, np.float64)
        if skip is None:
            _integrate(col, tau0, row, fix.index, fix.value)
        else:
            _integrate_excluding(col, tau0, row, skip, fix.index, fix.value)
    return x[0] if isinstance(y, np.ndarray) and y.ndim == 1 else x


@numba.njit(cache=True, nogil=True)
def _integrate(
    y: np.ndarray, tau0: float, x: np.ndarray, fix_index: np.ndarray, fix_value: np.ndarray
) -> None:  # pragma: no cover (JIT)
    """x[0] = 0, x[i + 1] = tau0 * sum_{j <= i} (y'[j] - mean(y')) with y' = y minus
    ``fix_value`` at ``fix_index``: one pass for the mean, one for the running sum."""
    mean = 0.0
    for value in y:
        mean += value
    for value in fix_value:
        mean -= value
    mean /= y.size
    acc = 0.0
    x[0] = 0.0
    k = 0
    for i in range(y.size):
        v = y[i]
        if k < fix_index.size and fix_index[k] == i:
            v -= fix_value[k]
            k += 1
        acc += v - mean
        x[i + 1] = acc * tau0


@numba.njit(cache=True, nogil=True)
def _integrate_excluding(
    y: np.ndarray,
    tau0: float,
    x: np.ndarray,
    excluded: np.ndarray,
    fix_index: np.ndarray,
    fix_value: np.ndarray,
) -> None:  # pragma: no cover (JIT)
    """:func:`_integrate` with the ``excluded`` samples (and their fixes) skipped: the mean is
    over the other samples, and an excluded sample adds nothing (x[i + 1] = x[i])."""
    mean = 0.0
    count = 0
    for i in range(y.size):
        if not excluded[i]:
            mean += y[i]
            count += 1
    for k in range(fix_index.size):
        if not excluded[fix_index[k]]:
            mean -= fix_value[k]
    mean /= count
    acc = 0.0
    x[0] = 0.0
    k = 0
    for i in range(y.size):
        v = y[i]
        if k < fix_index.size and fix_index[k] == i:
            v -= fix_value[k]
            k += 1
        if not excluded[i]:
            acc += v - mean
        x[i + 1] = acc * tau0


SUM_BLOCK = 1 << 15
"""Samples per block of :func:`_sum_sq_second_diff`: every factor's terms of one block are summed
while the block's phase (256 KB; three such windows for a long lag) stays in the core's cache."""


@numba.njit(fastmath=True, cache=True, nogil=True)
def _run_sums(
    x: np.ndarray, m: np.ndarray, runs: np.ndarray, out: np.ndarray, start: int, step: int
) -> None:  # pragma: no cover (JIT)
    """:func:`_block_sums`' terms inside the clean ``runs`` only, one job per (m, axis): jobs
    ``start, start + step, ...`` (:func:`imupipe.jit.spread`) of (m.size × k), into
    ``out[j, a]``.  Run [s, e) of samples holds the terms i = s .. e - 2m (their samples
    i .. i + 2m - 1 all lie in it)."""
    k = x.shape[0]
    for job in range(start, m.size * k, step):
        j, a = job // k, job % k
        lag = m[j]
        row = x[a]
        acc = 0.0
        for r in range(runs.shape[0]):
            first = runs[r, 0]
            # slices: indices from 0, which numba knows are not negative, so the sum vectorises
            far, mid, near = row[first + 2 * lag :], row[first + lag :], row[first:]
            for i in range(runs[r, 1] - 2 * lag + 1 - first):
                d = far[i] - 2.0 * mid[i] + near[i]
                acc += d * d
        out[j, a] = acc


@numba.njit(fastmath=True, cache=True, nogil=True)
def _block_sums(
    x: np.ndarray, m: np.ndarray, part: np.ndarray, start: int, step: int
) -> None:  # pragma: no cover (JIT)
    """part[a, b, j] = sum_i (x[a, i+2m] - 2 x[a, i+m] + x[a, i])**2 over the terms i of block
    b (:data:`SUM_BLOCK` samples) for factor m[j], for the jobs (a, b) ``start, start + step,
    ...`` (:func:`imupipe.jit.spread`) of (k × blocks).

    Each job sums one block for every m, so the block's phase is read from the cache, not from
    memory, once per m; :func:`_sum_sq_second_diff` adds the blocks up.  The inner loop runs
    over slices (indices from 0, which numba knows are not negative) and ``fastmath`` lets the
    compiler vectorise it by reassociating the sum: the result changes only by rounding
    (~1e-14 relative), the per-block sums keep it at least as accurate as one running sum.
    12 h at 100 Hz, 61 factors, one axis: 0.08 s of CPU against 0.50 s for one unblocked
    scalar pass per m."""
    k, size = x.shape
    blocks = part.shape[1]
    for job in range(start, k * blocks, step):
        a, b = job // blocks, job % blocks
        row = x[a]
        first = b * SUM_BLOCK
        for j in range(m.size):
            lag = m[j]
            count = min(first + SUM_BLOCK, size - 2 * lag) - first
            far, mid, near = row[first + 2 * lag :], row[first + lag :], row[first:]
            acc = 0.0
            for i in range(count):
                d = far[i] - 2.0 * mid[i] + near[i]
                acc += d * d
            part[a, b, j] = acc


def _sum_sq_second_diff(x: np.ndarray, m: np.ndarray) -> np.ndarray:
    """sum_i (x[a, i+2m] - 2 x[a, i+m] + x[a, i])**2 over the N - 2m terms, (len(m), k), for
    every m and axis of the (k, N) phase ``x`` (one contiguous row per axis): the blocks'
    sums (:func:`_block_sums`, spread over the cores) added up in block order, so the result
    does not depend on the number of threads."""
    k, size = x.shape
    blocks = (size + SUM_BLOCK - 1) // SUM_BLOCK
    part = np.zeros((k, blocks, m.size))
    spread(lambda start, step: _block_sums(x, m, part, start, step), k * blocks)
    # a running sum in block order (a sum over axis 1 may be pairwise when m has one factor)
    return np.ascontiguousarray(part.cumsum(axis=1)[:, -1].T)


def _sum_sq_second_diff_runs(x: np.ndarray, m: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """:func:`_sum_sq_second_diff` over the terms inside the clean ``runs`` only
    (:func:`_run_sums`, spread over the cores)."""
    out = np.empty((m.size, x.shape[0]))
    spread(lambda start, step: _run_sums(x, m, runs, out, start, step), m.size * x.shape[0])
    return out


def _oadev_of_phase(
    x: np.ndarray, tau0: float, m: np.ndarray, runs: np.ndarray | None = None
) -> np.ndarray:
    """Overlapping ADEV (len(m), k) from axis-major phase ``x`` (k, N); NIST SP 1065 eq. (11),
    over the terms inside the clean ``runs`` if given (NaN where no term is left)."""
    if runs is None:
        sums = _sum_sq_second_diff(x, m)
        n_terms = x.shape[1] - 2 * m
    else:
        sums = _sum_sq_second_diff_runs(x, m, runs)
        n_terms = run_terms(runs, m)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(sums / (2.0 * ((m * tau0) ** 2 * n_terms))[:, None])


def _checked_factors(m: np.ndarray, n: int) -> np.ndarray:
    """``m`` as int64, refusing factors outside 1..n // 2 (no term of eq. 11 would exist)."""
    m = np.asarray(m, dtype=np.int64)
    if m.size == 0 or m.min() < 1 or 2 * m.max() > n:
        raise ValueError(f"averaging factors must lie in 1..{n // 2}")
    return m


def _axis_groups(n: int, k: int) -> list[slice]:
    """Axes processed together so that their phase stays under :data:`PHASE_BUDGET_BYTES`."""
    per_group = max(1, min(k, PHASE_BUDGET_BYTES // (8 * (n + 1))))
    return [slice(a, min(a + per_group, k)) for a in range(0, k, per_group)]


def oadev(
    y: Rates,
    tau0: float,
    m: np.ndarray,
    correction: SparseCorrection | None = None,
    excluded: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of rate samples ``y`` at tau = m * tau0.

    ``y`` is (n,) or (n, k) (k axes at once), sample interval ``tau0`` in seconds; ``m`` the
    averaging factors (1 <= m <= n // 2); ``correction`` (1-D ``y`` only) is subtracted from y;
    ``excluded`` (bool (n,), all axes) marks samples no term may touch (module docstring).
    Returns ``adev`` with shape (len(m),) or (len(m), k), in the unit of y (NaN at a factor
    without any term), and ``n_terms`` = N - 2m (N = n + 1 phase points), or the terms inside
    the clean runs.  NIST SP 1065 eq. (11).
    """
    cols = _columns(y)
    n = len(cols[0])
    m = _checked_factors(m, n)
    runs = _runs_of(excluded, n)
    adev = np.concatenate(
        [
            _oadev_of_phase(phase(cols[g], tau0, correction, excluded), tau0, m, runs)
            for g in _axis_groups(n, len(cols))
        ],
        axis=1,
    )
    one_d = isinstance(y, np.ndarray) and y.ndim == 1
    return (adev[:, 0] if one_d else adev), (n + 1 - 2 * m if runs is None else run_terms(runs, m))


@dataclass(frozen=True)
class AllanCurve:
    """One axis' overlapping Allan deviation with its confidence interval.

    ``tau_s`` in seconds; ``adev``, ``adev_lo``, ``adev_hi`` in the unit of the input rate;
    ``edf`` equivalent degrees of freedom (Greenhall); ``n_terms`` = N - 2m (with excluded
    samples: the terms actually summed, see :func:`oadev`); ``alpha`` the
    power-law noise exponent identified at each tau (2 white PM ... -2 random-walk FM);
    ``confidence`` the two-sided level of [adev_lo, adev_hi].
    """

    tau_s: np.ndarray
    adev: np.ndarray
    adev_lo: np.ndarray
    adev_hi: np.ndarray
    edf: np.ndarray
    n_terms: np.ndarray
    alpha: np.ndarray
    confidence: float

    def up_to(self, tau_max_s: float) -> AllanCurve:
        """This curve at τ ≤ ``tau_max_s`` (s) only (every point's value, edf and noise type
        depend on its own τ alone, so the prefix equals the curve computed on that range)."""
        keep = self.tau_s <= tau_max_s * (1 + 1e-9)
        return AllanCurve(*(getattr(self, f)[keep] for f in _CURVE_ARRAYS), self.confidence)


_CURVE_ARRAYS = tuple(f.name for f in fields(AllanCurve) if f.name != "confidence")
"""The per-τ fields of :class:`AllanCurve`, in its order."""


def edf_runs(alpha: int, m: int, runs: np.ndarray) -> float:
    """Equivalent degrees of freedom of the gap-tolerant estimate at factor ``m``: the sum of
    :func:`imupipe.stats.edf.edf_oadev` over the clean runs holding a term (each run of L
    samples an independent record of L + 1 phase points; runs of equal length computed once)."""
    lengths, count = np.unique(runs[:, 1] - runs[:, 0], return_counts=True)
    use = lengths >= 2 * m
    pairs = zip(lengths[use], count[use], strict=True)
    return float(sum(c * edf_oadev(alpha, m, int(ln) + 1) for ln, c in pairs))


def allan_curves(
    y: Rates,
    tau0: float,
    m: np.ndarray | None = None,
    confidence: float = 0.683,
    correction: SparseCorrection | None = None,
    excluded: np.ndarray | None = None,
    stable32_noise_id: bool = False,
    bridged: np.ndarray | None = None,
) -> list[AllanCurve]:
    """Overlapping ADEV with Stable32-style intervals for each axis of ``y`` (see :data:`Rates`).

    ``m`` defaults to :func:`tau_factors`; ``correction`` (one axis only) is subtracted from
    y.  Per tau: noise type by :func:`imupipe.stats.edf.noise_ids`, with ``redder_tail`` (at
    fewer than 30 averages the type may only stay or get redder; ``stable32_noise_id`` keeps
    Stable32's own identification, which may turn white again there, as its tables do, and
    reads every average where the identification may read a centred window of them,
    ``window``), edf by
    :func:`imupipe.stats.edf.edf_oadev`, interval by :func:`imupipe.stats.edf.chi2_interval` at
    ``confidence`` (0.683, Stable32's default).  ``excluded`` (bool (n,)): the gap-tolerant
    estimate (module docstring); factors without any term are left out, the edf
    is :func:`edf_runs`, and the noise type is identified on the phase held flat across the
    excluded samples.  ``bridged`` (bool (n,)): more samples the estimate skips as it skips
    ``excluded`` at the shorter τ, where that leaves at least half the terms of a record without
    any, and reads (as the values ``y`` holds there, their fill) at the longer τ, where it would
    leave fewer (short runs of lost samples, :class:`imupipe.analysis.condition.ConditionedSeries`).
    """
    if bridged is not None and bridged.any():
        return _bridged_curves(y, tau0, m, confidence, correction, excluded, bridged,
                               stable32_noise_id)  # fmt: skip
    cols = _columns(y)
    n = len(cols[0])
    runs = _runs_of(excluded, n)
    m = tau_factors(n) if m is None else _checked_factors(m, n)
    n_terms = n + 1 - 2 * m if runs is None else run_terms(runs, m)
    if runs is not None:
        keep = n_terms > 0
        m, n_terms = m[keep], n_terms[keep]
    curves: list[AllanCurve] = []
    for group in _axis_groups(n, len(cols)):
        x = phase(cols[group], tau0, correction, excluded)
        adev = _oadev_of_phase(x, tau0, m, runs)
        for i in range(x.shape[0]):
            alpha = noise_ids(
                x[i], m, redder_tail=not stable32_noise_id, window=not stable32_noise_id
            )
            edf = np.array(
                [
                    edf_oadev(int(a), int(mj), n + 1)
                    if runs is None
                    else edf_runs(int(a), int(mj), runs)
                    for a, mj in zip(alpha, m, strict=True)
                ]
            )
            lo, hi = chi2_interval(adev[:, i], edf, confidence)
            curves.append(AllanCurve(m * tau0, adev[:, i], lo, hi, edf, n_terms, alpha, confidence))
    return curves


def _bridged_curves(
    y: Rates,
    tau0: float,
    m: np.ndarray | None,
    confidence: float,
    correction: SparseCorrection | None,
    excluded: np.ndarray | None,
    bridged: np.ndarray,
    stable32_noise_id: bool,
) -> list[AllanCurve]:
    """:func:`allan_curves` with ``bridged`` samples skipped at the shorter τ (a prefix of the
    factors: at least half of the N + 1 − 2m terms of a record without excluded samples left)
    and read at the longer τ."""
    n = len(_columns(y)[0])
    strict = bridged if excluded is None else excluded | bridged
    m = tau_factors(n) if m is None else _checked_factors(m, n)
    whole = run_terms(_runs_of(strict, n), m) >= (n + 1 - 2 * m) / 2
    k = len(m) if whole.all() else int(np.argmin(whole))
    parts = [
        allan_curves(y, tau0, factors, confidence, correction, mask, stable32_noise_id)
        for factors, mask in ((m[:k], strict), (m[k:], excluded))
        if len(factors)
    ]
    if len(parts) == 1:
        return parts[0]
    return [
        AllanCurve(
            *(np.concatenate([getattr(a, f), getattr(b, f)]) for f in _CURVE_ARRAYS),
            a.confidence,
        )
        for a, b in zip(*parts, strict=True)
    ]
