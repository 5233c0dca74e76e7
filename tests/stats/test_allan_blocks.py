"""The blocked Allan sums (:func:`imupipe.stats.allan._sum_sq_second_diff`) over several blocks
of :data:`imupipe.stats.allan.SUM_BLOCK` samples: every term counted once, at lags shorter and
longer than a block, for every axis."""

from __future__ import annotations

import math

import numba
import numpy as np

from imupipe.stats import allan
from imupipe.stats.allan import oadev


def test_sums_over_several_blocks_equal_the_textbook_expression():
    n = 3 * allan.SUM_BLOCK + 1234  # four blocks, the last one partial
    rng = np.random.default_rng(21)
    y = rng.standard_normal((n, 2)) * [1.0, 1e-3] + np.array([0.0, 9.81])
    m = np.array([1, 7, allan.SUM_BLOCK - 1, allan.SUM_BLOCK, allan.SUM_BLOCK + 5, n // 2])
    ours, n_terms = oadev(y, 0.01, m)
    x = 0.01 * np.vstack([np.zeros(2), np.cumsum(y - y.mean(axis=0), axis=0)])
    for j, mj in enumerate(m):
        d = x[2 * mj :] - 2 * x[mj:-mj] + x[: -2 * mj]
        assert d.shape[0] == n_terms[j]
        for a in range(2):
            exact = math.fsum(d[:, a] ** 2)  # correctly rounded sum of the same terms
            textbook = math.sqrt(exact / (2 * (mj * 0.01) ** 2 * n_terms[j]))
            assert abs(ours[j, a] / textbook - 1) < 1e-13, (mj, a)


def test_block_sums_do_not_depend_on_the_thread_count():
    """Each block's sum is formed by one job and the blocks are added in one thread: the
    result is the same bits with one thread or all of them."""
    y = np.random.default_rng(22).standard_normal(2 * allan.SUM_BLOCK + 99)
    m = allan.tau_factors(y.size)
    everything = oadev(y, 1.0, m)[0]
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        one = oadev(y, 1.0, m)[0]
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(one, everything)
