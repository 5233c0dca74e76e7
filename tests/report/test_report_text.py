"""report.md and the terminal table: every number a user reads, converted from the SI result
into the paper's units with factors written out here (1° = π/180 rad, 1 mg = 9.80665e-3 m/s²,
1 h = 3600 s), not with imupipe's unit table; unresolved terms as their bound in the same unit;
the loop's before/after in the right order; input strings escaped.

The result is built by hand (SI values chosen here), like tests/test_report.py's
``synthetic_result`` but smaller and without figures (a small builder copied, not imported)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from imupipe.analysis.results import AnalysisResult, AxisResult, InputSummary
from imupipe.device.frame_schema import SCHEMA_NAME
from imupipe.model import ieee952
from imupipe.model.loop import AcceptedEffect, Goodness, LoopResult, RejectedCandidate
from imupipe.report import report
from imupipe.report.report import format_table, report_markdown
from imupipe.stats.allan import AllanCurve

DEG = 180 / math.pi  # ° per rad
MG = 1 / 9.80665e-3  # mg per m/s²
TAU = np.array([0.01, 0.1, 1.0, 10.0, 100.0])

# SI values of the final model (value, lo, hi); None value: unresolved, hi its 95 % bound
GYRO_N = (2.0e-3, 1.9e-3, 2.1e-3)  # rad/s/√Hz
GYRO_B = (5.0e-5, 4.0e-5, 6.0e-5)  # rad/s
GYRO_K_BOUND = 3.0e-6  # rad/s²/√Hz, unresolved on every gyro
ACCEL_N = (2.0e-3, 1.9e-3, 2.2e-3)  # m/s²/√Hz
ACCEL_B = (1.2e-3, 1.0e-3, 1.5e-3)  # m/s²
ACCEL_K_BOUND = 4.0e-5  # m/s³/√Hz
RAMP_BOUND = 7.0e-8  # rad/s², gyro_x only; the other axes have no bound at all


def fmt(x: float) -> str:
    """The reports' number format: 4 significant digits."""
    return f"{x:.4g}"


def _term(v: tuple[float, float, float] | None, unit: str, bound: float | None = None):
    if v is None:
        return ieee952.NoiseTerm(None, None, bound, unit, "recording too short")
    return ieee952.NoiseTerm(*v, unit, None)


def _terms(sensor: str, axis: str, n_scale: float = 1.0) -> ieee952.NoiseTerms:
    gyro = sensor == "gyro"
    u = "rad/s" if gyro else "m/s^2"
    n, b = (GYRO_N, GYRO_B) if gyro else (ACCEL_N, ACCEL_B)
    k = GYRO_K_BOUND if gyro else ACCEL_K_BOUND
    return ieee952.NoiseTerms(
        quantization=_term(None, "rad" if gyro else "m/s"),
        random_walk=_term(tuple(x * n_scale for x in n), f"{u}/sqrt(Hz)"),
        bias_instability=_term(b, u),
        rate_random_walk=_term(None, f"{u}/s/sqrt(Hz)", k),
        rate_ramp=_term(None, f"{u}/s", RAMP_BOUND if axis == "gyro_x" else None),
        fit_tau_min_s=0.01,
        fit_tau_max_s=100.0,
        deviance_per_dof=1.0234,
        fit_note="white noise dominates" if axis == "gyro_x" else "",
    )


def _curve() -> AllanCurve:
    adev = 1e-3 / np.sqrt(TAU)
    return AllanCurve(
        TAU, adev, adev * 0.9, adev * 1.1, TAU * 0 + 50.0, TAU * 0 + 99, TAU * 0, 0.95
    )


def _loop(terms_after: ieee952.NoiseTerms) -> LoopResult:
    z = np.zeros_like(TAU)
    before = Goodness(4.23456, 40.0, 40, 1 / 2001, z, 5.98765, 100.0, 3.14159, 4, (0.01, 200.0))
    after = Goodness(1.034567, 30.0, 38, 0.41234, z, 2.21212, 0.1, 0.912345, 0, (0.001, 200.0))
    effect = AcceptedEffect(
        kind="temperature",
        params={"coefficient": 1.23456e-4, "lag_s": 12},
        intervals={"coefficient": [1.11111e-4, 1.33333e-4]},
        evidence={"level": "moving average"},
        error_before=4.23456,
        error_after=1.034567,
    )
    rejected = RejectedCandidate("sinusoid", {}, {}, {}, "ΔBIC 2.1 < 10")
    return LoopResult(
        name="accel_x",
        tau_s=TAU,
        adev_before=_curve().adev,
        adev_after=_curve().adev,
        terms_before=_terms("accel", "accel_x", n_scale=1.5),
        terms_after=terms_after,
        model_adev_before=_curve().adev,
        model_adev_after=_curve().adev,
        before=before,
        after=after,
        accepted=[effect],
        rejected=[rejected],
    )


def result(
    path: str = "run.mcap", topic: str = "/imu", warnings: tuple[str, ...] = ()
) -> AnalysisResult:
    axes = {}
    for name in ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"):
        sensor = name.split("_")[0]
        gyro = sensor == "gyro"
        terms = _terms(sensor, name)
        axes[name] = AxisResult(
            name=name,
            sensor=sensor,
            unit="rad/s" if gyro else "m/s^2",
            mean=1.0e-3 if gyro else (-9.80665 if name == "accel_z" else 0.05),
            rms=9.0e-3 if gyro else 0.03,
            curve=_curve(),
            terms=terms,
            loop=_loop(terms) if name == "accel_x" else None,
        )
    inp = InputSummary(
        path=path,
        topic=topic,
        frames=360_000,
        rate_hz=100.0,
        duration_s=3600.0,
        warnings=list(warnings),
        source=SCHEMA_NAME,
    )
    return AnalysisResult(input=inp, axes=axes, device={"serial_number": "42"})


@pytest.fixture(scope="module")
def md() -> str:
    return report_markdown(result(), {})


def _row(md: str, quantity: str, axis: str, unit: str) -> list[str]:
    for line in md.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[:2] == [quantity, axis] and cells[-1] == unit:
            return cells
    raise AssertionError(f"no row {quantity} {axis} [{unit}] in\n{md}")


def _interval(v: tuple[float, float, float], factor: float) -> str:
    return f"{fmt(v[0] * factor)} [{fmt(v[1] * factor)}, {fmt(v[2] * factor)}]"


def test_terms_in_the_papers_units_with_paper_and_datasheet(md: str) -> None:
    # N gyro: rad/s/√Hz -> °/√s (1/√Hz = √s); paper 0.05; datasheet 2 °/√h = 2/60 °/√s
    assert _row(md, "Random walk N", "gyro_y", "°/√s")[2:] == [
        _interval(GYRO_N, DEG),
        "0.05",
        fmt(2 / 60),
        "°/√s",
    ]
    # ... and again in the datasheet's own unit, °/√h = °/√s × 60
    assert _row(md, "Random walk N", "gyro_y", "°/√h")[2:] == [
        _interval(GYRO_N, DEG * 60),
        "3",  # the paper's 0.05 °/√s
        "2",
        "°/√h",
    ]
    # N accel: m/s²/√Hz -> mg/√s; paper 0.28 (accel_z); datasheet 0.12 m/s/√h
    assert _row(md, "Random walk N", "accel_z", "mg/√s")[2:] == [
        _interval(ACCEL_N, MG),
        "0.28",
        fmt(0.12 / 60 * MG),
        "mg/√s",
    ]
    assert _row(md, "Random walk N", "accel_x", "m/s/√h")[2:] == [
        _interval(ACCEL_N, 60),
        fmt(0.29 / MG * 60),  # the paper's 0.29 mg/√s
        "0.12",
        "m/s/√h",
    ]
    assert _row(md, "Bias instability B", "accel_y", "mg")[2:] == [
        _interval(ACCEL_B, MG),
        "0.161",
        "0.1",
        "mg",
    ]
    assert _row(md, "Bias instability B", "gyro_x", "°/s")[2:4] == [_interval(GYRO_B, DEG), "0.008"]
    # mean and rms: no interval; the paper's accel bias is in g (0.0273 g = 27.3 mg)
    assert _row(md, "Bias (mean)", "accel_z", "mg")[2:4] == ["-1000", "-998.6"]
    assert _row(md, "Bias (mean)", "accel_x", "mg")[2:4] == [fmt(0.05 * MG), "27.3"]
    assert _row(md, "Bias (mean)", "gyro_x", "°/s")[2:4] == [fmt(1e-3 * DEG), "0.331"]
    assert _row(md, "Output noise (rms)", "gyro_z", "°/s")[2:] == [
        fmt(9e-3 * DEG),
        "0.52",
        "0.8",
        "°/s",
    ]
    assert _row(md, "Output noise (rms)", "accel_x", "mg")[2:4] == [fmt(0.03 * MG), "3"]


def test_unresolved_terms_show_their_bound_in_the_displayed_unit(md: str) -> None:
    # K unresolved: its 95 % upper bound, converted like a value (not printed in SI)
    assert _row(md, "Rate random walk K", "gyro_y", "°/s/√s")[2] == f"≤ {fmt(GYRO_K_BOUND * DEG)}"
    assert _row(md, "Rate random walk K", "accel_x", "mg/s/√s")[2] == (
        f"≤ {fmt(ACCEL_K_BOUND * MG)}"
    )
    assert _row(md, "Rate ramp R", "gyro_x", "°/s²")[2] == f"≤ {fmt(RAMP_BOUND * DEG)}"
    # neither value nor bound: a dash; no paper value for the terms the paper does not list
    assert _row(md, "Rate ramp R", "gyro_y", "°/s²")[2:4] == ["—", "—"]
    assert _row(md, "Quantization Q", "accel_y", "mg·s")[2:] == ["—", "—", "—", "mg·s"]
    # each unresolved term is listed with its reason; resolved ones are not
    assert "- gyro_z rate_random_walk: recording too short" in md
    assert "- accel_y quantization: recording too short" in md
    assert "- gyro_x random_walk:" not in md and "- accel_z bias_instability:" not in md


def test_fit_summary_input_and_device(md: str) -> None:
    assert "- gyro_x: τ 0.01–100 s, D/dof 1.023; white noise dominates" in md
    assert "- accel_y: τ 0.01–100 s, D/dof 1.023\n" in md
    assert "| run.mcap | /imu | imupipe_msgs/msg/Adis16364Frame | 360000 | 100 Hz |" in md
    assert "| 3600.0 s (1 h) |" in md
    assert "Device: serial\\_number = 42" in md
    assert "### Warnings\n\n- none\n" in md
    assert md.startswith("# imupipe report: run.mcap\n")


def test_loop_before_after_rounded_in_order(md: str) -> None:
    row = next(ln for ln in md.splitlines() if ln.startswith("| accel_x | "))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells == [
        "accel_x",
        "4.235 → 1.035",  # error
        "≤ 0.0004998 → 0.4123",  # p-value: no bootstrap replicate reached the deviance before
        "3.142 → 0.9123",  # rms z
        "5.988 → 2.212 (τ 100 → 0.1 s)",  # max |z| at tau
        "0.01–200 → 0.001–200",  # the fitted tau, before → after
        "38",  # dof after
        "temperature",
    ]
    assert sum(ln.startswith("| gyro_") for ln in md.split("## Closed loop")[1].splitlines()) == 0
    assert (
        "p-value: the share of parametric-bootstrap replicates of the model whose deviance "
        "reaches the fit's, drawn 200 at a time until 10 reach it or 2000 are drawn (Besag & "
        "Clifford 1991; ≤ 0.0004998: none did, and the true p-value is at most that). "
        "Besides its own test, an effect is accepted only where the model's deviance falls by "
        "at least χ²₁(0.95) = 3.84 in Allan space or in the time domain"
    ) in md
    assert (
        "- accepted **temperature** (coefficient = 0.0001235 [0.0001111, 0.0001333], "
        "lag_s = 12; level: moving average): error 4.235 → 1.035"
    ) in md
    assert "- rejected candidate sinusoid: ΔBIC 2.1 < 10" in md
    # the per-term table: before (N × 1.5) then after, in the paper's unit
    n_before = tuple(1.5 * x for x in ACCEL_N)
    details = md.split("### accel_x")[1]
    assert (
        f"| random_walk | {_interval(n_before, MG)} | {_interval(ACCEL_N, MG)} | mg/√s |"
    ) in details
    assert f"| rate_random_walk | ≤ {fmt(ACCEL_K_BOUND * MG)} |" in details


def test_a_widened_range_gives_the_error_before_on_both_ranges(md: str) -> None:
    """Where a short-τ line widened the fitted range, the error cell also gives the baseline's
    error refitted on the final range (the one comparable with the error after), and a sentence
    says so; without it, neither."""
    assert "on the final τ" not in md and "widened the fitted τ range" not in md
    r = result()
    loop = replace(r.axes["accel_x"].loop, error_before_final_range=52.3456)
    r = replace(r, axes={**r.axes, "accel_x": replace(r.axes["accel_x"], loop=loop)})
    wide = report_markdown(r, {})
    row = next(ln for ln in wide.splitlines() if ln.startswith("| accel_x | "))
    assert row.split("|")[2].strip() == "4.235 (52.35 on the final τ) → 1.035"
    assert "a modelled short-τ line widened the fitted τ range, the error before" in wide
    line = next(ln for ln in format_table(r).splitlines() if ln.startswith("accel_x "))
    assert "4.235 (52.35 on the final τ) → 1.035" in line


def test_terminal_table_matches_the_report() -> None:
    table = format_table(result())
    head = table.splitlines()[0]
    assert head == (
        "run.mcap [/imu]: 360000 frames, 100 Hz, 1 h analysed; final model (after the closed loop)"
    )
    line = next(ln for ln in table.splitlines() if ln.startswith("Rate random walk K  gyro_z"))
    assert line.split()[5:7] == ["≤", fmt(GYRO_K_BOUND * DEG)]
    loop = next(ln for ln in table.splitlines() if ln.startswith("accel_x "))
    assert loop.split()[1:4] == ["4.235", "→", "1.035"]
    assert "closed loop (error = gamma deviance per degree of freedom" in table


def test_input_strings_cannot_format_the_report() -> None:
    md = report_markdown(
        result(path="/d/*run*|x.mcap", topic="/imu`a", warnings=("gap at <b>1</b>\nnext",)), {}
    )
    assert md.startswith("# imupipe report: \\*run\\*|x.mcap\n")
    assert "| /d/\\*run\\*\\|x.mcap | /imu\\`a |" in md
    # the line break is written as the two characters \n, and that backslash escaped
    assert "- gap at \\<b\\>1\\</b\\>\\\\nnext\n" in md
    table = format_table(result(topic="/imu\x1b[2J"))
    assert "\x1b" not in table and "[/imu\\x1b[2J]" in table


def test_kalibr_block_fence_is_longer_than_any_backtick_run() -> None:
    md = report_markdown(result(topic="/imu````x"), {})
    block = md.split("## Kalibr `imu.yaml`\n\n")[1]
    assert block.startswith("`````yaml\n")
    assert block.rstrip().endswith("\n`````")
    plain = report_markdown(result(), {}).split("## Kalibr `imu.yaml`\n\n")[1]
    assert plain.startswith("```yaml\n")
    # the yaml holds the worst axis' N in SI (no unit conversion in Kalibr files)
    assert f"gyroscope_noise_density: {GYRO_N[0]}" in plain


def test_other_sources_and_a_users_datasheet() -> None:
    from dataclasses import replace

    from imupipe.report.datasheet import parse_datasheet

    other = result()
    other = replace(other, input=replace(other.input, source="sensor_msgs/msg/Imu"))
    md = report_markdown(other, {})
    # not the paper's part: no paper column, no default datasheet
    assert "| quantity | axis | measured [95 % interval] | unit |" in md
    assert _row(md, "Random walk N", "accel_x", "mg/√s")[2:] == [_interval(ACCEL_N, MG), "mg/√s"]
    assert "Paper:" not in md and "Datasheet" not in md
    sheet = parse_datasheet(
        'part = "X1"\nsource = "x.pdf"\n[accel]\nN = { value = 30, unit = "mg/√Hz" }\n'
        'B = { value = 0.2, unit = "mg" }\n',
        "x.toml",
    )
    md = report_markdown(other, {}, sheet)
    assert 'Datasheet "X1": "x.pdf".' in md
    # a unit other than the paper's: a second row in the datasheet's unit (mg/√Hz = mg/√s)
    assert _row(md, "Random walk N", "accel_y", "mg/√s")[2:] == [
        _interval(ACCEL_N, MG),
        "30",
        "mg/√s",
    ]
    assert _row(md, "Random walk N", "accel_y", "mg/√Hz")[3] == "30"
    # the same unit as the paper's: one row only; gyros: no datasheet value
    assert sum(ln.startswith("| Bias instability B | accel_z |") for ln in md.splitlines()) == 1
    assert _row(md, "Random walk N", "gyro_x", "°/√s")[3] == "—"
    table = format_table(other, sheet)
    assert table.splitlines()[1].split() == [
        "quantity", "axis", "measured", "[95", "%", "interval]", "datasheet", "unit"
    ]  # fmt: skip


def test_duration_in_hours_and_one_sided_intervals() -> None:
    from dataclasses import replace

    r = result()
    for seconds, text in ((4409.64, "4409.6 s (1.22 h)"), (4410.36, "4410.4 s (1.23 h)")):
        r = replace(r, input=replace(r.input, duration_s=seconds))  # 1.2249 h, 1.2251 h
        assert f"| {text} |" in report_markdown(r, {})
        assert f", {text.split('(')[1][:-1]} analysed;" in format_table(r).splitlines()[0]
    # a value whose interval has no lower end is shown without an interval
    n = ieee952.NoiseTerm(2.0e-3, None, 2.1e-3, "m/s^2/sqrt(Hz)", None)
    axis = r.axes["accel_y"]
    r.axes["accel_y"] = replace(axis, terms=replace(axis.terms, random_walk=n))
    assert _row(report_markdown(r, {}), "Random walk N", "accel_y", "mg/√s")[2] == fmt(2e-3 * MG)


def test_a_harmonic_line_names_its_fundamental() -> None:
    harmonic = {"kind": "narrowband", "evidence": {"harmonic": 3, "harmonic_of_hz": 0.5652609}}
    assert report._kind_text(harmonic) == "narrowband (harmonic 3 of 0.5653 Hz)"
    assert report._kind_text({"kind": "narrowband", "evidence": {}}) == "narrowband"
    # a fundamental found after its stronger harmonic (a sinusoid at 3 f1) names it
    fundamental = {
        "kind": "narrowband",
        "evidence": {"its_harmonic": 3, "fundamental_of_hz": 0.0235},
    }
    assert report._kind_text(fundamental) == "narrowband (fundamental of 0.0235 Hz, its harmonic 3)"


def test_segments_are_a_table_with_their_frames_and_times() -> None:
    from imupipe.analysis.condition import Segment

    segments = [Segment(0, 120_000, 0.0, 1199.99), Segment(120_001, 360_000, 1200.01, 3599.99)]
    r = result()
    r = replace(r, input=replace(r.input, segments=[s.as_dict() for s in segments]))
    lines = report_markdown(r, {}).splitlines()
    at = lines.index("Segments: 2")
    assert lines[at + 2 : at + 6] == [
        r"| first frame | end frame (exclusive) | frames | start \[s\] | stop \[s\] |",
        "| --- | --- | --- | --- | --- |",
        "| 0 | 120000 | 120000 | 0 | 1199.99 |",
        "| 120001 | 360000 | 239999 | 1200.01 | 3599.99 |",
    ]


@pytest.mark.parametrize(
    ("window", "text"),
    [
        ((0.0, None), None),
        ((10.0, None), "window from t = 10 s to the last frame (--start, --end)"),
        ((0.0, -60.0), "window from t = 0 s to 60 s before the last frame (--start, --end)"),
        ((0.0, -0.5), "window from t = 0 s to 0.5 s before the last frame (--start, --end)"),
        ((5.0, 100.0), "window from t = 5 s to t = 100 s (--start, --end)"),
    ],
)
def test_the_analysed_window_in_words(window, text) -> None:
    assert report.window_text(window) == text


def test_an_accepted_effect_shows_the_falls_its_acceptance_read() -> None:
    """A bias step of the real ADIS16405 unit 2 (accel_y, session 50): its Allan-space error
    rose (3.089 → 3.172) and it was accepted on the time-domain deviance's fall of 42; the
    report says so, not the rising error alone.  A fall the rule did not judge is not shown,
    and an effect without the errors' evidence (an AVAR term's line) gets nothing."""
    evidence = {
        "allan_error_fall_chi2": -0.26872,
        "time_domain_error_before": 1.05628,
        "time_domain_error_after": 1.09298,
        "time_domain_deviance_fall": 41.9785,
        "time_domain_error_judged": True,
    }
    assert report._falls_text(evidence) == (
        " (Allan deviance fall -0.3; time-domain 1.056 → 1.093, deviance fall 42.0)"
    )
    unjudged = evidence | {"time_domain_error_judged": False}
    assert report._falls_text(unjudged) == " (Allan deviance fall -0.3)"
    assert report._falls_text({"level": "moving average"}) == ""


def test_an_effects_interval_is_shown_only_when_it_has_both_ends() -> None:
    assert (
        report._params({"params": {"a": 1.0}, "intervals": {"a": [0.5, 2.0]}}) == "a = 1 [0.5, 2]"
    )
    assert report._params({"params": {"a": 1.0}, "intervals": {"a": [0.5]}}) == "a = 1"


def test_the_events_section_names_the_shortest_and_longest_window_tested() -> None:
    from types import SimpleNamespace

    scales = [{"window_s": w} for w in (0.5, 1.0, 2.0, 512.0)]
    doc = {
        "detector": {"tests": 1200, "scales": scales, "axes": ["gyro_x"], "false_alarm": 1e-3},
        "found": [],
        "common_mode": {"alpha": 1e-3, "tests": 0, "pairs": []},
    }
    events = SimpleNamespace(as_dict=lambda: doc)
    (_, _, tested, _, none, _) = report._events_section(SimpleNamespace(events=events))
    assert tested.startswith("1200 windows of 4 lengths (0.5–512 s) tested on gyro_x;")
    assert none == "None found."


def test_a_report_with_a_non_finite_number_is_refused_not_written(
    tmp_path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """report.json is strict JSON: a NaN that reached the document is an error, not `NaN`."""
    monkeypatch.setattr(report, "report_json", lambda result: {"n": math.nan})
    with pytest.raises(ValueError, match="Out of range float values"):
        report.write_report(None, tmp_path, figures=False)
    assert not (tmp_path / "report.json").exists()
