"""The independent generator of benchmarks/ (issue 13 validation) does what IEEE 952 says: each
process' Allan deviation (by allantools, not by imupipe) matches its coefficient, and its ROS 2
bag decodes to exactly the values generated."""

from __future__ import annotations

import sys
from pathlib import Path

import allantools
import numpy as np
import pytest
from scipy import signal, stats

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
import independent_generator as gen

from imupipe.io.decode import decode

TAU0 = 0.1
N = 1 << 17


def adev(y: np.ndarray, taus: list[float]) -> np.ndarray:
    return allantools.oadev(y, rate=1 / TAU0, data_type="freq", taus=np.array(taus))[1]


def test_white_rate_adev_at_one_second_is_n_within_its_interval():
    n_coef = 3e-4
    y = gen.white_rate(N, TAU0, n_coef, np.random.default_rng(1))
    (dev,) = adev(y, [1.0])
    edf = (N // 10) * 2 / 3  # white FM, m = 10: ~ (2/3) N/m (Greenhall & Riley 2003)
    lo, hi = (np.sqrt(edf / stats.chi2.ppf(q, edf)) for q in (0.995, 0.005))
    assert lo * n_coef < dev < hi * n_coef
    assert dev == pytest.approx(n_coef, rel=0.02)


def test_flicker_plateau_is_0664_b():
    b = 2e-5
    devs = [adev(gen.flicker_rate(N, TAU0, b, np.random.default_rng(s)), [1.0, 10.0, 100.0])
            for s in range(4)]  # fmt: skip
    plateau = np.sqrt(np.mean(np.square(devs), axis=0))
    np.testing.assert_allclose(plateau, np.sqrt(2 * np.log(2) / np.pi) * b, rtol=0.1)


def test_rate_random_walk_quantisation_and_ramp():
    k, q, r = 1e-6, 2e-6, 3e-7
    rng = np.random.default_rng(2)
    walks = [adev(gen.rate_random_walk(N, TAU0, k, rng), [100.0]) for _ in range(6)]
    assert np.sqrt(np.mean(np.square(walks))) == pytest.approx(k * np.sqrt(100 / 3), rel=0.15)
    (dq,) = adev(gen.quantisation_rate(N, TAU0, q, rng), [TAU0])
    assert dq == pytest.approx(np.sqrt(3) * q / TAU0, rel=0.02)
    (dr,) = adev(r * np.arange(N) * TAU0, [50.0])
    assert dr == pytest.approx(r * 50 / np.sqrt(2), rel=1e-6)
    model = gen.AxisNoise(1e-4, 0.0, k, q, r)
    assert model.adev(50.0) == pytest.approx(
        np.sqrt(1e-8 / 50 + k**2 * 50 / 3 + 3 * q**2 / 2500 + r**2 * 2500 / 2)
    )


def test_effect_is_on_one_axis_and_described():
    y, temp, truth = gen.generate(0.05, 50.0, 3, "sinusoid", 5.0)
    clean, _, _ = gen.generate(0.05, 50.0, 3)
    axis = gen.AXES.index(truth.effect["axis"])
    diff = y - clean
    assert np.count_nonzero(np.abs(diff).max(axis=0) > 0) == 1 and np.abs(diff[:, axis]).max() > 0
    assert np.abs(diff[:, axis]).max() == pytest.approx(truth.effect["amplitude"], rel=0.01)
    assert temp.shape == (9000,) and abs(temp.mean() - 25) < 1.5


def test_a_thermal_lag_is_the_temperature_through_a_first_order_lag():
    """The ``thermal_lag`` effect is c·(T_lag − mean) with dT_lag/dt = (T − T_lag)/lag, from
    rest: recovered here by a least-squares fit of the ODE's Euler form (not the generator's
    filter) — each step's change of the effect over the temperature's lead on it is 1/lag."""
    y, temp, truth = gen.generate(0.5, 10.0, 5, "thermal_lag", 10.0)
    clean, _, _ = gen.generate(0.5, 10.0, 5)
    axis = gen.AXES.index(truth.effect["axis"])
    effect = (y - clean)[:, axis]
    coef, lag = truth.effect["coefficient_per_degC"], truth.effect["lag_s"]
    assert 300 <= lag <= 1800 and coef > 0
    level = effect / coef  # T_lag up to its mean
    lead = temp[1:] - level[1:]  # up to the same constant: fit it as an offset
    step = np.diff(level) / 0.1
    (rate, _), *_ = np.linalg.lstsq(np.column_stack([lead, np.ones_like(lead)]), step)
    assert 1 / rate == pytest.approx(lag, rel=0.01)
    assert np.count_nonzero(np.abs(y - clean).max(axis=0) > 0) == 1


def test_a_shift_steps_gravity_on_both_horizontal_accelerometers_and_stays():
    """``shift``: a lasting tilt.  After the 1 s lean accel x and y stand g·sin θ·(cos φ, sin φ)
    above their clean values, as the truth's ``steps`` say; the larger one is size × its axis'
    ADEV at T/10 (a bias step's size) on the named axis; z moves by g(cos θ − 1) (~θ/2 of it);
    before the lean nothing differs."""
    y, _, truth = gen.generate(0.5, 10.0, 6, "shift", 10.0)
    clean, _, _ = gen.generate(0.5, 10.0, 6)
    e, diff = truth.effect, y - clean
    t = np.arange(len(y)) * 0.1
    after, before = t >= e["time_s"] + 1.0, t < e["time_s"]
    for b, name in ((3, "accel_x"), (4, "accel_y")):
        np.testing.assert_allclose(diff[after, b], e["steps"][name], rtol=1e-9)
        assert not diff[before, b].any()
    main = e["axis"]
    assert abs(e["steps"][main]) == max(abs(v) for v in e["steps"].values())
    assert abs(e["steps"][main]) == pytest.approx(10.0 * truth.noise[main].adev(180.0), rel=1e-9)
    z = 9.80665 * (np.cos(e["theta_rad"]) - 1)  # ~θ/2 of the larger step: 1e-4 of it here
    np.testing.assert_allclose(diff[after, 5], z, rtol=1e-6)


def test_bag_decodes_to_the_generated_values(tmp_path: Path):
    y, temp, _ = gen.generate(20 / 3600, 50.0, 4)
    gen.write_bag(tmp_path / "bag", y, temp, 50.0, 1_700_000_000_000_000_000)
    rec = decode(tmp_path / "bag")
    got = rec.frames.select(gen.AXES).to_numpy()
    np.testing.assert_array_equal(got, y)
    np.testing.assert_allclose(np.diff(rec.frames["t_s"].to_numpy()), 0.02, atol=1e-9)


def test_vibration_is_a_resonance_sampled_at_the_sensors_rate():
    """The vibration kind: white noise through a resonance run 8× faster than the sensor and
    sampled, its spectrum peaking at the resonance (here 31 Hz at 100 Hz, where an AR(2) at
    the sensor's own rate is another process), its half-power width f/Q; added at its rms."""
    rng = np.random.default_rng(4)
    x = gen._sampled_resonance(1 << 18, 0.01, 31.0, 50.0, rng)
    f, p = signal.welch(x, fs=100.0, nperseg=1 << 12)
    half = f[p > p.max() / 2]
    assert (half.max() + half.min()) / 2 == pytest.approx(31.0, abs=0.08)
    assert half.max() - half.min() == pytest.approx(31.0 / 50.0, rel=0.3)
    y, _, truth = gen.generate(0.2, 100.0, 5, "vibration", 3.0)
    clean, _, _ = gen.generate(0.2, 100.0, 5)
    axis = gen.AXES.index(truth.effect["axis"])
    assert np.std(y[:, axis] - clean[:, axis]) == pytest.approx(truth.effect["rms"], rel=1e-9)
    assert 5.0 <= truth.effect["frequency_hz"] <= 45.0
