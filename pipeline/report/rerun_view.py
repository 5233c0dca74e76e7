"""Stage 6 of ``imupipe analyze``: the Rerun recording (``recording.rrd``, rerun-sdk 0.41).

What a user sees when the file opens (``docs/viewer.md``):

- left, ``signals/{gyro,accel,temperature,supply}``: one time-series plot per quantity, each with
  its own y scale, over the whole recording (visible time range and x axis unbounded, x axes
  linked).  Gyro and accel are drawn with each axis' mean removed (the mean is in the series
  name), so the noise of accel_z (≈ −9.8 m/s²) is as visible as that of x and y.  By default a
  recording of more than ``2 * ENVELOPE_BINS`` frames is sent as a min/max envelope of
  :data:`ENVELOPE_BINS` bins (what the plot shows at full zoom-out anyway); ``full=True``
  (``imupipe analyze --rrd-full``) sends every frame.
- right, tabs: ``allan/<sensor>`` — log-log Allan deviation.  Rerun's time-series views all
  follow the one active timeline (a log10 τ timeline would empty the signal plots) and have no
  log axis, so the curves are drawn in a 2-D view at (log10 τ, −log10 σ) (2-D views point y
  down), with decade grid lines labelled in SI, a legend beside the grid and no labels on the
  curves; ``residual/<sensor>`` — the loop's normalised residual z(τ) before/after, same axes;
  ``summary`` — the noise terms as Markdown tables, SI beside the paper's units.
- The layout and the series names are sent before the bulk data, so a viewer streaming the
  file shows them at once; the layout is sent again with the analysis views' bounds at the end.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl
import rerun as rr
import rerun.blueprint as rrb

from imupipe.analysis.results import AnalysisResult, AxisResult
from imupipe.errors import ViewerError
from imupipe.io.columns import ENVELOPE_BINS, envelope, envelope_times
from imupipe.report.paper import PAPER_TABLE
from imupipe.report.report import (
    _LOOP_HEADER,
    _OTHER_TERMS,
    _PAPER_QUANTITIES,
    _fmt,
    _loop_rows,
    _md_table,
    _term_text,
    default_datasheet,
    is_adis16364,
)
from imupipe.report.rerun_streams import open_stream, release_closed_streams, send_blueprint
from imupipe.units import PAPER_UNIT, SI_UNIT, from_si
from imupipe.vocab import ACCEL_AXES, GYRO_AXES

TIMELINE = "sensor_time"
SENSORS = ("gyro", "accel")


@dataclass(frozen=True)
class SignalPlot:
    """One time-series plot of raw signals sharing one quantity and unit."""

    entity: str
    title: str
    columns: tuple[str, ...]
    unit: str
    centred: bool
    """Each column drawn with its mean removed (the mean stated in the series name)."""


SIGNAL_PLOTS = (
    SignalPlot("signals/gyro", "gyro", GYRO_AXES, "rad/s", True),
    SignalPlot("signals/accel", "accel", ACCEL_AXES, "m/s²", True),
    SignalPlot("signals/temperature", "temperature", ("temp_c",), "°C", False),
    SignalPlot("signals/supply", "supply", ("supply_v",), "V", False),
)
COLORS = {
    "x": (31, 119, 180),
    "y": (255, 127, 14),
    "z": (44, 160, 44),
    "c": (214, 39, 40),
    "v": (148, 103, 189),
}
CHUNK_ROWS = 100_000
"""Rows of raw signal per Rerun chunk (~2 MB per group).  12 h at 100 Hz, same machine:
500 k rows cost 2.1-2.2 s CPU and +0.19-0.25 GB peak, 100 k rows 1.5-1.7 s and +0.06 GB."""
GRID_COLOR = (110, 110, 110)
LEGEND_COLOR = (210, 210, 210)
Z_SCALE = 0.3
"""Scene units per unit of z in the residual views (±3 spans 1.8 decades of τ)."""
Z_LIMIT = 10.0
"""Largest |z| the residual views show."""
LEGEND_WIDTH = 3.4
"""Scene units (decades) right of the grid kept for the legend."""
WHOLE_RECORDING = rrb.TimeRangeBoundary.infinite()


def _color(name: str) -> tuple[int, int, int]:
    return COLORS.get(name[-1], (200, 200, 200))


def _light(color: tuple[int, int, int]) -> tuple[int, int, int]:
    return tuple(int(0.5 * v + 0.5 * 255) for v in color)


def signal_columns(frames: pl.DataFrame) -> dict[str, list[str]]:
    """The signal columns present in ``frames`` with at least one value, by plot title (ROS
    bags may lack temperature and supply, or carry them as nulls)."""
    present = {
        plot.title: [
            c
            for c in plot.columns
            if c in frames.columns and frames[c].null_count() < frames.height
        ]
        for plot in SIGNAL_PLOTS
    }
    return {title: cols for title, cols in present.items() if cols}


def _means(frames: pl.DataFrame, columns: dict[str, list[str]]) -> dict[str, float]:
    """Mean of each column (NaN and nulls ignored) of the centred plots, else 0."""
    centred = {p.title for p in SIGNAL_PLOTS if p.centred}
    return {
        c: float(frames[c].cast(pl.Float64).fill_nan(None).mean() or 0.0)
        if title in centred
        else 0.0
        for title, cols in columns.items()
        for c in cols
    }


def log_series_styles(
    rec: rr.RecordingStream,
    columns: dict[str, list[str]],
    means: dict[str, float],
    mean_note: str = "",
) -> None:
    """Series names, colours and MinMax aggregation (zoomed out, a plot keeps the extremes) of
    the signal plots with ``columns`` (by title); a centred series is named with the mean that
    is removed from it (``means``, followed by ``mean_note``)."""
    for plot in SIGNAL_PLOTS:
        names = columns.get(plot.title)
        if not names:
            continue
        series = [
            f"{c} − mean ({means[c]:.6g} {plot.unit}{mean_note})"
            if plot.centred
            else f"{c} [{plot.unit}]"
            for c in names
        ]
        style = rr.SeriesLines(
            names=series,
            colors=[_color(c) for c in names],
            widths=1.0,
            aggregation_policy=rr.components.AggregationPolicy.MinMax,
        )
        rec.log(plot.entity, style, static=True)


def _send_signals(
    rec: rr.RecordingStream,
    frames: pl.DataFrame,
    columns: dict[str, list[str]],
    means: dict[str, float],
    full: bool,
) -> None:
    """Bulk-send each plot's columns (nulls as NaN so the plot shows gaps; the mean removed for
    centred plots), as a min/max envelope of :data:`ENVELOPE_BINS` bins unless ``full``, in
    chunks of :data:`CHUNK_ROWS` rows, flushing after each chunk so that Rerun's encoding
    buffers stay small (measured: +1.2 GB for 12 h sent whole, +0.06 GB in chunks)."""
    t_s = frames["t_s"].to_numpy()
    if not full:
        t_s = envelope_times(t_s, ENVELOPE_BINS)
    for plot in SIGNAL_PLOTS:
        names = columns.get(plot.title)
        if not names:
            continue
        ys = [frames[c].cast(pl.Float64).fill_null(np.nan).to_numpy() for c in names]
        if not full:
            ys = [envelope(y, ENVELOPE_BINS) for y in ys]
        offset = np.array([means[c] for c in names])
        for start in range(0, len(t_s), CHUNK_ROWS):
            stop = start + CHUNK_ROWS
            with np.errstate(invalid="ignore"):  # inf - inf in a NaN/inf frame: NaN, silently
                part = np.column_stack([y[start:stop] for y in ys]) - offset
            t_ns = np.round(t_s[start:stop] * 1e9).astype("timedelta64[ns]")
            rec.send_columns(
                plot.entity,
                indexes=[rr.TimeColumn(TIMELINE, duration=t_ns)],
                columns=rr.Scalars.columns(scalars=part),
            )
            rec.flush()


EXCISED_COLOR = (214, 39, 40)
EXCISED_NAME = "excised: disturbance event"


def _floors(frames: pl.DataFrame, columns: dict[str, list[str]], means: dict[str, float]) -> dict:
    """Where each centred plot's excised-event bars go (:func:`_log_events`): 5 % of the
    plot's span below the lowest value it draws (its means removed), clear of the data and of
    the legend in the top left corner."""
    floors = {}
    for plot in SIGNAL_PLOTS:
        names = columns.get(plot.title)
        if not (plot.centred and names):
            continue
        lows, highs = [], []
        for c in names:
            y = frames[c].cast(pl.Float64).fill_nan(None)
            lo, hi = y.min(), y.max()
            if lo is not None:
                lows.append(float(lo) - means[c])
                highs.append(float(hi) - means[c])
        if lows:
            floors[plot.title] = min(lows) - 0.05 * (max(highs) - min(lows))
    return floors


def _log_events(rec: rr.RecordingStream, result: AnalysisResult, floors: dict[str, float]) -> None:
    """Each disturbance event excised on every axis as a red bar over its interval below the
    gyro and accel signal plots' data (``floors``: :func:`_floors`), on the recording's
    timeline: entity ``<plot>/excised``, a child of the plot (its view shows it), a NaN after
    each event breaking the line."""
    found = result.events
    if found is None:
        return
    spans = [e.excised for e in found.events if e.excised is not None]
    if not spans:
        return
    t_s = found.t0_stamp_s + found.tau0_s * np.array([[a, b, b] for a, b in spans]).ravel()
    t_ns = np.round(t_s * 1e9).astype("timedelta64[ns]")
    for plot in SIGNAL_PLOTS:
        if plot.title not in floors:
            continue
        entity = f"{plot.entity}/excised"
        style = rr.SeriesLines(names=EXCISED_NAME, colors=[EXCISED_COLOR], widths=3.0)
        rec.log(entity, style, static=True)
        level = np.tile([floors[plot.title], floors[plot.title], np.nan], len(spans))
        rec.send_columns(
            entity,
            indexes=[rr.TimeColumn(TIMELINE, duration=t_ns)],
            columns=rr.Scalars.columns(scalars=level),
        )


def _log10(values: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log10(np.asarray(values, dtype=float))


def _strip(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Finite (x, y) points of a curve as one 2-D strip, y negated (2-D views point down)."""
    keep = np.isfinite(x) & np.isfinite(y)
    return np.column_stack([x[keep], -y[keep]])


def _model_adev(axis: AxisResult) -> np.ndarray:
    """Fitted IEEE 952 composite model σ(τ) (:meth:`imupipe.model.ieee952.NoiseTerms.avar`)."""
    return np.sqrt(np.maximum(axis.terms.avar(axis.curve.tau_s), 0.0))


@dataclass(frozen=True)
class Extent:
    """Scene rectangle of a log-log view: x in log10 τ [s], y in scene units (y down)."""

    x0: float
    x1: float
    top: float
    bottom: float

    def bounds(self) -> rrb.VisualBounds2D:
        """The visual bounds showing the grid, its labels (left, below) and the legend (right)."""
        return rrb.VisualBounds2D(
            x_range=[self.x0 - 1.1, self.x1 + LEGEND_WIDTH],
            y_range=[self.top - 0.3, self.bottom + 0.5],
        )


def _tau_range(axes: list[AxisResult]) -> tuple[float, float]:
    x = _log10(np.concatenate([a.curve.tau_s for a in axes]))
    return float(np.floor(np.nanmin(x))), float(np.ceil(np.nanmax(x)))


def allan_extent(axes: list[AxisResult]) -> Extent:
    """Whole decades of τ and of σ covering the measured deviations and their intervals."""
    y = _log10(
        np.concatenate([np.r_[a.curve.adev, a.curve.adev_lo, a.curve.adev_hi] for a in axes])
    )
    y = y[np.isfinite(y)]
    x0, x1 = _tau_range(axes)
    return Extent(x0, x1, -float(np.ceil(y.max())), -float(np.floor(y.min())))


def _z(axis: AxisResult, which: str) -> np.ndarray:
    """The loop's residual z ``before`` or ``after`` over that fit's τ range (NaN elsewhere)."""
    good = getattr(axis.loop, which)
    return good.fitted(axis.curve.tau_s, good.z)


def residual_extent(axes: list[AxisResult]) -> Extent:
    """Whole decades of τ; z from −zmax to +zmax (at least ±4, at most ±:data:`Z_LIMIT`)."""
    z = np.abs(np.concatenate([np.r_[_z(a, "before"), _z(a, "after")] for a in axes]))
    z = z[np.isfinite(z)]
    zmax = float(np.clip(np.ceil(z.max()) if z.size else 4.0, 4.0, Z_LIMIT))
    x0, x1 = _tau_range(axes)
    return Extent(x0, x1, -Z_SCALE * zmax, Z_SCALE * zmax)


def _tau_axis(rec: rr.RecordingStream, path: str, ext: Extent, levels: dict[str, float]) -> None:
    """Grid lines at each decade of τ and at the ``levels`` (label -> scene y), labelled: τ
    below the grid, the levels left of it."""
    xs = np.arange(ext.x0, ext.x1 + 1)
    strips = [[(v, ext.top), (v, ext.bottom)] for v in xs]
    strips += [[(ext.x0, y), (ext.x1, y)] for y in levels.values()]
    rec.log(
        f"{path}/grid",
        rr.LineStrips2D(strips, colors=GRID_COLOR, radii=rr.Radius.ui_points(0.5), draw_order=0),
        static=True,
    )
    positions = [(v, ext.bottom + 0.25) for v in xs] + [(ext.x0 - 0.55, y) for y in levels.values()]
    labels = [f"τ = 1e{int(v)} s" for v in xs] + list(levels)
    rec.log(
        f"{path}/grid_labels",
        rr.Points2D(positions, labels=labels, radii=0.0, colors=LEGEND_COLOR, show_labels=True),
        static=True,
    )


def log_extent(x: np.ndarray, y: np.ndarray) -> Extent:
    """Whole decades covering the finite log10 values ``x`` (τ) and ``y`` (σ)."""
    x, y = x[np.isfinite(x)], y[np.isfinite(y)]
    return Extent(
        float(np.floor(x.min())),
        float(np.ceil(x.max())),
        -float(np.ceil(y.max())),
        -float(np.floor(y.min())),
    )


def decade_grid(rec: rr.RecordingStream, path: str, ext: Extent, unit: str) -> None:
    """Decade grid of a log-log deviation view: τ in s below it, σ in ``unit`` left of it."""
    decades = np.arange(-ext.bottom, -ext.top + 1)
    _tau_axis(rec, path, ext, {f"1e{int(v)} {unit}": -v for v in decades[::-1]})


@dataclass(frozen=True)
class LegendEntry:
    label: str
    color: tuple[int, int, int]
    width: float
    """Line width in UI points; 0 for an entry drawn as dots."""


def _legend(rec: rr.RecordingStream, path: str, ext: Extent, entries: list[LegendEntry]) -> None:
    """Legend right of the grid: one sample (line or dots) per entry with its label over it."""
    xc = ext.x1 + LEGEND_WIDTH / 2
    ys = ext.top + 0.2 + 0.4 * np.arange(len(entries))
    for i, (entry, y) in enumerate(zip(entries, ys, strict=True)):
        base = f"{path}/legend/{i}"
        if entry.width:
            sample = rr.LineStrips2D(
                [[(xc - 1.0, y), (xc + 1.0, y)]],
                colors=entry.color,
                radii=rr.Radius.ui_points(entry.width / 2),
            )
        else:
            sample = rr.Points2D(
                np.column_stack([np.linspace(xc - 1.0, xc + 1.0, 5), np.full(5, y)]),
                colors=entry.color,
                radii=rr.Radius.ui_points(3.0),
            )
        rec.log(f"{base}/sample", sample, static=True)
        rec.log(
            f"{base}/label",
            rr.Points2D([(xc, y)], labels=entry.label, radii=0.0, colors=entry.color),
            static=True,
        )


ADEV_WIDTH, MODEL_WIDTH, MODEL_BEFORE_WIDTH = 3.0, 2.0, 1.0


def _log_allan(rec: rr.RecordingStream, sensor: str, axes: list[AxisResult]) -> None:
    """Measured σ(τ) with its 95 % interval as bars, the IEEE 952 model (before and after the
    loop when it ran) and the measured σ after the loop's corrections (dots), one colour per
    axis; decade grid in SI and a legend."""
    path = f"allan/{sensor}"
    looped = any(a.loop is not None for a in axes)
    for axis in axes:
        c, color = axis.curve, _color(axis.name)
        x = _log10(c.tau_s)
        y, lo, hi = _log10(c.adev), _log10(c.adev_lo), _log10(c.adev_hi)
        base = f"{path}/{axis.name}"
        rec.log(
            f"{base}/adev",
            rr.LineStrips2D(
                [_strip(x, y)],
                colors=color,
                radii=rr.Radius.ui_points(ADEV_WIDTH / 2),
                draw_order=3,
            ),
            static=True,
        )
        ok = np.isfinite(x) & np.isfinite(lo) & np.isfinite(hi)
        bars = np.stack([np.column_stack([x, -lo]), np.column_stack([x, -hi])], axis=1)[ok]
        rec.log(
            f"{base}/interval",
            rr.LineStrips2D(bars, colors=color, radii=rr.Radius.ui_points(0.5), draw_order=2),
            static=True,
        )
        models = {"model": (_model_adev(axis), color, MODEL_WIDTH)}
        if axis.loop is not None:
            rec.log(
                f"{base}/adev_after",
                rr.Points2D(
                    _strip(x, _log10(axis.loop.adev_after)),
                    colors=color,
                    radii=rr.Radius.ui_points(3.0),
                    draw_order=3,
                ),
                static=True,
            )
            models = {
                "model_before": (axis.loop.model_adev_before, _light(color), MODEL_BEFORE_WIDTH),
                "model_after": (axis.loop.model_adev_after, color, MODEL_WIDTH),
            }
        for name, (model, shade, width) in models.items():
            rec.log(
                f"{base}/{name}",
                rr.LineStrips2D(
                    [_strip(x, _log10(model))],
                    colors=shade,
                    radii=rr.Radius.ui_points(width / 2),
                    draw_order=1,
                ),
                static=True,
            )
    ext = allan_extent(axes)
    decade_grid(rec, path, ext, SI_UNIT[sensor]["mean"].replace("^2", "²"))
    entries = [LegendEntry(a.name, _color(a.name), ADEV_WIDTH) for a in axes]
    entries.append(LegendEntry("measured, bars: 95 %", LEGEND_COLOR, ADEV_WIDTH))
    if looped:
        entries += [
            LegendEntry("model before loop", _light(LEGEND_COLOR), MODEL_BEFORE_WIDTH),
            LegendEntry("model after loop", LEGEND_COLOR, MODEL_WIDTH),
            LegendEntry("after loop corrections", LEGEND_COLOR, 0.0),
        ]
    else:
        entries.append(LegendEntry("IEEE 952 model", LEGEND_COLOR, MODEL_WIDTH))
    _legend(rec, path, ext, entries)


def _log_residuals(rec: rr.RecordingStream, sensor: str, axes: list[AxisResult]) -> None:
    """The loop's normalised residual z(τ) before (thin, light) and after (thick) per axis,
    the 0 and ±3 levels, τ decades, a legend."""
    path = f"residual/{sensor}"
    ext = residual_extent(axes)
    zmax = ext.bottom / Z_SCALE
    for axis in axes:
        x = _log10(axis.curve.tau_s)
        color = _color(axis.name)
        for name, z, shade, width in (
            ("z_before", _z(axis, "before"), _light(color), MODEL_BEFORE_WIDTH),
            ("z_after", _z(axis, "after"), color, ADEV_WIDTH),
        ):
            z = np.clip(np.asarray(z, float), -zmax, zmax)
            rec.log(
                f"{path}/{axis.name}/{name}",
                rr.LineStrips2D(
                    [_strip(x, Z_SCALE * z)], colors=shade, radii=rr.Radius.ui_points(width / 2)
                ),
                static=True,
            )
    levels = {"z = +3": -3 * Z_SCALE, "z = 0": 0.0, "z = −3": 3 * Z_SCALE}
    _tau_axis(rec, path, ext, levels)
    entries = [LegendEntry(a.name, _color(a.name), ADEV_WIDTH) for a in axes]
    entries += [
        LegendEntry("z before loop", _light(LEGEND_COLOR), MODEL_BEFORE_WIDTH),
        LegendEntry(f"z after loop (clipped ±{zmax:g})", LEGEND_COLOR, ADEV_WIDTH),
    ]
    _legend(rec, path, ext, entries)


def _si_text(unit: str) -> str:
    return unit.replace("sqrt(Hz)", "√Hz").replace("^2", "²").replace("^3", "³")


def _cell(axis: AxisResult, name: str, unit: str) -> str:
    if name in ("mean", "rms"):
        return _fmt(from_si(getattr(axis, name), unit))
    return _term_text(getattr(axis.terms, name), unit)


def _code(text: str) -> str:
    """An untrusted string as a Markdown code span."""
    return "`" + text.replace("`", "'") + "`"


def summary_markdown(result: AnalysisResult) -> str:
    """The noise terms per sensor as Markdown tables: measured value [95 % interval] in SI and in
    the paper's units side by side, the paper's and the datasheet's values in the paper's units
    (:mod:`imupipe.report.paper`), then the loop's before → after and the warnings."""
    inp = result.input
    md = [
        f"{_code(inp.path)} [{_code(inp.topic)}]: {inp.frames} frames, {inp.rate_hz:.4g} Hz, "
        f"{inp.duration_s / 3600:.3g} h analysed.  Measured values with their 95 % interval in "
        "SI, and in the units of the ADIS16364 paper (the paper's and the datasheet's values "
        "are in those units)."
    ]
    header = (
        "quantity",
        "axis",
        "measured (SI)",
        "SI unit",
        "measured",
        "paper",
        "datasheet",
        "unit",
    )
    datasheet, adis = default_datasheet(result), is_adis16364(result)
    for sensor in SENSORS:
        axes = result.by_sensor(sensor)
        if not axes:
            continue
        rows = []
        for name, label in (*_PAPER_QUANTITIES, *_OTHER_TERMS):
            si, paper_unit = SI_UNIT[sensor][name], PAPER_UNIT[sensor][name]
            for axis in axes:
                ref = PAPER_TABLE.get(name, {}).get(axis.name) if adis else None
                paper = None if ref is None else ref.measured_si()
                spec = None if datasheet is None else datasheet.get(sensor, name)
                sheet = None if spec is None else spec.si()
                rows.append(
                    (
                        label,
                        axis.name,
                        _cell(axis, name, si),
                        _si_text(si),
                        _cell(axis, name, paper_unit),
                        "—" if paper is None else _fmt(from_si(paper, paper_unit)),
                        "—" if sheet is None else _fmt(from_si(sheet, paper_unit)),
                        paper_unit,
                    )
                )
        md += ["", f"## {sensor}", "", _md_table(header, rows)]
    loop_rows = _loop_rows(result)
    if loop_rows:
        md += ["", "## Closed loop (before → after)", "", _md_table(_LOOP_HEADER, loop_rows)]
    if inp.warnings:
        md += ["", "## Warnings", ""] + [f"- {_code(w)}" for w in inp.warnings]
    return "\n".join(md) + "\n"


def _signal_view(plot: SignalPlot, note: str) -> rrb.TimeSeriesView:
    """A time-series plot of one quantity over the whole recording, legend top left."""
    kind = ", mean removed" if plot.centred else ""
    return rrb.TimeSeriesView(
        origin=plot.entity,
        name=f"{plot.title}{kind} [{plot.unit}]{note}",
        time_ranges=rrb.VisibleTimeRange(TIMELINE, start=WHOLE_RECORDING, end=WHOLE_RECORDING),
        axis_x=rrb.TimeAxis(view_range=rrb.TimeRange(start=WHOLE_RECORDING, end=WHOLE_RECORDING)),
        axis_y=rrb.ScalarAxis(zoom_lock=False),
        plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop, visible=True),
    )


def blueprint(
    result: AnalysisResult | None, signal_titles: list[str], bin_s: float | None = None
) -> rrb.Blueprint:
    """Raw signals on the left (one plot per quantity, ``bin_s``: the envelope's bin in s, None
    when every frame is shown); on the right tabs of the log-log Allan deviation per sensor and
    of the loop's residuals (when it ran), the summary below them.  ``result`` None: the layout
    sent before the data (no bounds yet; the sensors are those of ``signal_titles``)."""
    note = "" if bin_s is None else f" · min/max per {bin_s:.3g} s"
    signals = [_signal_view(p, note) for p in SIGNAL_PLOTS if p.title in signal_titles]
    sensors = [s for s in SENSORS if (result.by_sensor(s) if result else s in signal_titles)]
    allan = [
        rrb.Spatial2DView(
            origin=f"allan/{s}",
            name=f"{s} Allan deviation",
            visual_bounds=allan_extent(result.by_sensor(s)).bounds() if result else None,
        )
        for s in sensors
    ]
    looped = {s: [a for a in result.by_sensor(s) if a.loop] for s in sensors} if result else {}
    residual = [
        rrb.Spatial2DView(
            origin=f"residual/{s}",
            name=f"{s} loop residual z",
            visual_bounds=residual_extent(axes).bounds(),
        )
        for s, axes in looped.items()
        if axes
    ]
    right = rrb.Vertical(
        rrb.Tabs(*allan, *residual, active_tab=0),
        rrb.TextDocumentView(origin="summary", name="Noise terms (SI and the paper's units)"),
        row_shares=[1, 1],
    )
    if not signals:
        return rrb.Blueprint(right, collapse_panels=True, auto_views=False)
    left = rrb.Vertical(*signals, name="Raw signals")
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[2, 3]), collapse_panels=True, auto_views=False
    )


class RrdWriter:
    """Writes ``recording.rrd`` in two steps, so that the costly part overlaps the analysis.

    Construction opens the file, sends the layout and the series names, and starts a thread
    that bulk-sends the raw ``frames`` (columns ``t_s`` and any of gyro_x..z rad/s, accel_x..z
    m/s², temp_c °C, supply_v V) — a min/max envelope unless ``full``; Rerun encodes and writes
    them on its own threads.  :meth:`finish` adds the Allan views, residuals, summary and the
    final layout once the analysis is done, and flushes.
    """

    def __init__(self, path: Path, frames: pl.DataFrame, full: bool = False) -> None:
        self.path = Path(path)
        columns = signal_columns(frames)
        self.groups = list(columns)
        n = frames.height
        enveloped = not full and n > 2 * ENVELOPE_BINS
        t = frames["t_s"]
        self.bin_s = (
            math.ceil(n / ENVELOPE_BINS) * float(t[-1] - t[0]) / (n - 1) if enveloped else None
        )
        means = _means(frames, columns)
        self._floors = _floors(frames, columns, means)
        self._rec = rec = open_stream("imupipe")
        rec.save(self.path)
        log_series_styles(rec, columns, means)
        rec.flush()  # the names before the data: log() is batched, send_columns() is not
        send_blueprint(rec, blueprint(None, self.groups, self.bin_s))
        self._sender = threading.Thread(
            target=_send_signals,
            args=(rec, frames, columns, means, not enveloped),
            name="rrd-signals",
            daemon=True,
        )
        self._sender.start()

    def finish(self, result: AnalysisResult) -> Path:
        """Log the analysis results and the final layout, flush and close; returns the path."""
        rec = self._rec
        for sensor in SENSORS:
            axes = result.by_sensor(sensor)
            if axes:
                _log_allan(rec, sensor, axes)
            looped = [a for a in axes if a.loop is not None]
            if looped:
                _log_residuals(rec, sensor, looped)
        rec.log(
            "summary",
            rr.TextDocument(summary_markdown(result), media_type="text/markdown"),
            static=True,
        )
        _log_events(rec, result, self._floors)
        self._sender.join()
        send_blueprint(rec, blueprint(result, self.groups, self.bin_s))
        del rec
        self._close()
        return self.path

    def discard(self) -> None:
        """Stop after a failed analysis: wait for the sender, close, and delete the file."""
        self._sender.join()
        self._close()
        self.path.unlink(missing_ok=True)

    def _close(self) -> None:
        """Flush and disconnect the stream, and let rerun drop it
        (:mod:`imupipe.report.rerun_streams`)."""
        self._rec.flush()
        self._rec.disconnect()
        del self._rec
        release_closed_streams()


def write_rrd(result: AnalysisResult, frames: pl.DataFrame, path: Path, full: bool = False) -> Path:
    """Write the Rerun recording of ``result`` and the raw ``frames`` to ``path`` in one go."""
    return RrdWriter(path, frames, full).finish(result)


def rerun_executable() -> str:
    """The ``rerun`` CLI of this environment (next to the interpreter), else the one on PATH."""
    local = Path(sys.executable).with_name("rerun")
    found = str(local) if local.exists() else shutil.which("rerun")
    if found is None:
        raise ViewerError("the rerun executable was not found (pip install rerun-sdk)")
    return found


def open_viewer(path: Path) -> None:
    """Open the Rerun viewer on a recording, or on ``recording.rrd`` in a result folder."""
    path = Path(path)
    if path.is_dir():
        path = path / "recording.rrd"
    if not path.is_file():
        raise ViewerError(f"{path}: no Rerun recording")
    subprocess.run([rerun_executable(), str(path)], check=True)
