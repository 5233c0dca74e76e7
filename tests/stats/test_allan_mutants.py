"""imupipe.stats.allan at the edges mutation testing probes: the phase held flat across excluded
samples, corrections inside a mask, a clean run exactly 2m long, axis groups that do not divide
the axes, and the factor limits.  Independent references: numpy on each clean run, values
written out."""

from __future__ import annotations

import numpy as np
import pytest

from imupipe.stats import allan
from imupipe.stats.allan import SparseCorrection, allan_curves, oadev, phase, tau_factors


def test_phase_skips_excluded_samples_written_out() -> None:
    """Mean over the kept samples (1, 3, 5 → 3); an excluded sample (NaN) adds nothing."""
    y = np.array([1.0, np.nan, 3.0, 5.0])
    x = phase(y, 0.5, excluded=np.array([False, True, False, False]))
    np.testing.assert_array_equal(x, [0.0, -1.0, -1.0, -1.0, 0.0])
    # the 2-D form: one row per axis
    x2 = phase(np.column_stack([y, 2 * y]), 0.5, excluded=np.array([False, True, False, False]))
    np.testing.assert_array_equal(x2, [[0.0, -1.0, -1.0, -1.0, 0.0], [0.0, -2.0, -2.0, -2.0, 0.0]])


def test_correction_inside_a_mask_equals_corrected_copy() -> None:
    """Spikes corrected on the fly while a gap is excluded = the corrected copy with the gap;
    a correction at an excluded sample is ignored (not subtracted from the mean)."""
    rng = np.random.default_rng(21)
    y = rng.standard_normal(4_000)
    excluded = np.zeros(4_000, dtype=bool)
    excluded[1_000:1_300] = True
    idx = np.array([5, 1_100, 2_500, 3_999])  # 1_100 lies in the gap
    fix = SparseCorrection(idx, np.array([40.0, -1e6, 25.0, -30.0]))
    y[idx] += fix.value
    clean = y.copy()
    clean[idx] -= fix.value
    m = np.array([1, 3, 10, 100, 600])
    got, terms = oadev(y, 0.01, m, fix, excluded)
    want, want_terms = oadev(clean, 0.01, m, excluded=excluded)
    np.testing.assert_allclose(got, want, rtol=1e-10)
    np.testing.assert_array_equal(terms, want_terms)
    np.testing.assert_allclose(
        phase(y, 0.01, fix, excluded), phase(clean, 0.01, excluded=excluded), rtol=0, atol=1e-12
    )


def test_run_of_exactly_2m_samples_holds_one_term() -> None:
    """A clean run of L = 2m samples holds L + 1 - 2m = 1 term of eq. (11) and adds its own
    edf (a record of 2m + 1 phase points); a run of 2m - 1 holds none."""
    runs = np.array([[0, 20], [21, 40], [50, 91]])  # lengths 20, 19, 41
    np.testing.assert_array_equal(allan.run_terms(runs, np.array([10, 20, 21])), [1 + 0 + 22, 2, 0])
    want = allan.edf_oadev(0, 10, 21) + allan.edf_oadev(0, 10, 42)
    assert allan.edf_runs(0, 10, runs) == pytest.approx(want, rel=1e-14)
    assert allan.edf_runs(0, 20, runs) == pytest.approx(allan.edf_oadev(0, 20, 42), rel=1e-14)
    # the estimate uses exactly those terms: numpy on each run, pooled
    rng = np.random.default_rng(3)
    y = rng.standard_normal(91)
    excluded = np.ones(91, dtype=bool)
    for s, e in runs:
        excluded[s:e] = False
    adev, n_terms = oadev(y, 1.0, np.array([10]), excluded=excluded)
    assert n_terms[0] == 23
    total = 0.0  # NIST SP 1065 eq. (11) on each run's own phase (allantools drops 1-term runs)
    for s, e in runs:
        x = np.concatenate([[0.0], np.cumsum(y[s:e])])
        d = x[20:] - 2 * x[10:-10] + x[:-20]
        total += np.sum(d**2)
    assert adev[0] == pytest.approx(np.sqrt(total / (2 * 10**2 * 23)), rel=1e-10)


def test_axis_groups_that_do_not_divide_the_axes(monkeypatch: pytest.MonkeyPatch) -> None:
    """Three axes, two per group (a last group of one): the same curves as all at once."""
    y = np.random.default_rng(6).standard_normal((2_000, 3)) * [1.0, 2.0, 3.0]
    m = tau_factors(2_000)
    together, _ = oadev(y, 0.1, m)
    curves = allan_curves(y, 0.1, m)
    assert allan._axis_groups(2_000, 3) == [slice(0, 3)]
    monkeypatch.setattr(allan, "PHASE_BUDGET_BYTES", 8 * 2_001 * 2)
    assert allan._axis_groups(2_000, 3) == [slice(0, 2), slice(2, 3)]
    np.testing.assert_allclose(oadev(y, 0.1, m)[0], together, rtol=1e-14)
    for a, b in zip(allan_curves(y, 0.1, m), curves, strict=True):
        np.testing.assert_allclose(a.adev, b.adev, rtol=1e-14)
        np.testing.assert_array_equal(a.alpha, b.alpha)


def test_factor_limits() -> None:
    """m = n // 2 is the longest factor (one term), m = 0 and an empty set are refused; the
    default grid stops at n // 4 (Stable32's T/4) and needs n >= 4."""
    adev, n_terms = oadev(np.arange(10.0) % 3, 1.0, np.array([5]))
    assert n_terms[0] == 1 and np.isfinite(adev[0])
    for bad in ([0, 1], []):
        with pytest.raises(ValueError, match=r"must lie in 1\.\.5$"):
            oadev(np.zeros(10), 1.0, np.array(bad, dtype=np.int64))
    np.testing.assert_array_equal(tau_factors(4), [1])
    np.testing.assert_array_equal(tau_factors(43), [1, 2, 3, 4, 5, 6, 7, 8, 9, 10])
    np.testing.assert_array_equal(tau_factors(100, per_decade=2), [1, 3, 10])
    np.testing.assert_array_equal(tau_factors(400, per_decade=1), [1, 10, 100])  # m_max = 10²
    (curve,) = allan_curves(np.random.default_rng(1).standard_normal(43), 0.5)
    np.testing.assert_array_equal(curve.n_terms, 44 - 2 * np.arange(1, 11))
    np.testing.assert_allclose(curve.tau_s, 0.5 * np.arange(1, 11))


@pytest.mark.parametrize("gap", [False, True])
def test_correction_reads_only_its_own_entries(gap: bool) -> None:
    """A correction whose arrays are slices of longer ones (as ``within`` returns) subtracts
    only its own entries: the element after its last index (3001, value 1e3) is never read."""
    rng = np.random.default_rng(22)
    y = rng.standard_normal(4_000)
    index, value = np.array([5, 1_100, 2_500, 3_001]), np.array([40.0, -7.0, 25.0, 1e3])
    fix = SparseCorrection(index[:3], value[:3])
    clean = y.copy()
    clean[index[:3]] -= value[:3]
    excluded = np.zeros(4_000, dtype=bool)
    if gap:
        excluded[1_500:1_700] = True
    m = np.array([1, 10, 300])
    got = oadev(y, 0.01, m, fix, excluded if gap else None)[0]
    np.testing.assert_allclose(got, oadev(clean, 0.01, m, excluded=excluded)[0], rtol=1e-10)
