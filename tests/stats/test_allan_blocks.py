"""The blocked Allan sums (:func:`imupipe.stats.allan._sum_sq_second_diff`) over several blocks
of :data:`imupipe.stats.allan.SUM_BLOCK` samples: every term counted once, at lags shorter and
longer than a block, for every axis."""

from __future__ import annotations

import functools
import math
import operator

import numpy as np
import pytest

from imupipe.jit import set_cores_here, usable_cores
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


@pytest.mark.parametrize("factors", ["grid", "one"])
def test_block_sums_are_added_in_block_order_whatever_the_thread_count(factors: str):
    """Each block's sum is formed by one job and the blocks are added in block order: the
    result is the same bits with one thread or three, and with a single factor m too (where a
    numpy sum over the blocks would add them pairwise, in another order)."""
    rng = np.random.default_rng(2)  # a seed where a pairwise sum of the blocks differs
    y = rng.standard_normal(40 * allan.SUM_BLOCK + 99)
    y *= np.repeat(rng.uniform(1, 2, 41), allan.SUM_BLOCK)[: y.size]
    m = allan.tau_factors(y.size) if factors == "grid" else np.array([3])
    x = allan.phase(y, 1.0)[None]
    part = np.zeros((1, 41, m.size))
    allan._block_sums(x, m, part, 0, 1)
    in_order = functools.reduce(operator.add, part[0], np.zeros(m.size))
    for threads in (1, 3):
        set_cores_here(threads)
        try:
            assert np.array_equal(allan._sum_sq_second_diff(x, m)[:, 0], in_order), threads
        finally:
            set_cores_here(usable_cores())
