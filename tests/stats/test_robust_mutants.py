"""imupipe.stats.robust: the quantisation step and the |x| quantile (used by the outlier
detector) against numpy, at the edges mutation testing found untested."""

from __future__ import annotations

import numpy as np
import pytest

from imupipe.stats import robust


def test_quantum_counts_distinct_values_of_the_probe() -> None:
    """Quantised when the first ``probe`` finite samples take at most probe // 8 values (at
    least 2 allowed); the step is the least gap between them; fewer than 2 values: 0."""
    assert robust.quantum(np.full(100, 0.05)) == 0.0  # one value: no step to see
    assert robust.quantum(np.array([0.0, 0.1, 0.0, 0.1])) == 0.1  # 2 values of 4 samples
    x = np.tile(np.arange(8) * 0.25, 8)  # 64 samples, 8 values: 64 // 8 = 8 allowed
    assert robust.quantum(x) == 0.25
    y = np.tile(np.arange(9) * 0.25, 8)[:64]  # 9 values in 64 samples: not quantised
    assert robust.quantum(y) == 0.0
    z = np.concatenate([np.tile([1.0, 1.5, 3.0], 30), [np.nan, np.inf], np.arange(500.0)])
    assert robust.quantum(z, probe=92) == 0.5  # non-finite samples ignored, the rest unprobed
    assert robust.quantum(z) == 0.0
    # the default probe is the first 65 536 samples, not fewer: 2 values in the first 1000
    # samples, white noise after them
    w = np.concatenate([np.tile([0.0, 0.25], 500), np.random.default_rng(1).random(999)])
    assert robust.quantum(w) == 0.0
    assert robust.quantum(w, probe=1000) == 0.25


@pytest.mark.parametrize("p", [0.0, 0.3, 0.5, 0.999, 1.0])
def test_abs_quantile_equals_numpy(p: float) -> None:
    x = np.random.default_rng(2).standard_normal(10_001) * 3.0 - 0.5
    assert robust.abs_quantile(x, p) == np.quantile(np.abs(x), p, method="higher")


def test_abs_quantile_of_nothing_or_non_finite_is_nan() -> None:
    assert np.isnan(robust.abs_quantile(np.empty(0), 0.5))
    assert np.isnan(robust.abs_quantile(np.array([1.0, np.nan, 2.0]), 0.5))
    assert np.isnan(robust.abs_quantile(np.array([1.0, -np.inf]), 0.5))
