"""AVAR of the narrowband-vibration and prefilter terms against independent PSD integrals.

Each closed form of :mod:`imupipe.model.effects` is checked against a numerical integration
written here from the PSD alone (IEEE Std 952-1997 Annex C: σ²(τ) = 4∫ S(f) sin⁴(πfτ)/(πfτ)² df
for a continuous rate, the limit τ0 → 0; for a sampled one the discrete kernel
(4/m²) sin⁴(πfmτ0)/sin²(πfτ0) over the aliased PSD), so a wrong sign, factor or
parametrisation of the implementation fails; the sinusoid's also against the Allan sums of a
sampled sinusoid.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import integrate

from imupipe.model import ieee952
from imupipe.model.effects import (
    gauss_markov_avar,
    oscillator_avar,
    prefilter_avar,
    sinusoid_avar,
)
from imupipe.stats.allan import allan_curves

TAU = np.array([0.03, 0.2, 0.5, 1.0, 1.7, 4.0, 12.0, 60.0, 400.0])


def oscillator_psd(f: np.ndarray, f0: float, width_hz: float) -> np.ndarray:
    """Two-sided PSD (1/Hz) of a unit-variance damped oscillator x'' + 2a x' + ω0² x = w:
    q / ((ω0² − ω²)² + 4a²ω²) with q = 4aω0² (variance q / (4aω0²) = 1), a = π·width,
    ω0² = (2π f0)² + a²."""
    a = np.pi * width_hz
    w0sq = (2 * np.pi * f0) ** 2 + a**2
    w = 2 * np.pi * f
    return 4 * a * w0sq / ((w0sq - w**2) ** 2 + 4 * a**2 * w**2)


@pytest.mark.parametrize(("f0", "width"), [(0.56, 0.02), (1.69, 0.3), (0.05, 0.004)])
def test_oscillator_avar_matches_psd_integral(f0, width):
    closed = oscillator_avar(TAU, f0, width, 1e-6)  # the continuous-time limit
    for t, c in zip(TAU, closed, strict=True):

        def integrand(f, t=t):
            return (
                4 * oscillator_psd(f, f0, width) * np.sin(np.pi * f * t) ** 4 / (np.pi * f * t) ** 2
            )

        edges = [0, f0 - 5 * width, f0 + 5 * width, 20 * f0 + 50 / t]
        num = sum(
            integrate.quad(integrand, max(lo, 0), hi, limit=2000, epsabs=0, epsrel=1e-8)[0]
            for lo, hi in itertools.pairwise(edges)
            if hi > max(lo, 0)
        )
        num += integrate.quad(integrand, edges[-1], np.inf, limit=500)[0]
        assert c == pytest.approx(num, rel=1e-3), t


def test_oscillator_unit_variance_psd_and_sinusoid_limit():
    # the test's PSD integrates to the unit variance the closed form assumes
    var = 2 * sum(
        integrate.quad(oscillator_psd, lo, hi, args=(0.56, 0.02), limit=500)[0]
        for lo, hi in ((0, 0.46), (0.46, 0.66), (0.66, 10), (10, np.inf))
    )
    assert var == pytest.approx(1.0, rel=1e-5)
    # a line far narrower than 1/τ is a random-phase sinusoid of variance 1 (amplitude √2)
    tau = TAU[TAU < 20]
    np.testing.assert_allclose(
        oscillator_avar(tau, 0.56, 1e-7, 0.01),
        2 * sinusoid_avar(tau, 0.56, 0.01),
        rtol=1e-4,
        atol=1e-6,
    )
    # long τ: the spread line's power is white at S(0) = 4a/ω0², σ² → S(0)/τ
    a = np.pi * 0.02
    s0 = 4 * a / ((2 * np.pi * 0.56) ** 2 + a**2)
    assert oscillator_avar(np.array([5000.0]), 0.56, 0.02, 0.01)[0] * 5000 == pytest.approx(
        s0, rel=1e-2
    )


def discrete_kernel(f: np.ndarray, m: np.ndarray, tau0: float) -> np.ndarray:
    """The Allan variance's transfer function for samples every τ0 at τ = mτ0 (two-sided)."""
    return (
        4
        / m[:, None] ** 2
        * np.sin(np.pi * f * m[:, None] * tau0) ** 4
        / np.sin(np.pi * f * tau0) ** 2
    )


@pytest.mark.parametrize(("f0", "width"), [(31.0, 0.3), (45.0, 2.0), (3.0, 0.5)])
def test_sampled_oscillator_avar_matches_the_aliased_psd_integral(f0, width):
    """At 100 Hz a line at 31 or 45 Hz: the AVAR of the samples is the aliased PSD against the
    discrete kernel, 1.39× / 2.05× the continuous form's near the line's peak τ."""
    tau0, m = 0.01, np.array([1, 2, 3, 5, 8, 16, 40, 100, 1000])
    fs = 1 / tau0
    f = (np.arange(200_000) + 0.5) * (fs / 2) / 200_000
    aliased = sum(oscillator_psd(np.abs(f + j * fs), f0, width) for j in range(-50, 51))
    expected = (aliased * discrete_kernel(f, m, tau0)).sum(1) * (fs / 2) / 200_000
    np.testing.assert_allclose(oscillator_avar(m * tau0, f0, width, tau0), expected, rtol=2e-3)


def test_sampled_sinusoid_avar_is_the_allan_sums_of_its_samples():
    """2^16 samples of a 31 Hz sinusoid at 100 Hz (a vibration aliased near Nyquist): the
    Allan sums equal the sampled form within 1 %; the continuous form is 1.3865× low
    ((π f0 τ0 / sin π f0 τ0)²)."""
    tau0, n = 0.01, 1 << 16
    m = np.array([1, 2, 3, 4, 5, 7, 10, 33])
    y = 0.3 * np.sin(2 * np.pi * 31.0 * np.arange(n) * tau0 + 0.4)
    (curve,) = allan_curves([y], tau0, m)
    expected = 0.09 * sinusoid_avar(m * tau0, 31.0, tau0)
    np.testing.assert_allclose(np.asarray(curve.adev) ** 2, expected, rtol=1e-2)
    x = np.pi * 31.0 * m * tau0
    continuous = 0.09 * np.sin(x) ** 4 / x**2
    np.testing.assert_allclose(expected / continuous, 1.38652, rtol=1e-4)


def test_sampled_gauss_markov_avar_is_the_ar1_sum():
    """A Gauss–Markov process of Tc = 2 samples, sampled: an AR(1) of coefficient e^{-1/2};
    its AVAR from the autocovariance sum, and → the continuous form for τ0 ≪ Tc."""
    tau0, tc = 0.01, 0.02
    m = np.array([1, 2, 3, 10, 100])
    r = np.exp(-np.arange(400) * tau0 / tc)

    def var_mean(q: int) -> float:
        k = np.arange(1, q)
        return (q + 2 * np.sum((q - k) * r[k])) / q**2

    expected = [2 * var_mean(q) - 2 * var_mean(2 * q) for q in m]
    np.testing.assert_allclose(gauss_markov_avar(m * tau0, tc, tau0), expected, rtol=1e-9)
    tau = np.array([0.5, 3.0, 40.0])
    a = tau / 2.0
    continuous = 2 * 2.0 / tau * (1 - (3 - 4 * np.exp(-a) + np.exp(-2 * a)) / (2 * a))
    np.testing.assert_allclose(gauss_markov_avar(tau, 2.0, 1e-4), continuous, rtol=1e-6)


def gain(kind: str, f: np.ndarray, length: float) -> np.ndarray:
    """|H(f)|² of each prefilter family (DC gain 1)."""
    if kind == "moving_average":
        return np.sinc(f * length) ** 2
    if kind == "bartlett":
        return np.sinc(f * length) ** 4
    return 1.0 / (1.0 + (2 * np.pi * f * length) ** 2)


def sampled_avar(kind: str, length: float, tau0: float, m: np.ndarray) -> np.ndarray:
    """AVAR of white noise through |H|², sampled every τ0, per unit long-run PSD: the aliased
    PSD Σ_j |H(f + j/τ0)|² normalised to 1 at f = 0, integrated against the discrete kernel."""
    fs = 1 / tau0
    f = (np.arange(50_000) + 0.5) * (fs / 2) / 50_000
    images = np.arange(-400, 401) * fs
    aliased = np.zeros_like(f)
    for image in images:  # one image at a time: all 801 at once peak at ~10 GB
        aliased += gain(kind, f + image, length)
    aliased /= gain(kind, images, length).sum()
    kernel = (
        4
        / m[:, None] ** 2
        * np.sin(np.pi * f * m[:, None] * tau0) ** 4
        / np.sin(np.pi * f * tau0) ** 2
    )
    return (aliased * kernel).sum(1) * (fs / 2) / 50_000


@pytest.mark.parametrize(
    ("kind", "length"),
    [("moving_average", 0.035), ("bartlett", 0.0108), ("bartlett", 0.1), ("first_order", 0.004)],
)
def test_prefilter_avar_matches_aliased_psd_integral(kind, length):
    tau0 = 0.01
    m = np.array([1, 2, 3, 5, 8, 16, 40, 100])
    expected = sampled_avar(kind, length, tau0, m)
    np.testing.assert_allclose(prefilter_avar(m * tau0, tau0, kind, length), expected, rtol=1e-2)


def test_prefilter_term_is_a_short_tau_deficit_of_the_white_noise():
    tau0, tau = 0.01, np.array([0.01, 0.02, 0.04, 1.0, 10.0])
    deficit = ieee952.effect_shape("prefilter", ("bartlett", 0.04, tau0), tau0)(tau)
    # white noise through a low-pass: less variance at short τ, the white level at long τ
    assert np.all(deficit < 0)
    # past the filter's length the deficit is exactly -P/τ² (a FIR filter), so against the
    # white level 1/τ it falls tenfold per decade: 2.76e-3 at 10 s for a 40 ms Bartlett
    assert deficit[3] * tau[3] ** 2 == pytest.approx(deficit[4] * tau[4] ** 2, rel=1e-9)
    assert abs(deficit[-1]) * tau[-1] < 3e-3
    assert deficit[0] * tau[0] < -0.5
