"""Correlation of overlapping AVAR estimates across τ: the lag sums against a sum over every
lag written out here, and the correlations against Monte Carlo of the noises themselves."""

from __future__ import annotations

import numpy as np
import pytest

from imupipe.stats.allan import oadev
from imupipe.stats.avar_covariance import avar_correlation, lag_sums

TAU0 = 0.01


def generalized_covariance(h, n2, b2, k2):
    """G(h) of the phase (u²s²), written out from the AVAR asymptotes (Allan 1966; IEEE 952):
    Σ s_a s_b G(a − b) over the stencil (1, −2, 1) at (0, h, 2h) is 2h²·AVAR(h)."""
    h = np.abs(h)
    with np.errstate(divide="ignore", invalid="ignore"):
        flicker = np.where(h > 0, h * h * np.log(h), 0.0)
    return -n2 * h / 2 + b2 * flicker / (2 * np.pi) + k2 * (h**3 - TAU0**2 * h) / 12


def every_lag(m, n, terms_m, terms_n, coef):
    """Σ over every lag l of w(l) C_mn(l)², C from the nine stencil products, lag by lag."""
    q2, n2, b2, k2 = coef
    lags = np.arange(-(terms_n - 1), terms_m)
    c = np.zeros(lags.size)
    for a, sa in enumerate((1.0, -2.0, 1.0)):
        for b, sb in enumerate((1.0, -2.0, 1.0)):
            u = lags + a * m - b * n
            c += sa * sb * (generalized_covariance(u * TAU0, n2, b2, k2) + q2 * (u == 0))
    pairs = np.minimum(terms_m, lags + terms_n) - np.maximum(0, lags)
    return float(np.sum(pairs * c**2))


@pytest.mark.parametrize(
    "coef",
    [(0, 1e-6, 0, 0), (0, 0, 1e-8, 0), (1e-8, 1e-6, 0, 0), (1e-8, 1e-6, 1e-8, 0)],
    ids=["white", "flicker", "white+quantisation", "three terms"],
)
@pytest.mark.parametrize("m, n", [(1, 1), (1, 2), (3, 7), (64, 128), (100, 1000), (700, 3000)])
def test_lag_sums_equal_the_sum_over_every_lag(m, n, coef):
    """Exact where pieces are summed lag by lag (m, n small), to 2e-4 where the Gauss–Legendre
    pieces take over, over 20 000 samples."""
    terms_m, terms_n = 20_001 - 2 * m, 20_001 - 2 * n
    got = lag_sums([m], [n], [terms_m], [terms_n], TAU0, coef)[0]
    want = every_lag(m, n, terms_m, terms_n, coef)
    assert got == pytest.approx(want, rel=2e-4 if n >= 64 else 1e-12)


def test_rate_random_walk_lag_sum_where_it_is_not_zero():
    """A random walk's C vanishes beyond the stencil's reach (|G| is a cubic there), so its sum
    runs over the lags −2m … 2n only (written out here without cancellation noise)."""
    coef, m, n, terms = (0, 0, 0, 1e-10), 3, 7, 20_001 - 14
    lags = np.arange(-2 * m, 2 * n + 1)
    c = sum(
        sa * sb * generalized_covariance((lags + a * m - b * n) * TAU0, 0, 0, 1e-10)
        for a, sa in enumerate((1.0, -2.0, 1.0))
        for b, sb in enumerate((1.0, -2.0, 1.0))
    )
    pairs = np.minimum(20_001 - 6, lags + terms) - np.maximum(0, lags)
    got = lag_sums([m], [n], [20_001 - 6], [terms], TAU0, coef)[0]
    assert got == pytest.approx(float(np.sum(pairs * c**2)), rel=1e-9)


def flicker(rng, n):
    """Flicker rate noise, B = 1 (two-sided PSD 1/(2πf)), synthesised 4× longer and cut."""
    f = np.fft.rfftfreq(4 * n, TAU0)
    shape = np.zeros_like(f)
    shape[1:] = np.sqrt(1 / (2 * np.pi * f[1:]) / TAU0)
    return np.fft.irfft(np.fft.rfft(rng.standard_normal(4 * n)) * shape, 4 * n)[:n]


NOISES = {
    "white": ((0, 1.0, 0, 0), lambda rng, n: rng.standard_normal(n) / np.sqrt(TAU0)),
    "random walk": ((0, 0, 0, 1.0), lambda rng, n: np.cumsum(rng.standard_normal(n)) * 0.1),
    "white phase": ((1.0, 0, 0, 0), lambda rng, n: np.diff(rng.standard_normal(n + 1)) / TAU0),
    # white and flicker cross at τ = 2π·ln2 ... the mix changes the correlation along the grid
    "white + flicker": (
        (0, 1.0, 0.1**2, 0),
        lambda rng, n: rng.standard_normal(n) / np.sqrt(TAU0) + 0.1 * flicker(rng, n),
    ),
}


@pytest.mark.parametrize("noise", sorted(NOISES))
def test_correlations_are_those_of_the_noise(noise):
    """2000 records of 8192 samples: the empirical correlation of their AVAR estimates at
    m = 1 … 512 (octaves) equals the computed one, neighbours (m, 2m) and (m, 4m) on average to
    0.02 (their Monte Carlo error ~0.005), every entry to 0.08.  Neighbours: 0.45–0.53 white,
    0.72–0.89 random walk, 0.40 white phase (whose far entries stay at 0.5)."""
    coef, draw = NOISES[noise]
    n, m = 8192, 2 ** np.arange(10)
    rng = np.random.default_rng(5)
    avar = np.array([oadev(draw(rng, n), TAU0, m)[0] ** 2 for _ in range(2000)])
    empirical = np.corrcoef(avar.T)
    computed = avar_correlation(m, n + 1 - 2 * m, TAU0, coef)
    for k in (1, 2):
        assert np.mean(np.diag(computed, k)) == pytest.approx(
            np.mean(np.diag(empirical, k)), abs=0.02
        )
    assert np.max(np.abs(computed - empirical)) < 0.08
    assert np.allclose(np.diag(computed), 1.0) and np.allclose(computed, computed.T)


def test_no_noise_correlates_nothing():
    m = np.array([1, 2, 4])
    assert np.array_equal(avar_correlation(m, 100 - 2 * m, TAU0, (0, 0, 0, 0)), np.eye(3))
