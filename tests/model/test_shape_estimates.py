"""An AVAR column's continuous shape parameter — a Gauss–Markov Tc, a prefilter's length, a
line's width — is estimated between its grid's points, and its 95 % interval ends where the
profile room crosses 0 (session 44: ``loop._shape_refined``, ``effects.crossing_interval``).

The grids step by ×1.2–1.4 (×2.3 for a line's widths), and a strong effect's shape is known to
a few per cent: read at the grid's best point, its interval's ends interpolated linearly
between grid points (the chord of a concave room lies under it), a strong Gauss–Markov Tc of
the independent generator (2 h at 100 Hz, size 10: 63 records found) was within its interval
on 56 of 63, the standardised errors' spread 1.45; now 60 of 63, spread 0.87.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from imupipe.analysis.analyze import axis_result
from imupipe.model import effects, loop
from imupipe.stats.allan import allan_curves, tau_factors
from imupipe.vocab import AXES, CHI2_95

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
import independent_generator as gen  # shares no code with imupipe


def test_an_interval_ends_where_a_concave_room_crosses_zero() -> None:
    """A room χ²₁(0.95) − ((u − ln 7)/0.1)² on a grid of ×1.78 steps with the best, 7, among
    its points: the interval is 7·exp(±0.1·√χ²₁(0.95)) to Brent's tolerance (linear
    interpolation gave [5.87, 7.80]); an end beyond the grid's last point is censored there."""
    u = np.log(np.append(np.geomspace(1.0, 100.0, 9), 7.0))
    u.sort()

    def room_at(v: float) -> float:
        return CHI2_95 - ((v - np.log(7.0)) / 0.1) ** 2

    room = np.array([room_at(v) for v in u])
    lo, hi = effects.crossing_interval(u, room, room_at)
    half = 0.1 * np.sqrt(CHI2_95)
    assert [lo, hi] == pytest.approx([7 * np.exp(-half), 7 * np.exp(half)], rel=2e-3)

    def at_end(v: float) -> float:
        return CHI2_95 - ((v - u[-1] - 0.05) / 0.1) ** 2

    lo, hi = effects.crossing_interval(u, np.array([at_end(v) for v in u]), at_end)
    assert hi == pytest.approx(100.0, rel=1e-12)
    assert lo == pytest.approx(100.0 * np.exp(0.05 - half), rel=2e-3)


def test_a_refit_that_disagrees_with_the_grid_keeps_the_grids_bracket() -> None:
    """``room_at`` refits at the bracket's ends, and a non-convex refit can land on another
    branch: here it reads the grid's best point (room χ²₁(0.95)) at −2.34, as a Butterworth
    prefilter of a third of a sample did on recording 4400019 of the independent generator,
    where brentq raised "f(a) and f(b) must have different signs" and the analysis ended in a
    traceback.  The bracket keeps the grid's values; the root is found between the points."""
    u = np.log(np.geomspace(1.0, 100.0, 9))
    best = u[4]

    def room_at(v: float) -> float:
        if v == best:
            return -2.34  # another branch
        return CHI2_95 - ((v - best) / 0.2) ** 2

    room = np.array([CHI2_95 if v == best else room_at(v) for v in u])
    lo, hi = effects.crossing_interval(u, room, room_at)
    half = 0.2 * np.sqrt(CHI2_95)
    assert [lo, hi] == pytest.approx(np.exp([best - half, best + half]), rel=2e-3)


@pytest.mark.parametrize("at", [1, -2])
def test_an_interval_crossing_beside_the_grids_end_is_found_not_censored(at: int) -> None:
    """The room crosses 0 between the grid's end and its neighbour inside (index 1, or the
    last but one): Brent's root there, not the grid's end."""
    u = np.log(np.geomspace(1.0, 100.0, 9))

    def room_at(v: float) -> float:
        return CHI2_95 - ((v - u[at]) / 0.2) ** 2

    lo, hi = effects.crossing_interval(u, np.array([room_at(v) for v in u]), room_at)
    half = 0.2 * np.sqrt(CHI2_95)
    assert [lo, hi] == pytest.approx(np.exp([u[at] - half, u[at] + half]), rel=2e-3)


def test_an_interval_of_two_separate_regions_spans_both() -> None:
    """A room with two bumps (at 3.16 and 31.6 on a ×1.33 grid, each 0.1 wide in the log, the
    room negative between them): the interval runs from the first's lower crossing to the
    second's upper one."""
    u = np.log(np.geomspace(1.0, 100.0, 17))
    a, b = u[4], u[12]

    def room_at(v: float) -> float:
        return CHI2_95 - min((v - a) ** 2, (v - b) ** 2) / 0.01

    lo, hi = effects.crossing_interval(u, np.array([room_at(v) for v in u]), room_at)
    half = 0.1 * np.sqrt(CHI2_95)
    assert [lo, hi] == pytest.approx([np.exp(a - half), np.exp(b + half)], rel=2e-3)


def _fake(deviance: float) -> SimpleNamespace:
    return SimpleNamespace(deviance=deviance)


def test_a_shape_is_refined_between_the_grids_points_in_each_family() -> None:
    """Prefilter specs (family, length s, τ0) of two families on a ×1.33 grid, the moving
    average's deviance least at 0.047 s and the Bartlett's at 0.061 s, 1 above: each family's
    length is refined (to Brent's tolerance), τ0 kept, and the best is the moving average's
    at 0.047 s (a 4-sample moving average at 100 Hz, between its grid's lengths, was a
    Bartlett window's best grid point); one width searched (a line whose width is the
    spectrum's): nothing to refine."""
    least = {"moving_average": 0.047, "bartlett": 0.061}

    def deviance(spec: tuple) -> float:
        return 50 * np.log(spec[1] / least[spec[0]]) ** 2 + (spec[0] == "bartlett")

    grid = np.geomspace(0.0025, 0.2, 16)
    fits = [((f, float(v), 0.01), _fake(deviance((f, v)))) for f in least for v in grid]
    refined = loop._shape_refined("prefilter", fits, lambda s: _fake(deviance(s)))
    assert refined[:-2] == fits
    for (spec, fit), family in zip(refined[-2:], least, strict=True):
        assert spec[0] == family and spec[2] == 0.01
        assert spec[1] == pytest.approx(least[family], rel=2e-3)
        assert fit.deviance < min(f.deviance for s, f in fits if s[0] == family)
    assert loop._best(refined)[0][0] == "moving_average"
    one = [((0.5, 0.01), _fake(3.0))]
    assert loop._shape_refined("narrowband", one, lambda s: _fake(0.0)) == one


def test_no_prefilter_is_searched_that_leaves_the_samples_white() -> None:
    """A moving average no longer than one sample, or a Bartlett window no longer than half of
    one, leaves sampled white noise white: its column (the AVAR's deficit under N²/τ) is 0 and
    its fitted value arbitrary (3.5e5 m/s²/√Hz on a real accel_x).  Each family's grid starts
    at its first length that correlates neighbouring samples."""
    tau0 = 0.01
    ax = SimpleNamespace(tau=np.geomspace(tau0, 100.0, 30), tau_min=tau0,
                         sig=SimpleNamespace(tau0=tau0))  # fmt: skip
    specs = loop._grids(ax, SimpleNamespace(effect_parameters={}))["prefilter"]
    shortest = {f: min(length for g, length, _ in specs if g == f) for f in effects.PREFILTERS}
    grid = np.geomspace(0.25 * tau0, 128 * tau0, 24)
    assert shortest == {
        "moving_average": grid[grid > tau0][0],
        "bartlett": grid[grid > tau0 / 2][0],
        "first_order": grid[0],
        "butterworth2": grid[0],
        "butterworth4": grid[0],
    }
    assert max(length for _, length, _ in specs) == pytest.approx(1.28, rel=1e-12)
    assert len(specs) == 18 + 21 + 3 * 24  # of 5 × 24
    tau = np.array([0.01, 0.02, 0.04])
    one_sample = effects.prefilter_avar(tau, tau0, "moving_average", tau0)
    np.testing.assert_allclose(one_sample, 1 / tau, rtol=1e-12)
    assert effects.prefilter_avar(tau, tau0, "moving_average", 1.01 * tau0)[0] < 0.99 / tau[0]


@pytest.mark.parametrize(
    ("seed", "tau_c", "tau_c_interval", "sigma_interval"),
    [
        (440007, 4.785, (4.369, 5.264), (1.9311e-3, 2.0700e-3)),
        (440019, 4.747, (4.339, 5.215), (1.2814e-3, 1.3721e-3)),
    ],
)
def test_a_strong_gauss_markov_tc_between_the_grids_points(
    seed, tau_c, tau_c_interval, sigma_interval
) -> None:
    """The independent generator's Gauss–Markov effect of size 10 (2 h at 100 Hz; the axis'
    own noise: white, flicker, random walk, quantisation): Tc 4.66 and 4.55 s, between the
    grid's 3.92 and 5.15 s.  Read at 5.15 s, the intervals [4.78, 5.31] s and [4.66, 5.33] s
    missed the truth, and on 440019 σ's [1.31, 1.39]e-3 rad/s missed 1.29e-3 too."""
    y, _, truth = gen.generate(2.0, 100.0, seed, "gauss_markov", 10.0)
    effect = truth.effect
    x = y[:, AXES.index(effect["axis"])].copy()
    (curve,) = allan_curves([x], 0.01, tau_factors(len(x)))
    result = axis_result(effect["axis"], x, curve, 0.01, None, None, True)
    (gm,) = result.loop.accepted
    assert gm.kind == "gauss_markov"
    assert gm.params["tau_c_s"] == pytest.approx(tau_c, rel=1e-3)
    lo, hi = gm.intervals["tau_c_s"]
    assert (lo, hi) == pytest.approx(tau_c_interval, rel=1e-3)
    assert lo < effect["tau_c_s"] < hi
    lo, hi = gm.intervals["sigma"]
    assert (lo, hi) == pytest.approx(sigma_interval, rel=1e-3)
    assert lo < effect["sigma"] < hi
