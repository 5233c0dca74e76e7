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

from imupipe.analysis.results import (
    ERROR_MEASURE,
    AnalysisResult,
    AxisResult,
    allan_frame,
    jsonable,
    report_json,
)
from imupipe.device.frame_schema import SCHEMA_NAME as ADIS16364_SOURCE
from imupipe.escape import printable
from imupipe.model.loop import BOOT_EXCEEDANCES, N_BOOT
from imupipe.report.datasheet import Datasheet, adis16364
from imupipe.report.exports import render as render_export
from imupipe.report.exports import write_exports
from imupipe.report.paper import PAPER_SOURCE, PAPER_TABLE
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


def _measured(axis: AxisResult, name: str, unit: str) -> str:
    """The final model's term ``name`` (or the axis' mean/rms) in ``unit``, with its interval."""
    if name in ("mean", "rms"):
        return _fmt(from_si(getattr(axis, name), unit))
    return _term_text(getattr(axis.terms, name), unit)


def is_adis16364(result: AnalysisResult) -> bool:
    """Whether the recording holds ADIS16364 frames (the paper's part)."""
    return result.input.source == ADIS16364_SOURCE


def default_datasheet(result: AnalysisResult) -> Datasheet | None:
    """The datasheet shown when none is given: the ADIS16364's for its recordings, else none."""
    return adis16364() if is_adis16364(result) else None


def paper_rows(
    result: AnalysisResult, datasheet: Datasheet | None = None
) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
    """(header, rows) of the headline table: quantity, axis, the final model's value with its
    interval, the paper's measured value (ADIS16364 recordings only), the ``datasheet`` value
    (when given), unit — in the paper's units (:mod:`imupipe.report.paper`).  A datasheet value
    whose own unit differs from the paper's gets a second row in the datasheet's unit."""
    paper = is_adis16364(result)
    header = ("quantity", "axis", "measured [95 % interval]")
    header += ("paper",) * paper + ("datasheet",) * (datasheet is not None) + ("unit",)

    def row(label: str, axis: AxisResult, name: str, unit: str) -> tuple[str, ...]:
        cells = (label, axis.name, _measured(axis, name, unit))
        if paper:
            ref = PAPER_TABLE.get(name, {}).get(axis.name)
            cells += ("—" if ref is None else _fmt(from_si(ref.measured_si(), unit)),)
        if datasheet is not None:
            spec = datasheet.get(axis.sensor, name)
            cells += ("—" if spec is None else _fmt(from_si(spec.si(), unit)),)
        return (*cells, unit)

    rows = []
    for name, label in _PAPER_QUANTITIES + _OTHER_TERMS:
        rows += [row(label, a, name, PAPER_UNIT[a.sensor][name]) for a in result.axes.values()]
        for axis in result.axes.values():
            spec = datasheet.get(axis.sensor, name) if datasheet else None
            if spec is not None and spec.unit != PAPER_UNIT[axis.sensor][name]:
                rows.append(row(label, axis, name, spec.unit))
    return header, rows


def _before_after(model: dict, key: str) -> str:
    return f"{_fmt(model.get(key + '_before'))} → {_fmt(model.get(key + '_after'))}"


def _p_before_after(model: dict) -> str:
    """The bootstrap p-values before → after, "≤ floor" where no replicate reached the
    deviance (``p_value_floor``: the true p is at most that)."""

    def text(p: float | None) -> str:
        return f"≤ {_fmt(p)}" if p is not None and p <= model["p_value_floor"] else _fmt(p)

    return f"{text(model.get('p_value_before'))} → {text(model.get('p_value_after'))}"


def _loop_rows(result: AnalysisResult) -> list[tuple[str, ...]]:
    """Per looped axis: error, p-value, rms z and max |z| (at which tau), before → after."""
    rows = []
    for axis in result.axes.values():
        if axis.loop is None:
            continue
        model = jsonable(axis.loop.as_model_dict())
        kinds = ", ".join(e.kind for e in axis.loop.accepted) or "none"
        tau_max = _before_after(model, "tau_max_abs_z")
        ranges = [
            "–".join(_fmt(t) for t in model[f"fit_tau_range_s_{when}"])
            for when in ("before", "after")
        ]
        error = _before_after(model, "error")
        if (same := model.get("error_before_final_range")) is not None:  # the range widened
            error = (
                f"{_fmt(model['error_before'])} ({_fmt(same)} on the final τ) → "
                f"{_fmt(model['error_after'])}"
            )
        rows.append(
            (
                axis.name,
                error,
                _p_before_after(model),
                _before_after(model, "rms_z"),
                f"{_before_after(model, 'max_abs_z')} (τ {tau_max} s)",
                ranges[1] if ranges[0] == ranges[1] else " → ".join(ranges),
                str(model.get("dof", "—")),
                kinds,
            )
        )
    return rows


_LOOP_HEADER = ("axis", "error", "p-value", "rms z", "max |z|", "fitted τ [s]", "dof", "effects")
"""The loop's statistics read the fitted τ, which reach T/2 (allan.parquet and the figures stop
at T/4): the fitted range is shown beside them.  Where a modelled short-τ line widened it, the
error cell also gives the baseline's error on the final range (``error_before_final_range``)."""


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


_SEGMENT_COLUMNS = {
    "start_frame": "first frame",
    "stop_frame": "end frame (exclusive)",
    "frames": "frames",
    "t_start_s": "start [s]",
    "t_stop_s": "stop [s]",
}
"""Column titles of report.md's segment table (the keys of
:meth:`imupipe.analysis.condition.Segment.as_dict`; another key is its own title)."""


def _number(v: object) -> str:
    """A float to 10 significant digits (a stamp in s to 10 µs over a day), anything else as is."""
    return f"{v:.10g}" if isinstance(v, float) else str(v)


def _segment_table(segments: list[dict]) -> list[str]:
    """The analysed segments as a Markdown table, one row each (times from the first frame)."""
    keys = list(segments[0])
    rows = [[_SEGMENT_COLUMNS.get(k, k) for k in keys], ["---"] * len(keys)]
    rows += [[_number(s.get(k)) for k in keys] for s in segments]
    return ["| " + " | ".join(_md(c) for c in row) + " |" for row in rows]


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


def window_text(window_s: tuple[float, float | None]) -> str | None:
    """The time window analysed, in words (None: the whole recording)."""
    start, end = window_s
    if start == 0 and end is None:
        return None
    if end is None:
        to = "the last frame"
    else:
        to = f"{-end:g} s before the last frame" if end < 0 else f"t = {end:g} s"
    return f"window from t = {start:g} s to {to} (--start, --end)"


def format_table(result: AnalysisResult, datasheet: Datasheet | None = None) -> str:
    """The paper-style terminal table printed by ``imupipe analyze``: the final model's terms
    (``datasheet``: default :func:`default_datasheet`) and the loop's table.  The input's
    warnings are not in it: the command prints them once, on stderr, after it (they were in
    both, so a terminal showed each twice)."""
    inp = result.input
    head = (
        f"{printable(inp.path)} [{printable(inp.topic)}]: {inp.frames} frames, "
        f"{inp.rate_hz:.4g} Hz, {inp.duration_s / 3600:.3g} h analysed; final model (after the "
        "closed loop)"
    )
    if window := window_text(inp.window_s):
        head += f"; {window}"
    parts = [head, _text_table(*paper_rows(result, datasheet or default_datasheet(result)))]
    loop_rows = _loop_rows(result)
    if loop_rows:
        parts.append(f"closed loop (error = {ERROR_MEASURE}):")
        parts.append(_text_table(_LOOP_HEADER, loop_rows))
    return "\n".join(parts)


def kalibr_yaml(result: AnalysisResult) -> str:
    """Kalibr ``imu.yaml`` of the final model (:func:`imupipe.report.exports.kalibr`)."""
    return render_export(report_json(result), "kalibr")[1]


def report_markdown(
    result: AnalysisResult, figures: dict[str, Path], datasheet: Datasheet | None = None
) -> str:
    """``report.md``: input summary and warnings, the final model's terms (next to the paper's
    for ADIS16364 recordings, and to the datasheet's), the loop's before/after per axis, the
    figures, and the Kalibr file."""
    inp = result.input
    datasheet = datasheet or default_datasheet(result)
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
    if window := window_text(inp.window_s):
        md += [f"Analysed: {window}.", ""]
    if result.device:
        md += ["Device: " + ", ".join(f"{_md(k)} = {_md(v)}" for k, v in result.device.items()), ""]
    if inp.segments:
        md += [f"Segments: {len(inp.segments)}", "", *_segment_table(inp.segments), ""]
    md += ["### Warnings", ""] + ([f"- {_md(w)}" for w in inp.warnings] or ["- none"]) + [""]
    md += [
        "## Noise terms (final model)",
        "",
        "The model after the closed loop (the IEEE 952 fit where it accepted nothing), each"
        " value with its 95 % interval, in the paper's units.",
    ]
    if is_adis16364(result):
        md.append(f"Paper: {PAPER_SOURCE}.")
    if datasheet is not None:
        # part and source come from the user's file: JSON-quoted (no line breaks), letters
        # such as č and § as they are, every other non-printable character escaped
        part, source = (
            printable(json.dumps(text, ensure_ascii=False))
            for text in (datasheet.part, datasheet.source)
        )
        md.append(f"Datasheet {part}: {source}.")
    md += [
        "",
        _md_table(*paper_rows(result, datasheet)),
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
    md += _events_section(result)
    loop_rows = _loop_rows(result)
    if loop_rows:
        floor = next(a.loop.p_value_floor for a in result.axes.values() if a.loop)
        md += [
            "## Closed loop: model error before and after",
            "",
            f"Error: {ERROR_MEASURE}. p-value: the share of parametric-bootstrap replicates "
            f"of the model whose deviance reaches the fit's, drawn {N_BOOT} at a time until "
            f"{BOOT_EXCEEDANCES} reach it or {round(1 / floor) - 1} are drawn (Besag & "
            f"Clifford 1991; ≤ {_fmt(floor)}: none did, and the true p-value is at most that). "
            "Besides its "
            "own test, an effect is accepted only where the model's deviance falls by at least "
            "χ²₁(0.95) = 3.84 in Allan space or in the time domain (−2 ln L of the whitened "
            "series) and the time-domain one does not rise by more than that (a linear ramp, "
            "which neither can show, only where it does not rise); each accepted effect below "
            "gives its Allan-space error before → after and, in parentheses, the falls that "
            "rule read.",
            "",
        ]
        if any(axis.loop and axis.loop.error_before_final_range for axis in result.axes.values()):
            md += [
                "Where a modelled short-τ line widened the fitted τ range, the error before is "
                "given on both ranges: the baseline's own, and (in parentheses) the final one, "
                "where it compares with the error after.",
                "",
            ]
        md += [_md_table(_LOOP_HEADER, loop_rows), ""]
        md += _loop_details(result)
    md += ["## Figures", ""]
    md += [f"![{name}]({path.name})" for name, path in figures.items()] + [""]
    md += ["## Kalibr `imu.yaml`", "", *_fence(kalibr_yaml(result).rstrip(), "yaml"), ""]
    return "\n".join(md)


def _events_section(result: AnalysisResult) -> list[str]:
    """``## Disturbance events``: what the joint search tested and one row per event found."""
    if result.events is None:
        return []
    doc = result.events.as_dict()
    det = doc["detector"]
    md = [
        "## Disturbance events (found jointly on all axes)",
        "",
        f"{det['tests']} windows of {len(det['scales'])} lengths "
        f"({_fmt(det['scales'][0]['window_s']) if det['scales'] else '-'}–"
        f"{_fmt(det['scales'][-1]['window_s']) if det['scales'] else '-'} s) tested on "
        f"{', '.join(det['axes'])}; record-wide false-alarm probability {det['false_alarm']:g}. "
        "Transients are excised on every axis (the Allan variance skips every term touching "
        "them); steps are kept and left to the loop.",
        "",
    ]
    together = _common_mode_lines(doc["common_mode"])
    if not doc["found"]:
        return [*md, "None found.", "", *together]
    rows = [
        (
            e["kind"],
            f"{e['start_s']:.1f}",
            f"{e['duration_s']:.1f}",
            ", ".join(
                f"{a} {_fmt(e['size'][a]['value'])} {e['size'][a]['unit']} (z {e['z'][a]:.1f})"
                for a in e["axes"]
            ),
            e["handling"],
        )
        for e in doc["found"]
    ]
    header = ("kind", "start (s)", "duration (s)", "axes: size (z)", "handling")
    excised = f"Excised: {doc['excised_samples']} samples."
    return [*md, _md_table(header, rows), "", excised, "", *together]


def _common_mode_lines(doc: dict) -> list[str]:
    """The axis pairs whose level fluctuations move together (report.json
    ``events.common_mode``), a table and what it means; nothing when none do."""
    if not doc["pairs"]:
        return []
    rows = []
    for pair in doc["pairs"]:
        top, windows = pair["strongest"], pair["significant_window_s"]
        rows.append((
            "–".join(pair["axes"]),
            f"{top['value']:.2f} ({_fmt(top['window_s'])} s)",
            f"{_fmt(windows[0])}–{_fmt(windows[-1])} s" if len(windows) > 1
            else f"{_fmt(windows[0])} s",
            f"{pair['p_value']:.2g}" if pair["p_value"] >= 1e-16 else "< 1e-16",
        ))  # fmt: skip
    return [
        "### Axes that move together",
        "",
        "The correlation of the axes' level fluctuations in the detector's windows (their "
        "z-scores about the local level, clipped at 3), tested against independence "
        f"(Fisher's z, family-wise α = {doc['alpha']:g} over {doc['tests']} correlations):",
        "",
        _md_table(("axes", "strongest r (window)", "significant at", "p"), rows),
        "",
        "A cause common to these axes moves them together: at long windows usually the "
        "temperature or the supply moving every bias, at short ones a vibration or tilt of the "
        "mount. Each axis' noise terms describe that axis alone; a filter that gives each axis "
        "an independent bias state does not know that these biases move together. A recording "
        "with the sensor's temperature lets the loop model a temperature coupling per axis.",
        "",
    ]


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


def _kind_text(record: dict) -> str:
    """An effect's or candidate's kind, with the fundamental a harmonic line belongs to (or the
    modelled line a fundamental found after it is the harmonic of)."""
    evidence = record.get("evidence") or {}
    order, f1 = evidence.get("harmonic"), evidence.get("harmonic_of_hz")
    harmonic = "" if order is None else f" (harmonic {order} of {_fmt(f1)} Hz)"
    order, f_n = evidence.get("its_harmonic"), evidence.get("fundamental_of_hz")
    if order is not None:
        harmonic = f" (fundamental of {_fmt(f_n)} Hz, its harmonic {order})"
    return f"{record.get('kind')}{harmonic}"


def _falls_text(evidence: dict) -> str:
    """Both errors' falls (χ² units) that the loop's acceptance rule read for an effect
    (:func:`imupipe.model.loop._error_reasons`), where it measured them: the Allan-space error
    may rise while the time-domain likelihood rises more (a bias step on a real unit)."""
    if "allan_error_fall_chi2" not in evidence:
        return ""
    text = f" (Allan deviance fall {evidence['allan_error_fall_chi2']:.1f}"
    if evidence.get("time_domain_error_judged"):
        text += (
            f"; time-domain {_fmt(evidence['time_domain_error_before'])} → "
            f"{_fmt(evidence['time_domain_error_after'])}, deviance fall "
            f"{evidence['time_domain_deviance_fall']:.1f}"
        )
    return text + ")"


def _loop_details(result: AnalysisResult) -> list[str]:
    md = []
    for axis in result.axes.values():
        if axis.loop is None:
            continue
        md += [f"### {axis.name}", ""]
        for effect in jsonable(axis.loop.accepted):
            level = (effect.get("evidence") or {}).get("level")  # a coupling's regressor
            md.append(
                f"- accepted **{_kind_text(effect)}** ({_params(effect)}"
                f"{'' if level is None else f'; level: {level}'}): error "
                f"{_fmt(effect.get('error_before'))} → {_fmt(effect.get('error_after'))}"
                + _falls_text(effect.get("evidence") or {})
            )
        for cand in jsonable(axis.loop.rejected):
            md.append(f"- rejected candidate {_kind_text(cand)}: {cand.get('reason', '')}".rstrip())
        before, after = axis.loop.terms_before, axis.loop.terms_after
        rows = []
        for name in TERM_NAMES:
            unit = PAPER_UNIT[axis.sensor][name]
            b, a = getattr(before, name), getattr(after, name)
            rows.append((name, _term_text(b, unit), _term_text(a, unit), unit))
        md += ["", _md_table(("term", "before", "after", "unit"), rows), ""]
    return md


def write_report(
    result: AnalysisResult,
    out_dir: Path,
    figures: bool = True,
    datasheet: Datasheet | None = None,
    processes: int = 1,
) -> dict:
    """Write report.json, report.md (+ PNG figures), imu.yaml and allan.parquet into ``out_dir``
    (``processes``: :func:`imupipe.report.figures.write_figures`).

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

        pngs = write_figures(result, out_dir, processes)
    (out_dir / "report.md").write_text(report_markdown(result, pngs, datasheet))
    write_exports(doc, ["kalibr"], out_dir)
    allan_frame(result).write_parquet(out_dir / "allan.parquet")
    return doc
