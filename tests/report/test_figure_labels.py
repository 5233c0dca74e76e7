"""Log-axis tick labels in plain Unicode (``imupipe.report.figures.PowerOfTenLabels``): the
labels a reader sees, and no mathtext parsed while a report's figures are drawn (its first parse
in a process builds matplotlib's mathtext grammar, ~0.3 s of CPU per drawing process)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.mathtext
import pytest

from imupipe.report import figures


@pytest.mark.parametrize(
    ("value", "label"),
    [
        (1e-3, "10⁻³"),
        (2e-3, "2×10⁻³"),
        (5e-5, "5×10⁻⁵"),
        (1.0, "10⁰"),
        (10.0, "10¹"),
        (300.0, "3×10²"),
        (1e-10, "10⁻¹⁰"),
        (0.1, "10⁻¹"),
        (0.046, "4.6×10⁻²"),
        (5.25e-2, "5.25×10⁻²"),
        (9.9996e-4, "10⁻³"),
        (9.5e-3, "9.5×10⁻³"),  # below 10: its own decade
    ],
)
def test_power_of_ten_labels(value: float, label: str) -> None:
    assert figures.PowerOfTenLabels()._num_to_string(value, 0.0, 0.0) == label


def test_a_reports_figures_parse_no_mathtext(
    tmp_path: Path, synthetic_result, monkeypatch: pytest.MonkeyPatch
) -> None:
    parsed: list[str] = []
    parse = matplotlib.mathtext.MathTextParser.parse

    def counting(self, s, *args, **kwargs):
        parsed.append(s)
        return parse(self, s, *args, **kwargs)

    monkeypatch.setattr(matplotlib.mathtext.MathTextParser, "parse", counting)
    written = figures.write_figures(synthetic_result(), tmp_path, processes=1)
    assert len(written) == 3 and parsed == []


def _minor_labels(lo: float, hi: float) -> list[str]:
    """The minor tick labels of a log y axis viewing ``lo`` to ``hi``, as drawn."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    try:
        ax.plot([0, 1], [lo, hi])
        ax.set_yscale("log")
        figures.log_labels(ax.yaxis)
        fig.canvas.draw()
        return [t.get_text() for t in ax.yaxis.get_ticklabels(minor=True) if t.get_text()]
    finally:
        plt.close(fig)


def test_labels_of_a_narrow_log_view_name_its_minor_ticks() -> None:
    """A view under a decade wide labels its minor ticks (matplotlib's rule), as 2×10⁻⁴ …"""
    labels = _minor_labels(2e-4, 9e-4)
    assert "2×10⁻⁴" in labels and "4×10⁻⁴" in labels


def test_a_view_narrower_than_a_decade_has_distinct_labels() -> None:
    """A fleet's N within ±10 % of 5×10⁻²: matplotlib puts minor ticks at 4.4, 4.6, … ×10⁻²."""
    labels = _minor_labels(4.55e-2, 5.45e-2)
    assert len(labels) >= 3 and len(set(labels)) == len(labels)
    assert "4.6×10⁻²" in labels and "5×10⁻²" in labels
