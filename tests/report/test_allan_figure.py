"""What the report's Allan figure draws, read back from the figure: each axis' points and their
intervals, each fitted term's asymptote in its own line style, the final model, the legend, the
view, and the loop figure's ±3 guides (the figures are checked by eye as well; these pin the
numbers behind them)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from imupipe.report import figures


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> list:
    """The figures the module closes (kept open for the test)."""
    closed: list = []
    monkeypatch.setattr(figures.plt, "close", closed.append)
    return closed


def test_points_intervals_asymptotes_and_model_of_each_axis(
    tmp_path: Path, synthetic_result, drawn
) -> None:
    result = synthetic_result(with_loop=False)
    figures.allan_figure(result, "gyro", tmp_path / "allan.png")
    (fig,) = drawn
    (ax,) = fig.axes
    gyros = result.by_sensor("gyro")
    assert len(ax.containers) == 3
    colors = ("tab:blue", "tab:orange", "tab:green")  # x, y, z
    for axis, bars, color in zip(gyros, ax.containers, colors, strict=True):
        c = axis.curve
        points, _caps, (segments,) = bars.lines
        np.testing.assert_array_equal(points.get_ydata(), c.adev)
        assert points.get_color() == color
        ends = np.array([[seg[0, 1], seg[1, 1]] for seg in segments.get_segments()])
        lo = np.where(np.isnan(c.adev_lo), c.adev, c.adev_lo)  # no interval: a bar of 0
        hi = np.where(np.isnan(c.adev_hi), c.adev, c.adev_hi)
        np.testing.assert_allclose(ends, np.column_stack([lo, hi]), rtol=1e-12)
        lines = [
            ln for ln in ax.get_lines() if ln.get_color() == color and len(ln.get_xdata()) == 200
        ]
        tau = np.geomspace(c.tau_s[0], c.tau_s[-1], 200)
        n_value = axis.terms.random_walk.value
        (n_line,) = [ln for ln in lines if np.allclose(ln.get_ydata(), n_value / np.sqrt(tau))]
        np.testing.assert_allclose(n_line.get_xdata(), tau, rtol=1e-12)  # N/√τ, dashed
        assert tuple(n_line._unscaled_dash_pattern[1]) == (3.7, 1.6)  # matplotlib's "--"
        b_line = [ln for ln in lines if ln.get_linestyle() == "-."]
        assert len(b_line) == (axis.terms.bias_instability.value is not None)
        (model,) = [ln for ln in lines if ln.get_linestyle() == "-"]
        np.testing.assert_allclose(model.get_ydata(), axis.terms.adev(tau), rtol=1e-12)
    b_lines = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-." and len(ln.get_xdata())]
    assert len(b_lines) == 3  # the three gyros' B
    labels = ax.get_legend_handles_labels()[1]
    assert labels == ["final model (reported terms)", "fitted N asymptote",
                      "fitted B asymptote", "fitted K asymptote", "gyro_x (68.3% interval)",
                      "gyro_y (68.3% interval)", "gyro_z (68.3% interval)"]  # fmt: skip
    tau_all = np.concatenate([a.curve.tau_s for a in gyros])
    assert ax.get_xlim() == pytest.approx((tau_all.min() / 1.5, tau_all.max() * 1.5))


def test_the_k_asymptote_has_its_own_dash(tmp_path: Path, synthetic_result, drawn) -> None:
    result = synthetic_result(with_loop=False)
    figures.allan_figure(result, "gyro", tmp_path / "allan.png")
    (ax,) = drawn[0].axes
    gyro_x = result.axes["gyro_x"]
    tau = np.geomspace(gyro_x.curve.tau_s[0], gyro_x.curve.tau_s[-1], 200)
    k = gyro_x.terms.rate_random_walk.value
    (k_line,) = [
        ln for ln in ax.get_lines()
        if len(ln.get_ydata()) == 200 and np.allclose(ln.get_ydata(), k * np.sqrt(tau / 3))
    ]  # fmt: skip
    assert tuple(k_line._unscaled_dash_pattern[1]) == (5, 1, 1, 1, 1, 1)  # dash-dot-dot


def test_the_loop_figure_marks_three_sigma_and_shows_corrections(
    tmp_path: Path, synthetic_result, drawn
) -> None:
    result = synthetic_result()
    figures.loop_figure(result, "accel", tmp_path / "loop.png")
    top, bottom = drawn[0].axes
    guides = sorted(ln.get_ydata()[0] for ln in bottom.get_lines() if ln.get_linestyle() == ":")
    assert guides == [-3.0, 3.0]
    after = [ln for ln in top.get_lines() if ln.get_label() == "after corrections"]
    loop = result.axes["accel_x"].loop
    np.testing.assert_array_equal(after[0].get_ydata(), loop.adev_after)  # 0.97 × measured
    heights = [bottom.get_position().height, top.get_position().height]
    assert heights[1] / heights[0] == pytest.approx(2.0, rel=1e-6)
    assert math.isfinite(bottom.get_ylim()[0])


def test_large_residuals_get_symmetric_decade_ticks(
    tmp_path: Path, synthetic_result, drawn
) -> None:
    """A rejected baseline with |z| up to 250: the residual panel turns logarithmic beyond
    |z| = 5 with ticks at ±3, 10, 30, 100 and 300, mirrored about 0."""
    result = synthetic_result()
    axis = result.axes["accel_x"]
    z = np.linspace(-250.0, 250.0, axis.curve.tau_s.size)
    loop = dataclasses.replace(axis.loop, before=dataclasses.replace(axis.loop.before, z=z))
    axes = {**result.axes, "accel_x": dataclasses.replace(axis, loop=loop)}
    figures.loop_figure(dataclasses.replace(result, axes=axes), "accel", tmp_path / "loop.png")
    bottom = drawn[0].axes[1]
    assert bottom.get_yscale() == "symlog"
    assert list(bottom.get_yticks()) == [-300, -100, -30, -10, -3, 0, 3, 10, 30, 100, 300]
