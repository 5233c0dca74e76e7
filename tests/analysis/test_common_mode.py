"""Axes that move together (:mod:`imupipe.analysis.common_mode`): the Fisher test of the event
detector's per-scale axis correlations, its Bonferroni family, and what the report says."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import special

from imupipe.analysis import common_mode as cm
from imupipe.analysis import events as ev
from imupipe.report import report
from imupipe.vocab import AXES

AXES3 = ("gyro_x", "accel_x", "accel_y")  # pairs in triu order: gx-ax, gx-ay, ax-ay
WINDOWS = 206  # dof 0.95 x 206 / 2 = 97.85


def detector(
    correlations: list[tuple[float, float, float]], windows: tuple[int, ...] | None = None
) -> ev.EventDetector:
    """A detector of three axes whose pair correlations at each scale are given."""
    k = len(correlations)
    scales = tuple(0.5 * 2**j for j in range(k))
    return ev.EventDetector(
        0.5, scales, windows or (WINDOWS,) * k, (6.0,) * k, (5.0,) * k, AXES3, tuple(correlations)
    )


def r_at(p: float, dof: float) -> float:
    """The correlation whose two-sided Fisher p-value is ``p`` at ``dof``."""
    return float(np.tanh(-special.ndtri(p / 2) / np.sqrt(dof - 3)))


def test_fisher_p_is_the_two_sided_normal_tail_of_atanh_r_times_sqrt_dof_minus_3() -> None:
    z = np.arctanh(0.5) * np.sqrt(100.0)
    assert cm.fisher_p(np.array([0.5, -0.5]), np.array([103.0, 103.0])) == pytest.approx(
        [special.erfc(z / np.sqrt(2))] * 2, rel=1e-12
    )
    assert cm.fisher_p(np.array([0.9]), np.array([3.0]))[0] == 1.0  # no dof left: no evidence
    with warnings.catch_warnings():  # a perfect correlation: p 0, no division by zero
        warnings.simplefilter("error")
        assert cm.fisher_p(np.array([1.0, -1.0]), np.array([50.0, 3.0])).tolist() == [0.0, 1.0]


@pytest.mark.parametrize("factor, named", [(0.9, True), (1.1, False)])
def test_a_pair_is_named_when_its_p_times_the_tests_is_at_most_alpha(factor, named) -> None:
    """Two scales x three pairs = 6 tests: a correlation whose own p is 0.9 alpha / 6 is named,
    one at 1.1 alpha / 6 is not (Bonferroni over scales and pairs, not per scale)."""
    dof = ev.scale_dof(WINDOWS)
    r = r_at(factor * cm.ALPHA / 6, dof)
    found = cm.common_mode(detector([(0.0, 0.0, 0.0), (0.0, -r, 0.0)]))
    assert found.tests == 6
    if named:
        (pair,) = found.pairs
        assert pair.axes == ("gyro_x", "accel_y")  # the second pair: negative counts too
        assert pair.p_value == pytest.approx(0.9 * cm.ALPHA, rel=1e-6)
        assert pair.significant_s == (1.0,) and pair.strongest == (1.0, pytest.approx(-r))
    else:
        assert found.pairs == ()
        assert found.warning() is None


def test_pairs_are_ordered_by_their_strongest_significant_correlation() -> None:
    """Each pair's strongest correlation is read among its significant scales only, and the
    pairs come strongest first; every scale's correlation is kept for the report."""
    found = cm.common_mode(
        detector([(0.1, 0.0, 0.62), (0.55, 0.0, 0.5), (0.9, 0.0, 0.3)], (WINDOWS, WINDOWS, 8))
    )  # 8 windows: dof 3.8, where even r = 0.9 is no evidence
    assert [p.axes for p in found.pairs] == [("accel_x", "accel_y"), ("gyro_x", "accel_x")]
    top, second = found.pairs
    assert top.significant_s == (0.5, 1.0) and top.strongest == (0.5, 0.62)
    assert second.significant_s == (1.0,) and second.strongest == (1.0, 0.55)
    assert second.correlation == (0.1, 0.55, 0.9)
    assert found.as_dict()["pairs"][1]["correlation"][1] == {"window_s": 1.0, "value": 0.55}
    assert found.as_dict()["pairs"][1]["strongest"] == {"window_s": 1.0, "value": 0.55}


def test_the_warning_names_the_three_strongest_pairs_and_counts_the_rest() -> None:
    found = cm.common_mode(detector([(0.4, 0.5, 0.85), (0.3, 0.2, 0.1)]))
    assert len(found.pairs) == 3
    assert (
        found.strongest(2)
        == "accel_x–accel_y r 0.85 at 0.5 s, gyro_x–accel_y r 0.50 at 0.5 s and 1 more pair"
    )
    assert found.strongest(1) == "accel_x–accel_y r 0.85 at 0.5 s and 2 more pairs"
    (alone,) = cm.common_mode(detector([(0.0, 0.0, 0.85), (0.0, 0.0, 0.1)])).pairs
    one = cm.CommonMode((alone,), 6).warning()  # fewer pairs than named: no "and ... more"
    assert one.startswith("axes that move together: accel_x–accel_y r 0.85 at 0.5 s (correlation")
    assert found.warning().startswith(
        "axes that move together: accel_x–accel_y r 0.85 at 0.5 s, gyro_x–accel_y r 0.50 at "
        "0.5 s, gyro_x–accel_x r 0.40 at 0.5 s (correlation of their level fluctuations, "
        "family-wise p ≤ 0.001)"
    )


def test_one_axis_has_no_pairs() -> None:
    det = ev.EventDetector(0.5, (0.5,), (100,), (6.0,), (np.inf,), ("gyro_x",), ((),))
    assert cm.common_mode(det) == cm.CommonMode((), 0)
    assert det.correlation == (0.0,)


def unit_means(seed: int, shared: float) -> dict[str, np.ndarray]:
    """4 h of unit white fine means; the three accelerometers share a common part whose
    pair correlation is ``shared``."""
    rng = np.random.default_rng(seed)
    common = rng.standard_normal(28_800)
    out = {a: rng.standard_normal(28_800) for a in AXES}
    for a in AXES[3:]:
        out[a] = np.sqrt(shared) * common + np.sqrt(1 - shared) * out[a]
    return out


def test_the_detector_names_the_accelerometers_sharing_noise_and_no_other_pair() -> None:
    """Accelerometers sharing a common part (pair correlation 0.15): their three pairs are
    named at the short windows, where the windows are many, and no gyro pair is; independent
    axes: none."""
    shared = ev.find_events(unit_means(1, 0.15), 0.5, 50, 28_800 * 50)[1]
    found = cm.common_mode(shared)
    assert {p.axes for p in found.pairs} == {
        ("accel_x", "accel_y"), ("accel_x", "accel_z"), ("accel_y", "accel_z")
    }  # fmt: skip
    for p in found.pairs:
        assert p.correlation[0] == pytest.approx(0.15, abs=0.03)
        assert p.significant_s[0] == 0.5
    assert found.tests == 15 * len(shared.scales_s)
    alone = ev.find_events(unit_means(1, 0.0), 0.5, 50, 28_800 * 50)[1]
    assert cm.common_mode(alone).pairs == ()


def test_the_report_tabulates_each_pair_with_its_strongest_window_and_span() -> None:
    """One row a pair: its strongest significant correlation and window, the span of its
    significant windows (0.3 at 2 s is not: p 0.0027 x 9 tests), its family-wise p."""
    pairs = [(0.1, 0.0, 0.95), (0.55, 0.0, 0.5), (0.0, 0.0, 0.3)]
    doc = cm.common_mode(detector(pairs)).as_dict()
    lines = report._common_mode_lines(doc)
    assert lines[0] == "### Axes that move together"
    assert "family-wise α = 0.001 over 9 correlations" in lines[2]
    table = lines[4].splitlines()
    assert table[2] == "| accel_x–accel_y | 0.95 (0.5 s) | 0.5–1 s | < 1e-16 |"
    p = doc["pairs"][1]["p_value"]
    assert p == pytest.approx(9 * cm.fisher_p(0.55, ev.scale_dof(WINDOWS)), rel=1e-9)
    assert table[3] == f"| gyro_x–accel_x | 0.55 (1 s) | 1 s | {p:.2g} |"
    assert report._common_mode_lines({**doc, "pairs": []}) == []


def test_the_critical_correlation_is_where_the_family_wise_p_reaches_alpha() -> None:
    dof = np.array([2.0, 97.85, 400.0])
    with warnings.catch_warnings():  # fewer than 3 dof: 1 without a numpy warning
        warnings.simplefilter("error")
        r = cm.critical_correlation(dof, 6)
    assert r[0] == 1.0  # no dof left: nothing passes
    assert r[1] == pytest.approx(np.tanh(-special.ndtri(1e-3 / 12) / np.sqrt(94.85)), rel=1e-12)
    assert 6 * cm.fisher_p(r[1:], dof[1:]) == pytest.approx([cm.ALPHA] * 2, rel=1e-9)


def test_the_figure_is_drawn_only_when_some_pair_moves_together(tmp_path) -> None:
    """common_mode.png: one line a named pair (and the not-significant band); no file when no
    pair moves together."""
    from types import SimpleNamespace

    from imupipe.report import figures

    def result(pairs: list[tuple[float, float, float]]) -> SimpleNamespace:
        return SimpleNamespace(events=ev.EventsFound(detector(pairs), (), 0.01, 0.0))

    path = tmp_path / "common_mode.png"
    assert figures.common_mode_figure(result([(0.0, 0.1, 0.0), (0.0, 0.0, 0.2)]), path) is None
    assert not path.exists()
    drawn = figures.common_mode_figure(result([(0.9, 0.1, 0.6), (0.8, 0.0, 0.2)]), path)
    assert drawn == path and path.stat().st_size > 10_000
    assert figures.common_mode_figure(SimpleNamespace(events=None), path) is None


def no_axes(sensor: str) -> list:
    """A result's ``by_sensor`` with no axis (module level: the forked child gets it pickled)."""
    return []


@pytest.mark.parametrize("processes", [1, 2])
def test_write_figures_lists_the_figure_under_its_caption(tmp_path, processes) -> None:
    """Serial or with the accelerometers' figures in a forked child, the figures report.md
    embeds include common_mode.png, captioned, when some pair moves together."""
    from types import SimpleNamespace

    from imupipe.report import figures

    found = ev.EventsFound(detector([(0.9, 0.1, 0.6)]), (), 0.01, 0.0)
    result = SimpleNamespace(events=found, by_sensor=no_axes)
    written = figures.write_figures(result, tmp_path, processes)
    assert written == {"Axes that move together": tmp_path / "common_mode.png"}
    assert (tmp_path / "common_mode.png").exists()


def test_a_pair_whose_family_wise_p_equals_alpha_is_named() -> None:
    """At most alpha: a pair whose p times the tests is alpha exactly is named (here the alpha
    given is the family-wise p of 0.6 at one scale of 6 tests)."""
    det = detector([(0.6, 0.0, 0.0), (0.0, 0.0, 0.0)])
    at = float(6 * cm.fisher_p(0.6, ev.scale_dof(WINDOWS)))
    (pair,) = cm.common_mode(det, alpha=at).pairs
    assert pair.axes == ("gyro_x", "accel_x") and pair.p_value == at
    assert cm.common_mode(det, alpha=at * (1 - 1e-9)).pairs == ()


def test_a_detector_without_scales_has_no_pairs() -> None:
    """A record too short for any window: six axes but no scale, no test, no pair."""
    det = ev.EventDetector(0.5, (), (), (), (), AXES, ())
    assert cm.common_mode(det) == cm.CommonMode((), 0)


def test_between_3_and_4_degrees_of_freedom_the_test_uses_what_is_left_above_3() -> None:
    """ν = 3.5: z = atanh r · √0.5 (not the √1 of a floor at 1), and the critical |r| of one
    test, tanh(Φ̄⁻¹(α / 2) / √0.5) = 0.99982."""
    p = cm.fisher_p(np.array([0.9]), np.array([3.5]))[0]
    assert p == pytest.approx(special.erfc(np.arctanh(0.9) * np.sqrt(0.5) / np.sqrt(2)), rel=1e-12)
    assert p == pytest.approx(0.2979, abs=1e-4)  # 0.1410 with a floor at 1
    r = cm.critical_correlation(np.array([3.5]), 1)[0]
    assert r == pytest.approx(np.tanh(-special.ndtri(cm.ALPHA / 2) / np.sqrt(0.5)), rel=1e-12)
    assert r == pytest.approx(0.99982, abs=1e-5)
    assert cm.fisher_p(np.array([r]), np.array([3.5]))[0] == pytest.approx(cm.ALPHA, rel=1e-6)


def test_the_figure_draws_each_named_pair_its_significant_windows_and_the_band(
    tmp_path, monkeypatch
) -> None:
    """Read back from common_mode.png's figure: one line a named pair, strongest first, in the
    colour of its rank and the style of its accelerometers (two: solid, one: dashed, none:
    dotted), dots at its significant windows only, the band ±critical |r| of the 12 tests, the
    zero line, a log window axis 0.12 up, r from -1 when some pair falls below -0.2 (else from
    -0.3), 880 × 495 px."""
    import struct
    from types import SimpleNamespace

    from imupipe.report import figures

    closed: list = []
    monkeypatch.setattr(figures.plt, "close", closed.append)
    axes = ("gyro_x", "gyro_y", "accel_x", "accel_y")  # pairs: gx-gy gx-ax gx-ay gy-ax gy-ay ax-ay

    def drawn(pairs: list[tuple[float, ...]]):
        det = ev.EventDetector(
            0.5, (0.5, 1.0), (WINDOWS,) * 2, (6.0,) * 2, (5.0,) * 2, axes, tuple(pairs)
        )
        path = tmp_path / f"common_mode_{len(closed)}.png"
        result = SimpleNamespace(events=ev.EventsFound(det, (), 0.01, 0.0))
        assert figures.common_mode_figure(result, path) == path
        return closed[-1].axes[0], path

    ax, path = drawn([(0.7, 0.0, 0.0, -0.6, 0.0, 0.9), (0.1, 0.0, 0.0, -0.1, 0.0, 0.8)])
    assert struct.unpack(">II", path.read_bytes()[16:24]) == (880, 495)
    colors = figures.plt.get_cmap("tab20").colors
    curves = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
    assert [(ln.get_label(), ln.get_linestyle(), ln.get_color()) for ln in curves] == [
        ("accel_x–accel_y", "-", colors[0]),
        ("gyro_x–gyro_y", ":", colors[1]),
        ("gyro_y–accel_x", "--", colors[2]),
    ]
    assert [ln.get_linewidth() for ln in curves] == [1.0] * 3  # drawn, not hidden
    assert [tuple(ln.get_ydata()) for ln in curves] == [(0.9, 0.8), (0.7, 0.1), (-0.6, -0.1)]
    dots = [ln for ln in ax.get_lines() if ln.get_marker() == "o"]
    assert [(tuple(d.get_xdata()), tuple(d.get_ydata()), d.get_color()) for d in dots] == [
        ((0.5, 1.0), (0.9, 0.8), colors[0]),
        ((0.5,), (0.7,), colors[1]),
        ((0.5,), (-0.6,), colors[2]),
    ]
    (band,) = ax.collections
    critical = cm.critical_correlation(np.array([ev.scale_dof(WINDOWS)]), 12)[0]
    assert critical == pytest.approx(0.384, abs=1e-3)
    y = band.get_paths()[0].vertices[:, 1]
    np.testing.assert_allclose([y.min(), y.max()], [-critical, critical], rtol=1e-12)
    assert band.get_label() == "not significant (family-wise α = 0.001)"
    assert any(tuple(ln.get_ydata()) == (0.0, 0.0) for ln in ax.get_lines())  # the zero line
    assert ax.get_xscale() == "log" and ax.get_ylim() == (-1.0, 1.0)
    assert ax.get_position().y0 == pytest.approx(0.12)  # room for the window axis' label
    ax, _ = drawn([(0.7, 0.0, 0.0, -0.2, 0.0, 0.9), (0.1, 0.0, 0.0, 0.5, 0.0, 0.8)])
    assert ax.get_ylim() == (-0.3, 1.0)  # lowest r -0.2: not below
    ax, _ = drawn([(0.7, 0.0, 0.0, 0.0, 0.0, 0.9), (0.1, 0.0, 0.0, 0.5, 0.0, 0.8)])
    assert ax.get_ylim() == (-0.3, 1.0)  # lowest r 0


def test_the_reports_span_runs_from_the_first_to_the_last_significant_window() -> None:
    """Significant at 0.5, 1 and 2 s: "0.5–2 s" (not the second window's 1 s); a p-value of
    1e-16 itself is printed, only smaller ones read "< 1e-16"."""
    doc = cm.common_mode(detector([(0.0, 0.0, 0.9), (0.0, 0.0, 0.6), (0.0, 0.0, 0.5)])).as_dict()
    doc["pairs"][0]["p_value"] = 1e-16
    (row,) = report._common_mode_lines(doc)[4].splitlines()[2:]
    assert row == "| accel_x–accel_y | 0.90 (0.5 s) | 0.5–2 s | 1e-16 |"
