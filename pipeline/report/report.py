"""Stage 5 of ``imupipe analyze``: write the result folder.

``report.json`` (SI, the issue 3 contract plus the issue 4 loop additions, schema in
``schemas/report.schema.json``), ``report.md`` (the paper's table side by side with ours, in the
paper's units, embedding the PNG figures of :mod:`imupipe.report.figures`), ``imu.yaml`` (Kalibr IMU
noise model) and ``allan.parquet`` (the Allan curves in long form).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from imupipe.analysis.results import (
    ERROR_MEASURE,
    AnalysisResult,
    AxisResult,
    allan_frame,
    jsonable,
    report_json,
)
from imupipe.escape import printable
from imupipe.report.paper import DATASHEET_RANDOM_WALK, DATASHEET_SOURCE, PAPER_SOURCE, PAPER_TABLE
from imupipe.units import PAPER_UNIT, from_si
from imupipe.vocab import TERM_NAMES

_PAPER_QUANTITIES: tuple[tuple[str, str], ...] = (
    ("random_walk", "Random walk N"),
    ("bias_instability", "Bias instability B"),
    ("mean", "Bias (mean)"),
    ("rms", "Output noise (rms)"),
)
_OTHER_TERMS: tuple[tuple[str, str], ...] = (
    ("quantization", "Quantization Q"),
    ("rate_random_walk", "Rate random walk K"),
    ("rate_ramp", "Rate ramp R"),
)


def _fmt(value: float | None) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.4g}"


def _term_text(term: object, unit: str, interval: bool = True) -> str:
    """A noise term in ``unit``: value [lo, hi], or ≤ its upper bound when unresolved."""
    if term.value is None:
        return "—" if term.hi is None else f"≤ {_fmt(from_si(term.hi, unit))}"
    text = _fmt(from_si(term.value, unit))
    if interval and term.lo is not None and term.hi is not None:
        text += f" [{_fmt(from_si(term.lo, unit))}, {_fmt(from_si(term.hi, unit))}]"
    return text


def _term_cell(axis: AxisResult, name: str) -> tuple[str, str]:
    """(measured value with interval, paper unit) of one IEEE 952 term or of mean/rms."""
    unit = PAPER_UNIT[axis.sensor][name]
    if name in ("mean", "rms"):
        return _fmt(from_si(getattr(axis, name), unit)), unit
    return _term_text(getattr(axis.terms, name), unit), unit


def paper_rows(result: AnalysisResult) -> list[tuple[str, str, str, str, str, str]]:
    """Rows (quantity, axis, measured [interval], paper measured, datasheet, unit) comparing our
    values with the paper's table, in the paper's units (see :mod:`imupipe.report.paper`)."""
    rows = []
    for name, label in _PAPER_QUANTITIES:
        for axis in result.axes.values():
            cell, unit = _term_cell(axis, name)
            ref = PAPER_TABLE[name].get(axis.name)
            paper, sheet = (ref.measured_si(), ref.datasheet_si()) if ref else (None, None)
            paper = "—" if paper is None else _fmt(from_si(paper, unit))
            sheet = "—" if sheet is None else _fmt(from_si(sheet, unit))
            rows.append((label, axis.name, cell, paper, sheet, unit))
    for axis in result.axes.values():  # N once more, in the datasheet's own units
        sheet = DATASHEET_RANDOM_WALK[axis.sensor]
        ref = PAPER_TABLE["random_walk"].get(axis.name)
        paper = "—" if ref is None else _fmt(from_si(ref.measured_si(), sheet.unit))
        cell = _term_text(axis.terms.random_walk, sheet.unit)
        rows.append(("Random walk N", axis.name, cell, paper, _fmt(sheet.datasheet), sheet.unit))
    for name, label in _OTHER_TERMS:
        for axis in result.axes.values():
            cell, unit = _term_cell(axis, name)
            rows.append((label, axis.name, cell, "—", "—", unit))
    return rows


_ROW_HEADER = ("quantity", "axis", "measured [95 % interval]", "paper", "datasheet", "unit")


def _before_after(model: dict, key: str) -> str:
    return f"{_fmt(model.get(key + '_before'))} → {_fmt(model.get(key + '_after'))}"


def _loop_rows(result: AnalysisResult) -> list[tuple[str, ...]]:
    """Per looped axis: error, p-value, rms z and max |z| (at which tau), before → after."""
    rows = []
    for axis in result.axes.values():
        if axis.loop is None:
            continue
        model = jsonable(axis.loop.as_model_dict())
        kinds = ", ".join(e["kind"] for e in axis.loop.as_effects()) or "none"
        tau_max = _before_after(model, "tau_max_abs_z")
        rows.append(
            (
                axis.name,
                _before_after(model, "error"),
                _before_after(model, "p_value"),
                _before_after(model, "rms_z"),
                f"{_before_after(model, 'max_abs_z')} (τ {tau_max} s)",
                str(model.get("dof", "—")),
                kinds,
            )
        )
    return rows


_LOOP_HEADER = ("axis", "error", "p-value", "rms z", "max |z|", "dof", "effects")


def _text_table(header: tuple[str, ...], rows: Iterable[tuple[str, ...]]) -> str:
    rows = [header, *rows]
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows
    )


_MD_SPECIAL = re.compile(r"([\\`*_\[\]<>#!~&])")
"""ASCII punctuation with a meaning inside a line in CommonMark/GFM (code, emphasis, links,
images, HTML, entities, strikethrough; ``#`` closes a heading).  Input strings never start a
line here, so list and heading markers need no escape, and ``|`` is escaped by
:func:`_md_table`, the only place a pipe means something."""


def _md(text: str) -> str:
    """A string from the input (path, topic, metadata, a warning naming them) as literal
    Markdown text: control characters escaped (:func:`imupipe.escape.printable`: one line, so it
    cannot start a heading or a table), Markdown punctuation backslash-escaped (CommonMark 2.4),
    so that no emphasis, link, image or HTML tag comes from the input."""
    return _MD_SPECIAL.sub(r"\\\1", printable(text))


def _fence(text: str, info: str) -> list[str]:
    """A fenced code block whose fence is longer than any backtick run in ``text``
    (CommonMark 4.5), so the text cannot close it."""
    longest = max((len(run) for run in re.findall("`+", text)), default=0)
    fence = "`" * max(3, longest + 1)
    return [fence + info, text, fence]


def _md_table(header: tuple[str, ...], rows: Iterable[tuple[str, ...]]) -> str:
    def line(cells: tuple[str, ...]) -> str:
        return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

    return "\n".join([line(header), "|" + "---|" * len(header), *map(line, rows)])


def format_table(result: AnalysisResult) -> str:
    """The paper-style terminal table printed by ``imupipe analyze``."""
    inp = result.input
    head = (
        f"{printable(inp.path)} [{printable(inp.topic)}]: {inp.frames} frames, "
        f"{inp.rate_hz:.4g} Hz, "
        f"{inp.duration_s / 3600:.3g} h analysed"
    )
    parts = [head, _text_table(_ROW_HEADER, paper_rows(result))]
    loop_rows = _loop_rows(result)
    if loop_rows:
        parts.append(f"closed loop (error = {ERROR_MEASURE}):")
        parts.append(_text_table(_LOOP_HEADER, loop_rows))
    parts += [f"warning: {printable(w)}" for w in inp.warnings]
    return "\n".join(parts)


def _kalibr_coefficient(axes: list[AxisResult], name: str, shape) -> tuple[float, str]:
    """Worst (largest) axis value of IEEE 952 term ``name`` in SI, and how it was obtained.

    When an axis cannot resolve the term, its upper bound is used: the term's own ``hi`` (95 %
    bound) when given, else the bound from the curve itself, ``min over tau of adev_hi(tau) /
    shape(tau)`` (a noise term cannot exceed the measured deviation at any tau; IEEE 952 Annex C
    shapes).  A bound makes the filter conservative, never optimistic.
    """
    values, notes = [], []
    for axis in axes:
        term = getattr(axis.terms, name)
        if term.value is not None:
            value, note = term.value, "fitted"
        elif term.hi is not None:
            value, note = term.hi, "upper bound of its interval, not resolved"
        else:
            curve = axis.curve
            hi = np.where(np.isfinite(curve.adev_hi), curve.adev_hi, curve.adev)
            value = float(np.min(hi / shape(np.asarray(curve.tau_s))))
            note = "upper bound from the Allan curve, not resolved"
        values.append(value)
        notes.append(f"{axis.name} {value:.3g} ({note})")
    worst = int(np.argmax(values))
    return values[worst], f"worst axis {axes[worst].name}; " + ", ".join(notes)


def kalibr_yaml(result: AnalysisResult) -> str:
    """Kalibr ``imu.yaml`` (continuous-time noise model, Kalibr wiki "IMU Noise Model").

    ``*_noise_density`` is the white-noise density N (rad/s/√Hz, m/s²/√Hz), ``*_random_walk`` the
    rate random walk K (rad/s²/√Hz, m/s³/√Hz) — both continuous-time, as Kalibr expects.  We use
    the worst axis of each sensor, so a filter tuned with it is conservative.
    """
    lines = [
        "# Kalibr IMU noise model written by imupipe (continuous-time, SI units).",
        f"# Source: {result.input.path}, {result.input.duration_s / 3600:.3g} h analysed.",
    ]
    labels = {"gyro": "gyroscope", "accel": "accelerometer"}
    shapes = {
        "random_walk": lambda tau: 1.0 / np.sqrt(tau),  # sigma_N = N / sqrt(tau)
        "rate_random_walk": lambda tau: np.sqrt(tau / 3.0),  # sigma_K = K sqrt(tau / 3)
    }
    keys = {"random_walk": "noise_density", "rate_random_walk": "random_walk"}
    for sensor in ("accel", "gyro"):
        axes = result.by_sensor(sensor)
        if not axes:
            continue
        for term in ("random_walk", "rate_random_walk"):
            value, how = _kalibr_coefficient(axes, term, shapes[term])
            unit = getattr(axes[0].terms, term).unit
            lines.append(f"# {labels[sensor]}_{keys[term]} [{unit}]: {how}")
            lines.append(f"{labels[sensor]}_{keys[term]}: {value:.6e}")
    lines.append(f"update_rate: {result.input.rate_hz:.6g}  # Hz")
    lines.append(f"rostopic: {result.input.topic}")
    return "\n".join(lines) + "\n"


def report_markdown(result: AnalysisResult, figures: dict[str, Path]) -> str:
    """``report.md``: input summary and warnings, the paper's table side by side with ours, the
    loop's before/after per axis, the figures, and the Kalibr file."""
    inp = result.input
    md = [
        f"# imupipe report: {_md(Path(inp.path).name)}",
        "",
        "## Input",
        "",
        _md_table(
            ("path", "topic", "source", "frames", "rate", "duration"),
            [
                (
                    _md(inp.path),
                    _md(inp.topic),
                    inp.source,
                    str(inp.frames),
                    f"{inp.rate_hz:.6g} Hz",
                    f"{inp.duration_s:.1f} s ({inp.duration_s / 3600:.3g} h)",
                )
            ],
        ),
        "",
    ]
    if result.device:
        md += ["Device: " + ", ".join(f"{_md(k)} = {_md(v)}" for k, v in result.device.items()), ""]
    if inp.segments:
        md += [f"Segments: {len(inp.segments)}", ""]
        md += [f"- {json.dumps(jsonable(s))}" for s in inp.segments] + [""]
    md += ["### Warnings", ""] + ([f"- {_md(w)}" for w in inp.warnings] or ["- none"]) + [""]
    md += [
        "## Noise terms next to the paper",
        "",
        "Measured value with its interval, the paper's measured value and the datasheet value,"
        " in the paper's units.",
        f"Paper: {PAPER_SOURCE}. Datasheet: {DATASHEET_SOURCE}.",
        "",
        _md_table(_ROW_HEADER, paper_rows(result)),
        "",
        "Terms the data cannot resolve are shown as their upper bound (≤):",
        "",
    ]
    md += [
        f"- {axis.name} {name}: {getattr(axis.terms, name).reason}"
        for axis in result.axes.values()
        for name in TERM_NAMES
        if getattr(axis.terms, name).value is None
    ] + [""]
    md += ["How each axis was fitted (τ range, deviance per degree of freedom, note):", ""]
    for axis in result.axes.values():
        fit = axis.terms.fit_summary()
        md.append(
            f"- {axis.name}: τ {_fmt(fit['tau_min_s'])}–{_fmt(fit['tau_max_s'])} s, "
            f"D/dof {_fmt(fit['deviance_per_dof'])}" + (f"; {fit['note']}" if fit["note"] else "")
        )
    md.append("")
    loop_rows = _loop_rows(result)
    if loop_rows:
        md += ["## Closed loop: model error before and after", "", f"Error: {ERROR_MEASURE}.", ""]
        md += [_md_table(_LOOP_HEADER, loop_rows), ""]
        md += _loop_details(result)
    md += ["## Figures", ""]
    md += [f"![{name}]({path.name})" for name, path in figures.items()] + [""]
    md += ["## Kalibr `imu.yaml`", "", *_fence(kalibr_yaml(result).rstrip(), "yaml"), ""]
    return "\n".join(md)


def _params(effect: dict) -> str:
    """``name = value [lo, hi]`` for each SI parameter of an effect (intervals when given)."""
    intervals = effect.get("intervals") or {}
    parts = []
    for name, value in effect.get("params", {}).items():
        text = f"{name} = {_fmt(value) if isinstance(value, float) else value}"
        bounds = intervals.get(name)
        if isinstance(bounds, list | tuple) and len(bounds) == 2:
            text += f" [{_fmt(bounds[0])}, {_fmt(bounds[1])}]"
        parts.append(text)
    return ", ".join(parts)


def _loop_details(result: AnalysisResult) -> list[str]:
    md = []
    for axis in result.axes.values():
        if axis.loop is None:
            continue
        md += [f"### {axis.name}", ""]
        for effect in jsonable(axis.loop.as_effects()):
            md.append(
                f"- accepted **{effect['kind']}** ({_params(effect)}): error "
                f"{_fmt(effect.get('error_before'))} → {_fmt(effect.get('error_after'))}"
            )
        for cand in jsonable(axis.loop.as_candidates()):
            md.append(f"- rejected candidate {cand.get('kind')}: {cand.get('reason', '')}".rstrip())
        before, after = axis.loop.terms_before, axis.loop.terms_after
        rows = []
        for name in TERM_NAMES:
            unit = PAPER_UNIT[axis.sensor][name]
            b, a = getattr(before, name), getattr(after, name)
            rows.append((name, _term_text(b, unit), _term_text(a, unit), unit))
        md += ["", _md_table(("term", "before", "after", "unit"), rows), ""]
    return md


def write_report(result: AnalysisResult, out_dir: Path, figures: bool = True) -> dict:
    """Write report.json, report.md (+ PNG figures), imu.yaml and allan.parquet into ``out_dir``.

    Returns the report.json document.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = report_json(result)
    (out_dir / "report.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    pngs = {}
    if figures:
        # imported here: matplotlib (~26 MB resident) stays out of the analysis' memory peak
        from imupipe.report.figures import write_figures

        pngs = write_figures(result, out_dir)
    (out_dir / "report.md").write_text(report_markdown(result, pngs))
    (out_dir / "imu.yaml").write_text(kalibr_yaml(result))
    allan_frame(result).write_parquet(out_dir / "allan.parquet")
    return doc
