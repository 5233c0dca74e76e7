"""Overlapping Allan deviation: NIST SP 1065 values, allantools agreement, estimator properties."""

from __future__ import annotations

import allantools
import numpy as np
import pytest

from imupipe.stats import allan
from imupipe.stats.allan import allan_curves, oadev, phase, tau_factors


def test_nist_sp1065_oadev(nist_1000):
    adev, n_terms = oadev(nist_1000, 1.0, np.array([1, 10, 100]))
    published = np.array([2.922319e-01, 9.159953e-02, 3.241343e-02])  # NIST SP 1065 p. 108
    np.testing.assert_allclose(adev, published, rtol=1e-6)
    np.testing.assert_array_equal(n_terms, [999, 981, 801])


def test_matches_allantools_on_random_data():
    rng = np.random.default_rng(3)
    n, tau0 = 20_000, 0.01
    y = rng.standard_normal((n, 3)) + np.cumsum(rng.standard_normal((n, 3)), axis=0) * 1e-3
    m = tau_factors(n)
    ours, _ = oadev(y, tau0, m)
    for axis in range(3):
        taus, ref, _, _ = allantools.oadev(
            y[:, axis], rate=1 / tau0, data_type="freq", taus=m * tau0
        )
        np.testing.assert_allclose(taus, m * tau0)
        np.testing.assert_allclose(ours[:, axis], ref, rtol=1e-9)


def test_white_noise_slope_is_minus_half():
    y = np.random.default_rng(4).standard_normal(1 << 16)
    m = tau_factors(y.size, min_terms=64)
    adev, _ = oadev(y, 1.0, m)
    slope = np.polyfit(np.log(m), np.log(adev), 1)[0]
    assert slope == pytest.approx(-0.5, abs=0.02)
    assert adev[0] == pytest.approx(1.0, rel=0.02)  # sigma(tau0) = sigma_y for white FM


def test_axis_grouping_and_plain_numpy_agree(monkeypatch: pytest.MonkeyPatch):
    """The compiled kernel equals the textbook numpy expression of NIST SP 1065 eq. (11), and
    processing axes one by one (long records) equals processing them together."""
    y = np.random.default_rng(5).standard_normal((5_000, 3)) + np.array([0.0, 1e3, -5.0])
    m = tau_factors(y.shape[0])
    together, _ = oadev(y, 0.1, m)
    x = 0.1 * np.vstack([np.zeros(3), np.cumsum(y - y.mean(axis=0), axis=0)])
    for j, mj in enumerate(m):
        d = x[2 * mj :] - 2 * x[mj:-mj] + x[: -2 * mj]
        textbook = np.sqrt((d**2).sum(axis=0) / (2 * (mj * 0.1) ** 2 * (x.shape[0] - 2 * mj)))
        np.testing.assert_allclose(together[j], textbook, rtol=1e-12)
    monkeypatch.setattr(allan, "PHASE_BUDGET_BYTES", 8 * 5_001)  # one axis at a time
    np.testing.assert_allclose(oadev(y, 0.1, m)[0], together, rtol=1e-14)


def test_axes_at_once_equal_per_column():
    y = np.random.default_rng(6).standard_normal((3_000, 4)) * [1.0, 2.0, 1e-3, 5e3]
    m = tau_factors(y.shape[0])
    stacked, n_terms = oadev(y, 0.5, m)
    assert stacked.shape == (m.size, 4)
    for axis in range(4):
        single, single_terms = oadev(y[:, axis], 0.5, m)
        assert single.shape == (m.size,)
        np.testing.assert_array_equal(single, stacked[:, axis])
        np.testing.assert_array_equal(single_terms, n_terms)


def test_large_offset_does_not_cost_precision():
    """A 1 g accelerometer offset is removed before integrating, so it costs no digits."""
    y = np.random.default_rng(7).standard_normal(100_000) * 1e-3
    m = np.array([1, 10, 1000])
    np.testing.assert_allclose(oadev(y + 9.81, 0.01, m)[0], oadev(y, 0.01, m)[0], rtol=1e-9)


def test_phase_is_mean_free_integral():
    y = np.array([1.0, 2.0, 3.0, 6.0])
    np.testing.assert_allclose(phase(y, 0.5), [0.0, -1.0, -1.5, -1.5, 0.0])


def test_tau_factors_grid():
    n = 4_320_000
    m = tau_factors(n, per_decade=10)
    assert m[0] == 1 and m.dtype == np.int64
    assert np.all(np.diff(m) > 0)
    assert m[-1] <= n // 4 and m[-1] > n // 4 / 10**0.1
    for decade in range(1, 5):  # decades 10..100 ... 1e5..1e6 each hold >= 10 factors
        assert np.count_nonzero((m >= 10**decade) & (m < 10 ** (decade + 1))) >= 10
    np.testing.assert_array_equal(m[m < 10], np.arange(1, 10))
    assert tau_factors(n, per_decade=20).size > 1.8 * m.size
    assert tau_factors(1000, min_terms=10)[-1] == 100
    with pytest.raises(ValueError):
        tau_factors(3)


def test_rejects_factors_longer_than_half_the_record():
    with pytest.raises(ValueError):
        oadev(np.zeros(10), 1.0, np.array([6]))


def test_allan_curves_one_per_column():
    rng = np.random.default_rng(8)
    y = rng.standard_normal((20_000, 2)) * [1.0, 3.0]
    curves = allan_curves(y, 0.01)
    assert len(curves) == 2
    for curve, scale in zip(curves, (1.0, 3.0), strict=True):
        assert curve.confidence == 0.683
        np.testing.assert_allclose(curve.tau_s, tau_factors(20_000) * 0.01)
        assert np.all(curve.adev_lo < curve.adev) and np.all(curve.adev < curve.adev_hi)
        assert np.all(curve.alpha[:20] == 0)  # white FM identified at short tau
        assert curve.adev[0] == pytest.approx(scale, rel=0.03)
        assert np.all(curve.edf > 0)


def test_sparse_correction_equals_corrected_copy():
    """Spikes removed on the fly (SparseCorrection) give the ADEV of the corrected series."""
    from imupipe.stats.allan import SparseCorrection

    rng = np.random.default_rng(4)
    y = rng.standard_normal(20_000)
    idx = np.array([0, 17, 5_000, 19_999])
    fix = SparseCorrection(idx, rng.standard_normal(4) * 30)
    y[idx] += fix.value
    clean = y.copy()
    clean[idx] -= fix.value
    m = tau_factors(len(y))
    np.testing.assert_allclose(oadev(y, 0.1, m, fix)[0], oadev(clean, 0.1, m)[0], rtol=1e-10)
    (curve,) = allan_curves(y, 0.1, m, correction=fix)
    (ref,) = allan_curves(clean, 0.1, m)
    np.testing.assert_array_equal(curve.alpha, ref.alpha)
    np.testing.assert_allclose(curve.adev_hi, ref.adev_hi, rtol=1e-10)
    half = fix.within(5_000, 20_000)
    np.testing.assert_array_equal(half.index, [0, 14_999])
    with pytest.raises(ValueError, match="one 1-D"):
        oadev(np.column_stack([y, y]), 0.1, m, fix)


def _gapped_series(seed: int, n: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
    """White + random-walk rate with a NaN gap, a lone NaN sample and a short excised burst."""
    rng = np.random.default_rng(seed)
    y = rng.standard_normal(n) + 1e-2 * np.cumsum(rng.standard_normal(n))
    excluded = np.zeros(n, dtype=bool)
    excluded[6_000:6_700] = True  # missing frames
    excluded[11_111] = True  # one NaN row
    excluded[15_000:15_040] = True  # an excised event
    y[excluded] = np.nan
    return y, excluded


def test_gap_tolerant_oadev_equals_pooled_allantools_segments():
    """Independent estimate: allantools' overlapping ADEV of each clean segment, its terms
    pooled (avar_s * terms_s summed over segments, / total terms) — exactly the terms kept."""
    y, excluded = _gapped_series(7)
    tau0 = 0.01
    runs = allan.clean_runs(excluded)
    np.testing.assert_array_equal(runs, [[0, 6000], [6700, 11111], [11112, 15000], [15040, 20000]])
    m = np.array([1, 2, 5, 10, 50, 200, 1000, 2400])
    ours, n_terms = oadev(y, tau0, m, excluded=excluded)
    num = np.zeros(m.size)
    den = np.zeros(m.size)
    for s, e in runs:
        seg = y[s:e]
        for j, mj in enumerate(m):
            if e - s >= 2 * mj:
                _, dev, _, ns = allantools.oadev(
                    seg, rate=1 / tau0, data_type="freq", taus=[mj * tau0]
                )
                num[j] += dev[0] ** 2 * ns[0]
                den[j] += ns[0]
    np.testing.assert_array_equal(n_terms, den)
    np.testing.assert_allclose(ours, np.sqrt(num / den), rtol=1e-10)
    assert n_terms[-1] == 6000 + 1 - 4800 + 4960 + 1 - 4800  # only two runs hold m = 2400


def test_gap_free_mask_is_bitwise_the_plain_estimate():
    y = np.random.default_rng(8).standard_normal((3_000, 2))
    m = tau_factors(3_000)
    plain = allan_curves(y, 0.01, m)
    masked = allan_curves(y, 0.01, m, excluded=np.zeros(3_000, dtype=bool))
    for a, b in zip(plain, masked, strict=True):
        np.testing.assert_array_equal(a.adev, b.adev)
        np.testing.assert_array_equal(a.edf, b.edf)
        np.testing.assert_array_equal(a.n_terms, b.n_terms)


def test_gap_tolerant_curves_edf_and_factors():
    """The edf is the sum of each clean run's Greenhall edf; factors without a term are left
    out; NaN samples under the mask never reach the estimate."""
    y, excluded = _gapped_series(9)
    (c,) = allan_curves(y, 0.01, excluded=excluded)
    assert np.all(np.isfinite(c.adev)) and np.all(c.n_terms > 0)
    grid = tau_factors(20_000)
    np.testing.assert_allclose(c.tau_s, 0.01 * grid[grid <= 3000])  # longest run: 6000 samples
    runs = allan.clean_runs(excluded)
    j = int(np.searchsorted(c.tau_s, 1.0 - 1e-9))  # m = 100
    expected = sum(
        allan.edf_oadev(int(c.alpha[j]), 100, int(e - s) + 1) for s, e in runs if e - s >= 200
    )
    assert c.edf[j] == pytest.approx(expected, rel=1e-12)
    # fewer usable terms than a gap-free record of the same length: a smaller edf
    m = np.round(c.tau_s / 0.01).astype(int)
    gap_free = [allan.edf_oadev(int(a), int(mj), 20_001) for a, mj in zip(c.alpha, m, strict=True)]
    assert np.all(c.edf < gap_free)


def test_excluded_mask_shape_and_all_excluded_are_refused():
    y = np.ones(100)
    with pytest.raises(ValueError, match="shape"):
        oadev(y, 1.0, np.array([1]), excluded=np.zeros(99, dtype=bool))
    with pytest.raises(ValueError, match="every sample"):
        oadev(y, 1.0, np.array([1]), excluded=np.ones(100, dtype=bool))


def test_bridged_samples_are_skipped_where_half_the_terms_remain_and_read_beyond() -> None:
    """``bridged``: short runs of lost samples (here one in 200, 0.5 %) are skipped like the
    ``excluded`` ones at the τ where that leaves at least half of the N + 1 − 2m terms, and read
    (their fill) at the longer τ: each part equals the curve of its own mask, field by field."""
    rng = np.random.default_rng(11)
    n = 20_000
    y = rng.normal(0, 1, n)
    bridged = np.zeros(n, dtype=bool)
    bridged[rng.choice(n, 100, replace=False)] = True
    excluded = np.zeros(n, dtype=bool)
    excluded[5_000:5_400] = True  # a long gap, skipped at every τ
    m = tau_factors(n)
    (c,) = allan_curves(y, 0.01, m, excluded=excluded, bridged=bridged)
    (strict,) = allan_curves(y, 0.01, m, excluded=excluded | bridged)
    (loose,) = allan_curves(y, 0.01, m, excluded=excluded)
    k = int(np.argmax(strict.n_terms < (n + 1 - 2 * strict.tau_s / 0.01) / 2))
    assert 0 < k < len(strict.tau_s)  # both parts present
    np.testing.assert_array_equal(c.tau_s, loose.tau_s)  # every τ the long gap leaves
    for field in ("adev", "adev_lo", "adev_hi", "edf", "n_terms", "alpha"):
        got = getattr(c, field)
        np.testing.assert_array_equal(got[:k], getattr(strict, field)[:k], err_msg=field)
        np.testing.assert_array_equal(got[k:], getattr(loose, field)[k:], err_msg=field)
    none = np.zeros(n, dtype=bool)
    (same,) = allan_curves(y, 0.01, m, excluded=excluded, bridged=none)
    np.testing.assert_array_equal(same.adev, loose.adev)  # nothing bridged: the plain call


def test_bridged_samples_switch_at_half_the_terms_to_the_factor() -> None:
    """With every factor m from 1 to 300, the first one read across the bridged samples is the
    first whose skipping would keep fewer than half of the N + 1 − 2m terms."""
    rng = np.random.default_rng(12)
    n = 6_000
    y = rng.normal(0, 1, n)
    bridged = np.zeros(n, dtype=bool)
    bridged[rng.choice(n, 30, replace=False)] = True
    m = np.arange(1, 301)
    (c,) = allan_curves(y, 1.0, m, bridged=bridged)
    kept = allan.run_terms(allan.clean_runs(bridged), m)
    first = int(np.argmax(kept < (n + 1 - 2 * m) / 2))
    assert 0 < first < 299
    np.testing.assert_array_equal(c.n_terms[:first], kept[:first])
    np.testing.assert_array_equal(c.n_terms[first:], n + 1 - 2 * m[first:])
