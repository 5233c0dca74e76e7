"""An IMU noise generator from the IEEE Std 952-1997 PSD definitions, independent of imupipe.

It shares no code with ``imupipe.recording.simulator``/``noise`` and does not import imupipe: it is
the "data we did not write" of issue 13's validation (``benchmarks/loop_validation.py``).

Noise of each axis (rate Ω in rad/s or m/s², sample interval τ0; IEEE 952 Annex C, two-sided
PSDs S_Ω(f), so that σ²(τ) = 4 ∫₀^∞ S_Ω(f) sin⁴(πfτ)/(πfτ)² df):

* white rate noise (angle random walk) N:  S_Ω = N²                → σ² = N²/τ;
  samples: N/√τ0 · n_k (variance S·(1/τ0) over the band ±1/(2τ0)).
* flicker (bias instability) B:  S_Ω = B²/(2π f)                    → σ² = (2 ln 2/π) B² (plateau);
  made in the frequency domain: complex Gaussian bins scaled by √(n S_Ω(f_k)/τ0), no power at
  DC, inverse real FFT of twice the length (the first half kept: no wrap-around).
* rate random walk K:  S_Ω = (K/2π)²/f²                             → σ² = K² τ/3;
  samples: a random walk with increments K √τ0 · n_k.
* quantisation Q:  S_θ = τ0 Q² (white angle noise of variance Q²)   → σ² = 3 Q²/τ²;
  rate samples: the first difference of that angle noise over τ0.
* rate ramp R:  Ω = R t                                             → σ² = R² τ²/2.

Plus at most one undeclared effect (:data:`EFFECT_KINDS`) on one axis, and optional rounding
to an LSB.  Written as a ROS 2 bag (``sensor_msgs/msg/Imu`` on ``/imu/data_raw`` and
``sensor_msgs/msg/Temperature`` on ``/imu/temperature`` at 1 Hz) with the ``rosbags`` writer;
each Imu message is serialised once by ``rosbags`` as a template and its stamp and six values
are written into copies (vectorised), so a 12 h / 400 Hz bag takes minutes, not hours.

Run ``python benchmarks/independent_generator.py OUT.bag --hours 2 --rate 100 --effect
sinusoid --size 3`` to write one recording and print its truth as JSON.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal

AXES = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
EFFECT_KINDS = (
    "temperature",
    "sinusoid",
    "narrowband",
    "gauss_markov",
    "bias_step",
    "ramp",
    "warmup",
    "event",
    "tilt",
    "outliers",
    "vibration",
    "thermal_lag",
    "prefilter",
    "lowpass",
    "shift",
)
"""Undeclared effects (``thermal_lag``: the temperature coupling through a first-order lag,
the heat reaching the sensing element after the thermometer; ``prefilter``: the sensor's own
low-pass filter on the axis' output, a moving average, Bartlett window or first-order
low-pass; ``lowpass``: a MEMS part's digital low-pass, a Butterworth of order 2 or 4 run at the
output rate, as the configurable DLPF of many MEMS IMUs; ``shift``: a lasting tilt, a step of
gravity's projection on accel x and y of different sizes at one instant).  A supply-voltage
coupling is not generated: a sensor_msgs/Imu bag carries no supply channel (nothing could be
coupled to it)."""
OVERSAMPLE = 8
"""A vibration is generated this many times faster than the sensor's rate and sampled."""
LN2 = np.log(2.0)


@dataclass(frozen=True)
class AxisNoise:
    """IEEE 952 coefficients of one axis (SI: N in unit/√Hz, B in unit, K in unit·√Hz/s...
    i.e. rad/s/√Hz, rad/s, rad/s²/√Hz, rad, rad/s² for a gyro)."""

    n: float
    b: float
    k: float
    q: float
    r: float = 0.0

    def adev(self, tau: np.ndarray | float) -> np.ndarray:
        """The model's Allan deviation at ``tau`` (s): the sum of the five terms' AVARs."""
        tau = np.asarray(tau, dtype=float)
        avar = (
            self.n**2 / tau
            + 2 * LN2 / np.pi * self.b**2
            + self.k**2 * tau / 3
            + 3 * self.q**2 / tau**2
            + self.r**2 * tau**2 / 2
        )
        return np.sqrt(avar)


@dataclass
class Truth:
    """What was generated: the noise of every axis and the undeclared effect (if any)."""

    hours: float
    rate_hz: float
    seed: int
    noise: dict[str, AxisNoise]
    effect: dict = field(default_factory=dict)  # kind, axis (axes), size, parameters

    def as_json(self) -> dict:
        return {
            "hours": self.hours,
            "rate_hz": self.rate_hz,
            "seed": self.seed,
            "noise": {a: asdict(v) for a, v in self.noise.items()},
            "effect": self.effect,
        }


def white_rate(n: int, tau0: float, coef: float, rng: np.random.Generator) -> np.ndarray:
    """White rate noise of two-sided PSD coef² (angle random walk N = coef)."""
    return coef / np.sqrt(tau0) * rng.standard_normal(n)


def flicker_rate(n: int, tau0: float, b: float, rng: np.random.Generator) -> np.ndarray:
    """Rate noise of two-sided PSD B²/(2π f) at every resolved frequency (no DC), by shaping
    white complex Gaussian bins in the frequency domain (length 2n, first half returned)."""
    m = 2 * n
    f = np.fft.rfftfreq(m, tau0)
    psd = np.zeros_like(f)
    psd[1:] = b**2 / (2 * np.pi * f[1:])
    amp = np.sqrt(m * psd / tau0)
    bins = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / np.sqrt(2)
    if m % 2 == 0:  # the Nyquist bin of a real series is real
        bins[-1] = amp[-1] * rng.standard_normal()
    return np.fft.irfft(bins, m)[:n]


def rate_random_walk(n: int, tau0: float, k: float, rng: np.random.Generator) -> np.ndarray:
    """A rate random walk of two-sided PSD (K/2π)²/f²: increments of variance K² τ0."""
    return np.cumsum(k * np.sqrt(tau0) * rng.standard_normal(n))


def quantisation_rate(n: int, tau0: float, q: float, rng: np.random.Generator) -> np.ndarray:
    """Rate from white angle noise of variance Q² (S_θ = τ0 Q²): first differences / τ0."""
    return np.diff(q * rng.standard_normal(n + 1)) / tau0


def axis_noise(noise: AxisNoise, n: int, tau0: float, rng: np.random.Generator) -> np.ndarray:
    """One axis' rate samples: the sum of the five IEEE 952 processes."""
    t = np.arange(n) * tau0
    return (
        white_rate(n, tau0, noise.n, rng)
        + flicker_rate(n, tau0, noise.b, rng)
        + rate_random_walk(n, tau0, noise.k, rng)
        + quantisation_rate(n, tau0, noise.q, rng)
        + noise.r * t
    )


def random_noise(axis: str, rng: np.random.Generator) -> AxisNoise:
    """Coefficients drawn log-uniformly over ranges typical of MEMS IMUs (gyro: rad/s...,
    accelerometer: m/s²...)."""
    u = rng.uniform
    if axis.startswith("gyro"):
        return AxisNoise(10 ** u(-3.7, -3.0), 10 ** u(-5.0, -4.2), 10 ** u(-7.0, -6.0),
                         10 ** u(-6.5, -5.5))  # fmt: skip
    return AxisNoise(10 ** u(-3.5, -2.8), 10 ** u(-4.6, -3.8), 10 ** u(-6.5, -5.5),
                     10 ** u(-6.0, -5.0))  # fmt: skip


def lab_temperature(n: int, tau0: float, rng: np.random.Generator) -> np.ndarray:
    """A lab temperature (°C): 25 + a slow cycle (0.3-1 K, period 40-120 min) + a small random
    walk.  Only the declared channel; couples into an axis only with the "temperature" effect."""
    t = np.arange(n) * tau0
    period = rng.uniform(2400, 7200)
    walk = np.cumsum(rng.standard_normal(n)) * 0.02 * np.sqrt(tau0 / 60)
    return 25 + rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * t / period + rng.uniform(0, 6.3)) + walk


def _sampled_resonance(
    n: int, tau0: float, f: float, q_factor: float, rng: np.random.Generator
) -> np.ndarray:
    """``n`` samples every ``tau0`` s of white noise through a resonance at ``f`` Hz of quality
    ``q_factor``, run as an AR(2) every τ0 / :data:`OVERSAMPLE` s in blocks (bounded memory)."""
    dt = tau0 / OVERSAMPLE
    r = np.exp(-np.pi * f * dt / q_factor)
    den = [1, -2 * r * np.cos(2 * np.pi * f * dt), r * r]
    state = np.zeros(2)
    out = np.empty(n)
    for start in range(0, n, 1 << 20):
        count = min(1 << 20, n - start)
        fine, state = signal.lfilter([1.0], den, rng.standard_normal(count * OVERSAMPLE), zi=state)
        out[start : start + count] = fine[::OVERSAMPLE]
    return out


def _lean(y: np.ndarray, lean: np.ndarray, theta: float, phi: float, tau0: float) -> None:
    """Add to the (n, 6) rate ``y`` in place a lean of the unit by ``theta`` × ``lean`` (rad;
    ``lean`` the fraction leant at each sample, 0..1) about the horizontal axis at azimuth
    ``phi``: gravity's projection on accel x and y, g sin(θ·lean) (cos/sin φ), and on z,
    g (cos(θ·lean) − 1); the gyros x and y see the rotation's rate."""
    rate = (np.diff(lean, prepend=0.0) / tau0) * theta
    y[:, 3] += 9.80665 * np.sin(theta * lean) * np.cos(phi)
    y[:, 4] += 9.80665 * np.sin(theta * lean) * np.sin(phi)
    y[:, 5] += 9.80665 * (np.cos(theta * lean) - 1)
    y[:, 0] += rate * np.sin(phi)
    y[:, 1] -= rate * np.cos(phi)


def add_effect(
    y: np.ndarray,
    temp: np.ndarray,
    kind: str,
    size: float,
    truth_noise: dict[str, AxisNoise],
    tau0: float,
    rng: np.random.Generator,
) -> dict:
    """Add one undeclared effect of ``kind`` to the (n, 6) rate ``y`` in place.

    ``size`` scales the effect against the noise where it shows: the effect's amplitude is
    ``size`` × the axis' noise ADEV at the effect's characteristic τ (sinusoid 0.371/f, its
    ADEV peak; Gauss-Markov 1.89 Tc; step/event: their duration or T/10; ramp and warm-up:
    T/4 and the warm-up time; temperature and its thermal lag: half its cycle); outliers:
    ``size`` × 10 × the white-noise sigma of one sample; the sensor's prefilter and a
    lowpass: its −3 dB bandwidth 0.2 / ``size`` of the sample rate.  Returns the effect's
    description (SI units)."""
    n = len(y)
    t = np.arange(n) * tau0
    duration = n * tau0
    a = int(rng.integers(6))
    axis = AXES[a]
    noise = truth_noise[axis]

    def amp_of(b: int, tau: float) -> float:
        return float(size * truth_noise[AXES[b]].adev(tau))

    def amp(tau: float) -> float:
        return amp_of(a, tau)

    out: dict = {"kind": kind, "axis": axis, "size": size}
    if kind == "sinusoid":
        f = 10 ** rng.uniform(-2.5, -0.5)
        amplitude = amp(0.371 / f)
        y[:, a] += amplitude * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        out |= {"frequency_hz": f, "amplitude": amplitude}
    elif kind == "narrowband":
        # a damped oscillator (second-order Gauss-Markov): white noise through a resonance
        f = 10 ** rng.uniform(-1.5, 0.3)
        q_factor = rng.uniform(20, 100)
        r = np.exp(-np.pi * f * tau0 / q_factor)
        x = signal.lfilter([1.0], [1, -2 * r * np.cos(2 * np.pi * f * tau0), r * r],
                           rng.standard_normal(n))  # fmt: skip
        rms = amp(0.371 / f)
        y[:, a] += rms * x / x.std()
        out |= {"frequency_hz": f, "q_factor": q_factor, "rms": rms}
    elif kind == "vibration":
        # a mechanical resonance (5 Hz up to 0.45 of the sample rate, often aliased from
        # above): white noise through a resonance generated OVERSAMPLE times faster, then
        # sampled instantaneously (an AR(2) at the sensor's rate is another process near Nyquist)
        f = 10 ** rng.uniform(np.log10(5.0), np.log10(0.45 / tau0))
        q_factor = rng.uniform(20, 100)
        x = _sampled_resonance(n, tau0, f, q_factor, rng)
        rms = amp(0.371 / f)
        y[:, a] += rms * x / x.std()
        out |= {"frequency_hz": f, "q_factor": q_factor, "rms": rms}
    elif kind == "gauss_markov":
        tc = 10 ** rng.uniform(0.5, 2.5)
        phi = np.exp(-tau0 / tc)
        sigma = amp(1.89 * tc)
        x = signal.lfilter([np.sqrt(1 - phi * phi)], [1, -phi], rng.standard_normal(n))
        y[:, a] += sigma * x
        out |= {"tau_c_s": tc, "sigma": sigma}
    elif kind == "bias_step":
        at = rng.uniform(0.2, 0.8) * duration
        step = amp(duration / 10) * rng.choice([-1, 1])
        y[t >= at, a] += step
        out |= {"time_s": at, "step": step}
    elif kind == "ramp":
        slope = amp(duration / 4) / (duration / 4) * np.sqrt(2) * rng.choice([-1, 1])
        y[:, a] += slope * (t - duration / 2)
        out |= {"slope_per_s": slope}
    elif kind == "warmup":
        tw = rng.uniform(300, 1800)
        amplitude = amp(tw) * 3 * rng.choice([-1, 1])
        y[:, a] += amplitude * np.exp(-t / tw)
        out |= {"tau_s": tw, "amplitude": amplitude}
    elif kind == "temperature":
        coef = amp(1800.0) / max(float(temp.std()), 1e-3)
        y[:, a] += coef * (temp - temp.mean())
        out |= {"coefficient_per_degC": coef}
    elif kind == "thermal_lag":
        lag = 10 ** rng.uniform(np.log10(300.0), np.log10(1800.0))
        a_lag = np.exp(-tau0 / lag)  # dT/dt = (temp - T)/lag, exact per sample, from rest
        lagged = signal.lfilter([1 - a_lag], [1, -a_lag], temp - temp[0]) + temp[0]
        coef = amp(1800.0) / max(float(lagged.std()), 1e-3)
        y[:, a] += coef * (lagged - lagged.mean())
        out |= {"coefficient_per_degC": coef, "lag_s": lag}
    elif kind == "event":
        # a bump of the table: 2-4 axes at once, 1-60 s, a box with cosine-tapered edges
        others = rng.choice([b for b in range(6) if b != a], int(rng.integers(1, 4)), replace=False)
        axes = sorted({a, *others.tolist()})
        at, length = rng.uniform(0.1, 0.9) * duration, rng.uniform(1, 60)
        inside = (t >= at) & (t < at + length)
        shape = signal.windows.tukey(int(inside.sum()), 0.2)
        sizes = {}
        for b in axes:
            s = size * truth_noise[AXES[b]].adev(length) * rng.choice([-1, 1]) * 3
            y[inside, b] += s * shape
            sizes[AXES[b]] = float(s)
        out |= {"axis": AXES[a], "axes": [AXES[b] for b in axes], "time_s": at,
                "duration_s": length, "sizes": sizes}  # fmt: skip
    elif kind == "tilt":
        # a tilt episode: the unit leans by theta about a random horizontal axis for 360 s and
        # comes back (1 s each way): gravity shifts accel x/y by g sin(theta) (cos/sin of the
        # azimuth) and accel z by g (cos(theta) - 1); the gyros see the 1 s rotations
        at, length, phi = rng.uniform(0.1, 0.8) * duration, 360.0, rng.uniform(0, 2 * np.pi)
        worst = max(truth_noise[AXES[b]].adev(length) for b in (3, 4))
        theta = float(np.arcsin(min(1.0, size * 3 * worst / 9.80665)))
        lean = np.clip((t - at) / 1.0, 0, 1) - np.clip((t - at - length) / 1.0, 0, 1)
        _lean(y, lean, theta, phi, tau0)
        out |= {"axis": "accel_x" if abs(np.cos(phi)) >= abs(np.sin(phi)) else "accel_y",
                "axes": ["accel_x", "accel_y"], "time_s": at, "duration_s": length,
                "theta_rad": theta, "azimuth_rad": phi}  # fmt: skip
    elif kind == "shift":
        # the unit leans by theta at a random time and stays (1 s to lean): gravity's
        # projection steps by g sin(theta) on accel x and y (cos/sin of the azimuth) and by
        # g (cos(theta) - 1) on z; the gyros see the 1 s rotation.  The larger of the x/y steps
        # is size x that axis' ADEV at T/10 (as a bias step's), the other a random share of it
        at, phi = rng.uniform(0.2, 0.8) * duration, rng.uniform(0, 2 * np.pi)
        main = 3 if abs(np.cos(phi)) >= abs(np.sin(phi)) else 4
        lean_of = max(abs(np.cos(phi)), abs(np.sin(phi)))
        theta = float(np.arcsin(min(1.0, amp_of(main, duration / 10) / (9.80665 * lean_of))))
        lean = np.clip((t - at) / 1.0, 0, 1)
        _lean(y, lean, theta, phi, tau0)
        steps = {"accel_x": 9.80665 * np.sin(theta) * np.cos(phi),
                 "accel_y": 9.80665 * np.sin(theta) * np.sin(phi)}  # fmt: skip
        out |= {"axis": AXES[main], "axes": ["accel_x", "accel_y"], "time_s": at,
                "theta_rad": theta, "azimuth_rad": phi, "steps": steps}  # fmt: skip
    elif kind == "prefilter":
        # the sensor's digital low-pass on everything the axis outputs (before the LSB
        # rounding): a moving average, a Bartlett window (two moving averages) or a first-order
        # low-pass whose -3 dB bandwidth is 0.2 / size of the sample rate
        family = str(rng.choice(["moving_average", "bartlett", "first_order"]))
        fc = 0.2 / (size * tau0)
        if family == "first_order":
            pole = np.exp(-2 * np.pi * fc * tau0)
            num, den = np.array([1 - pole]), np.array([1.0, -pole])
            length_s = -tau0 / np.log(pole)  # its time constant, 1 / (2π fc)
        else:
            taps = max(2, round((0.443 if family == "moving_average" else 0.3195) / (fc * tau0)))
            num = np.ones(taps) / taps
            if family == "bartlett":
                num = np.convolve(num, num)
            den = np.array([1.0])
            length_s = taps * tau0
        state = signal.lfilter_zi(num, den) * y[0, a]  # started at rest on the first sample
        y[:, a] = signal.lfilter(num, den, y[:, a], zi=state)[0]
        f, h = signal.freqz(num, den, worN=1 << 16, fs=1 / tau0)
        bandwidth = float(f[np.argmax(np.abs(h) ** 2 < 0.5)])
        out |= {"filter": family, "length_s": length_s, "bandwidth_3db_hz": bandwidth}
    elif kind == "lowpass":
        # a digital Butterworth low-pass (scipy's bilinear design, prewarped so that its -3 dB
        # point is exact) on everything the axis outputs, before the LSB rounding
        order = int(rng.choice([2, 4]))
        fc = 0.2 / (size * tau0)
        sos = signal.butter(order, fc, fs=1 / tau0, output="sos")
        y[:, a] = signal.sosfilt(sos, y[:, a], zi=signal.sosfilt_zi(sos) * y[0, a])[0]
        out |= {"filter": f"butterworth{order}", "order": order, "bandwidth_3db_hz": fc,
                "length_s": 1 / (2 * np.pi * fc)}  # fmt: skip
    elif kind == "outliers":
        count = int(rng.integers(30, 200))
        where = rng.choice(n, count, replace=False)
        sigma = noise.n / np.sqrt(tau0)
        y[where, a] += size * 10 * sigma * rng.uniform(1, 3, count) * rng.choice([-1, 1], count)
        out |= {"count": count, "min_size": size * 10 * sigma}
    else:
        raise ValueError(f"unknown effect {kind!r}; one of {', '.join(EFFECT_KINDS)}")
    return out


def generate(
    hours: float,
    rate_hz: float,
    seed: int,
    effect: str | None = None,
    size: float = 1.0,
    lsb: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray, Truth]:
    """(rate (n, 6) in rad/s and m/s², temperature (n,) °C, truth) of one recording; ``lsb``
    (gyro, accel): round the output to these steps (0: no rounding)."""
    rng = np.random.default_rng(seed)
    tau0 = 1.0 / rate_hz
    n = round(hours * 3600 * rate_hz)
    noise = {a: random_noise(a, rng) for a in AXES}
    y = np.column_stack([axis_noise(noise[a], n, tau0, rng) for a in AXES])
    y[:, 5] += 9.80665  # gravity on accel_z: a static unit, z up
    temp = lab_temperature(n, tau0, rng)
    described = add_effect(y, temp, effect, size, noise, tau0, rng) if effect else {}
    for cols, step in ((slice(0, 3), lsb[0]), (slice(3, 6), lsb[1])):
        if step > 0:
            y[:, cols] = np.round(y[:, cols] / step) * step
    return y, temp, Truth(hours, rate_hz, seed, noise, described)


def _template_offsets(typestore, imu) -> tuple[bytes, list[int]]:
    """A serialised Imu template and the byte offsets of sec, nanosec and the six values,
    found by serialising distinct sentinel values with rosbags."""
    sentinels = [np.pi * 1e-3 * (k + 1.234567) for k in range(6)]  # values found nowhere else
    msg = imu(12345678, 87654321, sentinels)
    raw = bytes(typestore.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
    offsets = [raw.index(np.uint32(12345678).tobytes()), raw.index(np.uint32(87654321).tobytes())]
    offsets += [raw.index(np.float64(v).tobytes()) for v in sentinels]
    return raw, offsets


def write_bag(path: Path, y: np.ndarray, temp: np.ndarray, rate_hz: float, t0_ns: int) -> None:
    """``y`` (n, 6) as sensor_msgs/Imu at ``rate_hz`` and the temperature at 1 Hz into a ROS 2
    bag (MCAP storage) at ``path`` with the rosbags writer."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types

    def imu(sec: int, nsec: int, v: list[float]):
        return T["sensor_msgs/msg/Imu"](
            header=T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="imu"
            ),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.full(9, -1.0),
            angular_velocity=T["geometry_msgs/msg/Vector3"](x=v[0], y=v[1], z=v[2]),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=T["geometry_msgs/msg/Vector3"](x=v[3], y=v[4], z=v[5]),
            linear_acceleration_covariance=np.zeros(9),
        )

    raw, offsets = _template_offsets(ts, imu)
    n = len(y)
    stamps = t0_ns + np.round(np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    every = max(1, round(rate_hz))
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data_raw", "sensor_msgs/msg/Imu", typestore=ts)
        tconn = writer.add_connection(
            "/imu/temperature", "sensor_msgs/msg/Temperature", typestore=ts
        )
        for start in range(0, n, 1 << 16):
            stop = min(n, start + (1 << 16))
            block = np.frombuffer(raw, np.uint8)[None, :].repeat(stop - start, 0)
            s = stamps[start:stop]
            block[:, offsets[0] : offsets[0] + 4] = (
                (s // 10**9).astype("<u4").view(np.uint8).reshape(-1, 4)
            )
            block[:, offsets[1] : offsets[1] + 4] = (
                (s % 10**9).astype("<u4").view(np.uint8).reshape(-1, 4)
            )
            for k in range(6):
                o = offsets[2 + k]
                block[:, o : o + 8] = (
                    np.ascontiguousarray(y[start:stop, k], "<f8").view(np.uint8).reshape(-1, 8)
                )
            for i in range(stop - start):
                writer.write(conn, int(s[i]), block[i].tobytes())
                if (start + i) % every == 0:
                    st = int(s[i])
                    msg = T["sensor_msgs/msg/Temperature"](
                        header=T["std_msgs/msg/Header"](
                            stamp=T["builtin_interfaces/msg/Time"](
                                sec=st // 10**9, nanosec=st % 10**9
                            ),
                            frame_id="imu",
                        ),
                        temperature=float(temp[start + i]),
                        variance=0.0,
                    )
                    writer.write(tconn, st, ts.serialize_cdr(msg, tconn.msgtype))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="bag directory to create")
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--effect", choices=EFFECT_KINDS, default=None)
    parser.add_argument("--size", type=float, default=1.0)
    args = parser.parse_args()
    y, temp, truth = generate(args.hours, args.rate, args.seed, args.effect, args.size)
    write_bag(args.out, y, temp, args.rate, 1_700_000_000_000_000_000)
    print(json.dumps(truth.as_json(), indent=1))


if __name__ == "__main__":
    main()
