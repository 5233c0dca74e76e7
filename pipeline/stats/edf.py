"""Confidence intervals for the overlapping Allan deviation, computed the way Stable32 does.

Three steps, each from the frequency-stability literature:

1. **Noise identification** (power-law exponent ``alpha`` of S_y(f) ~ f**alpha, an integer in
   -2..2) at each averaging factor m.  With at least :data:`ACF_MIN_POINTS` averaged points
   Stable32 uses the lag-1 autocorrelation method (Riley & Greenhall 2004, "Power law noise
   identification using the lag 1 autocorrelation", 18th EFTF); with fewer it falls back to the
   B1 bias ratio (Barnes 1969; Howe, Beard, Greenhall & Riley 2000, Table 3) and, to separate
   white from flicker PM, the R(n) = Mod AVAR / AVAR ratio (NIST SP 1065 section 5.2.6).
2. **Equivalent degrees of freedom** by Greenhall's algorithm (Greenhall & Riley 2003,
   "Uncertainty of stability variances based on finite differences", 35th PTTI), for the
   overlapping Allan variance: difference order d = 2, filter factor F = m, stride factor S = m.
3. **Chi-square interval**: sigma_lo**2 = edf * sigma**2 / chi2_{(1+c)/2}(edf) and
   sigma_hi**2 = edf * sigma**2 / chi2_{(1-c)/2}(edf) (NIST SP 1065 eq. 45).

All functions work on dimensionless numbers; data arrays may be in any unit.
"""

from __future__ import annotations

import functools

import numba
import numpy as np
from scipy.special import comb, gammaincinv

from imupipe.jit import kernel_input, spread

ACF_MIN_POINTS = 30
"""Fewest averaged points for which the lag-1 ACF method is used (Riley & Greenhall 2004)."""

B1_MIN_POINTS = 10
"""Fewest averaged points for the B1 method; below it the previous tau's noise type is kept."""

ACF_COPY_MAX = 1 << 22
"""Longest m-averaged series (values; 32 MB) formed as an array for the lag-1 ACF passes: the
passes then read it contiguously instead of striding through the phase (1.6-1.8x slower
measured for m = 2..8).  Longer series (small m on long records, e.g. 24 h at 1 kHz) are read
from the phase on the fly, so that no array proportional to the record is allocated."""

ACF_WINDOW = 1 << 18
"""Averages of the centred window from which the lag-1 ACF identifies the noise type at a
factor m whose series is longer (:func:`noise_ids` with ``window``): at m = 1..16 of 12 h at
100 Hz (4.3 M samples) the full series cost 0.18 of the 0.23 s per axis the identification
takes.  Its p = -2 (delta + d) scatters by ~2/sqrt(2**18) = 0.004 about the full series' for
white noise; the type is rounded from it only where p lies farther than
:data:`ACF_WINDOW_MARGIN` from a half-integer (the rounding's and the differencing order's
boundaries), else the full series decides, so the type is the full series' one short of a
change of the noise within the record."""

ACF_WINDOW_MARGIN = 0.1
"""Least distance of the window's p from a half-integer for its type to be taken."""

_J_MAX = 100
"""Greenhall & Riley 2003, section 4: largest number of terms summed exactly in BasicSum."""

# Greenhall & Riley 2003, Table 2 (unmodified variances, d = 2): 1/edf ~ (a0 - a1/r)/r.
_TABLE2_D2 = {2: (35.0 / 18.0, 1.0), 1: (790.0, 410.0), 0: (2.0 / 3.0, 1.0 / 3.0),
              -1: (0.852, 0.375), -2: (1.079, 0.368)}  # fmt: skip
# Greenhall & Riley 2003, Table 3 (alpha = 1, d = 2): sz(0, m) ~ b0 + b1 ln m.
_TABLE3_D2 = (15.23, 12.0)


@numba.njit(cache=True, nogil=True)
def _value(src: np.ndarray, m: int, phase: bool, t: int) -> float:  # pragma: no cover (JIT)
    """u_t, the t-th value of the series identified: u_t = x[(t+1) m] - x[t m] (m times the
    t-th non-overlapping m-averaged frequency, NIST SP 1065 eq. (2); the factor does not change
    the lag-1 ACF) of phase x = ``src`` if ``phase``, else the sample src[t]."""
    return src[(t + 1) * m] - src[t * m] if phase else src[t]


@numba.njit(cache=True, nogil=True)
def _detrended(
    src: np.ndarray, m: int, phase: bool, line: tuple[float, float], t: int
) -> float:  # pragma: no cover (JIT)
    """z_0(t) = u_t - (intercept + slope t) (:func:`_value`), ``line`` = (intercept, slope)."""
    return _value(src, m, phase, t) - (line[0] + line[1] * t)


@numba.njit(cache=True, nogil=True)
def _push(w: np.ndarray, z0: float, k: int) -> None:  # pragma: no cover (JIT)
    """Advance the forward-difference window ``w`` by the k-th detrended value z0 (k = 0, 1, ...).

    Afterwards w[j] = z_j(k - j) for j <= min(k, w.size - 1), where z_j+1(t) = z_j(t+1) - z_j(t)
    is the j-th difference, formed by the same subtractions as differencing an array in place.
    """
    top = min(k, w.size - 1)
    for j in range(top):
        new = z0 - w[j]
        w[j] = z0
        z0 = new
    w[top] = z0


@numba.njit(cache=True, nogil=True)
def _acf_pass(
    src: np.ndarray,
    m: int,
    phase: bool,
    count: int,
    line: tuple[float, float],
    d: int,
    mean: float,
    w: np.ndarray,
) -> tuple[float, float, float]:  # pragma: no cover (JIT)
    """One streaming pass over z_d, the d-th difference of the detrended series z_0(t),
    t < ``count`` (:func:`_detrended`), every value recomputed from ``src``.

    Returns num = sum (z_t - mean)(z_t+1 - mean) and den = (z_last - mean)**2 +
    sum_{t < last} (z_t - mean)**2 of Riley & Greenhall 2004, eq. (2) (r1 = num / den), and the
    index-order sum of z_d+1 for the next pass's mean.  ``w``: scratch of >= d + 2 values.
    """
    window = w[: d + 2]
    last = count - 1 - d  # last index of z_d: its d + 1 inputs start there
    for k in range(d + 1):
        _push(window, _detrended(src, m, phase, line, last + k), k)
    den = (window[d] - mean) ** 2
    for k in range(d + 1):
        _push(window, _detrended(src, m, phase, line, k), k)
    a = window[d] - mean  # z_d(0)
    num = 0.0
    acc = 0.0
    for k in range(d + 1, count):  # z_d(t + 1) and z_d+1(t) complete, t = k - d - 1
        _push(window, _detrended(src, m, phase, line, k), k)
        b = window[d] - mean
        num += a * b
        den += a * a
        acc += window[d + 1]
        a = b
    return num, den, acc


@numba.njit(cache=True, nogil=True)
def _acf_power(
    src: np.ndarray, m: int, phase: bool, count: int, dmax: int
) -> float:  # pragma: no cover (JIT)
    """Riley & Greenhall's estimate p = -2 (delta + d) of alpha (:func:`acf_noise_id`, before
    rounding) for the ``count`` values u_t of :func:`_value`, with no array proportional to
    ``count``: each pass recomputes every detrended, differenced value from ``src`` (the same
    float64 expressions, in the same order, as detrending and differencing a copy in place, so
    p is the same to the bit).

    Linear drift removed by the closed-form normal equations with centred abscissa
    t' = t - (L-1)/2: sum t'**2 = L (L**2-1)/12, slope = (sum t u - (L-1)/2 sum u) / sum t'**2.
    """
    total = 0.0
    weighted = 0.0
    for t in range(count):
        u = _value(src, m, phase, t)
        total += u
        weighted += t * u
    slope = (weighted - 0.5 * (count - 1) * total) / (count * (count**2 - 1.0) / 12.0)
    line = (total / count - slope * 0.5 * (count - 1), slope)
    acc = 0.0
    for t in range(count):
        acc += _detrended(src, m, phase, line, t)
    w = np.empty(dmax + 2)
    p = 0.0
    for d in range(dmax + 1):  # d: int64 from the start (one compiled _acf_pass)
        num, den, acc = _acf_pass(src, m, phase, count, line, d, acc / (count - d), w)
        r1 = num / den if den > 0 else 0.0  # no variation left to correlate: white
        delta = r1 / (1.0 + r1)
        p = -2.0 * (delta + d)
        if delta < 0.25:
            break
    return p


@numba.njit(cache=True, nogil=True)
def _acf_noise_id(
    src: np.ndarray, m: int, phase: bool, count: int, dmax: int
) -> int:  # pragma: no cover
    """:func:`_acf_power` rounded to the nearest integer: the noise type alpha."""
    return int(np.rint(_acf_power(src, m, phase, count, dmax)))


def acf_noise_id(ybar: np.ndarray, dmax: int = 2) -> int:
    """Power-law exponent alpha of the averaged fractional frequencies ``ybar`` by lag-1 ACF.

    Riley & Greenhall 2004, section 3: remove the linear frequency drift, then difference the
    series d times until delta = r1 / (1 + r1) < 0.25 (or d = dmax, 2 for the Allan variance);
    then p = -2 (delta + d) estimates alpha and is rounded to the nearest integer.
    """
    ybar = kernel_input(ybar, np.float64)
    return int(_acf_noise_id(ybar, 1, False, ybar.size, dmax))


def b1_theory(n: int, mu: int) -> float:
    """Expected B1 ratio (N-sample variance / Allan variance) for tau-exponent ``mu``.

    Barnes 1969 bias function B1(N, r=1, mu); closed forms from Howe et al. 2000, Table 3:
    B1 = N (1 - N**mu) / (2 (N - 1) (1 - 2**mu)), with the limits mu = 0 (flicker FM) and
    mu = -1 (white FM, B1 = 1).
    """
    if mu == 0:
        return n * np.log(n) / (2.0 * (n - 1) * np.log(2.0))
    return n * (1.0 - float(n) ** mu) / (2.0 * (n - 1) * (1.0 - 2.0**mu))


def _rn_theory(m: int, alpha: int) -> float:
    """Expected R(n) = Mod AVAR / AVAR for white PM (alpha 2) and flicker PM (alpha 1).

    White PM: R = 1/m.  Flicker PM: ratio of the IEEE 1139-2008 asymptotic forms
    Mod AVAR ~ 3 ln(256/27) / (8 pi**2) and AVAR ~ (1.038 + 3 ln(2 pi f_h tau)) / (4 pi**2),
    with f_h = 1/(2 tau0) (Nyquist), so 2 pi f_h tau = pi m.
    """
    if alpha == 2:
        return 1.0 / m
    avar = (1.038 + 3.0 * np.log(np.pi * m)) / (4.0 * np.pi**2)
    mvar = 3.0 * np.log(256.0 / 27.0) / (8.0 * np.pi**2)
    return mvar / avar


@numba.njit(cache=True, nogil=True, inline="always")
def _second_difference(x: np.ndarray, m: int, i: int) -> float:  # pragma: no cover (JIT)
    return x[i + 2 * m] - 2.0 * x[i + m] + x[i]


@numba.njit(cache=True, nogil=True)
def _mvar_over_avar(x: np.ndarray, m: int) -> float:  # pragma: no cover (JIT)
    """R(n) measured on phase ``x``: modified over overlapping Allan variance at factor m.

    NIST SP 1065 eq. (14) (MVAR: second differences d_i averaged over m adjacent starts) and
    eq. (11) (overlapping AVAR); the common 1/(2 m**2 tau**2) factors cancel except for 1/m**2.
    The m-sums of d are differences c_{j+m} − c_j of its running sum c, both ends carried along
    in one pass: no array of the record's length.
    """
    size = x.size - 2 * m
    avar = 0.0
    for i in range(size):
        d = _second_difference(x, m, i)
        avar += d * d
    lo, hi = 0.0, 0.0  # c_j and c_{j+m}
    for i in range(m):
        hi += _second_difference(x, m, i)
    mvar = 0.0
    for j in range(size - m + 1):
        moving = hi - lo
        mvar += moving * moving
        if j + m < size:
            hi += _second_difference(x, m, j + m)
        lo += _second_difference(x, m, j)
    terms = float(size - m + 1) * float(m) ** 2  # float: (M - m + 1) m² overflows int64
    return (mvar / terms) / (avar / size)


def b1_noise_id(x: np.ndarray, m: int) -> int:
    """Power-law exponent alpha from the B1 ratio, with R(n) for white vs flicker PM.

    ``x`` is phase (in units of tau0 * y).  The N = floor((len(x) - 1) / m) averaged
    frequencies give B1 = (sample variance) / (non-overlapping Allan variance); the measured
    ratio is compared with :func:`b1_theory` at mu = 1, 0, -1, -2 (alpha = -2, -1, 0, >= 1),
    boundaries at the geometric means of neighbours.  For mu = -2 the R(n) ratio decides
    between alpha = 2 and alpha = 1 (boundary at the geometric mean of the two theories).
    NIST SP 1065 section 5.2.6; Howe et al. 2000.
    """
    ybar = np.diff(x[::m]) / m
    n = ybar.size
    avar = 0.5 * np.mean(np.diff(ybar) ** 2)
    if avar == 0:  # averages that do not vary (a constant series): no type to read, white FM
        return 0
    b1 = ybar.var(ddof=1) / avar
    mu = -2
    for mu_hi in (-1, 0, 1):
        bound = np.sqrt(b1_theory(n, mu_hi - 1) * b1_theory(n, mu_hi))
        if b1 > bound:
            mu = mu_hi
    if mu > -2:
        return -mu - 1
    bound = np.sqrt(_rn_theory(m, 2) * _rn_theory(m, 1))
    return 2 if _mvar_over_avar(x, m) < bound else 1


@numba.njit(cache=True, nogil=True)
def _acf_ids(
    x: np.ndarray, m: np.ndarray, copy_max: int, out: np.ndarray, start: int, step: int
) -> None:  # pragma: no cover (JIT)
    """``out[i]`` = :func:`acf_noise_id` of the m-averaged frequencies for the factors
    ``m[i]``, i = ``start, start + step, ...`` (:func:`imupipe.jit.spread`); series of at most
    ``copy_max`` values are formed once and read contiguously, longer ones are read from the
    phase on the fly (same values either way)."""
    for i in range(start, m.size, step):
        count = (x.size - 1) // m[i]
        src, stride, phase = x, m[i], True
        if count <= copy_max:
            src = np.empty(count)
            for t in range(count):
                src[t] = _value(x, m[i], True, t)
            stride, phase = 1, False
        # one call: a single compiled _acf_noise_id (stride int64, phase bool, not literals)
        out[i] = _acf_noise_id(src, stride, phase, count, 2)


def _window_ids(x: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(type, decided) per factor ``m``: the noise type of the :data:`ACF_WINDOW` averages
    centred in the factor's series, decided where their p is clear of the rounding's
    boundaries (:data:`ACF_WINDOW_MARGIN`)."""
    ids, decided = np.zeros(m.size, dtype=np.int64), np.zeros(m.size, dtype=bool)
    for i, k in enumerate(m.tolist()):
        first = ((x.size - 1) // k - ACF_WINDOW) // 2
        u = np.diff(x[first * k : (first + ACF_WINDOW) * k + 1 : k])  # as _value forms u_t
        p = _acf_power(u, 1, False, ACF_WINDOW, 2)
        ids[i], decided[i] = int(np.rint(p)), abs(p % 1.0 - 0.5) > ACF_WINDOW_MARGIN
    return ids, decided


def noise_ids(
    x: np.ndarray, m: np.ndarray, redder_tail: bool = False, window: bool = False
) -> np.ndarray:
    """Stable32's noise identification for the Allan variance at each averaging factor ``m``.

    ``x`` is phase (cumulative sum of the fractional-frequency samples times tau0); ``m``
    increasing.  With at least :data:`ACF_MIN_POINTS` m-averaged frequencies the lag-1 ACF
    method is used, with at least :data:`B1_MIN_POINTS` the B1/R(n) method, and with fewer the
    previous (shorter) tau's result is kept (white FM, 0, if there is none); this reproduces
    every Alpha column of the Stable32 tables in the reference set.  Results are clipped to
    -2..2, the range the Allan variance resolves.

    ``redder_tail``: where fewer than :data:`ACF_MIN_POINTS` averages are left (the last
    octaves of a curve), the type may only stay or get redder: each B1 result is capped at the
    previous τ's type.  In a sum of independent power-law noises (an IMU's N, B, K, R) the type
    with the steepest AVAR slope τ**(-α-1) dominates at every longer τ, so a whiter type there
    is B1's scatter on 10-29 points — carried on to T/2, a white or flicker PM reading gives
    those τ an edf 10-100 times that of the record's few independent averages (a clean 12 h
    ADIS16364 accelerometer: edf 344 instead of 8.5 at τ = 3981 s).  Short τ keep the ACF's
    reading: there a prefiltered sensor's correlated samples legitimately read red at m = 1, 2
    and white after.

    ``window``: a series of more than :data:`ACF_WINDOW` averages is identified from its
    centred window where that is clear of the boundaries (:func:`_window_ids`).
    """
    m = np.asarray(m, dtype=np.int64)
    points = (x.size - 1) // m  # m-averaged frequencies
    acf_m = m[points >= ACF_MIN_POINTS]
    acf = np.empty(acf_m.size, dtype=np.int64)
    full = np.ones(acf_m.size, dtype=bool)
    if window:
        long = np.flatnonzero(points[points >= ACF_MIN_POINTS] > ACF_WINDOW)
        ids, decided = _window_ids(x, acf_m[long])
        acf[long[decided]], full[long[decided]] = ids[decided], False
    rest_m, rest = acf_m[full], np.empty(int(full.sum()), dtype=np.int64)
    spread(lambda start, step: _acf_ids(x, rest_m, ACF_COPY_MAX, rest, start, step), rest_m.size)
    acf[full] = rest
    alphas = np.empty(len(m), dtype=np.int64)
    previous = 0
    for i, mi in enumerate(m):
        if points[i] >= ACF_MIN_POINTS:
            previous = acf[i]  # m increasing: the ACF factors come first
        elif points[i] >= B1_MIN_POINTS:
            b1 = b1_noise_id(x, int(mi))
            previous = min(b1, previous) if redder_tail else b1
        alphas[i] = np.clip(previous, -2, 2)
    return alphas


EDF_KEPT = 8192
"""Values of :func:`edf_oadev` kept (a float each, with its three integer arguments)."""


def _sw(t: np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall & Riley 2003 eq. (7): generalised autocovariance sw(t) of noise type alpha."""
    at = np.abs(t)
    with np.errstate(divide="ignore", invalid="ignore"):
        lg = np.where(at > 0, np.log(np.where(at > 0, at, 1.0)), 0.0)
    table = {2: -at, 1: t**2 * lg, 0: at**3, -1: -(t**4) * lg, -2: -(at**5),
             -3: t**6 * lg, -4: at**7}  # fmt: skip
    return table[alpha]


def _sx(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Greenhall & Riley 2003 eq. (8): sx(t) = F**2 [2 sw(t) - sw(t - 1/F) - sw(t + 1/F)].

    For F = inf (no averaging filter) sx(t) = sw(t, alpha + 2).
    """
    if np.isinf(f):
        return _sw(t, alpha + 2)
    return f**2 * (2.0 * _sw(t, alpha) - _sw(t - 1.0 / f, alpha) - _sw(t + 1.0 / f, alpha))


def _sz(t: np.ndarray, f: float, alpha: int, d: int) -> np.ndarray:
    """Greenhall & Riley 2003 eq. (9): sz(t) = sum_k (-1)**k C(2d, d+k) sx(t - k), |k| <= d."""
    return sum((-1) ** abs(k) * comb(2 * d, d + k) * _sx(t - k, f, alpha) for k in range(-d, d + 1))


def _basic_sum(j: int, m_terms: float, s: float, f: float, alpha: int, d: int) -> float:
    """Greenhall & Riley 2003 eq. (10): sz(0)**2 + 2 sum_{j<J} (1 - j/M) sz(j/S)**2
    + (1 - J/M) sz(J/S)**2."""
    jj = np.arange(1, j)
    inner = 2.0 * np.sum((1.0 - jj / m_terms) * _sz(jj / s, f, alpha, d) ** 2)
    last = (1.0 - j / m_terms) * _sz(np.array(j / s), f, alpha, d) ** 2
    return float(_sz(np.array(0.0), f, alpha, d) ** 2 + inner + last)


@functools.lru_cache(maxsize=EDF_KEPT)
def edf_oadev(alpha: int, m: int, n_phase: int) -> float:
    """Equivalent degrees of freedom of the overlapping Allan variance (d = 2, F = S = m).

    Greenhall & Riley 2003, section 4 ("the algorithm"), cases 2-4 for unmodified variances.
    ``n_phase`` is the number of phase points N; L = m/F + m d = 2m + 1, M = N - 2m terms,
    J = min(M, (d + 1) S), r = M/S.  Case 4 with K = ceil(r) <= d (white PM, very few terms)
    sums the exact correlations of the d-th differences, rho_k = (-1)**k C(2d, d+k) / C(2d, d).

    Memoised (a pure function of three integers, :data:`EDF_KEPT` kept): a record with gaps
    sums it over its runs' lengths at every factor (``allan.edf_runs``), and the loop asks for
    the curves of the same runs again — 4491 calls for 773 values on a real ADIS16405 unit,
    1.3 s of Python holding the GIL while the other axis' thread waited.
    """
    d = 2
    s = float(m)
    m_terms = n_phase - 2 * m
    if m_terms < 1:
        raise ValueError(f"m={m} needs at least {2 * m + 1} phase points, got {n_phase}")
    r = m_terms / s
    j = min(m_terms, (d + 1) * m)
    if alpha == 2:
        k_ceil = int(np.ceil(r))
        if k_ceil > d:
            a0 = comb(4 * d, 2 * d) / comb(2 * d, d) ** 2
            return 1.0 / ((a0 - (d / 2.0) / r) / m_terms)
        k = np.arange(1, k_ceil)
        rho2 = (comb(2 * d, d + k) / comb(2 * d, d)) ** 2
        return 1.0 / ((1.0 + 2.0 * np.sum((1.0 - k / r) * rho2)) / m_terms)
    if alpha == 1:
        b0, b1 = _TABLE3_D2
        if j <= _J_MAX:
            sz0 = _sz(np.array(0.0), float(m), 1, d) ** 2
            return m_terms * sz0 / _basic_sum(j, m_terms, s, float(m), 1, d)
        if r > d + 1:
            a0, a1 = _TABLE2_D2[1]
            return (b0 + b1 * np.log(m)) ** 2 * r / (a0 - a1 / r)
        mp = _J_MAX / r
        return _J_MAX * (b0 + b1 * np.log(m)) ** 2 / _basic_sum(_J_MAX, _J_MAX, mp, mp, 1, d)
    if j <= _J_MAX:
        f = float(m) if m * (d + 1) <= _J_MAX else np.inf
        sz0 = _sz(np.array(0.0), f, alpha, d) ** 2
        return m_terms * sz0 / _basic_sum(j, m_terms, s, f, alpha, d)
    if r > d + 1:
        a0, a1 = _TABLE2_D2[alpha]
        return r / (a0 - a1 / r)
    mp = _J_MAX / r
    sz0 = _sz(np.array(0.0), np.inf, alpha, d) ** 2
    return _J_MAX * sz0 / _basic_sum(_J_MAX, _J_MAX, mp, np.inf, alpha, d)


def chi2_interval(
    dev: np.ndarray, edf: np.ndarray, confidence: float = 0.683
) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided chi-square interval of a deviation with ``edf`` degrees of freedom.

    NIST SP 1065 eq. (45): sigma_lo = sigma sqrt(edf / chi2_{(1+c)/2}),
    sigma_hi = sigma sqrt(edf / chi2_{(1-c)/2}), c = ``confidence``.
    """
    tail = (1.0 - confidence) / 2.0
    # the chi-square quantile as scipy.stats.chi2.ppf computes it, 2·P⁻¹(k/2, q) with P the
    # regularised lower incomplete gamma function, without importing scipy.stats (0.35 s)
    lo = dev * np.sqrt(edf / (2 * gammaincinv(edf / 2, 1.0 - tail)))
    hi = dev * np.sqrt(edf / (2 * gammaincinv(edf / 2, tail)))
    return lo, hi
