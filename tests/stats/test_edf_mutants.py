"""imupipe.stats.edf against an independent implementation and values written out: Greenhall's
edf (allantools.edf_greenhall) on every branch of the algorithm, the B1 and R(n) theories, and
the white vs flicker PM decision of the B1 method."""

from __future__ import annotations

import allantools
import numpy as np
import pytest

from imupipe.stats import edf

# (m, N phase points): J = min(N - 2m, 3m) <= 100 with F = m (m <= 33) and F = inf (m = 40,
# 50), J > 100 with r = (N - 2m)/m > 3 (Table 2 asymptote), and J > 100 with r <= 3
GREENHALL_CASES = [(1, 1001), (10, 1001), (33, 5000), (40, 1260), (50, 121), (30, 100_000),
                   (200, 100_000), (100, 350), (300, 1000), (60, 300), (3, 8)]  # fmt: skip


@pytest.mark.parametrize("alpha", [2, 1, 0, -1, -2])
def test_edf_equals_allantools_greenhall(alpha: int) -> None:
    for m, n in GREENHALL_CASES:
        if alpha == 2 and np.ceil((n - 2 * m) / m) <= 2:
            continue  # white PM with few terms: allantools does not implement it (below)
        want = allantools.edf_greenhall(alpha=alpha, d=2, m=m, N=n, overlapping=True)
        assert edf.edf_oadev(alpha, m, n) == pytest.approx(want, rel=1e-9), (m, n)


def test_edf_white_pm_fewer_terms_than_a_stride() -> None:
    """White PM, r = M/m <= 1 (K = 1): the M second differences m apart are uncorrelated,
    edf = M exactly; r in (1, 2]: 1/edf = (1 + 2 (1 - 1/r) (4/6)²) / M."""
    assert edf.edf_oadev(2, 100, 250) == pytest.approx(50.0, rel=1e-14)
    assert edf.edf_oadev(2, 50, 121) == pytest.approx(21.0, rel=1e-14)
    assert edf.edf_oadev(2, 100, 400) == pytest.approx(200 / (1 + 2 * 0.5 * 4 / 9), rel=1e-14)


def test_b1_and_rn_theories_written_out() -> None:
    # Barnes B1(N = 50, mu = -2) = 50 (1 - 50**-2) / (2 * 49 * (1 - 1/4)) = 0.68
    assert edf.b1_theory(50, -2) == pytest.approx(0.68, rel=1e-14)
    assert edf.b1_theory(5, 1) == pytest.approx(2.5, rel=1e-14)  # random-walk FM: N / 2
    # R(n): white PM 1/m; flicker PM 3 ln(256/27)/(8π²) over (1.038 + 3 ln(π m))/(4π²)
    assert edf._rn_theory(10, 2) == 0.1
    assert edf._rn_theory(10, 1) == pytest.approx(0.2964874510844128, rel=1e-12)
    assert edf._rn_theory(25, 1) == pytest.approx(0.2388034919097826, rel=1e-12)


def _pink(n: int, rng: np.random.Generator) -> np.ndarray:
    """n samples with a 1/f power spectrum (white noise shaped by 1/sqrt(f) in frequency)."""
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n)
    spectrum[1:] /= np.sqrt(f[1:])
    spectrum[0] = 0.0
    return np.fft.irfft(spectrum, n)


def test_b1_method_tells_white_from_flicker_pm() -> None:
    """With 10..29 averages, white PM (white phase) and flicker PM (pink phase) both look like
    mu = -2 to B1; R(n) = Mod AVAR / AVAR separates them (2 vs 1) in most records."""
    rng = np.random.default_rng(12)
    white = [edf.b1_noise_id(rng.standard_normal(2001), 100) for _ in range(30)]
    pink = [edf.b1_noise_id(_pink(2001, rng), 100) for _ in range(30)]
    assert np.mean(np.equal(white, 2)) >= 0.8
    assert np.mean(np.equal(pink, 1)) >= 0.7


def test_noise_id_thresholds_choose_the_method() -> None:
    """30 averaged points use the ACF method, 29 the B1 method, 9 keep the previous result."""
    x = np.cumsum(np.random.default_rng(4).standard_normal(3001))  # white FM phase
    points = (x.size - 1) // np.array([100, 103, 334])
    np.testing.assert_array_equal(points, [30, 29, 8])
    np.testing.assert_array_equal(
        edf.noise_ids(x, np.array([100])), [edf.acf_noise_id(np.diff(x[::100]))]
    )
    np.testing.assert_array_equal(edf.noise_ids(x, np.array([103])), [edf.b1_noise_id(x, 103)])
    ids = edf.noise_ids(x, np.array([103, 334]))
    assert ids[1] == ids[0]
    assert edf.noise_ids(x, np.array([334]))[0] == 0  # nothing earlier: white FM


def test_chi2_interval_default_is_stable32s_68_3_percent() -> None:
    lo, hi = edf.chi2_interval(np.array([1.0]), np.array([10.0]))
    lo2, hi2 = edf.chi2_interval(np.array([1.0]), np.array([10.0]), 0.683)
    assert (lo[0], hi[0]) == (lo2[0], hi2[0])


@pytest.mark.parametrize("count", [30, 41, 200])
def test_acf_removes_a_linear_frequency_drift_exactly(count: int) -> None:
    """Riley & Greenhall 2004 §3: the linear drift is removed before the lag-1 ACF (normal
    equations, Σt'² = L (L² − 1) / 12): a drift 1e4 times the noise changes no identification
    of white FM, white PM or random-walk FM records."""
    rng = np.random.default_rng(count)
    drift = 1e4 * np.arange(count) + 3e4
    for make in (lambda w: w[1:], np.diff, np.cumsum):
        for _ in range(5):
            y = make(rng.standard_normal(count + 1))[:count]
            assert edf.acf_noise_id(y + drift) == edf.acf_noise_id(y)


def test_long_series_branch_differences_at_most_twice(monkeypatch: pytest.MonkeyPatch) -> None:
    """Series longer than ACF_COPY_MAX are read from the phase on the fly, with the same
    dmax = 2 as the copy: a record whose second difference is still red (δ ≥ 0.25) but whose
    third would be anticorrelated (a slow sinusoid plus a period-2 term, integrated twice) is
    identified alike by both branches (α = −2, clipped), not as white PM after a third
    difference."""
    t = np.arange(3_000)
    s = 10 * np.sin(2 * np.pi * t / 100) + (-1.0) ** t
    y = np.cumsum(np.cumsum(s))
    x = np.concatenate([[0.0], np.cumsum(y)])  # phase: u_t = x[t + 1] - x[t] = y_t
    copied = edf.noise_ids(x, np.array([1]))
    monkeypatch.setattr(edf, "ACF_COPY_MAX", 0)
    np.testing.assert_array_equal(edf.noise_ids(x, np.array([1])), copied)
    np.testing.assert_array_equal(copied, [-2])
