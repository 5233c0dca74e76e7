"""Stage 6 of ``imupipe analyze``: the Rerun recording (``recording.rrd``, rerun-sdk 0.41).

Contents, all under one blueprint so the file opens ready to read:

- ``signals/{gyro,accel,housekeeping}``: the raw series (gyro_x..z rad/s, accel_x..z m/s²,
  temp_c °C, supply_v V) against sensor time (the ``sensor_time`` duration timeline), sent in
  bulk with ``send_columns`` — one Arrow chunk per group, never a per-sample ``log``.
- ``allan/<sensor>``: log-log Allan deviation.  Rerun's time-series view has no log axis, so the
  curves are drawn in a 2-D view at (log10 tau, -log10 sigma) — 2-D views point y down, hence the
  minus — with labelled decade grid lines: measured deviation, its interval as vertical bars,
  the fitted IEEE 952 model and, when the closed loop ran, the measured deviation after its
  time-domain corrections (points) and the model after the loop.
- ``residual/<sensor>``: normalised residual z before/after the loop against log10 tau, with the
  0 and ±3 lines (same 2-D convention).
- ``summary``: the paper-style table as a text document.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import polars as pl
import rerun as rr
import rerun.blueprint as rrb

from imupipe.analysis.results import AnalysisResult, AxisResult
from imupipe.errors import ViewerError
from imupipe.report.report import format_table
from imupipe.vocab import ACCEL_AXES, GYRO_AXES

TIMELINE = "sensor_time"
SIGNAL_GROUPS: dict[str, tuple[str, ...]] = {
    "gyro": GYRO_AXES,
    "accel": ACCEL_AXES,
    "housekeeping": ("temp_c", "supply_v"),
}
"""One entity per group: its columns are sent as one batch of scalars per row, so a group shares
one time column and one row-id column (the dominant cost of a 4.32 M-row chunk)."""
SIGNAL_UNITS = {"gyro_": "rad/s", "accel_": "m/s²", "temp_c": "°C", "supply_v": "V"}
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
Z_SCALE = 0.25
"""Scene units per unit of z in the residual views (keeps ±3 comparable to a few decades)."""


def _color(name: str) -> tuple[int, int, int]:
    return COLORS.get(name[-1], (200, 200, 200))


def signal_columns(frames: pl.DataFrame) -> dict[str, list[str]]:
    """The signal columns present in ``frames`` with at least one value, by group (ROS bags may
    lack temperature and supply, or carry them as nulls)."""
    present = {
        group: [c for c in cols if c in frames.columns and frames[c].null_count() < frames.height]
        for group, cols in SIGNAL_GROUPS.items()
    }
    return {group: cols for group, cols in present.items() if cols}


def _label(column: str) -> str:
    unit = next(u for prefix, u in SIGNAL_UNITS.items() if column.startswith(prefix))
    return f"{column} [{unit}]"


def _send_signals(rec: rr.RecordingStream, frames: pl.DataFrame) -> None:
    """Bulk-send each signal group in chunks of :data:`CHUNK_ROWS` rows (one scalar per column
    of the group, nulls as NaN so the plot shows gaps), flushing after each chunk so that Rerun's
    encoding buffers stay small (measured: +1.2 GB for 12 h sent whole, +0.06 GB in chunks);
    the time column is converted chunk by chunk too."""
    t_s = frames["t_s"].to_numpy()
    for group, columns in signal_columns(frames).items():
        path = f"signals/{group}"
        for start in range(0, frames.height, CHUNK_ROWS):
            part = frames.slice(start, CHUNK_ROWS).select(
                pl.col(columns).cast(pl.Float64).fill_null(np.nan)
            )
            t_ns = np.round(t_s[start : start + CHUNK_ROWS] * 1e9).astype("timedelta64[ns]")
            rec.send_columns(
                path,
                indexes=[rr.TimeColumn(TIMELINE, duration=t_ns)],
                columns=rr.Scalars.columns(scalars=part.to_numpy()),
            )
            rec.flush()
        style = rr.SeriesLines(
            names=[_label(c) for c in columns], colors=[_color(c) for c in columns], widths=1.0
        )
        rec.log(path, style, static=True)


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


def _decade_grid(
    rec: rr.RecordingStream, path: str, x: np.ndarray, y: np.ndarray, x_unit: str, y_unit: str
) -> None:
    """Decade grid lines with labels spanning the finite range of log10 x and log10 y."""
    x0, x1 = np.floor(np.nanmin(x)), np.ceil(np.nanmax(x))
    y0, y1 = np.floor(np.nanmin(y)), np.ceil(np.nanmax(y))
    xs, ys = np.arange(x0, x1 + 1), np.arange(y0, y1 + 1)
    strips = [[(v, -y0), (v, -y1)] for v in xs] + [[(x0, -v), (x1, -v)] for v in ys]
    rec.log(
        f"{path}/grid",
        rr.LineStrips2D(strips, colors=GRID_COLOR, radii=rr.Radius.ui_points(0.5), draw_order=0),
        static=True,
    )
    positions = [(v, -y0 + 0.15) for v in xs] + [(x0 - 0.1, -v) for v in ys]
    labels = [f"τ=1e{int(v)} {x_unit}" for v in xs] + [f"1e{int(v)} {y_unit}" for v in ys]
    rec.log(
        f"{path}/grid_labels",
        rr.Points2D(positions, labels=labels, radii=rr.Radius.ui_points(0.1), colors=GRID_COLOR),
        static=True,
    )


def _log_allan(rec: rr.RecordingStream, sensor: str, axes: list[AxisResult]) -> None:
    path = f"allan/{sensor}"
    xs, ys = [], []
    for axis in axes:
        c, color = axis.curve, _color(axis.name)
        x = _log10(c.tau_s)
        y, lo, hi = _log10(c.adev), _log10(c.adev_lo), _log10(c.adev_hi)
        xs.append(x)
        ys.append(y)
        base = f"{path}/{axis.name}"
        rec.log(
            f"{base}/adev",
            rr.LineStrips2D(
                [_strip(x, y)],
                colors=color,
                radii=rr.Radius.ui_points(1.5),
                labels=axis.name,
                draw_order=3,
            ),
            static=True,
        )
        ok = np.isfinite(x) & np.isfinite(lo) & np.isfinite(hi)
        bars = np.stack([np.column_stack([x, -lo]), np.column_stack([x, -hi])], axis=1)[ok]
        rec.log(
            f"{base}/interval",
            rr.LineStrips2D(bars, colors=color, radii=rr.Radius.ui_points(1.0), draw_order=2),
            static=True,
        )
        models = {"model": _model_adev(axis)}
        if axis.loop is not None:
            after = _log10(axis.loop.adev_after)
            rec.log(
                f"{base}/adev_after",
                rr.Points2D(
                    _strip(x, after), colors=color, radii=rr.Radius.ui_points(3.0), draw_order=3
                ),
                static=True,
            )
            models = {
                "model_before": np.asarray(axis.loop.model_adev_before, float),
                "model_after": np.asarray(axis.loop.model_adev_after, float),
            }
        for name, model in models.items():
            shade = tuple(int(0.55 * v + 0.45 * 255) for v in color)
            rec.log(
                f"{base}/{name}",
                rr.LineStrips2D(
                    [_strip(x, _log10(model))],
                    colors=color if name == "model_after" else shade,
                    radii=rr.Radius.ui_points(1.0 if name == "model_before" else 2.5),
                    labels=f"{axis.name} {name.replace('_', ' ')}",
                    draw_order=1,
                ),
                static=True,
            )
    _decade_grid(rec, path, np.concatenate(xs), np.concatenate(ys), "s", axes[0].unit)


def _log_residuals(rec: rr.RecordingStream, sensor: str, axes: list[AxisResult]) -> None:
    path = f"residual/{sensor}"
    xs = []
    for axis in axes:
        x = _log10(axis.curve.tau_s)
        xs.append(x)
        for name, z in (("z_before", axis.loop.z_before), ("z_after", axis.loop.z_after)):
            color = _color(axis.name)
            rec.log(
                f"{path}/{axis.name}/{name}",
                rr.LineStrips2D(
                    [_strip(x, Z_SCALE * np.asarray(z, float))],
                    colors=color if name == "z_after" else tuple(v // 2 + 64 for v in color),
                    radii=rr.Radius.ui_points(2.0 if name == "z_after" else 1.0),
                    labels=f"{axis.name} {name}",
                ),
                static=True,
            )
    x = np.concatenate(xs)
    x0, x1 = np.floor(np.nanmin(x)), np.ceil(np.nanmax(x))
    levels = (-3.0, 0.0, 3.0)
    rec.log(
        f"{path}/levels",
        rr.LineStrips2D(
            [[(x0, -Z_SCALE * z), (x1, -Z_SCALE * z)] for z in levels],
            colors=GRID_COLOR,
            radii=rr.Radius.ui_points(0.5),
            labels=[f"z = {z:+g}" for z in levels],
        ),
        static=True,
    )


def blueprint(result: AnalysisResult, signal_groups: list[str]) -> rrb.Blueprint:
    """Signals on the left (one time-series view per group), Allan and residual views on the
    right, the summary table below them."""
    signals = [rrb.TimeSeriesView(origin=f"signals/{g}", name=g) for g in signal_groups]
    sensors = [s for s in ("gyro", "accel") if result.by_sensor(s)]
    allan = [
        rrb.Spatial2DView(origin=f"allan/{s}", name=f"{s}: log10 Allan deviation vs log10 τ")
        for s in sensors
    ]
    residual = [
        rrb.Spatial2DView(origin=f"residual/{s}", name=f"{s}: normalised residual z vs log10 τ")
        for s in sensors
        if any(a.loop is not None for a in result.by_sensor(s))
    ]
    right = rrb.Vertical(
        rrb.Tabs(*allan, *residual, name="Allan deviation"),
        rrb.TextDocumentView(origin="summary", name="Noise terms vs the paper"),
        row_shares=[3, 2],
    )
    left = rrb.Vertical(*signals, name="Raw signals") if signals else None
    layout = rrb.Horizontal(left, right) if left is not None else right
    return rrb.Blueprint(layout, collapse_panels=True, auto_views=False)


class RrdWriter:
    """Writes ``recording.rrd`` in two steps, so that the costly part overlaps the analysis.

    Construction opens the file and starts a thread that bulk-sends the raw ``frames`` (columns
    ``t_s`` and any of gyro_x..z rad/s, accel_x..z m/s², temp_c °C, supply_v V); Rerun encodes
    and writes them on its own threads.  :meth:`finish` adds the Allan views, residuals,
    summary and blueprint once the analysis is done, and flushes.
    """

    def __init__(self, path: Path, frames: pl.DataFrame) -> None:
        self.path = Path(path)
        self.groups = list(signal_columns(frames))
        self._rec = rr.RecordingStream("imupipe", make_default=False, make_thread_default=False)
        self._rec.save(self.path)
        self._sender = threading.Thread(
            target=_send_signals, args=(self._rec, frames), name="rrd-signals", daemon=True
        )
        self._sender.start()

    def finish(self, result: AnalysisResult) -> Path:
        """Log the analysis results and the blueprint, flush and close; returns the path."""
        rec = self._rec
        for sensor in ("gyro", "accel"):
            axes = result.by_sensor(sensor)
            if axes:
                _log_allan(rec, sensor, axes)
            looped = [a for a in axes if a.loop is not None]
            if looped:
                _log_residuals(rec, sensor, looped)
        text = format_table(result)
        rec.log(
            "summary", rr.TextDocument(f"```\n{text}\n```", media_type="text/markdown"), static=True
        )
        self._sender.join()
        rec.send_blueprint(blueprint(result, self.groups), make_active=True, make_default=True)
        rec.flush()
        rec.disconnect()
        return self.path

    def discard(self) -> None:
        """Stop after a failed analysis: wait for the sender, close, and delete the file."""
        self._sender.join()
        self._rec.disconnect()
        self.path.unlink(missing_ok=True)


def write_rrd(result: AnalysisResult, frames: pl.DataFrame, path: Path) -> Path:
    """Write the Rerun recording of ``result`` and the raw ``frames`` to ``path`` in one go."""
    return RrdWriter(path, frames).finish(result)


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
