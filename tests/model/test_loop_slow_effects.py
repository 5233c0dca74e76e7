"""Slow time-domain effects (a bias step, a warm-up drift, a ramp) against a random walk's
wander: their GLS tests are whitened with the rate random walk K at the upper end of its
interval (``loop.SLOW_KINDS``), so an unresolved K is not read as a drift or a step, while a real
step, whose correction lowers K's bound, is still found.

The record is gyro_x of the independent generator's clean recording 1300006 (10.46 h at 100 Hz;
``benchmarks/independent_generator.py``, which shares no code with imupipe): its K, 6.76e-7
rad/s²/√Hz, lies just under what the Allan curve can show, and a loop whitened with the fitted K
accepted a 0.25 mrad/s warm-up with τ 3378 s there (p 3.5e-4 after Bonferroni)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
import independent_generator as gen

from imupipe.analysis.analyze import axis_result
from imupipe.stats.allan import allan_curves, tau_factors
from imupipe.vocab import AXES

SEED, HOURS, TAU0 = 1300006, 10.455166764188407, 0.01


@pytest.fixture(scope="module")
def wander() -> tuple[np.ndarray, gen.AxisNoise]:
    """gyro_x of the generator's recording SEED, drawn exactly as ``gen.generate`` draws it."""
    rng = np.random.default_rng(SEED)
    noise = {a: gen.random_noise(a, rng) for a in AXES}
    n = round(HOURS * 3600 / TAU0)
    return gen.axis_noise(noise["gyro_x"], n, TAU0, rng), noise["gyro_x"]


def analysed(y: np.ndarray):
    (curve,) = allan_curves([y], TAU0, tau_factors(len(y)))
    return axis_result("gyro_x", y, curve, TAU0, None, None, True)


def test_an_unresolved_random_walk_is_not_read_as_a_warm_up(wander) -> None:
    y, truth = wander
    result = analysed(y)
    assert result.loop.accepted == []
    k = result.terms.rate_random_walk
    assert k.value is None and k.hi == pytest.approx(8.83e-7, rel=0.01) and k.hi > truth.k
    assert result.terms.random_walk.value == pytest.approx(truth.n, rel=0.002)


def test_an_unresolved_random_walk_is_not_read_as_a_bias_step(wander) -> None:
    """The same noise, another draw of 11 h (seed 209): whitened with the fitted K, the loop
    accepted a bias step there."""
    _, truth = wander
    y = gen.axis_noise(truth, round(11 * 3600 / TAU0), TAU0, np.random.default_rng(209))
    assert analysed(y).loop.accepted == []


def test_a_real_step_on_the_same_wander_is_still_found(wander) -> None:
    y, truth = wander
    t_step = 0.55 * len(y) * TAU0
    size = 10 * float(truth.adev(0.1 * len(y) * TAU0))  # the generator's size 10 (docs)
    result = analysed(y + size * (np.arange(len(y)) * TAU0 >= t_step))
    (step,) = [e for e in result.loop.accepted if e.kind == "bias_step"]
    lo, hi = step.intervals["time_s"]
    assert lo <= t_step <= hi and hi - lo < 600
    assert step.params["size"] == pytest.approx(size, rel=0.3)
