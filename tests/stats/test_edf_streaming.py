"""The streaming lag-1 ACF noise identification equals, to the bit, the in-place algorithm.

``_oracle_*`` below is the previous implementation of imupipe.stats.edf (detrend and difference a
copy of the m-averaged series in place; Riley & Greenhall 2004), kept unchanged as the oracle:
the streaming kernel must form the same float64 values in the same order, so every r1, and
hence every alpha, is identical, while allocating nothing proportional to the series length.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from imupipe.stats.edf import ACF_MIN_POINTS, _acf_pass, _acf_power, acf_noise_id, noise_ids


@numba.njit
def _oracle_trend_sums(z):
    total = 0.0
    weighted = 0.0
    for i in range(z.size):
        total += z[i]
        weighted += i * z[i]
    return total, weighted


@numba.njit
def _oracle_lag1_acf_about(z, mean):
    num = 0.0
    den = (z[-1] - mean) ** 2
    for i in range(z.size - 1):
        a = z[i] - mean
        num += a * (z[i + 1] - mean)
        den += a * a
    return num / den if den > 0 else 0.0  # no variation left (a 2-point series): white


@numba.njit
def _oracle_consuming(z, total, weighted, dmax):
    size = z.size
    slope = (weighted - 0.5 * (size - 1) * total) / (size * (size**2 - 1.0) / 12.0)
    intercept = total / size - slope * 0.5 * (size - 1)
    acc = 0.0
    for i in range(size):
        z[i] = z[i] - (intercept + slope * i)
        acc += z[i]
    d = 0
    while True:
        r1 = _oracle_lag1_acf_about(z, acc / z.size)
        delta = r1 / (1.0 + r1)
        if delta < 0.25 or d >= dmax:
            return -2.0 * (delta + d)
        acc = 0.0
        for i in range(z.size - 1):
            z[i] = z[i + 1] - z[i]
            acc += z[i]
        z = z[:-1]
        d += 1


@numba.njit
def _oracle_acf_noise_id(ybar, dmax):
    total, weighted = _oracle_trend_sums(ybar)
    return _oracle_consuming(ybar.copy(), total, weighted, dmax)


@numba.njit
def _oracle_averaged(x, m):
    count = (x.size - 1) // m
    z = np.empty(count)
    total = 0.0
    weighted = 0.0
    for j in range(count):
        z[j] = x[(j + 1) * m] - x[j * m]
        total += z[j]
        weighted += j * z[j]
    return _oracle_consuming(z, total, weighted, 2)


def _outcome(f, *args):
    """f(*args), or the exception type (a division by zero in both versions)."""
    try:
        return f(*args)
    except ZeroDivisionError as exc:
        return type(exc)


def _flicker(rng: np.random.Generator, n: int) -> np.ndarray:
    """Flicker (1/f) noise: white noise shaped by 1/sqrt(f) in the frequency domain."""
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.arange(spectrum.size)
    spectrum[1:] /= np.sqrt(f[1:])
    return np.fft.irfft(spectrum, n)


def _series(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    """n rate samples of one power-law noise type, scaled, plus a random linear drift."""
    w = rng.standard_normal(n + 1)
    y = {
        "white_pm": np.diff(w),
        "flicker_pm": np.diff(_flicker(rng, n + 1)),
        "white_fm": w[:n],
        "flicker_fm": _flicker(rng, n),
        "random_walk_fm": np.cumsum(w[:n]),
        "random_run": np.cumsum(np.cumsum(w[:n])),  # alpha -4: differenced twice
    }[kind]
    drift = rng.normal() * rng.choice([0.0, 1e-4, 1.0]) * np.arange(n)
    return y * 10.0 ** rng.uniform(-6, 3) + drift


KINDS = ["white_pm", "flicker_pm", "white_fm", "flicker_fm", "random_walk_fm", "random_run"]


def _same(a, b) -> bool:
    """Equal to the bit (NaN equal to NaN), or the same exception type."""
    if isinstance(a, float) and isinstance(b, float):
        return np.float64(a).tobytes() == np.float64(b).tobytes()
    return a == b


@pytest.mark.parametrize("kind", KINDS)
def test_acf_estimate_is_bit_identical_to_in_place_algorithm(kind):
    """p = -2 (delta + d) before rounding, so any change in a single addition shows."""
    rng = np.random.default_rng(sum(map(ord, kind)))
    for n in [2, 3, 4, 5, 7, 30, 31, 100, *rng.integers(8, 5_000, 40)]:
        y = _series(rng, kind, int(n))
        for dmax in (0, 1, 2, 3):
            expected = _outcome(_oracle_acf_noise_id, y, dmax)
            assert _same(_outcome(_acf_power, y, 1, False, y.size, dmax), expected), (n, dmax)
            if isinstance(expected, float):
                assert acf_noise_id(y, dmax) == np.rint(expected)


@pytest.mark.parametrize("kind", KINDS)
def test_averaged_estimates_are_bit_identical_to_in_place_algorithm(kind):
    """Every m of a phase record (factor m, stride through x), and the alphas of noise_ids."""
    rng = np.random.default_rng(100 + sum(map(ord, kind)))
    for n in [30, 31, 61, 250, *rng.integers(100, 20_000, 25)]:
        x = np.concatenate(([0.0], np.cumsum(_series(rng, kind, int(n)))))
        m = np.unique(rng.integers(1, max(2, n // ACF_MIN_POINTS + 1), 12))
        m = m[(x.size - 1) // m >= ACF_MIN_POINTS]
        expected = [_oracle_averaged(x, int(k)) for k in m]
        for k, p in zip(m, expected, strict=True):
            assert _same(_acf_power(x, int(k), True, (x.size - 1) // k, 2), p), (n, k)
        np.testing.assert_array_equal(noise_ids(x, m), np.clip(np.rint(expected), -2, 2))


def test_series_kinds_exercise_every_difference_order():
    """The kinds above give alpha 2, 1, 0, -1, -2 and -4 (d = 0, 1 and 2 differences)."""
    rng = np.random.default_rng(3)
    alphas = [acf_noise_id(_series(rng, kind, 4_000), 3) for kind in KINDS]
    assert alphas == [2, 1, 0, -1, -2, -4]


def test_acf_pass_matches_direct_sums():
    """num, den and the next order's sum of the streaming pass, against numpy on the arrays."""
    rng = np.random.default_rng(5)
    x = np.concatenate(([0.0], np.cumsum(rng.standard_normal(3_001))))
    m, line = 3, (0.4, -2e-3)
    z = x[m::m] - x[:-m:m] - (line[0] + line[1] * np.arange((x.size - 1) // m))
    for d in range(4):
        zd = np.diff(z, d) - 0.25
        num, den, acc = _acf_pass(x, m, True, z.size, line, d, 0.25, np.empty(d + 2))
        assert num == pytest.approx(zd[:-1] @ zd[1:], rel=1e-12)
        assert den == pytest.approx(zd @ zd, rel=1e-12)
        assert acc == pytest.approx(np.diff(z, d + 1).sum(), rel=1e-9, abs=1e-9)


_RSS_SCRIPT = """
import os, threading, time
import numpy as np
from imupipe.stats import edf
from imupipe.stats.edf import noise_ids
edf.ACF_COPY_MAX = 1 << 16  # m-averaged series longer than 0.5 MB are streamed from the phase
x = np.concatenate(([0.0], np.cumsum(np.random.default_rng(1).standard_normal(8_000_000))))
m = np.array([1, 2, 3, 1000])
noise_ids(x[:100_001], m)  # compile or load the cached kernels first
page = os.sysconf("SC_PAGE_SIZE")
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * page
base, peak, done = rss(), [0], []
def sample():
    while not done:
        peak[0] = max(peak[0], rss())
        time.sleep(0.0005)
thread = threading.Thread(target=sample)
thread.start()
noise_ids(x, m)
done.append(1)
thread.join()
print((peak[0] - base) / 1e6)
"""


def test_noise_ids_allocates_nothing_proportional_to_n():
    """8 M samples: the m = 1 averaged series alone would be 64 MB; with series longer than
    2**16 values streamed, the peak grows < 8 MB."""
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run(
        [sys.executable, "-c", _RSS_SCRIPT], cwd=root, capture_output=True, text=True, check=True
    )
    assert float(out.stdout) < 8.0
