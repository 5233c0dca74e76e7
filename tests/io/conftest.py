"""Shared checks of the io tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

import imupipe


@pytest.fixture
def analysed_with_two_gaps() -> Callable[[Path, Path, int], dict]:
    """``check(recording, out, n)``: report.json of the default analysis (no loop, figures or
    rrd) of a 100 Hz recording of ``n`` grid samples that lost one message and then a run of
    150, after checking what every such recording must show: both gaps named, the whole grid
    analysed with exactly the 151 lost places masked (no cut to the longest segment), and at
    m = 1 the r + 1 Allan terms touching each run of r left out, on every axis."""

    def check(recording: Path, out: Path, n: int) -> dict:
        result = imupipe.analyze(recording, out, rrd=False, figures=False, loop=False)
        report = result.to_dict()
        warnings = " ".join(report["input"]["warnings"])
        assert "2 gap(s) in time or frame counter (151 frames missing)" in warnings
        assert f"uniform grid of {n} samples with 151 masked" in warnings
        assert "longest clean segment" not in warnings
        assert report["input"]["frames"] == n - 151
        for axis in report["axes"].values():
            assert axis["allan"]["tau_s"][0] == pytest.approx(0.01, rel=1e-4)  # jittered stamps
            assert axis["allan"]["n_terms"][0] == (n - 1) - 2 - 151
        return report

    return check
