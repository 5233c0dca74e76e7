"""The precision figures of benchmarks/interval_coverage.py (docs/validation.md, "Nor does the
record itself"): the Whittle Cramér–Rao bound is the textbook one for white noise, and the
IEEE 952 fit's B is at the bound on a 12 h record."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
import interval_coverage as bench


def test_white_noise_bound_is_that_of_a_sample_variance():
    """White noise alone: each of the n/2 ordinates carries one unit of information on ln N²,
    so σ(N)/N = ½ √(2/n); the absent terms are not estimated (NaN)."""
    spread = bench.whittle_crb(1e-3, 0.0, 0.0, 0.0, 1000.0, 0.01)
    assert spread[0] == pytest.approx(0.5 / np.sqrt(50_000), rel=1e-12)
    assert np.isnan(spread[1:]).all()


def test_flicker_bound_grows_when_a_random_walk_hides_it():
    """B's bound from N 5e-4, B 5e-5 over 12 h at 100 Hz (6.75 %), and much looser under a
    random walk 60× stronger (K 3e-5: B's band is covered, 22.7 %)."""
    bound = bench.whittle_crb(5e-4, 5e-5, 5e-7, 0.0, 12 * 3600, 0.01)
    assert bound[1] == pytest.approx(0.0675, abs=5e-4)
    assert bench.whittle_crb(5e-4, 5e-5, 3e-5, 0.0, 12 * 3600, 0.01)[1] > 3 * bound[1]


def test_the_fits_b_is_at_the_cramer_rao_bound():
    """The IEEE 952 fit (its points, evidence weights, sandwich variance at the truth) reads B
    from a 12 h curve within 2 % of the bound's spread (6.70 against 6.75 %) and within 1 % of
    the best linear reading of every τ (GLS, 6.65 %); N within 5 % of its bound (0.034 %)."""
    fit, gls = bench.allan_spreads((0.0, 5e-4, 5e-5, 5e-7), 12 * 3600, 0.01)
    bound = bench.whittle_crb(5e-4, 5e-5, 5e-7, 0.0, 12 * 3600, 0.01)
    assert np.isnan(fit[0]) and np.isnan(gls[0])  # no quantisation term
    assert fit[2] == pytest.approx(bound[1], rel=0.02)
    assert fit[2] == pytest.approx(gls[2], rel=0.01)
    assert gls[2] <= fit[2]
    assert fit[1] == pytest.approx(bound[0], rel=0.05)
