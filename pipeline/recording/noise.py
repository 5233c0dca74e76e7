"""Streaming noise generators for the virtual ADIS16364.

Every generator draws its randomness from a :class:`NormalStream`, whose standard normals are
cut from fixed-size chunks keyed by ``(seed, key, chunk index)``, and carries its filter state
from one call to the next.  The output therefore depends only on the seed and the sample index,
never on how a run is split into blocks: ``take(10)`` then ``take(5)`` equals ``take(15)``
(to the last bit; the rate random walk's running sum, restarted from its state, to rounding).

Units: a generator's output has the unit of its coefficient's numerator (°/s for gyros, mg
for accelerometers in this project).  Coefficients follow IEEE Std 952-1997, Annex C:

* white noise (angle/velocity random walk) ``N`` [unit·s^-1/2]: Allan deviation N/√τ;
* flicker noise (bias instability) ``B`` [unit]: one-sided PSD B²/(π f), Allan deviation
  plateau √(2 ln 2/π)·B = 0.664·B;
* rate random walk ``K`` [unit·s^-1/2 per s, i.e. unit/√s]: Allan deviation K·√(τ/3);
* first-order Gauss–Markov ``(sigma, tau_c)``: stationary std ``sigma``, correlation time
  ``tau_c`` [s] (exact discretisation x[k+1] = a·x[k] + sigma·√(1-a²)·w, a = exp(-dt/tau_c)).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

CHUNK = 1 << 16
"""Standard normals per keyed chunk."""

FLICKER_PLATEAU = math.sqrt(2.0 * math.log(2.0) / math.pi)
"""Allan deviation plateau of flicker noise per unit B (IEEE 952 eq. C.14: 0.664)."""


def keyed_rng(seed: int, *key: int) -> np.random.Generator:
    """Independent generator for ``(seed, *key)`` (PCG64 seeded by a SeedSequence)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, *key])))


class NormalStream:
    """Block-size independent stream of standard normals (float64)."""

    def __init__(self, seed: int, *key: int) -> None:
        self._seed = seed
        self._key = key
        self._chunk_index = 0
        self._buffer = np.empty(0)

    def take(self, n: int) -> np.ndarray:
        """The next ``n`` standard normals."""
        parts = [self._buffer]
        have = len(self._buffer)
        while have < n:
            chunk = keyed_rng(self._seed, *self._key, self._chunk_index).standard_normal(CHUNK)
            self._chunk_index += 1
            parts.append(chunk)
            have += CHUNK
        joined = np.concatenate(parts) if len(parts) > 1 else self._buffer
        self._buffer = joined[n:]
        return joined[:n]


class GaussMarkov:
    """First-order Gauss–Markov process sampled every ``dt_s`` seconds, started stationary."""

    def __init__(self, sigma: float, tau_c_s: float, dt_s: float, stream: NormalStream) -> None:
        self.sigma = sigma
        self._a = math.exp(-dt_s / tau_c_s)
        self._stream = stream
        self._state: float | None = None

    def take(self, n: int) -> np.ndarray:
        if self._state is None:
            self._state = self.sigma * float(self._stream.take(1)[0])
        drive = self.sigma * math.sqrt(1.0 - self._a**2) * self._stream.take(n)
        out, _ = signal.lfilter([1.0], [1.0, -self._a], drive, zi=[self._a * self._state])
        if n:
            self._state = float(out[-1])
        return out


class RateRandomWalk:
    """Rate random walk of coefficient ``k`` (unit/√s): increments of std k·√dt per sample."""

    def __init__(self, k: float, dt_s: float, stream: NormalStream) -> None:
        self._step = k * math.sqrt(dt_s)
        self._stream = stream
        self._state = 0.0

    def take(self, n: int) -> np.ndarray:
        out = self._state + np.cumsum(self._step * self._stream.take(n))
        if n:
            self._state = float(out[-1])
        return out


class FlickerNoise:
    """Flicker (1/f) noise with bias-instability coefficient ``b``, sampled every ``dt_s``.

    White noise drives a cascade of first-order pole–zero sections (Keshner, "1/f noise",
    Proc. IEEE 70(3), 1982): poles log-spaced at ``SECTIONS_PER_DECADE`` per decade from
    ``f_lo_hz`` up to the Nyquist frequency, each zero half a spacing above its pole, so the
    magnitude alternates between slope 0 and -20 dB/decade and averages to the 1/f power law.
    The gain makes the one-sided PSD B²/(π f), hence an Allan deviation plateau 0.664·B for
    1/(2π·f_nyquist) ≪ τ ≪ 1/(2π·f_lo).  Below ``f_lo_hz`` the PSD is flat.  The filter starts
    from rest, so the process starts at zero (the configured mean holds at turn-on).
    """

    SECTIONS_PER_DECADE = 2

    def __init__(self, b: float, dt_s: float, stream: NormalStream, f_lo_hz: float = 1e-6) -> None:
        self.b = b
        spacing = 10.0 ** (1.0 / self.SECTIONS_PER_DECADE)
        f_nyquist = 0.5 / dt_s
        n_sections = math.floor(math.log(f_nyquist / f_lo_hz, spacing))
        f_pole = f_lo_hz * spacing ** np.arange(n_sections)
        f_zero = f_pole * math.sqrt(spacing)
        poles = np.exp(-2.0 * np.pi * f_pole * dt_s)
        zeros = np.exp(-2.0 * np.pi * f_zero * dt_s)
        sos = np.zeros((n_sections, 6))
        sos[:, 0] = 1.0
        sos[:, 1] = -zeros
        sos[:, 3] = 1.0
        sos[:, 4] = -poles
        # Gain from the mean of f·|H|² over whole ripple periods inside the band.
        f_eval = np.geomspace(f_pole[2], f_pole[-3], 64 * (n_sections - 5), endpoint=False)
        _, response = signal.sosfreqz(sos, worN=f_eval, fs=1.0 / dt_s)
        h_minus1 = b**2 / math.pi  # one-sided PSD coefficient, unit²
        # one-sided PSD of unit white noise sampled every dt: 2·dt
        gain = math.sqrt(h_minus1 / (2.0 * dt_s * float(np.mean(f_eval * np.abs(response) ** 2))))
        sos[:, :3] *= gain ** (1.0 / n_sections)
        self.sos = sos
        self._zi = np.zeros((n_sections, 2))
        self._stream = stream

    def take(self, n: int) -> np.ndarray:
        if n == 0:  # (sosfilt refuses an empty input with its state)
            return np.empty(0)
        out, self._zi = signal.sosfilt(self.sos, self._stream.take(n), zi=self._zi)
        return out
