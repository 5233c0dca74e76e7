"""Builders shared by the model tests: rate series with known IEEE 952 terms."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

DEG = np.pi / 180


def _synth_rate(n, tau0, rng, n_white=0.0, b_flicker=0.0, k_rrw=0.0, q=0.0) -> np.ndarray:
    """Rate samples with known IEEE 952 terms (SI): white N, flicker B, RRW K, quantisation Q.

    Flicker has the two-sided PSD B²/(2πf) of IEEE 952 Annex C.
    """
    fs = 1 / tau0
    y = n_white / np.sqrt(tau0) * rng.standard_normal(n)
    if b_flicker:  # synthesised 8x longer and cut, so the record is not periodic
        f = np.fft.rfftfreq(8 * n, tau0)
        shape = np.zeros_like(f)
        shape[1:] = np.sqrt(b_flicker**2 / (2 * np.pi * f[1:]) * fs)  # two-sided S, IEEE 952
        y += np.fft.irfft(np.fft.rfft(rng.standard_normal(8 * n)) * shape, 8 * n)[:n]
    if k_rrw:
        y += np.cumsum(k_rrw * np.sqrt(tau0) * rng.standard_normal(n))
    if q:
        y += np.diff(q * rng.standard_normal(n + 1)) / tau0
    return y


@dataclass(frozen=True)
class PaperGyro:
    """The paper's measured ADIS16364 gyro terms in SI: N = 0.05 °/√s, B = 0.008 °/s."""

    n: float = 0.05 * DEG  # rad/s/√Hz
    b: float = 0.008 * DEG  # rad/s

    def rate(self, n: int, tau0: float, rng: np.random.Generator) -> np.ndarray:
        """``n`` rate samples (rad/s) at ``tau0`` (s) with this white noise and flicker."""
        return _synth_rate(n, tau0, rng, self.n, self.b)


@pytest.fixture(scope="session")
def synth_rate() -> Callable[..., np.ndarray]:
    """The builder ``synth_rate(n, tau0, rng, n_white, b_flicker, k_rrw, q)`` (SI)."""
    return _synth_rate


@pytest.fixture(scope="session")
def paper_gyro() -> PaperGyro:
    return PaperGyro()
