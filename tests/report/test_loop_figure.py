"""The closed-loop figure shows each model and its residual z only over the τ it was fitted
on (so does the viewer's residual view, through the same ``Goodness.fitted``), and keeps the
final model's residuals readable beside a rejected baseline's large ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imupipe.model.loop import Goodness
from imupipe.report import figures


def test_fitted_blanks_what_was_not_fitted() -> None:
    good = Goodness(1.0, 1.0, 1, 0.5, np.zeros(5), 0.0, 0.0, 0.0, 0, (0.02, 0.08))
    out = good.fitted(np.array([0.01, 0.02, 0.04, 0.08, 1.0]), np.arange(5.0))
    np.testing.assert_array_equal(out, [np.nan, 1.0, 2.0, 3.0, np.nan])


def test_residual_panel(tmp_path: Path, synthetic_result, monkeypatch: pytest.MonkeyPatch) -> None:
    drawn = []
    monkeypatch.setattr(figures.plt, "close", drawn.append)
    result = synthetic_result()
    figures.loop_figure(result, "accel", tmp_path / "loop.png")
    (fig,) = drawn
    _top, bottom = fig.axes
    (axis,) = [a for a in result.by_sensor("accel") if a.loop is not None][:1]
    loop, tau = axis.loop, np.asarray(axis.curve.tau_s)
    lo, hi = loop.after.tau_range
    z_after = next(ln for ln in bottom.get_lines() if ln.get_label() == axis.name).get_ydata()
    outside = (tau < lo * (1 - 1e-9)) | (tau > hi * (1 + 1e-9))
    assert outside.any() and np.isnan(z_after[outside]).all()
    np.testing.assert_array_equal(z_after[~outside], np.asarray(loop.z_after)[~outside])
    # a baseline's |z| beyond 5 within its fit: logarithmic beyond |z| = 5, plain-number ticks
    z_before = loop.before.fitted(tau, loop.z_before)
    assert np.nanmax(np.abs(z_before)) > figures.Z_LINEAR
    assert bottom.get_yscale() == "symlog"
    assert list(bottom.get_yticks()) == [-3, 0, 3]  # |z| ≤ 5.9: no tick at 10
