"""PNG figures for ``report.md`` (matplotlib, Agg backend; no display needed).

- ``allan_<sensor>.png``: log-log overlapping Allan deviation of the three axes of one sensor with
  their confidence intervals as error bars and the fitted IEEE 952 asymptotes (each term's own
  contribution, IEEE Std 952-1997 Annex C: sqrt(3) Q / tau, N / sqrt(tau), the flicker form whose
  plateau is 0.664 B, K sqrt(tau / 3), R tau / sqrt(2)) of the final model, and that model's
  deviation (exactly its reported terms, :meth:`imupipe.model.ieee952.NoiseTerms.adev`), like
  figures 4 (accelerometers) and 5 (gyroscopes) of the ADIS16364 paper.
- ``loop_<sensor>.png``: the closed loop of issue 4 — measured deviation (and, when an effect was
  regressed out in the time domain, the deviation after that correction), model before and after,
  and the normalised residual z before and after, each over its fit's τ range (symmetric-log
  beyond |z| = 5, so a rejected baseline's large z leaves the final model's readable).
- ``common_mode.png``: the correlation of each pair of axes that move together against the
  window length, with the family-wise test's critical |r| (only when some pair does).
"""

from __future__ import annotations

import math
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axis import Axis
from matplotlib.ticker import FormatStrFormatter, LogFormatter, LogLocator, NullLocator

from imupipe.analysis.common_mode import critical_correlation
from imupipe.analysis.results import AnalysisResult, AxisResult
from imupipe.model.ieee952 import design_columns
from imupipe.vocab import SENSOR_TITLES, TERM_NAMES

_SYMBOLS = {
    "quantization": "Q",
    "random_walk": "N",
    "bias_instability": "B",
    "rate_random_walk": "K",
    "rate_ramp": "R",
}
_STYLES = {"Q": (0, (1, 1)), "N": "--", "B": "-.", "K": (0, (5, 1, 1, 1, 1, 1)), "R": ":"}
_COLORS = {"x": "tab:blue", "y": "tab:orange", "z": "tab:green"}

_MARGINS = {"left": 0.1, "right": 0.98, "bottom": 0.08, "top": 0.94, "hspace": 0.08}
"""Fixed figure margins: a layout engine would cost an extra draw per figure (~0.15 s)."""


def _color(axis: AxisResult) -> str:
    return _COLORS.get(axis.name[-1], "k")


def _errorbar(ax: plt.Axes, axis: AxisResult, **kwargs: object) -> None:
    c = axis.curve
    adev = np.asarray(c.adev, dtype=float)
    lo = np.nan_to_num(adev - np.asarray(c.adev_lo, dtype=float), nan=0.0)
    hi = np.nan_to_num(np.asarray(c.adev_hi, dtype=float) - adev, nan=0.0)
    ax.errorbar(c.tau_s, adev, yerr=[lo, hi], fmt="o", ms=2.5, lw=0.8, capsize=1.5, **kwargs)


def _finish_loglog(ax: plt.Axes, axes: list[AxisResult]) -> None:
    """Limit the view to the measured data (asymptotes extend beyond it) and label it."""
    tau = np.concatenate([np.asarray(a.curve.tau_s, float) for a in axes])
    dev = np.concatenate([np.asarray(a.curve.adev, float) for a in axes])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(tau.min() / 1.5, tau.max() * 1.5)
    ax.set_ylim(np.nanmin(dev) / 3.0, np.nanmax(dev) * 3.0)
    ax.set_xlabel("averaging time τ [s]")
    ax.set_ylabel(f"Allan deviation σ(τ) [{axes[0].unit}]")
    ax.grid(True, which="major", lw=0.4, alpha=0.6)
    sparse_log_ticks(ax.xaxis, ax.yaxis)


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


class PowerOfTenLabels(LogFormatter):
    """Log-axis tick labels in plain Unicode, ``10⁻³`` and ``2×10⁻³``, where matplotlib's
    default (``LogFormatterSciNotation``) writes mathtext: the first mathtext label of a
    process builds its parser, ~0.3 s of CPU in each process that draws a report's figures.
    Which ticks are labelled is matplotlib's own rule (:class:`~matplotlib.ticker.LogFormatter`:
    decades, and minor ticks when the view spans few decades)."""

    def _num_to_string(self, x: float, vmin: float, vmax: float) -> str:
        """The coefficient to 3 significant digits: a view narrower than a decade (a fleet's N
        spread over ±10 %) gets minor ticks at 4.6, 4.8… ×10⁻², which must not all read
        ``5×10⁻²``."""
        fx = math.log10(x)
        exponent = round(fx) if abs(fx - round(fx)) < 1e-10 else math.floor(fx)
        coeff = float(f"{10 ** (fx - exponent):.3g}")
        if coeff >= 10:  # 9.9996… rounds up to the next decade
            coeff, exponent = coeff / 10, exponent + 1
        power = "10" + str(exponent).translate(_SUPERSCRIPT)
        return power if coeff == 1 else f"{coeff:g}×{power}"


def log_labels(*axes: Axis) -> None:
    """:class:`PowerOfTenLabels` on the major and minor ticks of log ``axes``."""
    for axis in axes:
        axis.set_major_formatter(PowerOfTenLabels())
        axis.set_minor_formatter(PowerOfTenLabels())


def sparse_log_ticks(*axes: Axis) -> None:
    """Minor ticks of log ``axes`` at 2 and 5 only (matplotlib's default puts one at 2…9 of
    every decade, and each tick costs ~1 ms to lay out and draw), labelled in plain text
    (:func:`log_labels`)."""
    for axis in axes:
        axis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
    log_labels(*axes)


def allan_figure(result: AnalysisResult, sensor: str, path: Path) -> Path | None:
    """Log-log Allan deviation with intervals and fitted asymptotes of one sensor's axes."""
    axes = result.by_sensor(sensor)
    if not axes:
        return None
    fig, ax = plt.subplots(figsize=(8, 5.5), gridspec_kw={**_MARGINS, "bottom": 0.1})
    used: set[str] = set()
    for axis in axes:
        color = _color(axis)
        conf = axis.curve.confidence
        _errorbar(ax, axis, color=color, label=f"{axis.name} ({conf:.1%} interval)")
        tau = np.asarray(axis.curve.tau_s, dtype=float)
        tau = np.geomspace(tau[0], tau[-1], 200)
        # each term's own AVAR contribution (IEEE 952 Annex C, as fitted by imupipe.model.ieee952)
        columns = design_columns(tau, getattr(axis.terms, "cutoff_hz", np.inf))
        for j, name in enumerate(TERM_NAMES):
            value, symbol = getattr(axis.terms, name).value, _SYMBOLS[name]
            if value is not None:
                ax.plot(tau, value * np.sqrt(columns[:, j]), ls=_STYLES[symbol], color=color)
                used.add(symbol)
        ax.plot(tau, axis.terms.adev(tau), "-", color=color, lw=1.2, alpha=0.7)
    ax.plot([], [], "-", color="0.3", label="final model (reported terms)")
    for symbol, style in _STYLES.items():
        if symbol in used:
            ax.plot([], [], ls=style, color="0.3", label=f"fitted {symbol} asymptote")
    _finish_loglog(ax, axes)
    ax.set_title(f"{SENSOR_TITLES[sensor]}: overlapping Allan deviation, IEEE 952 asymptotes")
    ax.legend(fontsize=7, ncol=2)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


Z_LINEAR = 5.0
"""|z| up to which the residual panel is linear (logarithmic beyond, when a z exceeds it)."""


def loop_figure(result: AnalysisResult, sensor: str, path: Path) -> Path | None:
    """Measured deviation with model before/after (top) and normalised residuals z (bottom)."""
    axes = [a for a in result.by_sensor(sensor) if a.loop is not None]
    if not axes:
        return None
    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=(8, 7.5), sharex=True, gridspec_kw={**_MARGINS, "height_ratios": (2, 1)}
    )
    z_max = 0.0
    for axis in axes:
        color, loop = _color(axis), axis.loop
        tau = np.asarray(axis.curve.tau_s, dtype=float)
        _errorbar(top, axis, color=color, label=f"{axis.name} measured")
        after = np.asarray(loop.adev_after, dtype=float)
        if not np.allclose(after, axis.curve.adev, rtol=1e-9, equal_nan=True):
            top.plot(tau, after, "s", mfc="none", color=color, ms=3.5, label="after corrections")
        fitted_before, fitted_after = loop.before.fitted, loop.after.fitted
        top.plot(tau, fitted_before(tau, loop.model_adev_before), "--", color=color, lw=1.0)
        top.plot(tau, fitted_after(tau, loop.model_adev_after), "-", color=color, lw=1.4)
        z_before, z_after = fitted_before(tau, loop.z_before), fitted_after(tau, loop.z_after)
        bottom.plot(tau, z_before, "o--", color=color, ms=2.5, lw=0.6, alpha=0.5)
        bottom.plot(tau, z_after, "o-", color=color, ms=2.5, lw=1.0, label=axis.name)
        z_max = max(z_max, float(np.nanmax(np.abs(np.r_[z_before, z_after, 0.0]))))
    top.plot([], [], "--", color="0.3", label="model before")
    top.plot([], [], "-", color="0.3", label="model after")
    _finish_loglog(top, axes)
    top.set_xlabel("")
    top.legend(fontsize=7, ncol=2)
    top.set_title(f"{SENSOR_TITLES[sensor]}: closed loop, model before (dashed) and after (solid)")
    for level in (-3.0, 3.0):
        bottom.axhline(level, color="0.5", lw=0.6, ls=":")
    bottom.axhline(0.0, color="0.3", lw=0.6)
    if z_max > Z_LINEAR:  # a rejected baseline's z in the hundreds would flatten the rest
        bottom.set_yscale("symlog", linthresh=Z_LINEAR)
        ticks = [t for t in (3, 10, 30, 100, 300, 1000, 3000) if t <= 1.5 * z_max]
        bottom.set_yticks([-t for t in ticks[::-1]] + [0] + ticks)
        bottom.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        bottom.yaxis.set_minor_locator(NullLocator())
    bottom.set_ylabel("normalised residual z")
    bottom.set_xlabel("averaging time τ [s]")
    bottom.grid(True, which="major", lw=0.4, alpha=0.6)
    bottom.legend(fontsize=7, title="after (before: faded)", title_fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def common_mode_figure(result: AnalysisResult, path: Path) -> Path | None:
    """The correlation of each pair of axes that move together against the window length,
    with the family-wise test's critical |r| (:mod:`imupipe.analysis.common_mode`); None when
    no pair moves together."""
    found = None if result.events is None else result.events.common_mode
    if found is None or not found.pairs:
        return None
    detector = result.events.detector
    fig, ax = plt.subplots(figsize=(8, 4.5), gridspec_kw={**_MARGINS, "bottom": 0.12})
    colors = plt.get_cmap("tab20").colors
    styles = {2: "-", 1: "--", 0: ":"}  # accelerometers in the pair: 2, 1 or 0
    for k, pair in enumerate(found.pairs):
        accels = sum(a.startswith("accel") for a in pair.axes)
        significant = [w in pair.significant_s for w in pair.window_s]
        color = colors[k % len(colors)]
        ax.plot(pair.window_s, pair.correlation, ls=styles[accels], color=color, lw=1.0,
                label="–".join(pair.axes))  # fmt: skip
        w, r = np.asarray(pair.window_s), np.asarray(pair.correlation)
        ax.plot(w[significant], r[significant], "o", color=color, ms=3.5)
    critical = critical_correlation(np.array(detector.dof), found.tests, found.alpha)
    ax.fill_between(detector.scales_s, -critical, critical, color="0.88", lw=0,
                    label=f"not significant (family-wise α = {found.alpha:g})")  # fmt: skip
    ax.axhline(0.0, color="0.3", lw=0.6)
    ax.set_xscale("log")
    sparse_log_ticks(ax.xaxis)
    lowest = min(min(p.correlation) for p in found.pairs)
    ax.set_ylim(-1.0 if lowest < -0.2 else -0.3, 1.0)
    ax.set_xlabel("window length [s]")
    ax.set_ylabel("correlation of the level fluctuations")
    ax.set_title("Axes that move together (dots: significant; solid: two accelerometers)")
    ax.grid(True, which="major", lw=0.4, alpha=0.6)
    ax.legend(fontsize=6, ncol=4, loc="lower left")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def sensor_figures(result: AnalysisResult, sensor: str, out_dir: Path) -> dict[str, Path]:
    """Write the figures of one sensor that apply into ``out_dir``; returns {caption: path}."""
    written: dict[str, Path] = {}
    for kind, make in (("allan", allan_figure), ("loop", loop_figure)):
        path = make(result, sensor, Path(out_dir) / f"{kind}_{sensor}.png")
        if path is not None:
            written[f"{SENSOR_TITLES[sensor]}: {kind}"] = path
    return written


def write_figures(result: AnalysisResult, out_dir: Path, processes: int = 1) -> dict[str, Path]:
    """Write every figure that applies into ``out_dir``; returns {caption: path}, gyroscopes
    first.  With ``processes`` > 1 (and ``fork`` available) the accelerometers' figures are
    drawn in a forked child while this process draws the gyroscopes' (matplotlib holds the
    GIL, so a thread would not draw at the same time); the child's error is raised here, and
    the child has ended when this returns, however it returns."""
    if processes < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return {
            **sensor_figures(result, "gyro", out_dir),
            **sensor_figures(result, "accel", out_dir),
            **_together(result, out_dir),
        }
    fork = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(1, mp_context=fork) as child:
        accel = child.submit(sensor_figures, result, "accel", Path(out_dir))
        gyro = sensor_figures(result, "gyro", out_dir)
        together = _together(result, out_dir)  # while the child draws the accelerometers'
        return {**gyro, **accel.result(), **together}


def _together(result: AnalysisResult, out_dir: Path) -> dict[str, Path]:
    """{caption: path} of :func:`common_mode_figure` when it is drawn (0.6–0.7 s on the real
    units' 15 pairs, session 53), else empty."""
    path = common_mode_figure(result, Path(out_dir) / "common_mode.png")
    return {} if path is None else {"Axes that move together": path}
