"""The loop does its full-rate work once per axis, whatever the number of rounds: the spike
search (none when the caller's outlier search already found nothing) and the hold-out curves
of the two halves.  A round that searched again would cost a full-rate pass each time (24 h at
1 kHz: tens of seconds per axis) and must give the same model."""

from __future__ import annotations

import numpy as np
import pytest

from imupipe.model import effects, loop
from imupipe.model.loop import AxisSignals, close_loop
from imupipe.stats.allan import allan_curves

TAU0, N = 0.1, 2**17  # 3.6 h at 10 Hz
WHITE = 8.7e-4 / np.sqrt(TAU0)  # rad/s per sample: N = 0.05 deg/sqrt(h), the paper's gyro


@pytest.fixture(scope="module")
def sinusoid_axis() -> tuple[np.ndarray, object]:
    """White noise plus a 0.02 Hz, 3 mrad/s sinusoid (the loop accepts it in round 1 and
    searches again in round 2), and its Allan curve."""
    rng = np.random.default_rng(11)
    t = np.arange(N) * TAU0
    y = WHITE * rng.standard_normal(N) + 3e-3 * np.sin(2 * np.pi * 0.02 * t + 0.3)
    return y, allan_curves(y, TAU0)[0]


def counting(monkeypatch, owner, name) -> list[int]:
    calls = [0]
    original = getattr(owner, name)

    def wrapped(*args, **kwargs):
        calls[0] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(owner, name, wrapped)
    return calls


def test_spike_search_and_half_curves_run_once_over_several_rounds(monkeypatch, sinusoid_axis):
    y, curve = sinusoid_axis
    searches = counting(monkeypatch, effects, "spike_candidate")
    halves = counting(monkeypatch, loop._Axis, "_half_curves")
    res = close_loop(AxisSignals("gyro_x", "gyro", y, TAU0, None, None), curve)
    assert [e.kind for e in res.accepted][:1] == ["sinusoid"]  # so a second round ran
    assert searches[0] == 1
    assert halves[0] == 1  # no spikes: the halves without a correction (one hold-out here)


def test_spike_free_series_is_not_searched_again_and_gives_the_same_model(
    monkeypatch, sinusoid_axis
):
    y, curve = sinusoid_axis
    searched = close_loop(AxisSignals("gyro_x", "gyro", y, TAU0, None, None), curve)
    searches = counting(monkeypatch, effects, "spike_candidate")
    trusted = close_loop(AxisSignals("gyro_x", "gyro", y, TAU0, None, None, spike_free=True), curve)
    assert searches[0] == 0
    assert trusted.terms_after.random_walk.value == searched.terms_after.random_walk.value
    assert [e.kind for e in trusted.accepted] == [e.kind for e in searched.accepted]
    assert [c.kind for c in trusted.rejected] == [c.kind for c in searched.rejected]


def test_accepted_spikes_give_the_allan_curve_of_the_corrected_series():
    """Spikes the loop accepts (twelve 0.5 s rectangles of 20 σ: they bend the curve at short
    τ) are removed at full rate: its curve after is the overlapping Allan deviation of the
    series minus the spike correction, at every τ (allan_curves of the corrected copy)."""
    rng = np.random.default_rng(1)
    y = WHITE * rng.standard_normal(N)
    for at in rng.choice(N - 10, 12, replace=False):
        y[at : at + 5] += 20 * WHITE
    res = close_loop(AxisSignals("gyro_x", "gyro", y, TAU0, None, None), allan_curves(y, TAU0)[0])
    assert [e.kind for e in res.accepted] == ["spike"]
    fix = effects.spike_candidate(y, TAU0).spikes
    assert len(fix.index) == 60  # every sample of the rectangles
    corrected = y.copy()
    corrected[fix.index] -= fix.value
    expected = allan_curves(corrected, TAU0)[0]
    assert res.tau_s == pytest.approx(np.asarray(expected.tau_s), rel=1e-12)
    assert res.adev_after == pytest.approx(np.asarray(expected.adev), rel=1e-12)


def test_a_shape_column_is_computed_once_and_is_the_one_of_its_own_tau_and_sample_interval(
    monkeypatch,
):
    """The loop's effect columns are kept by kind, shape, τ0 and τ: asked again, the very same
    read-only column, not computed again; another τ grid or another τ0 gets its own column
    (a key that forgot either would hand a 100 Hz axis a 10 Hz axis' prefilter)."""
    loop._shape_column.cache_clear()
    calls = counting(monkeypatch, loop.ieee952, "effect_shape")
    tau = np.geomspace(0.01, 100.0, 40)
    spec = ("moving_average", 0.16, 0.01)
    column = loop._shape("prefilter", 0.01)(tau, spec)
    again = loop._shape("prefilter", 0.01)(tau.copy(), spec)
    assert again is column and calls[0] == 1
    assert not column.flags.writeable
    np.testing.assert_array_equal(column, loop.ieee952.effect_shape("prefilter", spec, 0.01)(tau))
    other_tau = loop._shape("prefilter", 0.01)(tau[::2], spec)
    np.testing.assert_array_equal(other_tau, column[::2])
    other_tau0 = loop._shape("prefilter", 0.005)(tau, spec)
    assert calls[0] == 4
    expected = loop.ieee952.effect_shape("prefilter", spec, 0.005)(tau)
    np.testing.assert_array_equal(other_tau0, expected)
    assert not np.array_equal(other_tau0, column)
