"""Correlation of overlapping Allan variance estimates at different τ of one record.

The overlapping estimator at factor m (NIST SP 1065 eq. 11) is a quadratic form of the phase
x (the integrated rate, u·s):

    â(m) = 1/(2 m² τ0² M_m) Σ_{t<M_m} d_m(t)²,   d_m(t) = x(t + 2m) − 2 x(t + m) + x(t),

M_m the number of terms.  For Gaussian noise Cov(d_m(t)², d_n(s)²) = 2 C_mn(t − s)², with the
cross-covariance of the second differences

    C_mn(l) = Σ_{a,b ∈ {0,1,2}} s_a s_b G((l + a m − b n) τ0),   s = (1, −2, 1),

so Cov(â(m), â(n)) ∝ Σ_l w(l) C_mn(l)², w(l) the number of term pairs (t, s) at lag t − s = l.
G is the generalized covariance of the phase (Matheron's intrinsic random functions; a second
difference twice is a fourth-order difference, which annihilates the polynomial part of G of
degree ≤ 3, so only these terms matter), per IEEE Std 952-1997 term (rate PSD as in
:mod:`imupipe.model.ieee952`, AVAR asymptote on the right; each G reproduces it through
E d_h² = Σ s_a s_b G(·) = 2 τ² AVAR(τ)):

* random walk N (white rate):            G(h) = −N² |h| / 2                   N²/τ
* bias instability B (flicker rate):     G(h) = B² h² ln|h| / (2π)            (2 ln2/π) B²
* rate random walk K:                    G(h) = K² (|h|³ − τ0² |h|) / 12       K² τ/3
  (a sampled random walk of increments K √τ0, whose phase's second difference at m = 1 is
  white: the −τ0²|h| part, negligible beyond a few samples)
* quantisation Q (white phase):          G(l) = Q² [l = 0]  (samples)          3 Q²/τ²

The neighbouring estimates of a τ grid share most of their samples, so they are strongly
correlated (m and 2m: ρ ≈ 0.5 for white rate noise, 0.7 for flicker, 0.9 for a random
walk); a fit that counts them as independent over-counts its evidence
(:func:`imupipe.model.ieee952.CompositeFit.sandwich_factor`).
"""

from __future__ import annotations

import numpy as np

from imupipe.stats.allan import run_offsets

STENCIL = np.array([1.0, -2.0, 1.0])
"""Second-difference weights s of d_m(t) at phase offsets 0, m, 2m."""

_EXACT_PIECE = 48
"""Pieces of the lag axis up to this many lags are summed lag by lag; longer ones by
Gauss–Legendre quadrature with the Euler–Maclaurin end correction."""

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(12)


def phase_covariance(
    h_s: np.ndarray, tau0: float, white: float, flicker: float, rate_random_walk: float
) -> np.ndarray:
    """Generalized covariance G(h) (u²·s²) of the phase at lag ``h_s`` (s) of the IEEE 952
    terms with squared coefficients ``white`` = N², ``flicker`` = B², ``rate_random_walk`` = K²
    sampled every ``tau0`` s (module doc; quantisation, a white phase, is added at integer lags
    by the caller)."""
    h = np.abs(np.asarray(h_s, dtype=float))
    g = (-0.5 * white) * h
    if flicker > 0:  # h² ln h → 0 at h = 0
        g += (flicker / (2 * np.pi)) * h**2 * np.log(np.maximum(h, 1e-300))
    if rate_random_walk > 0:
        g += (rate_random_walk / 12) * (h**2 - tau0**2) * h
    return g


def _offsets(m: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lag shifts b n − a m (samples, shape (..., 9)) of C_mn for factors ``m``, ``n`` (arrays
    of one shape) and their weights s_a s_b (9,) (module doc)."""
    a, b = (k.ravel() for k in np.meshgrid(np.arange(3), np.arange(3), indexing="ij"))
    m, n = np.asarray(m)[..., None], np.asarray(n)[..., None]
    return b * n - a * m, np.outer(STENCIL, STENCIL).ravel()


def _cross(lag: np.ndarray, m: np.ndarray, n: np.ndarray, tau0: float, terms: tuple) -> np.ndarray:
    """C_mn (u²·s²) at (real) ``lag`` (samples) of the smooth terms ``terms`` = (N², B², K²);
    ``m``, ``n`` per lag (or scalars)."""
    shift, weight = _offsets(m, n)
    g = phase_covariance((np.asarray(lag, dtype=float)[..., None] - shift) * tau0, tau0, *terms)
    return g @ weight


def _pair_weight(lag: np.ndarray, terms_m: np.ndarray, terms_n: np.ndarray) -> np.ndarray:
    """w(l): the number of term pairs (t < M_m, s < M_n) with t − s = l."""
    lag = np.asarray(lag, dtype=float)
    return np.maximum(np.minimum(terms_m, lag + terms_n) - np.maximum(0.0, lag), 0.0)


def _lag_rules(
    m: np.ndarray, n: np.ndarray, terms_m: np.ndarray, terms_n: np.ndarray, flicker: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rules (pair, lag, weight) with Σ weight·f(lag) ≈ Σ_l f(l) over every lag of each
    pair's term pairs, for f = w·C_mn² (:func:`lag_sums`); all pairs at once.  The pieces of
    a pair are the gaps between its sorted cuts; a repeated cut makes an empty piece, which
    adds nothing."""
    first, last = -(terms_n - 1), terms_m - 1
    shift = _offsets(m, n)[0]
    lo, hi = shift.min(axis=1), shift.max(axis=1)
    if not flicker:  # white and RRW: C vanishes outside the shifts
        first, last = np.maximum(first, lo), np.minimum(last, hi)
    cuts = [shift, np.stack([first, last, np.zeros_like(first), terms_m - terms_n], axis=1)]
    if flicker:  # the flicker tail: octaves of the span beyond the shifts
        octave = np.maximum(hi - lo, 1)[:, None] * 2 ** np.arange(63)
        cuts += [hi[:, None] + octave, lo[:, None] - octave]
    cuts = np.sort(np.clip(np.concatenate(cuts, axis=1), first[:, None], last[:, None]), axis=1)
    p, q = cuts[:, :-1].astype(float), cuts[:, 1:].astype(float)
    pair = np.broadcast_to(np.arange(len(m))[:, None], p.shape)
    short = q - p <= _EXACT_PIECE  # summed lag by lag, each piece [p, q) without its end
    length = (q - p)[short].astype(np.int64)
    starts = np.repeat(p[short], length)
    within = run_offsets(length)
    a, b, long_pair = p[~short], q[~short], pair[~short]
    mid, half = (a + b) / 2, (b - a) / 2
    pairs = [np.arange(len(m)), np.repeat(pair[short], length)]
    pairs += [np.repeat(long_pair, _NODES.size), long_pair, long_pair]
    lags = [last.astype(float), starts + within, (mid[:, None] + half[:, None] * _NODES).ravel()]
    lags += [a, b]
    weights = [np.ones(len(m)), np.ones(starts.size), (half[:, None] * _WEIGHTS).ravel()]
    weights += [np.full(a.size, 0.5), np.full(b.size, -0.5)]
    return tuple(np.concatenate(v) for v in (pairs, lags, weights))


def _quantisation_sums(
    m: np.ndarray, n: np.ndarray, terms_m: np.ndarray, terms_n: np.ndarray, tau0: float, coef: tuple
) -> np.ndarray:
    """What white phase noise Q² adds to each pair's Σ_l w C_mn²: C gains Q² Σ s_a s_b at the
    lags l = b n − a m (shifts that coincide, e.g. at m = n, add up at one lag)."""
    shift, weight = _offsets(m, n)
    same = shift[:, :, None] == shift[:, None, :]
    c_q = coef[0] * (same @ weight)  # at each shift, the whole white-phase C of its lag
    once = 1.0 / same.sum(axis=2)  # a lag shared by k shifts counted once
    c_s = _cross(shift, m[:, None], n[:, None], tau0, tuple(coef[1:]))
    w = _pair_weight(shift, terms_m[:, None], terms_n[:, None])
    return np.sum(once * w * (2 * c_s * c_q + c_q**2), axis=1)


def lag_sums(
    m: np.ndarray,
    n: np.ndarray,
    terms_m: np.ndarray,
    terms_n: np.ndarray,
    tau0: float,
    coef: tuple[float, float, float, float],
) -> np.ndarray:
    """Σ_l w(l) C_mn(l)² over every lag, for each pair of estimates with factors ``m``, ``n``
    and ``terms_m``, ``terms_n`` terms, under the squared coefficients ``coef`` = (Q², N², B²,
    K²) (u²·s² squared).

    The lag axis is cut at the kinks of C (the shifts b n − a m) and of w, and beyond the
    shifts geometrically (the flicker tail, C ~ l⁻²); pieces up to 48 lags are summed lag by
    lag, longer ones integrated (12-point Gauss–Legendre) with the first Euler–Maclaurin
    correction −(f(q) − f(p))/2, good to O(f′) at the pieces' ends.  Every pair's rule is
    evaluated in one vectorised pass.
    """
    m, n, terms_m, terms_n = (np.asarray(v, dtype=np.int64) for v in (m, n, terms_m, terms_n))
    which, lags, weights = _lag_rules(m, n, terms_m, terms_n, coef[2] > 0)
    mm, nn, tm, tn = (np.asarray(v, dtype=float)[which] for v in (m, n, terms_m, terms_n))
    f = _pair_weight(lags, tm, tn) * _cross(lags, mm, nn, tau0, tuple(coef[1:])) ** 2
    total = np.bincount(which, weights=weights * f, minlength=len(m))
    if coef[0] > 0:
        total += _quantisation_sums(m, n, terms_m, terms_n, tau0, coef)
    return total


def avar_correlation(
    m: np.ndarray, n_terms: np.ndarray, tau0: float, coef: tuple[float, float, float, float]
) -> np.ndarray:
    """Correlation matrix of the overlapping AVAR estimates at factors ``m`` with ``n_terms``
    terms each (sample interval ``tau0``, s) under the IEEE 952 noise of squared coefficients
    ``coef`` = (Q², N², B², K²) in the units of :mod:`imupipe.model.ieee952` (module doc).
    The rate ramp and the loop's effects do not enter (a deterministic ramp has no variance;
    the effects' covariance is not modelled)."""
    m = np.asarray(m, dtype=np.int64)
    terms = np.asarray(n_terms, dtype=np.int64)
    i, j = np.triu_indices(len(m))
    s = np.empty((len(m), len(m)))
    s[i, j] = s[j, i] = lag_sums(m[i], m[j], terms[i], terms[j], tau0, coef)
    d = np.sqrt(np.diag(s))
    if not np.all(d > 0):  # no noise (every coefficient 0): nothing correlates the estimates
        return np.eye(len(m))
    return s / np.outer(d, d)
