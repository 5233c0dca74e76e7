"""Noise identification, Greenhall EDF and chi-square intervals against Stable32 tables.

tests/data/stable32_*.txt are Stable32 1.60 output tables (copied unchanged from the allantools
project's test data, LGPL-3.0); stable32_inputs.npz holds their inputs: the Keysight 53230A
phase record in units of 1e-14 s (exactly the printed decimals) and the pink-FM frequency set.
The PHASE.DAT table's input is the NIST SP 1065 1000-point set, generated in test_allan.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from imupipe.stats import edf
from imupipe.stats.allan import allan_curves, phase
from imupipe.stats.edf import (
    acf_noise_id,
    b1_noise_id,
    b1_theory,
    chi2_interval,
    edf_oadev,
    noise_ids,
)

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="module")
def stable32_inputs(nist_1000) -> dict[str, tuple[np.ndarray, str]]:
    """Rate samples (tau0 = 1 s) and table file for each Stable32 case."""
    arrays = np.load(DATA / "stable32_inputs.npz")
    keysight_phase = arrays["keysight_phase_1e14s"].astype(np.float64) / 1e14
    return {
        "phasedat": (nist_1000, "stable32_phasedat_oadev_octave.txt"),
        "keysight": (np.diff(keysight_phase), "stable32_keysight53230a_tic_oadev.txt"),
        "pink": (arrays["pink_frequency"], "stable32_pink_oadev_octave.txt"),
    }


@pytest.mark.parametrize("case", ["phasedat", "keysight", "pink"])
def test_reproduces_stable32_table(case, stable32_inputs):
    y, table_file = stable32_inputs[case]
    table = np.loadtxt(DATA / table_file, comments="#")
    m = table[:, 0].astype(np.int64)
    (curve,) = allan_curves(y, 1.0, m, confidence=0.683, stable32_noise_id=True)
    np.testing.assert_array_equal(curve.n_terms, table[:, 2])
    np.testing.assert_array_equal(curve.alpha, table[:, 3])
    np.testing.assert_allclose(curve.adev, table[:, 5], rtol=1e-4)
    np.testing.assert_allclose(curve.adev_lo, table[:, 4], rtol=1e-3)
    np.testing.assert_allclose(curve.adev_hi, table[:, 6], rtol=1e-3)


def test_pink_table_exercises_every_identification_path(stable32_inputs):
    """ACF (>= 30 points), B1 (10..29) and carry-over (< 10) all occur in the pink table."""
    y, _ = stable32_inputs["pink"]
    m = np.array([64, 512, 2048])
    assert [np.diff(phase(y, 1.0)[::k]).size for k in m] == [156, 19, 4]
    np.testing.assert_array_equal(noise_ids(phase(y, 1.0), m), [0, 0, 0])


@pytest.mark.parametrize(
    ("alpha", "make"),
    [
        (2, lambda w: np.diff(w)),  # white PM: y is the derivative of white phase
        (0, lambda w: w[1:]),  # white FM
        (-2, lambda w: np.cumsum(w)),  # random-walk FM
    ],
)
def test_acf_identifies_power_laws(alpha, make):
    y = make(np.random.default_rng(9).standard_normal(4_001))
    assert acf_noise_id(y) == alpha
    assert noise_ids(phase(y, 1.0), np.array([1]))[0] == alpha


def test_b1_identifies_white_fm_and_random_walk():
    """With 20 averages B1 is noisy: require the right answer in most of 40 records."""
    rng = np.random.default_rng(10)
    white = [b1_noise_id(phase(rng.standard_normal(200), 1.0), 10) for _ in range(40)]
    walks = [b1_noise_id(phase(np.cumsum(rng.standard_normal(200)), 1.0), 10) for _ in range(40)]
    assert np.mean(np.equal(white, 0)) >= 0.75
    assert np.mean(np.equal(walks, -2)) >= 0.75


def test_b1_theory_limits():
    assert b1_theory(50, -1) == pytest.approx(1.0)  # white FM: variance = Allan variance
    assert b1_theory(50, 1) == pytest.approx(25.0)  # random-walk FM: N/2
    assert b1_theory(50, 0) == pytest.approx(50 * np.log(50) / (2 * 49 * np.log(2)))


def test_edf_white_fm_follows_table_asymptote():
    """For many terms Greenhall's 1/edf -> (a0 - a1/r)/r with Table 2 (alpha 0, d 2)."""
    n_phase, m = 100_001, 1_000
    r = (n_phase - 2 * m) / m
    assert edf_oadev(0, m, n_phase) == pytest.approx(r / (2 / 3 - (1 / 3) / r))


def test_edf_exact_sum_matches_asymptote_at_the_switch():
    """White FM, m (d + 1) > Jmax: BasicSum with F = inf agrees with the Table 2 asymptote."""
    m, n_phase = 40, 1_260
    r = (n_phase - 2 * m) / m
    assert edf_oadev(0, m, n_phase) == pytest.approx(r / (2 / 3 - (1 / 3) / r), rel=1e-3)


def test_edf_white_pm_few_terms():
    """White PM with r <= d: exact correlations of the 2nd difference, rho_1**2 = 4/9."""
    m, n_phase = 100, 350  # M = 150 terms, r = 1.5, K = 2
    expected = 150 / (1 + 2 * (1 - 1 / 1.5) * 4 / 9)
    assert edf_oadev(2, m, n_phase) == pytest.approx(expected)
    with pytest.raises(ValueError):
        edf_oadev(0, 100, 200)


def test_edf_increases_with_record_and_decreases_with_tau():
    for alpha in (2, 1, 0, -1, -2):
        edfs = [edf_oadev(alpha, m, 10_001) for m in (1, 10, 100, 1000, 2500)]
        assert all(a > b for a, b in itertools.pairwise(edfs)), alpha
        assert edf_oadev(alpha, 10, 100_001) > edf_oadev(alpha, 10, 10_001)


def test_chi2_interval_definition_and_coverage():
    lo, hi = chi2_interval(np.array([2.0]), np.array([10.0]), confidence=0.9)
    assert lo[0] == pytest.approx(2.0 * np.sqrt(10 / chi2.ppf(0.95, 10)))
    assert hi[0] == pytest.approx(2.0 * np.sqrt(10 / chi2.ppf(0.05, 10)))
    # Coverage: variance estimates s2 = sigma2 chi2(edf)/edf contain sigma2 at the nominal rate.
    rng = np.random.default_rng(11)
    s = np.sqrt(rng.chisquare(7.0, 20_000) / 7.0)
    lo, hi = chi2_interval(s, np.full(s.size, 7.0), confidence=0.683)
    assert np.mean((lo <= 1.0) & (1.0 <= hi)) == pytest.approx(0.683, abs=0.01)


def test_mvar_over_avar_streams_the_numpy_formula():
    """R(n) without record-length arrays equals the numpy form of NIST SP 1065 eqs. (11), (14)."""
    from imupipe.stats.edf import _mvar_over_avar

    rng = np.random.default_rng(8)
    x = np.cumsum(rng.standard_normal(5_001))
    cases = [(x, m) for m in (1, 2, 7, 100, 1_000)]
    # (M - m + 1) m² above 2**63 (24 h at 1 kHz, m = 3.2 M): the count must not overflow
    cases.append((np.cumsum(rng.standard_normal(8_400_001)), 2_000_000))
    for x, m in cases:
        d2 = x[2 * m :] - 2.0 * x[m:-m] + x[: -2 * m]
        c = np.concatenate(([0.0], np.cumsum(d2)))
        moving = c[m:] - c[:-m]
        expected = (moving @ moving) / (moving.size * m**2) / ((d2 @ d2) / d2.size)
        assert _mvar_over_avar(x, m) == pytest.approx(expected, rel=1e-12)


def test_a_gapped_curve_computes_each_run_lengths_edf_once() -> None:
    """``edf_oadev`` is memoised: a record with gaps sums it over its runs' lengths at every
    factor, and a second curve of the same runs (the loop's corrected curves) computes none
    again; the memoised values are the algorithm's own."""
    y = np.random.default_rng(4).standard_normal(20_000)
    excluded = np.zeros(y.size, bool)
    excluded[np.random.default_rng(5).choice(y.size, 40, replace=False)] = True  # 41 runs
    edf_oadev.cache_clear()
    first = allan_curves(y, 0.01, excluded=excluded)[0]
    computed = edf_oadev.cache_info()
    assert computed.misses > 100 and computed.hits == 0
    again = allan_curves(1.5 * y, 0.01, excluded=excluded)[0]
    assert edf_oadev.cache_info()[:2] == (computed.misses, computed.misses)  # (hits, misses)
    assert np.array_equal(first.edf, again.edf)
    for args in [(0, 10, 2001), (-1, 37, 900), (2, 100, 250), (1, 5, 30)]:
        assert edf_oadev(*args) == edf_oadev.__wrapped__(*args)


def _white_window_in_random_walk(window: int) -> np.ndarray:
    """Phase of 4 windows of frequency samples: a random walk of frequency (alpha -2) but for
    the centred window, white (alpha 0)."""
    rng = np.random.default_rng(21)
    y = np.cumsum(rng.standard_normal(4 * window))
    y[3 * window // 2 : 5 * window // 2] = rng.standard_normal(window)
    return np.concatenate([[0.0], np.cumsum(y)])


def test_a_long_series_is_identified_from_its_centred_window(monkeypatch) -> None:
    """Series of more than ACF_WINDOW averages: with ``window`` their type is read from the
    centred ACF_WINDOW averages (here white inside a random walk), where that is clear of the
    boundaries; closer than ACF_WINDOW_MARGIN, or without ``window`` (Stable32's own
    identification), from every average."""
    monkeypatch.setattr(edf, "ACF_WINDOW", 4096)
    x = _white_window_in_random_walk(4096)
    m = np.array([1, 2, 8])  # 16384, 8192 and 2048 averages: the last is not long
    assert noise_ids(x, m).tolist() == [-2, -2, -2]
    # m = 1: the window is the white part (p 0.023; a third of the way in, -0.96); m = 2:
    # its window spans random walk too (p -1.87)
    assert noise_ids(x, m, window=True).tolist() == [0, -2, -2]
    monkeypatch.setattr(edf, "ACF_WINDOW_MARGIN", 0.5)  # no p is that clear
    assert noise_ids(x, m, window=True).tolist() == [-2, -2, -2]
    monkeypatch.setattr(edf, "ACF_WINDOW_MARGIN", 0.1)
    curves = {
        own: allan_curves([np.diff(x)], 1.0, m, stable32_noise_id=own)[0].alpha.tolist()
        for own in (False, True)
    }
    assert curves == {False: [0, -2, -2], True: [-2, -2, -2]}


def test_the_window_decides_a_white_record_as_every_average_does(monkeypatch) -> None:
    """The default window on 2**20 white frequency samples: the same types as every average;
    the window decides m = 1..3 (p within ~0.01 of 0); m = 4 and 8 (2**18 and 2**17
    averages, not more than the window) read every average."""
    y = np.random.default_rng(5).standard_normal(1 << 20)
    x = np.concatenate([[0.0], np.cumsum(y)])
    m = np.array([1, 2, 3, 4, 8])
    expected = noise_ids(x, m).tolist()
    full_path, read_whole = edf._acf_ids, []

    def recording(x, m, *rest):
        read_whole.extend(m.tolist())
        return full_path(x, m, *rest)

    monkeypatch.setattr(edf, "_acf_ids", recording)
    assert noise_ids(x, m, window=True).tolist() == expected == [0] * 5
    assert set(read_whole) == {4, 8}  # (each thread is given them all)


def test_ten_averages_are_identified_by_b1_and_nine_keep_the_previous_type() -> None:
    """B1_MIN_POINTS: a factor leaving 10 averages is identified by the B1 ratio (here a
    strongly red series: -2); with 9 the previous factor's type is kept (none: 0)."""
    y = np.cumsum(np.cumsum(np.random.default_rng(0).standard_normal(100)))
    x = np.concatenate([[0.0], np.cumsum(y)])
    assert noise_ids(x, np.array([10])).tolist() == [-2]
    assert noise_ids(x[:91], np.array([10])).tolist() == [0]


def test_a_series_one_average_longer_than_the_window_is_read_from_its_start(
    monkeypatch,
) -> None:
    """ACF_WINDOW + 1 averages: the centred window starts at the first average (and ends one
    before the last): its type is the window's, on white noise the full series' too."""
    monkeypatch.setattr(edf, "ACF_WINDOW", 4096)
    y = np.random.default_rng(2).standard_normal(4097)
    x = np.concatenate([[0.0], np.cumsum(y)])
    p_window = edf._acf_power(np.diff(x[:4097]), 1, False, 4096, 2)
    assert abs(p_window % 1.0 - 0.5) > edf.ACF_WINDOW_MARGIN
    assert noise_ids(x, np.array([1]), window=True).tolist() == [int(np.rint(p_window))] == [0]


def test_a_series_that_does_not_vary_reads_white_fm_at_every_factor():
    """A constant rate (its phase a straight line: the half of a constant record a spike was
    removed from) has no variation to correlate: both identifications read white FM (0)
    instead of dividing by zero (the ACF's ZeroDivisionError, B1's 0/0 RuntimeWarning, found
    by the odd-bag fuzz)."""
    x = np.arange(2001) * 0.5  # phase of a constant rate of 0.5
    assert edf.acf_noise_id(np.full(500, 3.25)) == 0
    assert edf.b1_noise_id(x, 100) == 0
    with np.errstate(all="raise"):
        ids = edf.noise_ids(x, np.array([1, 2, 50, 100]))
    assert ids.tolist() == [0, 0, 0, 0]
