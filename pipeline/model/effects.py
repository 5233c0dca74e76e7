"""Candidate effects the IEEE 952 noise model lacks, each found from the data alone.

Two families (issue 4):

* time-domain corrections on the decimated series (block means, ~1 s): temperature and supply
  coupling, bias step, warm-up drift, and spikes (robust z on the full-rate series).  Their
  coefficients come from a *spectral GLS*: the first differences of series and regressors are
  whitened by the rate PSD of the axis' own fitted IEEE 952 model (white N², flicker
  B²/(2π f) below the cut-off, rate random walk K²/(2π f)², Gauss–Markov 2σ²Tc/(1 + (2π f Tc)²);
  two-sided, IEEE Std 952-1997 Annex C) and regressed by ordinary least squares (Whittle
  approximation of the Gaussian likelihood, Whittle 1953).  Differencing makes flicker and rate
  random walk stationary, so the coefficient covariance accounts for them — an AR(p)
  pre-whitening does not, and overstates the evidence under flicker noise.  The zero-frequency
  bin is dropped: a constant rate offset and a linear rate ramp never explain a candidate (the
  ramp is the model's own R term).  A candidate chosen among m options (lags, change points,
  time constants) pays for the choice with a Bonferroni factor m on its p-value.
* extra Allan-variance model terms (unit amplitude columns over τ):
  sinusoid A·sin(2π f0 t):  A² sin⁴(π f0 τ) / (π f0 τ)²          (peak near τ = 0.371 / f0)
  first-order Gauss–Markov, variance σ², correlation time Tc:
  (2σ² Tc / τ) [1 − (Tc / 2τ)(3 − 4 e^{−τ/Tc} + e^{−2τ/Tc})]       (peak near τ = 1.89 Tc)
  (IEEE Std 952-1997 Annex C; El-Sheimy, Hou & Niu, IEEE TIM 57(1), 2008, Table I): the
  continuous-time forms, the limit τ0 → 0 of the exact AVAR of the samples the columns use
  (:func:`sinusoid_avar`, :func:`sampled_avar`).
"""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numba
import numpy as np
import scipy.fft
from numba.extending import get_cython_function_address
from scipy import interpolate, linalg, optimize, special

from imupipe.jit import cores_here, kernel_input, on_parts, part_bounds, parts, spread
from imupipe.stats import robust
from imupipe.stats.allan import NO_CORRECTION, SparseCorrection
from imupipe.vocab import CHI2_95

Z95 = float(special.ndtri(0.975))  # scipy.stats.norm.ppf, without importing scipy.stats
LAGS_S = tuple(30.0 * 10.0 ** (k / 2) for k in range(6))
"""A coupling's first-order lags tested (s; 30 s … 2.6 h, a factor √10 apart, each an option).
Heat reaches the sensing element through the package and the mount: a temperature read beside
it (a board sensor, a separate topic) leads the bias by the thermal time constant.  A pure
delay, the model before session 43 (0, 60 and 300 s), fits a lag's slow response but not its
attenuation of faster cycles: a gyro's bias following a lab's 25 → 28 °C with a 1 °C, 30 min
cycle through a 600 s lag (3e-4 rad/s/°C, 2 h at 100 Hz) came out as four effects (a 300 s
delay with a rate term, a ramp, a 60 s delay, a warm-up); now one coupling, 617 s
[585, 678], 3.15e-4 [3.01, 3.42]e-4 rad/s/°C."""
MIN_LAG_S = 10.0  # shortest lag estimated (s): shorter is the rate option's (lag ≈ −c_rate/c)
STEPS_PER_DECADE = 12  # an :class:`OptionFamily`'s estimate: its grid, then refined
PROFILE_POINTS = 9  # values across an estimated parameter's interval profiling its coefficient
XTOL = 1e-3  # an estimated parameter's value and interval ends: to 0.1 % (Brent, in its log)
MAX_EXPONENT = 500.0  # :func:`first_order_lag`'s spans: e^500 ≈ 1e217, below float64's 1.8e308
PSD_MAX_SAMPLES = 1 << 24  # longest series of the periodogram line search (psd_line)
LOWPASS_BLOCKS = 31  # moving average of ADIS TEMP/SUPPLY (coarsely quantised) in blocks
MAX_STEP_REVERSALS = 1 / 3  # a staircase turning back less often passes through its levels
N_WARMUP_TAU = 24  # warm-up time constants tried
MAX_GLS_POINTS = 1024  # coarse blocks of the exact GLS


def block_means(x: np.ndarray, b: int) -> np.ndarray:
    """Means of consecutive blocks of ``b`` samples (an incomplete last block is dropped)."""
    n = len(x) // b
    return x[: n * b].reshape(n, b).mean(axis=1)


def moving_average(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving average over ``w`` samples, same length (shorter windows at the ends)."""
    c = np.concatenate([[0.0], np.cumsum(x)])
    i = np.arange(len(x))
    lo, hi = np.maximum(i - w // 2, 0), np.minimum(i + w // 2 + 1, len(x))
    return (c[hi] - c[lo]) / (hi - lo)


def sinusoid_avar(tau: np.ndarray, f0: float, tau0: float) -> np.ndarray:
    """AVAR of a unit-amplitude sinusoid of frequency ``f0`` (Hz) sampled every ``tau0`` s, at
    ``tau`` = m τ0 (s).

    The mean of m samples of A sin(2π f0 t + φ) is a sinusoid of amplitude
    A sin(π f0 m τ0) / (m sin(π f0 τ0)) (the Dirichlet kernel), and two adjacent means differ by
    2 sin(π f0 τ) times that: σ²(τ) = A² sin⁴(π f0 τ) / (m sin(π f0 τ0))², averaged over φ.
    As τ0 → 0 this is IEEE Std 952-1997 Annex C's A² sin⁴(π f0 τ) / (π f0 τ)²; sampled, that
    continuous form reads the amplitude high by π f0 τ0 / sin(π f0 τ0): 18 % at 0.31 of the
    sample rate, 43 % at 0.45.
    """
    tau = np.asarray(tau, dtype=float)
    m = np.maximum(np.round(tau / tau0), 1.0)
    return np.sin(np.pi * f0 * tau) ** 4 / (m * np.sin(np.pi * f0 * tau0)) ** 2


def sampled_avar(tau: np.ndarray, tau0: float, s: complex, c: complex = 1.0) -> np.ndarray:
    """AVAR at ``tau`` = m τ0 (s) of a unit-variance stationary rate of autocovariance
    R(t) = Re[c e^{−s|t|}] (Re ``c`` = 1) sampled every ``tau0`` s.

    The mean of m samples has variance V(m) = (m R(0) + 2 Σ_{k=1}^{m−1} (m − k) R(k τ0)) / m²
    and σ²(m τ0) = 2 V(m) − 2 V(2m) (two adjacent means; as :func:`prefilter_avar`), the sum in
    closed form with z = e^{−s τ0}: Σ_{k=1}^{m−1} (m − k) z^k = z (m (1 − z) − (1 − z^m)) /
    (1 − z)².  Exact for the samples the Allan sums read, where the continuous-time integral
    of IEEE Std 952-1997 Annex C (the limit τ0 → 0) is not: it misreads a line near the
    Nyquist frequency and a correlation time of a few samples.
    """
    m = np.maximum(np.round(np.asarray(tau, dtype=float) / tau0), 1.0)
    st = complex(s) * tau0
    one_minus_z = -np.expm1(-st)

    def var_mean(mm: np.ndarray) -> np.ndarray:
        tail = np.exp(-st) * (mm * one_minus_z + np.expm1(-st * mm)) / one_minus_z**2
        return (mm * np.real(c) + 2 * np.real(c * tail)) / mm**2

    return 2 * var_mean(m) - 2 * var_mean(2 * m)


def gauss_markov_avar(tau: np.ndarray, tc: float, tau0: float) -> np.ndarray:
    """AVAR of a unit-variance first-order Gauss–Markov process with correlation time ``tc``
    (s), R(t) = e^{−|t|/Tc}, sampled every ``tau0`` s, at ``tau`` (s) (:func:`sampled_avar`;
    as τ0 → 0 the module doc's continuous form)."""
    return sampled_avar(tau, tau0, 1.0 / tc)


def oscillator_psd(f: np.ndarray, f0: float, width_hz: float) -> np.ndarray:
    """Two-sided PSD (1/Hz) at ``f`` (Hz) of the unit-variance damped oscillator of
    :func:`oscillator_avar`: S(f) = 4aω0² / ((ω0² − ω²)² + 4a²ω²), ω = 2πf,
    a = π ``width_hz`` (full width at half power), ω0² = (2π ``f0``)² + a² (Papoulis §10)."""
    a = np.pi * width_hz
    w0_sq = (2 * np.pi * f0) ** 2 + a * a
    w_sq = (2 * np.pi * np.asarray(f, dtype=float)) ** 2
    return 4 * a * w0_sq / ((w0_sq - w_sq) ** 2 + 4 * a * a * w_sq)


def oscillator_avar(tau: np.ndarray, f0: float, width_hz: float, tau0: float) -> np.ndarray:
    """AVAR of a unit-variance second-order Gauss–Markov process (a damped oscillator driven by
    white noise: a spread spectral line) sampled every ``tau0`` s, at ``tau`` (s).

    Autocovariance R(t) = e^{−a|t|} (cos ωd t + (a/ωd) sin ωd|t|), ωd = 2π ``f0`` (Hz), damping
    a = π ``width_hz`` (the line's full width at half power, Hz); its two-sided PSD is
    S(f) = 4aω0² / ((ω0² − ω²)² + 4a²ω²) at ω = 2πf (ω0² = ωd² + a²), the resonance of
    x'' + 2a x' + ω0² x = w
    (Papoulis, *Probability, Random Variables and Stochastic Processes*, §10; Maybeck, *Stochastic
    Models* vol. 1, §4.10).  R(t) = Re[c e^{−st}] with s = a − iωd, c = 1 − i a/ωd, whose
    sampled AVAR is :func:`sampled_avar` (the continuous limit, 4∫ S(f) sin⁴(πfτ)/(πfτ)² df of
    IEEE Std 952-1997 Annex C, reads a line near the Nyquist frequency wrong).
    ``width_hz`` → 0 gives a random-phase sinusoid of variance 1 (:func:`sinusoid_avar` × 2).
    """
    a, wd = np.pi * width_hz, 2 * np.pi * f0
    return sampled_avar(tau, tau0, complex(a, -wd), complex(1.0, -a / wd))


BUTTERWORTH_ORDERS = {"butterworth2": 2, "butterworth4": 4}
"""The Butterworth low-pass families of the sensor's prefilter and their (even) orders."""
PREFILTERS = ("moving_average", "bartlett", "first_order", *BUTTERWORTH_ORDERS)
"""Families of the sensor's prefilter (:func:`prefilter_avar`)."""
PREFILTER_SUPPORT = {
    "moving_average": 1.0,
    "bartlett": 2.0,
    "first_order": 40.0,
    **{k: 40.0 / np.sin(np.pi / (2 * n)) for k, n in BUTTERWORTH_ORDERS.items()},
}
"""Each prefilter's autocovariance is 0 (first order, Butterworth: below e^−40) beyond this many
lengths."""


def _butterworth_modes(order: int, length_s: float) -> list[tuple[complex, complex]]:
    """(s, c) per mode of the autocovariance r(t) ∝ Σ Re[c e^{−s|t|}] of unit white noise
    through the analog Butterworth low-pass of even ``order`` whose −3 dB angular frequency is
    1/L (L = ``length_s``): H(s) = ∏ 1/(s − p_j) at the left-half-plane poles
    p_j = e^{iπ(2j + n + 1)/(2n)}/L, conjugate pairs, and r(t) = Σ_i Res_{s = p_i} H(s) H(−s)
    e^{s|t|} (the inverse Laplace transform of |H|², Papoulis §10): one mode per pair, c its
    upper pole's residue (the pair's sum is twice its real part; :func:`prefilter_avar`
    normalises the constant away)."""
    poles = np.exp(1j * np.pi * (2 * np.arange(order) + order + 1) / (2 * order))
    upper = poles[poles.imag > 0]
    residues = [1 / (np.prod(p - poles[poles != p]) * np.prod(-p - poles)) for p in upper]
    return [(complex(-p / length_s), complex(c)) for p, c in zip(upper, residues, strict=True)]


def _prefilter_autocovariance(kind: str, t: np.ndarray, length_s: float) -> np.ndarray:
    """Autocovariance r(t) = (h ⋆ h)(t) of unit two-sided-PSD white noise through the
    ``kind`` prefilter (Wiener–Khinchin: the inverse Fourier transform of |H(f)|²), ∫ r dt = 1.

    * moving average over ``length_s`` = L: |H|² = sinc²(fL), r = (1 − |t|/L)₊ / L;
    * bartlett: two cascaded moving averages over L (the ADIS SENS_AVG filter), |H|² = sinc⁴(fL),
      r = B₃(t/L)/L with B₃ the centred cubic B-spline (support ±2L);
    * first_order low-pass of time constant L (bandwidth 1/(2πL)), |H|² = 1/(1 + (2πfL)²),
      r = e^{−|t|/L} / (2L).
    """
    x = np.abs(t) / length_s
    if kind == "moving_average":
        r = np.maximum(1 - x, 0.0)
    elif kind == "bartlett":
        r = np.where(x <= 1, 2 / 3 - x**2 + x**3 / 2, np.maximum(2 - x, 0.0) ** 3 / 6)
    elif kind == "first_order":
        r = np.exp(-x) / 2
    else:
        raise ValueError(f"unknown prefilter {kind!r}; one of {', '.join(PREFILTERS)}")
    return r / length_s


def prefilter_avar(tau: np.ndarray, tau0: float, kind: str, length_s: float) -> np.ndarray:
    """AVAR per unit N² (two-sided white PSD, u²/Hz) of white noise through the sensor's
    prefilter, sampled every ``tau0`` (s), at ``tau`` = m τ0: the random-walk column N²/τ of
    IEEE 952 with the prefilter's short-τ shape.

    The samples have autocovariance r_k = r(k τ0) (:func:`_prefilter_autocovariance`, aliasing
    included; a Butterworth low-pass in closed form, :func:`_butterworth_avar`), scaled so that
    τ0 Σ_k r_k = 1: N² is the series' long-run PSD level, the N the model reports. The mean of m
    samples has variance V(m) = (m r₀ + 2 Σ_{k<m} (m − k) r_k)/m², and σ²(mτ0) = 2 V(m) − 2
    V(2m) (two adjacent means: σ² = Var − Cov, Var(mean of 2m) = (Var + Cov)/2); → 1/τ for m τ0
    ≫ L, below it less (the filter's correlation) — exact for every m (IEEE Std 1139 / Allan
    1966, cf. :mod:`imupipe.model.ieee952` module doc).
    """
    tau = np.asarray(tau, dtype=float)
    if kind in BUTTERWORTH_ORDERS:
        return _butterworth_avar(tau, tau0, BUTTERWORTH_ORDERS[kind], length_s)
    m = np.maximum(np.round(tau / tau0).astype(np.int64), 1)
    support = PREFILTER_SUPPORT[kind] * length_s
    lags = np.arange(int(min(np.ceil(support / tau0), 2 * m.max())) + 1)
    r = _prefilter_autocovariance(kind, lags * tau0, length_s)
    r = r / (tau0 * (r[0] + 2 * r[1:].sum()))
    k = lags[1:]
    s0 = np.concatenate([[0.0], np.cumsum(r[1:])])  # Σ_{1≤k≤n} r_k
    s1 = np.concatenate([[0.0], np.cumsum(k * r[1:])])  # Σ_{1≤k≤n} k r_k

    def var_mean(mm: np.ndarray) -> np.ndarray:
        n = np.minimum(mm - 1, len(lags) - 1)
        return (mm * r[0] + 2 * (mm * s0[n] - s1[n])) / mm**2

    return 2 * var_mean(m) - 2 * var_mean(2 * m)


def _butterworth_avar(tau: np.ndarray, tau0: float, order: int, length_s: float) -> np.ndarray:
    """:func:`prefilter_avar` of a Butterworth low-pass in closed form: its autocovariance is
    a sum of modes Re[c e^{−s|t|}] (:func:`_butterworth_modes`), so its sampled AVAR is the sum
    of their :func:`sampled_avar` s (linear in c), scaled by the samples' long-run level
    τ0 Σ_k r_k = τ0 Σ_modes Re[c (1 + z)/(1 − z)], z = e^{−s τ0} (the geometric series)."""
    modes = _butterworth_modes(order, length_s)
    level = sum(np.real(c * (1 + np.exp(-s * tau0)) / -np.expm1(-s * tau0)) for s, c in modes)
    return sum(sampled_avar(tau, tau0, s, c) for s, c in modes) / (tau0 * level)


@dataclass(frozen=True)
class NoisePsd:
    """Two-sided rate PSD (u²/Hz) of an IEEE 952 model (Annex C), see module doc.

    ``white`` = N², ``flicker`` = B² (cut off above ``cutoff_hz``), ``rrw`` = K²,
    ``gauss_markov`` = ((σ², Tc), ...), ``lines`` = ((σ², centre Hz, width Hz), ...): spread
    lines, the PSD of :func:`oscillator_avar`'s damped oscillator.  ``quantization`` = Q²
    (u²·s²): white phase noise of AVAR 3Q²/τ², whose rate PSD (2πf)²·τ0·Q² needs the sample
    interval; :meth:`at` leaves it out, :class:`Whitener` adds its exact covariance.
    """

    white: float
    flicker: float
    cutoff_hz: float
    rrw: float
    gauss_markov: tuple[tuple[float, float], ...] = ()
    lines: tuple[tuple[float, float, float], ...] = ()
    quantization: float = 0.0

    @property
    def silent(self) -> bool:
        """No noise term at all (a fit whose curve is all deterministic columns: sinusoid,
        ramp, a prefilter's negative 3/τ²): its covariance is zero and cannot whiten."""
        terms = (self.white, self.flicker, self.rrw, self.quantization)
        columns = [v for v, *_ in self.gauss_markov] + [v for v, *_ in self.lines]
        return not any(terms) and not any(columns)

    def at(self, f: np.ndarray) -> np.ndarray:
        w = 2 * np.pi * np.asarray(f, dtype=float)
        with np.errstate(divide="ignore"):
            s = self.white + np.where(f <= self.cutoff_hz, self.flicker / w, 0.0) + self.rrw / w**2
        for var, tc in self.gauss_markov:
            s = s + 2 * var * tc / (1 + (w * tc) ** 2)
        for var, centre, width in self.lines:
            s = s + var * oscillator_psd(f, centre, width)
        return s

    def sampled(self, f: np.ndarray, tau0: float) -> np.ndarray:
        """:meth:`at` with the quantisation's rate PSD of samples every ``tau0`` s,
        (4 Q² / τ0) sin²(π f τ0) (IEEE Std 952-1997, Annex C, quantization noise; (2πf)² τ0 Q²
        at low f): the spectrum a Welch estimate of the sampled series reads."""
        f = np.asarray(f, dtype=float)
        return self.at(f) + 4 * self.quantization / tau0 * np.sin(np.pi * f * tau0) ** 2


NUGGET = 1e-9
"""Relative white floor added to the whitened differences' variance γ(0) (:class:`Whitener`)."""


class Whitener:
    """Exact GLS whitening of the first differences of coarse block means (Cholesky).

    The series (block means of ``dt``) is averaged into at most :data:`MAX_GLS_POINTS` coarse
    blocks of ``span`` s; their first differences are stationary under white, flicker and
    rate-random-walk noise, with autocovariance
    γ(k) = ∫ 4 sin⁴(π ν D) Σ_m S(ν + m/D) / (π(νD + m))² · e^{2πiνkD} dν  (D = span; block
    averaging sinc², differencing, aliasing images m), computed by an inverse FFT.  The series
    is whitened by the exact innovations of that Toeplitz covariance (Levinson–Durbin: row t of
    ``inv_chol`` turns x_t into its standardised one-step prediction error given x_0..x_{t−1},
    i.e. L⁻¹ with L the Cholesky factor) — exact, so the start and end of the record need no
    circular (Whittle) approximation, which fails at the edges for long-memory noise.

    ``masked`` (the masked fraction of each block of ``dt``, or bool: gaps and excised
    events) leaves out every coarse block whose masked fraction exceeds
    :data:`MAX_FILLED_FRACTION`: the differences are then taken between
    consecutive *observed* coarse blocks o_i, each the sum of the coarse differences from o_i
    to o_{i+1}, so their covariance is A Γ Aᵀ (Γ the Toeplitz covariance above, A the 0/1
    summing matrix) — the exact Gaussian likelihood of the observed block means (missing data
    marginalised out), whitened by forward substitution with its Cholesky factor L (L⁻¹ itself
    is formed only when read: :attr:`inv_chol`).  The level across a gap still counts (its
    variance grows with the gap's length under a random walk); the fill of a gap, a noise-free
    line, is never read as data.
    """

    def __init__(self, psd: NoisePsd, n: int, dt: float, masked: np.ndarray | None = None) -> None:
        self.factor = -(-n // MAX_GLS_POINTS)  # ceil: n ≥ 1 block
        self.span = self.factor * dt
        m = n // self.factor - 1  # differences
        grid = 16 * m
        nu = np.arange(grid // 2 + 1) / (grid * self.span)
        nu[0] = 1e-6 * nu[1]
        x = nu * self.span
        images = np.arange(-8, 9)[:, None]
        coloured = replace(psd, white=0.0)
        fold = np.sum(coloured.at(np.abs(nu + images / self.span)) / (np.pi * (x + images)) ** 2, 0)
        s_diff = 4 * np.sin(np.pi * x) ** 2 * (psd.white + np.sin(np.pi * x) ** 2 * fold)
        gamma = np.fft.irfft(s_diff, grid)[:m] / self.span
        # white phase noise e (variance Q²) in a block mean: (e_end − e_start)/D, so the
        # differences (e_b − 2e_{b−1} + e_{b−2})/D have covariance Q²/D²·(6, −4, 1): what
        # keeps a model whose short-τ curve is all 3Q²/τ² (a vibration line above the fitted
        # range, N fitted 0) from a zero, unwhitenable covariance
        gamma[:3] += psd.quantization / self.span**2 * np.array([6.0, -4.0, 1.0])[: min(m, 3)]
        # a nugget of NUGGET γ(0): a model without white noise (a baseline whose N went to 0
        # under a strong line's hump) has a band-limited spectrum whose Toeplitz covariance is
        # singular to rounding; its innovations' variances went negative (NaN errors)
        gamma[0] *= 1.0 + NUGGET
        self.blocks = _read_only(observed_blocks(masked, m + 1, self.factor))
        """Index of each coarse block the differences read (all of them without exclusions)."""
        self._chol: np.ndarray | None = None
        """The lower Cholesky factor L of the masked covariance (``None``: Levinson's L⁻¹)."""
        if len(self.blocks) == m + 1:
            self._inv_chol = _read_only(_innovations(gamma))
        else:
            cov = _summed_covariance(gamma, self.blocks)
            self._chol = _read_only(_cholesky(cov))
        # whitened constant difference: a linear rate ramp, the model's R term (nuisance)
        self.drift = _read_only(self.whitened(np.diff(self.blocks).astype(float)))

    @functools.cached_property
    def inv_chol(self) -> np.ndarray:
        """L⁻¹ (lower triangular, read-only): row t turns the differences into their t-th
        standardised innovation.  With blocks left out it is inverted from L when first read
        (LAPACK trtri, m³/3 flops: the bias-step scan reads its columns); whitening itself
        solves with L (:meth:`whitened`), and that is all most of a loop's whiteners do."""
        if self._chol is None:
            return self._inv_chol
        inv = np.array(self._chol, order="F")
        n, info = ctypes.c_int(len(inv)), ctypes.c_int(0)
        _DTRTRI(b"L", b"N", ctypes.byref(n), inv.ctypes.data, ctypes.byref(n), ctypes.byref(info))
        if info.value != 0:  # a zero pivot: potrf would have refused the matrix first
            raise linalg.LinAlgError(f"triangular inverse failed (LAPACK dtrtri {info.value})")
        return _read_only(inv)

    @property
    def log_det(self) -> float:
        """ln det Σ of the differences' covariance: 2 Σ ln Lₜₜ (Lₜₜ = √vₜ, the innovations'
        standard deviations)."""
        if self._chol is None:
            return -2 * float(np.sum(np.log(np.diag(self._inv_chol))))
        return 2 * float(np.sum(np.log(np.diag(self._chol))))

    def whitened(self, d: np.ndarray) -> np.ndarray:
        """L⁻¹ ``d``: the differences ``d`` (m,) or (m, k) as standardised innovations (with
        blocks left out by forward substitution with L, O(m²) a column)."""
        if self._chol is None:
            return self._inv_chol @ d
        x = np.array(d, dtype=float, order="F")  # (m,) or (m, k), overwritten with the solution
        if len(x) != len(self._chol):  # LAPACK would read past the factor or the differences
            raise ValueError(f"{len(x)} differences for a whitener of {len(self._chol)}")
        n, rhs = ctypes.byref(ctypes.c_int(len(x))), ctypes.c_int(x.size // max(len(x), 1))
        info = ctypes.c_int(0)
        if x.size:
            a, b = self._chol.ctypes.data, x.ctypes.data
            _DTRTRS(b"L", b"N", b"N", n, ctypes.byref(rhs), a, n, b, n, ctypes.byref(info))
        if info.value != 0:  # a zero pivot: potrf would have refused the matrix first
            raise linalg.LinAlgError(f"singular factor (LAPACK dtrtrs {info.value})")
        return x

    def coarse(self, v: np.ndarray) -> np.ndarray:
        """Coarse block means of ``v`` (n,) or (n, k) (an incomplete last block is dropped)."""
        n = len(v) // self.factor
        return v[: n * self.factor].reshape(n, self.factor, *v.shape[1:]).mean(axis=1)

    def __call__(self, v: np.ndarray) -> np.ndarray:
        """Whitened differences of the observed coarse block means of ``v``."""
        return self.whitened(np.diff(self.coarse(v)[self.blocks], axis=0))


_INT = ctypes.POINTER(ctypes.c_int)
_CHAR = ctypes.c_char_p
_PTR = ctypes.c_void_p
_DOUBLE = ctypes.POINTER(ctypes.c_double)


def _lapack(name: str, *argtypes: type) -> Callable[..., None]:
    """LAPACK routine ``name``, scipy's own (``scipy.linalg.cython_lapack``: the library
    ``scipy.linalg`` calls), called by ctypes: a foreign call that releases the GIL, where
    scipy's wrappers (``cholesky``, ``solve_triangular``, ``lapack.dtrtri``) hold it for the
    whole routine.  py-spy on a real ADIS16405 unit: 2.5 s of the two axis threads' loops held
    the GIL in the Cholesky factorisations, each whitener's 13 ms keeping the other thread's
    Python waiting; then (session 48, ``py-spy --gil``, per analysis) 1.2 s in the triangular
    solves and 0.3 s in the inverses.  Same routine, same arguments: the same bits
    (``tests/model/test_whitener.py``)."""
    address = get_cython_function_address("scipy.linalg.cython_lapack", name)
    return ctypes.CFUNCTYPE(None, *argtypes)(address)


_DPOTRF = _lapack("dpotrf", _CHAR, _INT, _PTR, _INT, _INT)
_DTRTRS = _lapack("dtrtrs", _CHAR, _CHAR, _CHAR, _INT, _INT, _PTR, _INT, _PTR, _INT, _INT)
_DTRTRI = _lapack("dtrtri", _CHAR, _CHAR, _INT, _PTR, _INT, _INT)
_DLASET = _lapack("dlaset", _CHAR, _INT, _INT, _DOUBLE, _DOUBLE, _PTR, _INT)


def _cholesky(cov: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor L of the symmetric ``cov`` (C-contiguous, overwritten; returned
    as a Fortran-ordered view, its upper triangle zero).  ``cov`` is symmetric to the bit
    (:func:`_rectangle_sums`), so its C buffer is its own Fortran layout: dpotrf('L') on it is
    what ``scipy.linalg.cholesky(cov, lower=True)`` computes on its Fortran copy, bit for bit
    (``tests/model/test_whitener.py``)."""
    n, info = ctypes.c_int(len(cov)), ctypes.c_int(0)
    _DPOTRF(b"L", ctypes.byref(n), cov.ctypes.data, ctypes.byref(n), ctypes.byref(info))
    if info.value != 0:
        raise linalg.LinAlgError(f"covariance not positive definite (LAPACK dpotrf {info.value})")
    if len(cov) > 1:  # the C view holds Lᵀ, its lower triangle cov's still: Fortran's upper
        # triangle, i.e. the upper triangle and diagonal of the block from column 2, set to 0
        zero, rest = ctypes.c_double(0.0), ctypes.c_int(len(cov) - 1)
        first_above = cov.ctypes.data + cov.itemsize * len(cov)
        _DLASET(b"U", ctypes.byref(rest), ctypes.byref(rest), ctypes.byref(zero),
                ctypes.byref(zero), first_above, ctypes.byref(n))  # fmt: skip
    return cov.T


def _read_only(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


MAX_FILLED_FRACTION = 0.01
"""Largest masked fraction of a coarse block the GLS still reads: a lost message or a NaN row
fills a trace of a block (one 10 ms sample of a 42 s block at 12 h), which moves its mean by
nothing the noise would show, and the exact Levinson whitener stays (O(m²) where leaving
blocks out costs a Cholesky of O(m³): 15 ms against ~100 ms for 1024 blocks)."""

MIN_OBSERVED_BLOCKS = 16
"""Fewest observed coarse blocks the GLS reads; with fewer, the mask is too dense to leave out
whole blocks and :func:`observed_blocks` keeps every block (the gaps' fill read as data)."""


def observed_blocks(masked: np.ndarray | None, n_coarse: int, factor: int) -> np.ndarray:
    """Indices of the ``n_coarse`` (= ``len(masked) // factor``) coarse blocks of ``factor``
    blocks whose ``masked`` fraction is at most :data:`MAX_FILLED_FRACTION` (all of them
    without a mask, or when fewer than :data:`MIN_OBSERVED_BLOCKS` would remain)."""
    every = np.arange(n_coarse)
    if masked is None:
        return every
    filled = block_means(np.asarray(masked, float), factor)  # len(masked) // factor blocks
    kept = np.flatnonzero(filled <= MAX_FILLED_FRACTION)
    return kept if len(kept) >= MIN_OBSERVED_BLOCKS else every


def _summed_covariance(gamma: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """Covariance of the differences between consecutive ``blocks`` (coarse indices): entry
    (i, j) is the sum of Γ over differences [bᵢ, bᵢ₊₁) × [bⱼ, bⱼ₊₁), Γ = Toeplitz(``gamma``).

    With Sₖ the sum of the first k coarse differences, Cov(Sₚ, S_q) = ½[C(p) + C(q) − C(|p − q|)]
    (stationarity: Var(Sₚ − S_q) = C(|p − q|)), C(k) = Var Sₖ = Σ_{|l|<k} (k − |l|) γ(|l|); the
    four corners of each rectangle leave ½[C(|hᵢ − lⱼ|) + C(|lᵢ − hⱼ|) − C(|hᵢ − hⱼ|) −
    C(|lᵢ − lⱼ|)] (l, h: the blocks' starts and ends) — O(m) to tabulate C instead of the
    O(m²) two-dimensional cumulative sum of Γ.  Block i ends where block i + 1 starts, so the
    four are shifted views of one table C(|bᵢ − bⱼ|) over the blocks b (one gather, not four).
    """
    m = len(gamma)
    increments = np.empty(m + 1)  # C(k) − C(k − 1) = γ(0) + 2 Σ_{0<l<k} γ(l)
    increments[0] = 0.0
    increments[1:] = 2 * np.cumsum(gamma) - gamma[0]
    return _rectangle_sums(np.cumsum(increments), kernel_input(blocks, np.int64))


@numba.njit(cache=True, nogil=True)
def _rectangle_sums(var_sum: np.ndarray, blocks: np.ndarray) -> np.ndarray:  # pragma: no cover
    """½[C(|bᵢ₊₁ − bⱼ|) + C(|bᵢ − bⱼ₊₁|) − C(|bᵢ₊₁ − bⱼ₊₁|) − C(|bᵢ − bⱼ|)] for every pair of
    differences (i, j), C = ``var_sum``: one pass, the lower triangle mirrored (the matrix is
    symmetric to the bit: the sum's two first terms swap, and IEEE addition commutes), instead
    of numpy's (m + 1)² index, gather and four shifted copies (7 ms at m = 1023, 136 times on a
    real ADIS16405 unit's loop)."""
    m = blocks.size - 1
    out = np.empty((m, m))
    for i in range(m):
        for j in range(i + 1):
            out[i, j] = 0.5 * (
                var_sum[abs(blocks[i + 1] - blocks[j])]
                + var_sum[abs(blocks[i] - blocks[j + 1])]
                - var_sum[abs(blocks[i + 1] - blocks[j + 1])]
                - var_sum[abs(blocks[i] - blocks[j])]
            )
            out[j, i] = out[i, j]
    return out


@numba.njit(cache=True, nogil=True)
def _innovations(gamma: np.ndarray) -> np.ndarray:
    """L⁻¹ (lower triangular) of the Toeplitz covariance of ``gamma`` by Levinson–Durbin.

    Row t: (x_t − Σ_j φ_{t,j} x_{t−j}) / √v_t with the order-t predictor φ_t and its error
    variance v_t (Brockwell & Davis, Time Series: Theory and Methods, §5.2).
    """
    m = len(gamma)
    out = np.zeros((m, m))
    out[0, 0] = 1 / np.sqrt(gamma[0])
    phi = np.zeros(m)  # φ_{t,1..t} in phi[:t]
    prev = np.zeros(m)
    v = gamma[0]
    for t in range(1, m):
        acc = 0.0
        for j in range(t - 1):
            acc += phi[j] * gamma[t - 1 - j]
        k = (gamma[t] - acc) / v
        for j in range(t - 1):  # not a slice assignment: see imupipe.jit
            prev[j] = phi[j]
        for j in range(t - 1):
            phi[j] = prev[j] - k * prev[t - 2 - j]
        phi[t - 1] = k
        v = v * max(1 - k * k, 1e-12)
        scale = 1 / np.sqrt(v)
        out[t, t] = scale
        for j in range(t):
            out[t, t - 1 - j] = -phi[j] * scale
    return out


@dataclass(frozen=True)
class SpectralFit:
    """OLS on whitened series: coefficients, covariance, Wald χ² of all coefficients."""

    beta: np.ndarray
    cov: np.ndarray
    chi2: float
    dispersion: float  # residual variance of the whitened series (≈ 1 when the PSD fits)
    rss: float  # its residual sum of squares (options with as many columns: profile deviance)

    def interval(self, j: int) -> list[float]:
        """95 % interval of coefficient ``j``."""
        half = Z95 * float(np.sqrt(self.cov[j, j]))
        return [float(self.beta[j] - half), float(self.beta[j] + half)]

    def p_value(self) -> float:
        return float(special.chdtrc(len(self.beta), self.chi2))  # chi2.sf

    def log_p_value(self) -> float:
        """ln :meth:`p_value`, finite where the p-value underflows to 0 (χ² beyond ~1400): there
        the leading term of the upper incomplete gamma's expansion, Γ(a, x) ~ x^(a−1) e^(−x)
        (Abramowitz & Stegun 6.5.32; a = k/2, x = χ²/2).  Options are ranked by it: two
        strong options both at p = 0 were otherwise ranked by their order (measured: a
        temperature coupling's low-passed level, χ² smaller, chosen over its unfiltered level)."""
        p = self.p_value()
        if p > 0:
            return float(np.log(p))
        a, x = len(self.beta) / 2, self.chi2 / 2
        return float((a - 1) * np.log(x) - x - special.gammaln(a))


def spectral_fit(
    yw: np.ndarray, xw: np.ndarray, drift: np.ndarray, mask: np.ndarray | None = None
) -> SpectralFit:
    """OLS of whitened ``yw`` on whitened regressors ``xw`` (m, k) plus the whitened ``drift``
    nuisance column (optionally on ``mask`` only); statistics of the ``xw`` coefficients."""
    x = np.column_stack([xw, drift])
    if mask is not None:
        yw, x = yw[mask], x[mask]
    k = xw.shape[1]
    xtx_inv = np.linalg.pinv(x.T @ x)
    beta = xtx_inv @ (x.T @ yw)
    e = yw - x @ beta
    s2 = float(e @ e) / max(len(yw) - len(beta), 1)
    b, c = beta[:k], s2 * xtx_inv[:k, :k]
    return SpectralFit(b, c, float(b @ np.linalg.pinv(c) @ b), s2, float(e @ e))


@dataclass
class Candidate:
    """One candidate effect: either a time-domain correction or an extra AVAR column.

    Time-domain candidates carry ``p_value`` (Bonferroni-adjusted for the options searched)
    and their raw ``regressors`` (n_d, k), so the coefficients can be re-estimated with
    another whitener or on part of the record.
    """

    kind: str
    params: dict[str, float]
    intervals: dict[str, list[float]]
    evidence: dict = field(default_factory=dict)
    correction: np.ndarray | None = None  # decimated series to subtract (n_d,)
    spikes: SparseCorrection | None = None  # full-rate samples to subtract (spikes)
    column: np.ndarray | None = None  # AVAR column (unit amplitude) over the curve's τ
    n_params: int = 1
    regressors: np.ndarray | None = None
    names: tuple[str, ...] = ()
    n_options: int = 1
    p_value: float = 1.0
    options: list[tuple[dict[str, np.ndarray], dict[str, float]]] = field(default_factory=list)
    drift_nuisance: bool = True  # a linear rate ramp is a nuisance (False: it is the effect)
    family: OptionFamily | None = None  # options of a shape parameter estimated when chosen

    def _drift(self, whiten: Whitener) -> np.ndarray:
        """The nuisance columns of the GLS: the whitened ramp, or none (m, 0)."""
        return whiten.drift if self.drift_nuisance else np.zeros((len(whiten.drift), 0))

    def refit(self, whiten: Whitener, y_d: np.ndarray) -> None:
        """Re-estimate coefficients, intervals, correction and p-value with ``whiten``.

        With ``options`` (searched alternatives) the best option is re-selected under
        ``whiten``; an option of a ``family`` (one column indexed by a shape parameter) is
        then estimated with that parameter free (:meth:`OptionFamily.estimate`: its intervals
        profiled, not conditional on the option).  The p-value is the chosen option's: the
        test is the search over the options, the estimate is not a test.
        """
        yw = whiten(y_d)
        profiled: dict[str, list[float]] = {}
        if self.options:
            fits = [
                spectral_fit(yw, whiten(np.column_stack(list(regs.values()))), self._drift(whiten))
                for regs, _ in self.options
            ]
            best = int(np.argmin([f.log_p_value() for f in fits]))
            regs, fixed = self.options[best]
            fit = tested = fits[best]
            self.intervals = {}  # the option chosen before may have had other coefficients
            family = self.family
            if family is not None and fixed[family.param] > 0 and family.hi > family.lo:
                zero = (*self.options[0], fits[0]) if family.zero else None
                regs, fixed, fit, profiled = family.estimate(
                    whiten, yw, self._drift(whiten), (regs, fixed), zero
                )
            self.regressors = np.column_stack(list(regs.values()))
            self.names = tuple(regs)
            self.params = dict(fixed)
        else:
            assert self.regressors is not None
            fit = tested = spectral_fit(yw, whiten(self.regressors), self._drift(whiten))
        for j, name in enumerate(self.names):
            self.params[name] = float(fit.beta[j])
            self.intervals[name] = fit.interval(j)
        self.intervals |= profiled
        g = self.regressors @ fit.beta
        self.correction = g - g.mean()
        self.p_value = min(1.0, self.n_options * tested.p_value())
        self.evidence |= {
            "wald_chi2": tested.chi2,
            "p_value_bonferroni": self.p_value,
            "n_options": self.n_options,
            "whitened_dispersion": fit.dispersion,
        }

    def holdout(self, whiten: Whitener, y_d: np.ndarray, segments: int) -> dict:
        """Fit on even segments, score on odd (and vice versa): whitened residual power.

        A bias step is local (its evidence sits at one change point), so it has no split.
        """
        assert self.regressors is not None
        if self.kind == "bias_step":
            return {"holds": True, "note": "a step is local; no hold-out split"}
        yw, xw = whiten(y_d), whiten(self.regressors)
        n = len(yw)
        even = (np.arange(n) * segments // n) % 2 == 0
        ratios = []
        drift = self._drift(whiten)
        for train in (even, ~even):
            beta = spectral_fit(yw, xw, drift, train).beta
            test = ~train
            base, e = yw[test], yw[test] - xw[test] @ beta
            if self.drift_nuisance:
                base = base - drift[test] * _slope(base, drift[test])
                e = e - drift[test] * _slope(e, drift[test])
            with np.errstate(divide="ignore", invalid="ignore"):  # a held-out part of zeros
                ratios.append(float(e @ e / (base @ base)))
        return {"holds": bool(max(ratios) < 1.0), "power_ratio_heldout": ratios}


def _best_option(
    kind: str,
    y_d: np.ndarray,
    whiten: Whitener,
    options: list[tuple[dict[str, np.ndarray], dict[str, float]]],
    family: OptionFamily | None = None,
) -> Candidate:
    """The option (regressors, fixed params) with the smallest p-value, Bonferroni × len."""
    cand = Candidate(kind, {}, {}, n_options=len(options), options=options, family=family)
    cand.n_params = max(len(regs) for regs, _ in options) + (len(options) > 1)
    cand.refit(whiten, y_d)
    return cand


def profile_deviance(rss: np.ndarray | float, best: SpectralFit) -> np.ndarray:
    """The profile deviance of fits whose whitened residual sums of squares are ``rss``
    against the ``best`` fit: their excess over its residual sum in its residual variance,
    (RSS − RSS_best)/s².  A best fit that leaves no residual (s² = 0: a series the whitener
    turns into zeros, a constant record) makes every worse fit infinitely worse and an equal
    one no worse (0), where the ratio is 0/0 (a fuzzed constant bag with one spike: a
    RuntimeWarning, then NaN intervals)."""
    excess = np.asarray(rss, dtype=float) - best.rss
    if best.dispersion > 0:
        return excess / best.dispersion
    return np.where(excess > 0, np.inf, 0.0)


def _profile_interval(fits: list[SpectralFit]) -> list[float]:
    """95 % profile interval of the coefficient of a one-column effect fitted at several values
    of its shape parameter (a lag, a warm-up's time constant).

    Fit j's profile deviance is its whitened residual sum of squares' excess over the best
    fit's, in the best one's residual variance: D_j = (RSS_j − RSS_min)/s²; within fit j the
    amplitude a adds (a − β_j)²/se_j², so the profile deviance of a is
    min_j [D_j + (a − β_j)²/se_j²]; the interval is {a : profile ≤ χ²₁(0.95)}, a union over the
    fits within χ²₁(0.95) of the best.  The difference of the fits' Wald χ² is D_j only for a
    weak effect: each Wald χ² divides by its own residual variance, so for a strong one
    (χ² ≫ the series' length) it is D_j times ~χ²/length (before session 43 the warm-up's τw
    interval was read from it: on 40 records of a 3e-4 warm-up of 600 s in white noise of
    1e-4 per 1 s block, 2 h, it held the truth on 13)."""
    rss = np.array([f.rss for f in fits])
    best = int(np.argmin(rss))
    room = CHI2_95 - profile_deviance(rss, fits[best])
    ok = np.flatnonzero(room >= 0)
    beta = np.array([fits[j].beta[0] for j in ok])
    half = np.sqrt(room[ok] * np.array([fits[j].cov[0, 0] for j in ok]))
    return [float(np.min(beta - half)), float(np.max(beta + half))]


def refined_between(
    u: np.ndarray, j: int, objective: Callable[[float], float], at_j: float
) -> float | None:
    """The log value of least ``objective`` between the neighbours of point ``j`` of a grid of
    log values ``u`` (ascending): scipy's bounded Brent search, to :data:`XTOL`; ``None`` where
    the grid has one value or that least is no lower than ``at_j``, the objective at point j."""
    near = (u[max(j - 1, 0)], u[min(j + 1, len(u) - 1)])
    if near[0] == near[1]:
        return None
    found = optimize.minimize_scalar(
        objective, bounds=near, method="bounded", options={"xatol": XTOL}
    )
    return float(found.x) if found.fun < at_j else None


def crossing_interval(
    u: np.ndarray, room: np.ndarray, room_at: Callable[[float], float]
) -> list[float]:
    """95 % interval of a positive parameter searched at the values e^u (``u`` ascending), from
    its profile ``room`` there (χ²₁(0.95) minus the profile deviance; ≥ 0 inside) and at any
    log value (``room_at``): each edge where the room crosses 0, by Brent's root search (to
    :data:`XTOL` in the log) between the outermost value inside and its neighbour outside;
    censored at the grid's ends.  Linear interpolation between grid points cuts the interval
    short, the chord of a concave room lying under it: on 40 records of a coupling through a
    600 s lag it held the lag on 28, the root on 40; on 63 strong Gauss–Markov effects of the
    independent generator (2 h, 100 Hz) a grid of ×1.24 steps held Tc on 56.

    The bracket's ends keep their grid values: ``room_at`` refits there, and a refit of the
    non-convex fit (or at e^{ln v}, a last bit off v) can land on another branch — measured:
    a room of 3.84 on the grid read −2.34 again, brentq raised "f(a) and f(b) must have
    different signs" and `imupipe analyze` ended in a traceback (a Butterworth prefilter of a
    third of a sample, independent generator recording 4400019)."""
    ok = np.flatnonzero(room >= 0)
    edges = []
    for inside, outside in ((ok[0], ok[0] - 1), (ok[-1], ok[-1] + 1)):
        edge = u[inside]
        if 0 <= outside < len(u):
            ends = {u[inside]: room[inside], u[outside]: room[outside]}

            def bracketed(x: float, ends: dict = ends) -> float:
                return ends[x] if x in ends else room_at(x)

            edge = optimize.brentq(bracketed, u[inside], u[outside], xtol=XTOL)
        edges.append(float(np.exp(edge)))
    return edges


def coupling_candidate(
    kind: str, y_d: np.ndarray, aux_d: np.ndarray | None, dt: float, unit: str, whiten: Whitener
) -> Candidate | None:
    """Coupling to an auxiliary channel: its level, with its rate, its curvature or a lag.

    Options: {level}, {level, d/dt}, {level, (level − its mean)²}, and the level through a
    first-order lag (:func:`first_order_lag`) of each of :data:`LAGS_S` under a quarter of the
    record (the lag then estimated up to the record's length: :class:`OptionFamily`, see
    :data:`LAGS_S` for why a lag); the best by spectral-GLS p-value is kept,
    Bonferroni-adjusted for the options (7 on 2 h, 9 on 12 h; 7 before session 43: the level
    and level + rate at pure delays of 0, 60 and 300 s, and the curvature).  The rate
    column also stands for lags shorter than the shortest tested (a lag τ ≈ −coefficient_rate
    / coefficient).  The curvature: a MEMS bias is a polynomial in temperature, and over a
    lab's ±3 °C a curvature of 3e-5 rad/s/°C² (on 1e-4 rad/s/°C) left a linear coupling's
    correction a residual the noise model read as a bias instability B of 1.45e-4 rad/s
    (truth 0; 2 h at 100 Hz, ``tests/test_odd_inputs.py::test_a_curved_temperature_coupling``).
    Only unlagged, the sensor's own temperature: the option cost every coupling's test a
    Bonferroni factor 7/6 in session 41 (at every lag 9/6, which lost the weak coupling of
    ``tests/model/test_loop_sim.py::test_temperature_coupling`` seed 17).  The level is
    :func:`coupling_level` (param ``lowpass_s``; ``evidence["level"]`` says which); it reads
    the channel only, so it costs no test.  Params ``reference_level`` (the curvature's
    centre) with ``coefficient_quadratic``.
    """
    if aux_d is None or np.ptp(aux_d) == 0:
        return None
    level, lowpass_s, level_note = coupling_level(aux_d, dt)
    fixed = {"lag_s": 0.0, "lowpass_s": lowpass_s}
    reference = float(level.mean())
    options = [
        ({"coefficient": level}, fixed),
        ({"coefficient": level, "coefficient_rate": np.gradient(level, dt)}, fixed),
        (
            {"coefficient": level, "coefficient_quadratic": (level - reference) ** 2},
            fixed | {"reference_level": reference},
        ),
    ]

    def lagged(lag_s: float) -> np.ndarray:
        return first_order_lag(level, lag_s / dt)

    record_s = len(y_d) * dt
    options += [
        ({"coefficient": lagged(lag_s)}, fixed | {"lag_s": lag_s})
        for lag_s in LAGS_S
        if lag_s < record_s / 4
    ]
    family = OptionFamily("lag_s", lagged, MIN_LAG_S, record_s, zero=True)
    cand = _best_option(kind, y_d, whiten, options, family)
    cand.evidence["level"] = level_note
    cand.evidence["unit"] = (
        f"rate per {unit} (coefficient_rate: per {unit}/s; coefficient_quadratic: per {unit}² "
        f"of the level's departure from reference_level, {unit})"
    )
    return cand


def first_order_lag(x: np.ndarray, blocks: float) -> np.ndarray:
    """``x`` through a first-order lag of time constant ``blocks`` samples, y_i = a y_{i−1} +
    (1 − a) x_i with a = e^{−1/blocks} (dy/dt = (x − y)/τ, its step response exact at the
    samples), starting in equilibrium with the first value — scipy.signal's ``lfilter([1 − a],
    [1, −a], x, zi=[a x_0])`` without importing scipy.signal (0.5–0.8 s).  Closed form per
    span of samples, y_i = a^i (a y_{s−1} + (1 − a) Σ_{j ≤ i} a^{−j} x_j) (i, j from the span's
    start s), the spans short enough that a^{−j} stays below e^{:data:`MAX_EXPONENT`}."""
    span = max(1, int(MAX_EXPONENT * blocks))
    y = np.empty(len(x))
    before = float(x[0])
    for s in range(0, len(x), span):
        part = np.asarray(x[s : s + span], dtype=float)
        j = np.arange(len(part)) / blocks
        y[s : s + len(part)] = np.exp(-j) * (
            np.exp(-1.0 / blocks) * before - np.expm1(-1.0 / blocks) * np.cumsum(np.exp(j) * part)
        )
        before = y[s + len(part) - 1]
    return y


@dataclass(frozen=True)
class OptionFamily:
    """Options of one column indexed by a positive shape parameter ``param`` (a coupling's
    lag, a warm-up's time constant): ``column(value)``, estimated between ``lo`` and ``hi``.

    The test searches a grid of options (each one of the Bonferroni count); the chosen option
    is then estimated with the parameter free (:meth:`estimate`): on a strong effect a shape
    off by a grid step leaves a residual the loop reads as more effects (a coupling through a
    300 s lag fitted as 240 s left a second coupling and a ramp), and the grid's points are
    too far apart to bound the parameter.  Not where ``hi`` ≤ ``lo`` (a warm-up's τw on a
    record of under 90 blocks, whose grid runs from 30 blocks down to a third of it).
    ``zero``: the candidate's first option is the family's limit at 0 (the level without a
    lag), reported where the data do not need more."""

    param: str
    column: Callable[[float], np.ndarray]
    lo: float
    hi: float
    zero: bool = False

    def estimate(
        self,
        whiten: Whitener,
        yw: np.ndarray,
        drift: np.ndarray,
        option: tuple[dict[str, np.ndarray], dict[str, float]],
        zero: tuple[dict[str, np.ndarray], dict[str, float], SpectralFit] | None,
    ) -> tuple[dict[str, np.ndarray], dict[str, float], SpectralFit, dict[str, list[float]]]:
        """(regressors, params, fit, 95 % profile intervals) of the parameter value whose GLS
        fits best, from the chosen ``option`` (regressors, params); ``zero``: the option of
        the family's limit at 0 with its fit (with :attr:`zero` set).

        The value minimises the GLS residual sum of squares over :data:`STEPS_PER_DECADE`
        values a decade from ``lo`` to ``hi``, refined between that grid's neighbours
        (:func:`refined_between`).  Its 95 % interval is where the profile
        deviance (the residual's excess over the best, in its residual variance) crosses
        χ²₁(0.95), found by Brent's root search beside the outermost grid value inside
        (:func:`crossing_interval`).  The coefficient's interval is profiled
        (:func:`_profile_interval`) over the best, the zero limit and :data:`PROFILE_POINTS`
        values across the parameter's interval: the grid's own points are too far apart for a
        strong effect, whose shape is known to a few per cent and its coefficient correlated
        with it.  Where the zero limit lies within χ²₁(0.95) of the best, the data do not need
        the parameter: the fit is the zero limit's (its interval from 0), although an option of
        the family was the most significant."""
        (name,) = option[0]
        decades = np.log10(self.hi / self.lo)
        u = np.log(np.geomspace(self.lo, self.hi, round(decades * STEPS_PER_DECADE) + 2))

        def fits_at(v: np.ndarray) -> list[SpectralFit]:  # at the values e^v, whitened at once
            xw = whiten(np.column_stack([self.column(float(np.exp(w))) for w in v]))
            return [spectral_fit(yw, xw[:, [k]], drift) for k in range(len(v))]

        def fit_at(v: float) -> SpectralFit:
            return fits_at(np.array([v]))[0]

        rss = np.array([f.rss for f in fits_at(u)])
        j = int(np.argmin(rss))
        refined = refined_between(u, j, lambda v: fit_at(v).rss, rss[j])
        best_u = float(u[j]) if refined is None else refined
        best = fit_at(best_u)

        def room(v: float) -> float:  # χ²₁(0.95) − the profile deviance at e^v
            return CHI2_95 - float(profile_deviance(fit_at(v).rss, best))

        searched = np.append(u, best_u)
        order = np.argsort(searched)
        rooms = CHI2_95 - profile_deviance(np.append(rss, best.rss), best)
        interval = crossing_interval(searched[order], rooms[order], room)
        fits = [best, *fits_at(np.linspace(*np.log(interval), PROFILE_POINTS))]
        if zero is not None:
            fits.append(zero[2])
        intervals = {name: _profile_interval(fits), self.param: interval}
        if zero is not None and profile_deviance(zero[2].rss, best) <= CHI2_95:
            interval[0] = 0.0
            return zero[0], dict(zero[1]), zero[2], intervals
        value = float(np.exp(best_u))
        return {name: self.column(value)}, option[1] | {self.param: value}, best, intervals


def coupling_level(x: np.ndarray, dt: float) -> tuple[np.ndarray, float, str]:
    """The level a coupling regresses on, from a channel's block means ``x`` (blocks of ``dt``
    s): (level, low-pass window s — 0 unfiltered —, what it is, for ``evidence["level"]``).

    - A staircase passing through its levels (:func:`is_staircase`: it moves less than one LSB
      a block; fewer than :data:`MAX_STEP_REVERSALS` of its steps turn back): a spline through
      its steps' midpoints (:func:`step_midpoints`).  Its block means, raw or low-passed, leave
      a sawtooth as slow as its steps in the correction, and under the baseline's whitener
      (which had soaked the coupling into B) the steps outweigh the slow motion the rate
      follows: a bag's temperature read in 0.25 °C steps at 1 Hz, a gyro's bias following a
      lab's 25 → 28 °C with a 1 °C, 30 min cycle by 3e-4 rad/s/°C (2 h at 100 Hz), gave
      4e-5 rad/s/°C and no effect, B 4.3e-4 rad/s (truth 0)
      (``tests/test_odd_inputs.py::test_a_temperature_read_in_steps_is_read_through_them``).
      On the simulator's TEMP word (0.136 °C steps of a 2.5 °C warming; 0.08 of its steps turn
      back) the weak coupling of ``tests/model/test_loop_sim.py::test_temperature_coupling``
      is found on 3 of 12 seeds either way (the spline's family p smaller on 7).
    - A staircase that dithers (a quantised random wander: ~0.58 of its steps turn back) or
      a channel whose changes are mostly read noise (:func:`read_noise_dominates`): the moving
      average over :data:`LOWPASS_BLOCKS` blocks (on the dithering temperature of
      ``tests/model/test_loop.py``, 4e-4 rad/s/°C, straight lines through the steps'
      midpoints, low-passed, found 12 of 30 seeds, the moving average 14).
    - Else the block means themselves: a channel that moves within the window needs its own
      level (a temperature random-walking 0.2 °C/√s at 1 Hz, a gyro's bias following it by
      1e-3 rad/s/K: the low-passed level left its wander within the 18 s window in the
      corrected curve, Allan error 0.16 → 2.93, refused;
      ``tests/test_odd_inputs.py::test_a_fast_temperature_is_corrected_unfiltered``).
    """
    lowpass_s = round(LOWPASS_BLOCKS * dt, 9)  # (s, to the ns)
    staircase = is_staircase(x)
    if staircase and step_reversals(x) < MAX_STEP_REVERSALS:
        return step_midpoints(x), 0.0, "a spline through its steps' midpoints (it reads in steps)"
    if staircase or read_noise_dominates(x):
        return moving_average(x, LOWPASS_BLOCKS), lowpass_s, "moving average"
    return x, 0.0, "block means"


def is_staircase(x: np.ndarray) -> bool:
    """Whether at least half of a channel's block-to-block differences are 0 (``x``: its block
    means): it moves less than one LSB a block and reads as a staircase."""
    d = np.diff(x)
    return bool(d.size >= 2 and np.mean(d == 0) >= 0.5)


def step_reversals(x: np.ndarray) -> float:
    """The share of a channel's steps (its nonzero block-to-block changes) that turn back
    from the step before (0 with fewer than two steps).  A channel passing smoothly through its
    quantisation levels turns back only where it turns (a lab's 1 °C, 30 min cycle read in
    0.1–0.5 °C steps: 0.05–0.28); a quantised random wander dithers about each level (0.58)."""
    d = np.sign(np.diff(x))
    d = d[d != 0]
    return float(np.mean(d[1:] != d[:-1])) if d.size >= 2 else 0.0


def step_midpoints(x: np.ndarray) -> np.ndarray:
    """A staircase's level: a natural cubic spline (scipy's ``CubicSpline``) through the
    midpoints of its steps, and the first and last blocks' values at the ends.  A quantised
    channel that steps from k to k + 1 LSB crossed k + ½ there.  A step read between two
    blocks' sampling instants is split over adjacent blocks (k, a fraction, k + 1): a run of
    same-signed changes of adjacent blocks is one step, its midpoint at the run's middle — each
    part as a point of its own rang the spline to 6.7 °C off a 0.25 °C staircase.  A spline,
    not straight lines, because a channel that turns back between two crossings of the same
    level (a crest) went beyond it, which straight lines hold flat: a lab's 1 °C, 30 min cycle
    on a 3 °C warming (1 s blocks), read in 0.1 / 0.25 / 0.5 / 1 °C steps, level rms error
    0.0008 / 0.0007 / 0.023 / 0.16 °C (straight lines 0.028 / 0.026 / 0.19 / 0.42; the steps
    themselves 0.029 / 0.075 / 0.14 / 0.29).  Held within half a (median) step of the
    readings, where a quantised channel must be: between irregular steps the spline rang to
    2.3 °C off the independent generator's temperature read in 0.25 °C steps; held, it is
    within 0.25 °C (rms 0.093, the steps themselves 0.069 — Akima's local interpolant 0.039,
    but it flattens a 1 °C cycle's crests read in 1 °C steps: 0.40)."""
    d = np.sign(np.diff(x))
    j = np.flatnonzero(d)
    if j.size == 0:
        return x.astype(float)
    new_run = np.concatenate(([True], (np.diff(j) > 1) | (d[j[1:]] != d[j[:-1]])))
    first = j[new_run]
    last = j[np.concatenate((new_run[1:], [True]))]
    at = np.concatenate(([0.0], (first + last) / 2 + 0.5, [len(x) - 1.0]))
    value = np.concatenate(([x[0]], (x[first] + x[last + 1]) / 2, [x[-1]]))
    level = interpolate.CubicSpline(at, value, bc_type="natural")(np.arange(len(x), dtype=float))
    half_step = np.median(np.abs(x[last + 1] - x[first])) / 2
    return np.clip(level, x - half_step, x + half_step)


def read_noise_dominates(x: np.ndarray) -> bool:
    """Whether a channel's block-to-block changes (``x``: its block means) are mostly read
    noise rather than its motion — then a coupling low-passes it (:func:`coupling_level`).

    −2 ρ₁ of the successive differences is at least ½ (white noise w adds 2σ_w² to their
    variance and −σ_w² to their lag-1 covariance: ρ₁ = −½; a random walk's differences are
    uncorrelated, a smooth signal's positively correlated)."""
    d = np.diff(x)
    if d.size < 2:
        return True
    d = d - d.mean()
    var = float(d @ d)
    return not var > 0 or -2 * float(d[1:] @ d[:-1]) / var >= 0.5


def _slope(y: np.ndarray, x: np.ndarray) -> float:
    return float(x @ y / (x @ x))


def step_candidate(y_d: np.ndarray, dt: float, whiten: Whitener) -> Candidate | None:
    """Single bias step, located by the GLS matched filter over the coarse change points.

    The whitened difference of a step after coarse block k is column k of L⁻¹, so with the
    drift nuisance u projected out, χ²(k) = (cₖᵀ yw)² / (‖cₖ‖² − (uᵀcₖ)²/‖u‖²) / s².
    Change points in 5–95 % of the record; time interval: change points with
    χ²_max − χ²(k) ≤ χ²₁(0.95), widened by one coarse block each side (a step inside coarse block
    k + 1 is seen partly by differences k and k + 1, so the grid resolves it to ±1 block);
    p-value Bonferroni-adjusted for the change points searched.  Across a gap (``whiten.blocks``
    skips coarse blocks) difference k spans the gap: a step there is placed at the first
    observed block after it and its interval covers the whole gap.  None with fewer than three
    differences, or when nothing but the drift is left (constant block means).
    """
    yw = whiten(y_d)
    m = len(yw)
    if m < 3:
        return None
    linv = whiten.inv_chol
    u = whiten.drift
    r = yw - u * _slope(yw, u)
    s2 = float(r @ r) / (m - 1)
    if not s2 > 0:  # nothing left but the drift (constant block means): no step to test
        return None
    prof = (r @ linv) ** 2 / ((linv**2).sum(axis=0) - (u @ linv) ** 2 / (u @ u)) / s2
    k = np.arange(m)
    inner = (k >= 0.05 * m) & (k <= 0.95 * m)  # never empty from m = 2 on
    kb = int(k[inner][np.argmax(prof[inner])])
    ok = k[inner & (prof[kb] - prof <= CHI2_95)]
    span, blocks = whiten.span, whiten.blocks
    step = (np.arange(len(y_d)) >= blocks[kb + 1] * whiten.factor).astype(float)
    cand = Candidate(
        "bias_step",
        {"time_s": float(blocks[kb + 1] * span)},
        {"time_s": [float(blocks[ok.min()] * span), float((blocks[ok.max() + 1] + 1) * span)]},
        regressors=step[:, None],
        names=("size",),
        n_options=int(inner.sum()),
        n_params=2,
    )
    cand.refit(whiten, y_d)
    return cand


def tone_candidate(
    y_d: np.ndarray, dt: float, f0: float, whiten: Whitener, n_frequencies: int
) -> Candidate:
    """GLS test of a tone at ``f0`` Hz in the block means ``y_d`` (rate units, blocks of ``dt``
    s): sin and cos of the blocks' mid-times as regressors, the drift a nuisance, Wald χ² on 2
    dof — the matched test of a sinusoid of known frequency under the (fitted) noise PSD —
    Bonferroni-adjusted for the ``n_frequencies`` the tone's frequency was chosen among.
    ``params``: the sin and cos amplitudes of the tone (the mean of A sin(2πf0t + φ) over a
    block is sinc(f0 dt) A sin at its mid-time); ``amplitude`` in the evidence."""
    t = (np.arange(len(y_d)) + 0.5) * dt
    phase = 2 * np.pi * f0 * t
    cand = Candidate(
        "sinusoid",
        {},
        {},
        regressors=np.sinc(f0 * dt) * np.column_stack([np.sin(phase), np.cos(phase)]),
        names=("sin", "cos"),
        n_options=n_frequencies,
        n_params=2,
    )
    cand.refit(whiten, y_d)
    cand.evidence["amplitude"] = float(np.hypot(cand.params["sin"], cand.params["cos"]))
    return cand


def warmup_candidate(y_d: np.ndarray, dt: float, whiten: Whitener) -> Candidate:
    """Warm-up drift a·e^{−t/τw}, τw over :data:`N_WARMUP_TAU` log-spaced values (30 dt … T/3).

    Reported as kind ``rate_ramp`` (slow drift); the linear part of a drift is the IEEE 952
    rate-ramp term R of the model.  The τw of the option chosen is then estimated between
    the grid's ends, with profile intervals (:class:`OptionFamily`): on 40 records of a 3e-4
    warm-up of 600 s in white noise of 1e-4 per 1 s block (2 h), τw's interval held the truth
    on 38 (13 before session 43, read from the options' Wald χ² at the grid's points).
    """
    t = np.arange(len(y_d)) * dt

    def decay(tau_w: float) -> np.ndarray:
        return np.exp(-t / tau_w)

    grid = np.geomspace(30 * dt, t[-1] / 3, N_WARMUP_TAU)
    options = [
        ({"warmup_amplitude": decay(tau_w)}, {"warmup_tau_s": float(tau_w)}) for tau_w in grid
    ]
    family = OptionFamily("warmup_tau_s", decay, grid[0], grid[-1])  # none under 90 blocks
    cand = _best_option("rate_ramp", y_d, whiten, options, family)
    cand.evidence["note"] = "linear drift: the model's rate_ramp term R"
    return cand


def ramp_candidate(y_d: np.ndarray, dt: float, whiten: Whitener) -> Candidate:
    """Linear rate ramp R·t over the whole record (kind ``ramp``), tested in the time domain.

    The whitened first difference of a ramp is the whitener's constant column, so this is the
    GLS test of a non-zero mean of the differences under the fitted noise PSD (flicker and rate
    random walk included: a random walk's differences have zero mean, its wander is in the
    covariance) — the one candidate fitted without the drift nuisance.  Every block mean counts,
    where the Allan fit sees the ramp only through its few longest τ (R²τ²/2).  ``slope_per_s``
    in rate units per second; one option, no Bonferroni factor.
    """
    t = np.arange(len(y_d)) * dt
    cand = Candidate(
        "ramp",
        {},
        {},
        regressors=(t - t.mean())[:, None],
        names=("slope_per_s",),
        drift_nuisance=False,
    )
    cand.refit(whiten, y_d)
    cand.evidence["note"] = "a linear drift of the rate: the IEEE 952 rate_ramp R = |slope|"
    return cand


LEVEL_BLOCK_S = 0.25
"""Spikes are measured from the median of their block of this length (at least
:data:`LEVEL_MIN_BLOCK` samples): a spike of up to a quarter block barely moves it, and slow
wander (drift, Gauss–Markov, a 0.5 Hz disturbance) does not count as a deviation."""
LEVEL_MIN_BLOCK = 16
TAIL_P = 1e-3
"""The noise scale is also read from the (1 − TAIL_P) quantile of |deviation| (as if Gaussian),
so a heavy-tailed core (real MEMS noise) is not taken for outliers; spikes must be rarer."""
SPIKE_FALSE_ALARM = 1e-3
"""Family-wise (whole record) false-alarm rate of the spike threshold under Gaussian noise."""


LEVEL_CHUNK = 1 << 20
"""Samples of the blocks whose medians are taken at once (an 8 MB sorted copy)."""


def _block_level(y: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """(median of each block of ``block`` samples (the last may be shorter), float32 deviation
    y_i − median of i's block).  The medians are :func:`imupipe.stats.robust.row_medians`
    over chunks of whole blocks (numba's np.median would cost ~1.5 s of compiling on a first
    run), the chunks on the usable cores (:func:`imupipe.jit.spread`: numpy's sort releases
    the GIL); the deviations a compiled pass over the blocks' parts (:func:`_deviation`)."""
    n = y.size
    whole = n // block
    level = np.empty((n + block - 1) // block)
    chunks = range(0, whole, max(1, LEVEL_CHUNK // block))

    def medians(start: int, step: int) -> None:
        for b in chunks[start::step]:
            rows = y[b * block : min(whole, b + chunks.step) * block].reshape(-1, block)
            level[b : b + len(rows)] = robust.row_medians(rows)

    spread(medians, len(chunks))
    if whole < level.size:
        level[whole] = np.median(y[whole * block :])
    return level, _deviation(y, level, block)


def _deviation(y: np.ndarray, level: np.ndarray, block: int) -> np.ndarray:
    """float32 y_i − level of i's block of ``block`` samples; the blocks' parts on the usable
    cores (:func:`imupipe.jit.on_parts`)."""
    dev = np.empty(y.size, np.float32)
    n_parts = parts(y.size)
    on_parts(_deviation_parts, n_parts, y, level, block, dev, n_parts)
    return dev


@numba.njit(cache=True, nogil=True)
def _deviation_parts(
    y: np.ndarray, level: np.ndarray, block: int, dev: np.ndarray, n_parts: int, start: int,
    step: int,
) -> None:  # pragma: no cover (JIT)  # fmt: skip
    """Parts ``start, start + step, …`` of ``n_parts`` parts of the blocks of
    :func:`_deviation`."""
    for p in range(start, n_parts, step):
        first, stop = part_bounds(level.size, n_parts, p)
        for b in range(first, stop):
            for i in range(b * block, min(y.size, (b + 1) * block)):
                dev[i] = y[i] - level[b]


def _beyond_parts(dev: np.ndarray, limit: float) -> np.ndarray:
    """:func:`_beyond` of the whole ``dev`` (indices in order), its parts on the usable
    cores."""
    n_parts = parts(dev.size)
    found: list[np.ndarray] = [np.empty(0, np.int64)] * n_parts

    def scan(start: int, step: int) -> None:
        for p in range(start, n_parts, step):
            first, stop = part_bounds(dev.size, n_parts, p)
            found[p] = _beyond(dev[first:stop], limit) + first

    spread(scan, n_parts)
    return np.concatenate(found)


@numba.njit(cache=True, nogil=True)
def _beyond(dev: np.ndarray, limit: float) -> np.ndarray:  # pragma: no cover (JIT)
    """Indices i with |dev_i| > limit: one pass counts them, a second gathers them (no
    full-length temporaries).  Not one pass into an array grown on demand: numba then counts
    references to the reassigned array at every element, 25x slower (measured: 76 against
    3 ms for 4.3 M values)."""
    count = 0
    for i in range(len(dev)):
        count += abs(dev[i]) > limit
    out = np.empty(count, np.int64)
    k = 0
    for i in range(len(dev) if count else 0):
        if abs(dev[i]) > limit:
            out[k] = i
            k += 1
    return out


def spike_candidate(
    y: np.ndarray, tau0: float, excluded: np.ndarray | None = None
) -> Candidate | None:
    """Spikes: samples whose deviation from their block's median exceeds a threshold with a
    family-wise false-alarm rate of :data:`SPIKE_FALSE_ALARM` (Gaussian), knowing the LSB.

    Deviation: y_i minus the median of i's block of :data:`LEVEL_BLOCK_S` (float32, 4 bytes a
    sample).  Noise scale: the larger of 1.4826 × median |deviation| and the (1 − TAIL_P)
    quantile of |deviation| / Φ⁻¹(1 − TAIL_P/2) (:mod:`imupipe.stats.robust`, no copies).
    Quantisation: with an LSB q (:func:`imupipe.stats.robust.quantum`) a quantised deviation of
    k·q stands for a true one beyond (k − 1/2)·q, so the limit is z·scale + q/2 — the tail of
    coarsely quantised noise (e.g. 7 LSB at z·scale = 6.2 LSB) is not a spike.  The correction
    replaces each spike by its block's median.  ``excluded`` (bool, len(y)): samples the
    analysis leaves out (gaps, NaN/inf frames and excised events, filled by a noise-free line
    from their neighbours' means) are no spikes, whatever their fill.
    """
    y = kernel_input(y, np.float64)
    block = max(LEVEL_MIN_BLOCK, round(LEVEL_BLOCK_S / tau0))
    level, dev = _block_level(y, min(block, y.size))
    sigma_mad = robust.MAD_TO_SIGMA * robust.mad(dev, center=0.0)
    sigma_tail = robust.abs_quantile(dev, 1.0 - TAIL_P) / float(-special.ndtri(TAIL_P / 2))
    scale = max(sigma_mad, sigma_tail)
    if not scale > 0:
        return None
    lsb = robust.quantum(y)
    thr = float(-special.ndtri(SPIKE_FALSE_ALARM / (2 * len(y))))  # norm.isf
    limit = thr * scale + lsb / 2
    idx = _beyond_parts(dev, limit)
    if excluded is not None:
        idx = idx[~excluded[idx]]
    if idx.size == 0:
        return None
    value = y[idx] - level[idx // min(block, y.size)]
    size = np.abs(value)
    return Candidate(
        "spike",
        {"count": float(idx.size), "size": float(np.median(size)), "sigma": scale},
        {},
        {
            "threshold_z": thr,
            "limit": limit,
            "lsb": lsb,
            "sigma_mad": sigma_mad,
            "sigma_tail": sigma_tail,
            "max_size": float(size.max()),
            "first_times_s": (idx[:10] * tau0).tolist(),
        },
        spikes=SparseCorrection(idx, value),
        n_params=int(idx.size),
        p_value=SPIKE_FALSE_ALARM,
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _hann(i: int, n: int) -> float:  # pragma: no cover (JIT)
    """Weight i of the symmetric n-point Hann window of np.hanning."""
    return 0.5 + 0.5 * np.cos(np.pi * (1 - n + 2 * i) / (n - 1)) if n > 1 else 1.0


@numba.njit(cache=True, nogil=True)
def _hann_windowed(
    y: np.ndarray, mean: float, fix_index: np.ndarray, fix_value: np.ndarray
) -> tuple[np.ndarray, float, float]:  # pragma: no cover (JIT)
    """(y' − mean)·w in float32, with y' = y minus ``fix_value`` at ``fix_index`` and w the
    symmetric Hann window of np.hanning, Σw and Σw², in one pass (w_i = 0.5 + 0.5 cos(π (2i +
    1 − n) / (n − 1)) = w_{n−1−i}, so one cosine per pair).  float32 halves the memory of the
    periodogram of a long series; its rounding (~1e-7 of the amplitude) lies far below the noise
    floor of an IMU record."""
    n = len(y)
    out = np.empty(n, np.float32)
    win_sum, win_sq_sum = 0.0, 0.0
    for i in range((n + 1) // 2):
        w = _hann(i, n)
        pair = 1.0 if i == n - 1 - i else 2.0
        out[i] = (y[i] - mean) * w
        out[n - 1 - i] = (y[n - 1 - i] - mean) * w
        win_sum += pair * w
        win_sq_sum += pair * w * w
    for k in range(fix_index.size):
        out[fix_index[k]] -= fix_value[k] * _hann(fix_index[k], n)
    return out, win_sum, win_sq_sum


@dataclass(frozen=True)
class HannSpectrum:
    """The Hann-windowed periodogram of one series, computed once (:func:`hann_spectrum`) and
    read by band: the magnitudes |X_k| (float32, k = 0 … n/2) of the rfft of the first ``n``
    samples (at most :data:`PSD_MAX_SAMPLES`), sampled every ``dt`` s, mean removed and minus a
    sparse correction, with the window's Σw and Σw² (``win_sum``, ``win_sq_sum``).  The power
    is in arbitrary units: only shapes and ratios are read from it."""

    magnitude: np.ndarray
    n: int
    dt: float
    win_sum: float
    win_sq_sum: float

    @property
    def bin_hz(self) -> float:
        """Bin spacing (Hz) of ``np.fft.rfftfreq(n, dt)``, whose bin k is k · bin_hz."""
        return 1.0 / (self.n * self.dt)

    def periodogram(self, f_lo: float, f_hi: float) -> tuple[np.ndarray, np.ndarray]:
        """(frequencies Hz, power) of every second bin in [f_lo, f_hi].

        A Hann window's DFT is X(k)/2 − X(k−1)/4 − X(k+1)/4, so for a smooth spectrum the
        powers of bins k and k+2 correlate by only (1/6)² ≈ 0.03 (adjacent bins: (2/3)² ≈
        0.44): every second bin gives ordinates close to independent, each ~ S(f) χ²₂ / 2
        (Brillinger, *Time Series: Data Analysis and Theory*, Thm 5.2.6), the premise of a
        Whittle likelihood."""
        step = self.bin_hz
        top = self.magnitude.size - 1
        k = np.arange(max(int(np.ceil(f_lo / step)), 1), min(int(f_hi / step), top) + 1)
        k = k[k % 2 == 0]
        return k * step, self.magnitude[k].astype(np.float64) ** 2

    def line(self, f_lo: float, f_hi: float) -> dict[str, float]:
        """Strongest line in [f_lo, f_hi] (parabolic peak); empty below three bins or where the
        band holds no power.

        Frequency 95 % interval from the Cramér–Rao bound for a real sinusoid in locally white
        noise, var(ω) = 24 σ² / (A² N (N² − 1)) (Rife & Boorstyn 1974), σ² from the band's
        median level; amplitude from the windowed peak (Hann coherent gain 1/2).
        ``line_p_value``: chance that noise alone puts a bin this far above the band's level —
        periodogram bins of noise are ~exponential (level = median / ln 2), so the largest of K
        bins exceeds v times the level with probability 1 − (1 − e^−v)^K (Fisher 1929's test of
        the largest periodogram ordinate, with the level estimated robustly; the Hann window's
        correlated bins make it conservative)."""
        n, dt, step = self.n, self.dt, self.bin_hz
        k = np.arange(max(int(f_lo / step) - 1, 1), min(int(f_hi / step) + 2, n // 2) + 1)
        band = k[(k * step >= f_lo) & (k * step <= f_hi)]
        if band.size < 3:
            return {}
        # the band and one bin either side, as float64 power: the whole spectrum stays float32
        first = max(int(band[0]) - 1, 0)
        spec = self.magnitude[first : int(band[-1]) + 2].astype(np.float64) ** 2
        band_power = spec[band - first]
        if not band_power.max() > 0:  # a band without power (a constant stretch) has no line
            return {}
        i = int(band[np.argmax(band_power)])
        i = min(max(i, 1), n // 2 - 1)
        a, b, c = np.log(spec[i - 1 - first : i + 2 - first] + 1e-300)
        # the vertex lies within half a bin of i only where i is a local maximum; at a band edge
        # below a stronger neighbour outside the band, the line is i itself
        delta = 0.5 * (a - c) / (a - 2 * b + c) if b >= max(a, c) and (a - 2 * b + c) < 0 else 0.0
        freq = (i + delta) / (n * dt)
        amp = 2 * np.sqrt(spec[i - first]) / self.win_sum
        noise_psd = np.median(band_power) / self.win_sq_sum  # per-sample variance equivalent
        sigma_f = np.sqrt(24 * noise_psd / (amp**2 * n * (n**2 - 1))) / (2 * np.pi * dt)
        sigma_f = np.hypot(sigma_f, 0.02 / (n * dt))  # + bias of log-parabolic Hann interpolation
        ratio = spec[i - first] / np.median(band_power)
        line_p = -np.expm1(band.size * np.log1p(-np.exp(-np.log(2) * ratio)))
        return {
            "frequency_hz": float(freq),
            "frequency_lo": float(freq - Z95 * sigma_f),
            "frequency_hi": float(freq + Z95 * sigma_f),
            "psd_amplitude": float(amp),
            "line_to_floor": float(ratio),
            "line_p_value": float(line_p),
            "psd_samples": n,
        }


def hann_spectrum(
    y: np.ndarray, dt: float, correction: SparseCorrection | None = None
) -> HannSpectrum:
    """The :class:`HannSpectrum` of ``y`` (sampled every ``dt`` s) minus ``correction`` over
    its first :data:`PSD_MAX_SAMPLES` samples: a longer FFT's buffers would outgrow the analysis
    of a 24 h / 1 kHz axis, and 2**24 samples already resolve a line to ~1e-4 Hz at 1 kHz."""
    n = min(len(y), PSD_MAX_SAMPLES)
    y = kernel_input(y[:n])
    fix = (correction or NO_CORRECTION).within(0, n)
    mean = (y.sum() - fix.value.sum()) / n
    windowed, win_sum, win_sq_sum = _hann_windowed(y, mean, fix.index, fix.value)
    coef = scipy.fft.rfft(windowed, overwrite_x=True)
    del windowed
    magnitude = np.abs(coef)
    magnitude.flags.writeable = False  # a kept spectrum is read by every view that asks
    return HannSpectrum(magnitude, n, float(dt), win_sum, win_sq_sum)


def hann_periodogram(
    y: np.ndarray,
    dt: float,
    f_lo: float,
    f_hi: float,
    correction: SparseCorrection | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies Hz, power) of every second bin of the Hann-windowed periodogram of ``y``
    (sampled every ``dt`` s) minus ``correction`` in [f_lo, f_hi] (:func:`hann_spectrum`,
    :meth:`HannSpectrum.periodogram`)."""
    return hann_spectrum(y, dt, correction).periodogram(f_lo, f_hi)


def psd_line(
    y: np.ndarray,
    dt: float,
    f_lo: float,
    f_hi: float,
    correction: SparseCorrection | None = None,
) -> dict[str, float]:
    """Strongest line of the Hann-windowed periodogram of ``y`` (sampled every ``dt`` s) minus
    ``correction`` in [f_lo, f_hi] (:func:`hann_spectrum`, :meth:`HannSpectrum.line`)."""
    return hann_spectrum(y, dt, correction).line(f_lo, f_hi)


ROLLOFF_BANDS = ((0.05, 0.2), (0.4, 0.5))
"""Mid and near-Nyquist bands (fractions of the sample rate) of :func:`psd_rolloff` for a
filter without a bandwidth or one near Nyquist (:func:`rolloff_bands`)."""
ROLLOFF_SEGMENT = 256


WELCH_BLOCK_SAMPLES = 1 << 20
"""Segments' samples transformed at once by :func:`welch_psd` (8 MB of float64 a block)."""


def welch_window(seg: int) -> np.ndarray:
    """The periodic ("DFT-even") Hann window of ``seg`` samples, 0.5 − 0.5 cos(2π n / seg),
    that ``scipy.signal.welch`` uses by default (``get_window("hann", seg)``, equal to 2e-16),
    without importing ``scipy.signal`` (0.5–0.8 s on a first call)."""
    return np.hanning(seg + 1)[:-1]


def welch_psd(y: np.ndarray, tau0: float, seg: int) -> tuple[np.ndarray, np.ndarray]:
    """Welch's PSD (Hann, 50 % overlap, each segment's mean removed; Welch 1967) of the first
    :data:`PSD_MAX_SAMPLES` samples of ``y`` (sampled every ``tau0`` s) in segments of ``seg``:
    frequencies (Hz) and one-sided PSD (units² / Hz), ``scipy.signal.welch``'s estimate with
    its defaults (the same segments, window and scaling Σ|X|² / (K fs Σw²), doubled but at 0
    and Nyquist; equal to ~1e-14).  The segments are transformed in blocks of
    :data:`WELCH_BLOCK_SAMPLES` by one ``scipy.fft.rfft`` call each, on the calling thread's
    cores: scipy 1.17's ``welch`` removes each segment's mean and transforms it in a Python
    loop, 10–40× slower on a 1 M-sample record (0.55 s against 0.02 s at 64 samples a
    segment, 2.6 s at 12 h / 100 Hz)."""
    n = min(len(y), PSD_MAX_SAMPLES)
    hop = seg - seg // 2
    segments = np.lib.stride_tricks.sliding_window_view(np.asarray(y[:n], dtype=float), seg)
    segments = segments[::hop]  # a view: segment k is samples [k hop, k hop + seg)
    window = welch_window(seg)
    power = np.zeros(seg // 2 + 1)
    rows = max(1, WELCH_BLOCK_SAMPLES // seg)
    with scipy.fft.set_workers(cores_here()):
        for k in range(0, len(segments), rows):
            block = segments[k : k + rows]
            spectra = scipy.fft.rfft((block - block.mean(axis=1, keepdims=True)) * window)
            power += np.sum(spectra.real**2 + spectra.imag**2, axis=0)
    psd = power * (tau0 / (len(segments) * float(np.sum(window**2))))
    psd[1 : None if seg % 2 else -1] *= 2  # one-sided: the negative frequencies' power
    return scipy.fft.rfftfreq(seg, tau0), psd


Welch = Callable[[int], tuple[np.ndarray, np.ndarray]]
"""A series' :func:`welch_psd` by segment length (kept by a caller that asks more than once)."""


def welch_band_variance(seg: int, segments: int, bins: int) -> float:
    """Relative variance Var(P̄)/E(P̄)² of the mean P̄ of ``bins`` adjacent ordinates of a
    :func:`welch_psd` (``segments`` Hann segments of ``seg`` samples, 50 % overlap) of Gaussian
    noise whose PSD is flat over them:

        (1 / (K b)) · Σ_{|k|<b} (1 − |k|/b) ρ²_k · [1 + 2 Σ_{m≥1} (1 − m/K) c²_m],

    ρ_k = |Σ w²_n e^{−2πikn/seg}| / Σ w²_n the correlation of one segment's windowed DFT at bins
    k apart, c_m = Σ w_n w_{n+m·seg/2} / Σ w²_n that of segments m hops apart at one frequency
    (Percival & Walden 1993, Spectral Analysis for Physical Applications, §6.6 and §6.17;
    Welch 1967).  For the Hann window ρ²₁ = 4/9, ρ²₂ = 1/36 and c²₁ = 1/36: ~2/(K b), twice
    the variance of independent ordinates (measured on white noise: the z of a band ratio had
    standard deviation 1.47 ± 0.03 with 1/(K b), 1.42 predicted).  No ordinate: infinite."""
    if bins < 1:
        return float("inf")
    w = welch_window(seg)  # and scipy.signal.welch's hop
    power = float(np.sum(w**2))
    lags = np.arange(min(bins, seg))
    rho2 = np.abs(np.fft.fft(w**2)[lags]) ** 2 / power**2
    within = rho2[0] + 2 * float(np.sum((1 - lags[1:] / bins) * rho2[1:]))
    hop = seg - seg // 2
    shifts = np.arange(1, min(segments, -(-seg // hop)))  # segments overlap while m·hop < seg
    c2 = np.array([np.dot(w[: seg - m * hop], w[m * hop :]) ** 2 for m in shifts]) / power**2
    across = 1 + 2 * float(np.sum((1 - shifts / segments) * c2))
    return within * across / (segments * bins)


def _band_ratio(
    pxx: np.ndarray, over: np.ndarray, under: np.ndarray, seg: int, n: int
) -> tuple[float, float]:
    """The ratio of the mean Welch PSD ``pxx`` in band ``over`` to that in band ``under``
    (masks of its ordinates; segments of ``seg`` of ``n`` samples, 50 % overlap) and the
    standard error of its logarithm, √(V_over + V_under) (:func:`welch_band_variance`)."""
    segments = max(1, 2 * n // seg - 1)
    ratio = float(pxx[over].mean() / pxx[under].mean())
    variance = welch_band_variance(seg, segments, int(over.sum()))
    variance += welch_band_variance(seg, segments, int(under.sum()))
    return ratio, float(np.sqrt(variance))


def rolloff_bands(fs: float, bandwidth_hz: float | None) -> tuple[tuple[float, float], ...]:
    """(pass band, stop band), Hz, of :func:`psd_rolloff` for a low-pass of −3 dB bandwidth
    ``bandwidth_hz`` at the sample rate ``fs``: [f₃/8, f₃/2] and [2f₃, min(8f₃, fs/2)), where
    the filters searched pass ≥ 80 % of the power (a moving average's |H|² = sinc²(fL) at
    f₃/2: 0.81) and stop ≥ 85 % of it (at 2f₃: a moving average 0.15, a Bartlett window 0.04,
    a first-order low-pass 0.2 falling as 1/f²).  A filter whose stop band would begin above
    :data:`ROLLOFF_BANDS`' near-Nyquist band (an anti-alias filter), or no bandwidth: the
    fixed :data:`ROLLOFF_BANDS`."""
    (m_lo, m_hi), (h_lo, h_hi) = ROLLOFF_BANDS
    if bandwidth_hz is None or 2 * bandwidth_hz >= h_lo * fs:
        return (m_lo * fs, m_hi * fs), (h_lo * fs, h_hi * fs)
    return (bandwidth_hz / 8, bandwidth_hz / 2), (2 * bandwidth_hz, min(8 * bandwidth_hz, fs / 2))


ROLLOFF_PASS_BINS = 16
"""Least Welch ordinates in :func:`psd_rolloff`'s pass band (its segment is lengthened to it)."""


def psd_rolloff(
    y: np.ndarray,
    tau0: float,
    welch: Welch | None = None,
    bandwidth_hz: float | None = None,
    model: NoisePsd | None = None,
) -> dict[str, float]:
    """The spectrum's view of a prefilter of −3 dB bandwidth ``bandwidth_hz`` (Hz): the mean
    Welch PSD (Hann, 50 % overlap; Welch 1967) of its stop band over that of its pass band
    (:func:`rolloff_bands`), over the first :data:`PSD_MAX_SAMPLES` samples at most, divided
    by the same ratio of the ``model`` PSD without the prefilter (:meth:`NoisePsd.sampled`: the
    baseline's flicker and random walk raise the pass band, its quantisation the stop band).
    Segments of :data:`ROLLOFF_SEGMENT` samples, longer where the pass band would hold fewer
    than :data:`ROLLOFF_PASS_BINS` ordinates (at most an eighth of the samples).

    The model's spectrum gives 1, a low-pass on some of its white noise less (a filter on all
    of it: the stop band's share left, ~0.04–0.2), an unmodelled rise towards Nyquist (rate
    quantisation, angle white noise) more.  Each band mean averages K segments × b bins of
    correlated ~χ²₂ periodogram ordinates, so ln(ratio) has standard error √(V_pass + V_stop)
    (:func:`welch_band_variance`: the Hann window's correlation of adjacent bins and of
    overlapping segments, ~2/(K b) each; the model's own uncertainty is not counted);
    ``p_value``: one-sided normal P(no roll-off).  Measured (session 45): the fixed bands
    5–20 Hz and 40–50 Hz at 100 Hz, both above a 2 Hz Bartlett filter's bandwidth, read a
    ratio of 0.99 (p 0.06) where three quarters of the white noise went through it.
    """
    n = min(len(y), PSD_MAX_SAMPLES)
    fs = 1.0 / tau0
    (p_lo, p_hi), (s_lo, s_hi) = rolloff_bands(fs, bandwidth_hz)
    wanted = ROLLOFF_PASS_BINS * fs / (p_hi - p_lo)
    seg = ROLLOFF_SEGMENT
    if wanted > seg:
        seg = int(min(2 ** np.ceil(np.log2(wanted)), max(seg, n // 8)))
    seg = min(seg, n)
    f, pxx = welch(seg) if welch is not None else welch_psd(y, tau0, seg)
    passed = (f >= p_lo) & (f <= p_hi)
    stopped = (f >= s_lo) & (f < s_hi)
    ratio, se = _band_ratio(pxx, stopped, passed, seg, n)
    expected = 1.0
    if model is not None:
        stop_level = model.sampled(f[stopped], tau0).mean()
        expected = float(stop_level / model.sampled(f[passed], tau0).mean())
    return {
        "high_to_mid": ratio / expected,
        "p_value": float(special.ndtr(np.log(ratio / expected) / se)),
        "band_hz": [s_lo, s_hi],
        "pass_band_hz": [p_lo, p_hi],
        "model_high_to_mid": expected,
    }


def band_excess(
    y: np.ndarray,
    tau0: float,
    f0: float,
    width_hz: float,
    welch: Welch | None = None,
) -> dict[str, float]:
    """The spectrum's view of a spread line at ``f0`` ± ``width_hz`` (Hz): the mean Welch PSD
    (Hann, 50 % overlap; Welch 1967) within |f − f0| ≤ w over that of each of its shoulders,
    the lower f0 − 4w ≤ f ≤ f0 − 2w (f > 0) and the upper f0 + 2w ≤ f ≤ f0 + 4w,
    w = max(``width_hz``, 1.5 bins).

    Segments of ≈ 2/w samples·s (a power of two, at least 64, at most an eighth of the first
    :data:`PSD_MAX_SAMPLES` samples) resolve the line without splitting it over many noisy
    bins.  Each ln(ratio) has standard error √(V_line + V_shoulder) (:func:`welch_band_variance`)
    and its one-sided normal P(no excess).  A line is a local maximum of the spectrum: it
    stands above both shoulders, so ``line_to_shoulders`` is the lesser ratio and ``p_value``
    the greater p (an intersection–union test, of level α: Berger 1982, Technometrics 24, 295).
    A smooth spectrum (white, flicker, a Gauss–Markov slope) gives ratios near 1; the edge of a
    low-pass passes the band and stops its upper shoulder, but not its lower one — measured:
    white noise through a second-order Butterworth low-pass at 4 Hz (200 Hz) stood 4.2× above
    both shoulders pooled, at 2.7 Hz, and was modelled as a vibration.  An upper shoulder beyond
    the Nyquist frequency is left out (a line near it is judged on its lower one); a line with
    no spectrum below it (f0 − 2w under the first bin: a "line" as wide as its frequency, which
    is what a low-pass' edge fits as) cannot show as a maximum: ``p_value`` 1, with
    ``lower_shoulder_hz`` the f0 − 2w it would need above 0.
    """
    n = min(len(y), PSD_MAX_SAMPLES)
    seg = int(np.clip(2 ** np.round(np.log2(2.0 / (width_hz * tau0))), 64, max(64, n // 8)))
    seg = min(seg, n)
    f, pxx = welch(seg) if welch is not None else welch_psd(y, tau0, seg)
    w = max(width_hz, 1.5 / (seg * tau0))
    offset = f - f0
    line = np.abs(offset) <= w
    sides = {
        "lower": (offset <= -2 * w) & (offset >= -4 * w) & (f > 0),
        "upper": (offset >= 2 * w) & (offset <= 4 * w),
    }
    if not line.any():
        return {}
    if not sides["lower"].any():
        return {"line_to_shoulders": np.nan, "p_value": 1.0, "lower_shoulder_hz": f0 - 2 * w}
    sides = {side: mask for side, mask in sides.items() if mask.any()}
    out: dict[str, float] = {}
    for side, shoulder in sides.items():
        ratio, se = _band_ratio(pxx, line, shoulder, seg, n)
        out[f"line_to_{side}_shoulder"] = ratio
        out[f"p_value_{side}"] = float(special.ndtr(-np.log(ratio) / se))
    weaker = max(sides, key=lambda side: out[f"p_value_{side}"])
    return out | {
        "line_to_shoulders": out[f"line_to_{weaker}_shoulder"],
        "p_value": out[f"p_value_{weaker}"],
        "resolution_hz": 1.0 / (seg * tau0),
    }
