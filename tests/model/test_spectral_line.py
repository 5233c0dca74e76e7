"""The spectrum's view of a spread line's centre (imupipe.model.spectral_line): the Whittle fit
of the damped oscillator's PSD gives an interval that covers the true centre, where the strongest
bin's tone interval (effects.psd_line) does not."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, signal

from imupipe.model import effects, spectral_line

TAU0, N = 0.1, 2**16
F0, WIDTH = 0.5, 0.01  # Hz: a line 65 bins wide


def spread_line(seed: int) -> np.ndarray:
    """A damped oscillator at F0 with full width WIDTH (rms 1) in white noise (rms 1)."""
    rng = np.random.default_rng(seed)
    r = np.exp(-np.pi * WIDTH * TAU0)
    ar = [1, -2 * r * np.cos(2 * np.pi * F0 * TAU0), r * r]
    x = signal.lfilter([1.0], ar, rng.standard_normal(N))
    return x / x.std() + rng.standard_normal(N)


def centre(y: np.ndarray) -> tuple[spectral_line.LineCentre, dict]:
    peak = effects.psd_line(y, TAU0, F0 / 1.2, F0 * 1.2)
    freqs, power = effects.hann_periodogram(y, TAU0, F0 / 1.2, F0 * 1.2)
    widths = np.geomspace(1 / (N * TAU0), 0.5 * F0, 14)
    return spectral_line.line_centre(freqs, power, peak["frequency_hz"], widths), peak


def test_oscillator_psd_has_unit_variance_and_its_width():
    psd = spectral_line.oscillator_psd
    below, _ = integrate.quad(psd, 0, F0, args=(F0, WIDTH), limit=500)
    above, _ = integrate.quad(psd, F0, np.inf, args=(F0, WIDTH), limit=500)
    var = 2 * (below + above)  # a two-sided, even PSD
    assert var == pytest.approx(1.0, rel=1e-3)
    top = spectral_line.oscillator_psd(F0, F0, WIDTH)
    half = spectral_line.oscillator_psd(np.array([F0 - WIDTH / 2, F0 + WIDTH / 2]), F0, WIDTH)
    assert half / top == pytest.approx(0.5, abs=0.01)


def test_every_second_hann_bin_in_the_band():
    y = np.sin(2 * np.pi * 0.5 * np.arange(N) * TAU0)
    freqs, power = effects.hann_periodogram(y, TAU0, 0.4, 0.6)
    step = 1 / (N * TAU0)
    k = np.rint(freqs / step).astype(int)
    assert np.all(k % 2 == 0) and np.all(np.diff(k) == 2)
    assert 0.4 <= freqs[0] < 0.4 + 2 * step and 0.6 - 2 * step < freqs[-1] <= 0.6
    assert freqs[np.argmax(power)] == pytest.approx(0.5, abs=step)


def test_the_centre_interval_covers_a_spread_line():
    covered, tone_covered = 0, 0
    for seed in range(8):
        c, peak = centre(spread_line(seed))
        covered += c.lo < F0 < c.hi
        tone_covered += peak["frequency_lo"] < F0 < peak["frequency_hi"]
        assert 0.05 * WIDTH < c.hi - c.lo < WIDTH  # a fraction of the width, not of a bin
        assert c.width_hz == pytest.approx(WIDTH, rel=0.5)
    assert covered >= 7  # 95 % nominal
    assert tone_covered <= 2  # the strongest bin's tone interval: the bug this replaces


def test_too_few_ordinates_give_no_centre():
    freqs = np.linspace(0.1, 0.2, 7)
    assert spectral_line.line_centre(freqs, np.ones(7), 0.15, np.array([0.01])) is None
