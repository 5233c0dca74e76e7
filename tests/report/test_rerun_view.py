"""The Rerun recording: bulk signals, log-log Allan view, blueprint; `rerun rrd verify` passes.

The blueprint is checked through rerun's blueprint API (the view objects' properties), the
recording's order and row counts through `rerun rrd print`, the views' labels through the
archetypes logged (a recording stand-in that keeps them)."""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import rerun.blueprint as rrb

import imupipe.report.rerun_view as rv
from imupipe.analysis.events import DisturbanceEvent, EventDetector, EventsFound
from imupipe.errors import ViewerError
from imupipe.fleet.curves import UNIT_COLUMN
from imupipe.report.rerun_view import open_viewer, rerun_executable, signal_columns, write_rrd
from imupipe.units import from_si


def _verify(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [rerun_executable(), "rrd", "verify", str(path)], capture_output=True, text=True
    )


def test_rrd_verifies_and_holds_every_signal(
    tmp_path: Path, synthetic_result, rrd_chunks, signal_frames
) -> None:
    frames = signal_frames(20_000)
    path = write_rrd(synthetic_result(), frames, tmp_path / "recording.rrd")
    done = _verify(path)
    assert done.returncode == 0, done.stdout + done.stderr
    chunks = rrd_chunks.rows(path)
    for group in ("gyro", "accel", "temperature", "supply"):
        assert chunks[f"/signals/{group}"] == 20_000  # every raw frame
    for axis in ("gyro_x", "gyro_y", "gyro_z", "accel_y", "accel_z"):
        sensor = axis.split("_")[0]
        for part in ("adev", "interval", "model"):
            assert f"/allan/{sensor}/{axis}/{part}" in chunks
    for part in ("adev", "interval", "model_before", "model_after"):
        assert f"/allan/accel/accel_x/{part}" in chunks
    assert {"/allan/gyro/grid", "/allan/gyro/grid_labels", "/summary"} <= set(chunks)
    assert {"/allan/gyro/legend/0/label", "/residual/accel/legend/0/sample"} <= set(chunks)
    assert {"/residual/accel/accel_x/z_before", "/residual/accel/accel_x/z_after"} <= set(chunks)
    assert not any(p.startswith("/residual/gyro") for p in chunks)  # no loop on the gyros


def test_ros_frames_without_temperature_or_supply(
    tmp_path: Path, synthetic_result, signal_frames
) -> None:
    frames = signal_frames(5_000, ros=True)
    assert list(signal_columns(frames)) == ["gyro", "accel"]  # no temperature, no supply plot
    path = write_rrd(synthetic_result(with_loop=False), frames, tmp_path / "ros.rrd")
    done = _verify(path)
    assert done.returncode == 0, done.stdout + done.stderr


def test_full_signals_go_in_bulk_chunks(
    tmp_path: Path, synthetic_result, rrd_chunks, signal_frames
) -> None:
    """--rrd-full sends 250 k frames per plot in CHUNK_ROWS-row batches, never per sample (the
    whole analyze wall time, rrd included, is reported by benchmarks/bench_decode.py --analyze)."""
    frames = signal_frames(250_000)
    path = write_rrd(synthetic_result(), frames, tmp_path / "big.rrd", full=True)
    for plot in ("gyro", "accel", "temperature", "supply"):
        rows = [
            r for e, r, c in rrd_chunks.lines(path) if e == f"/signals/{plot}" and "Scalars" in c
        ]
        assert sum(rows) == 250_000 and len(rows) <= -(-250_000 // rv.CHUNK_ROWS)


def test_open_viewer_refuses_a_folder_without_recording(tmp_path: Path) -> None:
    with pytest.raises(ViewerError, match="no Rerun recording"):
        open_viewer(tmp_path)


def _prop(view: rrb.View, archetype: str, field: str) -> list:
    """A blueprint property of a view as Python values, e.g. ('PlotLegend', 'visible')."""
    return getattr(view.properties[archetype], field).as_arrow_array().to_pylist()


def _views(container) -> list[rrb.View]:
    """Every view under a blueprint container, depth first."""
    if isinstance(container, rrb.View):
        return [container]
    return [v for c in container.contents for v in _views(c)]


def test_blueprint_shows_the_whole_recording_one_quantity_per_plot_with_legends(
    synthetic_result,
) -> None:
    bp = rv.blueprint(synthetic_result(), ["gyro", "accel", "temperature", "supply"], bin_s=0.43)
    views = _views(bp.root_container)
    plots = [v for v in views if isinstance(v, rrb.TimeSeriesView)]
    assert [v.origin for v in plots] == [
        "signals/gyro",
        "signals/accel",
        "signals/temperature",  # temperature and supply each on their own scale
        "signals/supply",
    ]
    whole = {"start": None, "end": None}  # both boundaries 'Infinite'
    for view in plots:
        assert _prop(view, "VisibleTimeRanges", "ranges") == [
            {"timeline": rv.TIMELINE, "range": whole}
        ]
        assert _prop(view, "TimeAxis", "view_range") == [whole]
        assert view.properties["TimeAxis"].link is None  # a linked axis shows the global ±30 s
        assert _prop(view, "PlotLegend", "visible") == [True]
    units = {p.entity: p.unit for p in rv.SIGNAL_PLOTS}
    assert [units[v.origin] for v in plots] == ["rad/s", "m/s²", "°C", "V"]
    assert "gyro, mean removed [rad/s] · min/max per 0.43 s" in [v.name for v in plots]
    allan = [v for v in views if isinstance(v, rrb.Spatial2DView)]
    assert [v.origin for v in allan] == ["allan/gyro", "allan/accel", "residual/accel"]
    ext = rv.allan_extent(synthetic_result().by_sensor("gyro"))
    bounds = _prop(allan[0], "VisualBounds2D", "range")[0]
    assert bounds["x_range"][0] < ext.x0 and bounds["x_range"][1] >= ext.x1 + rv.LEGEND_WIDTH
    assert bounds["y_range"][0] < ext.top and bounds["y_range"][1] > ext.bottom
    text = [v for v in views if isinstance(v, rrb.TextDocumentView)]
    assert [v.origin for v in text] == ["summary"]
    tabs = [v.name for v in allan]  # 4 tabs of <= 21 characters fit a 960 px column untruncated
    assert tabs == ["gyro Allan deviation", "accel Allan deviation", "accel loop residual z"]


class _KeepLogs:
    """Stands in for a RecordingStream: keeps what is logged, by entity path."""

    def __init__(self) -> None:
        self.logged: dict[str, object] = {}
        self.static: dict[str, bool] = {}

    def log(self, path: str, archetype: object, static: bool = False) -> None:
        self.logged[path] = archetype
        self.static[path] = static


def _labels(archetype: object) -> list[str]:
    return archetype.labels.as_arrow_array().to_pylist()


def test_allan_and_residual_views_label_tau_and_carry_a_legend(synthetic_result) -> None:
    result = synthetic_result()
    rec = _KeepLogs()
    rv._log_allan(rec, "accel", result.by_sensor("accel"))
    rv._log_residuals(rec, "accel", [result.axes["accel_x"]])
    ext = rv.allan_extent(result.by_sensor("accel"))
    taus = [f"τ = 1e{int(v)} s" for v in np.arange(ext.x0, ext.x1 + 1)]
    allan = _labels(rec.logged["allan/accel/grid_labels"])
    assert allan[: len(taus)] == taus
    assert "1e-3 m/s²" in allan  # sigma decades in SI
    residual = _labels(rec.logged["residual/accel/grid_labels"])
    assert residual == [*taus, "z = +3", "z = 0", "z = −3"]
    legend = [
        _labels(a)[0]
        for p, a in rec.logged.items()
        if p.startswith("allan/accel/legend/") and p.endswith("/label")
    ]
    assert legend == [
        "accel_x",
        "accel_y",
        "accel_z",
        "measured, bars: 95 %",
        "model before loop",
        "model after loop",
        "after loop corrections",
    ]
    curves = [p for p, a in rec.logged.items() if p.startswith("allan/accel/accel_")]
    assert curves and not any(rec.logged[p].labels for p in curves)  # no labels on the curves


def test_summary_states_si_beside_the_paper_units(synthetic_result) -> None:
    result = synthetic_result()
    md = rv.summary_markdown(result)
    n = result.axes["gyro_x"].terms.random_walk
    row = next(line for line in md.splitlines() if line.startswith("| Random walk N | gyro_x"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[2].startswith(f"{n.value:.4g} [")
    assert cells[3] == "rad/s/√Hz"
    assert cells[4].startswith(f"{from_si(n.value, '°/√s'):.4g} [")
    # the paper's value, and the datasheet's 2 °/√h in the paper's unit
    assert cells[5:] == ["0.05", "0.03333", "°/√s"]
    assert "## Closed loop (before → after)" in md and "`run.mcap`" in md


def test_layout_and_names_come_before_the_data_and_long_runs_are_enveloped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, synthetic_result, rrd_chunks, signal_frames
) -> None:
    monkeypatch.setattr(rv, "ENVELOPE_BINS", 1_000)
    frames = signal_frames(20_000)
    path = write_rrd(synthetic_result(), frames, tmp_path / "small.rrd")
    chunks = rrd_chunks.lines(path)
    first_data = next(i for i, c in enumerate(chunks) if "Scalars:scalars" in c[2])
    before = {(e, "SeriesLines:names" in cols) for e, _, cols in chunks[:first_data]}
    assert ("/viewport", False) in before
    assert {(f"/signals/{g}", True) for g in ("gyro", "accel", "temperature", "supply")} <= before
    assert (
        rrd_chunks.rows(path)["/signals/accel"] == 2_000
    )  # min and max of 1000 bins of 20 samples
    full = write_rrd(synthetic_result(), frames, tmp_path / "full.rrd", full=True)
    assert rrd_chunks.rows(full)["/signals/accel"] == 20_000
    assert path.stat().st_size < full.stat().st_size / 3


@pytest.mark.parametrize(("flags", "rows"), [((), 2_000), (("--rrd-full",), 6_000)])
def test_analyze_writes_an_envelope_unless_rrd_full(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    flags: tuple[str, ...],
    rows: int,
    rrd_chunks,
    small_recordings,
) -> None:
    """`imupipe analyze` (in process) on 6000 frames with 1000-bin envelopes."""
    from imupipe.cli import app

    monkeypatch.setattr(rv, "ENVELOPE_BINS", 1_000)
    run = small_recordings.recording(tmp_path / "run.mcap", 100.0, 6000, seed=2)
    out = tmp_path / "out"
    args = ["analyze", str(run), "--no-loop", "-q", "--out", str(out), *flags]
    assert app(args, standalone_mode=False) in (None, 0)
    chunks = rrd_chunks.rows(out / "recording.rrd")
    assert {chunks[f"/signals/{g}"] for g in ("gyro", "accel", "temperature", "supply")} == {rows}


def test_fleet_view_names_units_by_path_and_labels_the_band_where_it_is_widest() -> None:
    """fleet.rrd: a unit's label drawn at its curve's middle piled up over the median's."""
    from imupipe.analysis.results import ALLAN_SCHEMA
    from imupipe.fleet import rerun_view as fleet_view
    from imupipe.fleet.curves import fleet_frame, population_curves

    tau = np.geomspace(0.01, 1000.0, 11)
    curve = pl.DataFrame(
        {"axis": "gyro_x", "unit": "rad/s", "tau": tau, "adev": 1e-3 / np.sqrt(tau),
         "lo": np.nan, "hi": np.nan, "edf": 1.0, "terms": 1, "alpha": 0.0, "adev_after": np.nan,
         "model_before": np.nan, "model_after": np.nan, "z_before": np.nan, "z_after": np.nan},
        schema=ALLAN_SCHEMA,
    )  # fmt: skip
    fleet = fleet_frame(
        {f"u{k}": curve.with_columns(pl.col("adev") * (1 + k / 10)) for k in range(5)}
    )
    pop = population_curves(fleet)
    rec = _KeepLogs()
    fleet_view._log_axis(rec, "gyro_x", fleet, pop)
    units = [p for p in rec.logged if p.startswith("allan/gyro_x/units/")]
    assert units == [f"allan/gyro_x/units/u{k}" for k in range(5)]
    assert not any(rec.logged[p].labels for p in units)
    labels = {p: _labels(a)[0] for p, a in rec.logged.items() if p.endswith("/label")}
    assert labels == {
        "allan/gyro_x/population/median/label": "population median",
        "allan/gyro_x/population/lo/label": "2.5 % of units below",
        "allan/gyro_x/population/hi/label": "2.5 % of units above",
    }
    at = rec.logged["allan/gyro_x/population/hi/label"].positions.as_arrow_array().to_pylist()
    assert at[0] == pytest.approx([3.0, -np.log10(pop["hi"][-1])])  # log10 τ = 3, y down


def _fleet(axes: dict[str, tuple[str, float]]) -> tuple[pl.DataFrame, pl.DataFrame]:
    """Five units' curves on each axis (``{axis: (unit, ADEV at 1 s)}``), and their population."""
    from imupipe.analysis.results import ALLAN_SCHEMA
    from imupipe.fleet.curves import fleet_frame, population_curves

    tau = np.geomspace(0.01, 1000.0, 11)
    curves: dict[str, list[pl.DataFrame]] = {f"u{k}": [] for k in range(5)}
    for axis, (unit, a1) in axes.items():
        curve = pl.DataFrame(
            {"axis": axis, "unit": unit, "tau": tau, "adev": a1 / np.sqrt(tau),
             "lo": np.nan, "hi": np.nan, "edf": 1.0, "terms": 1, "alpha": 0.0,
             "adev_after": np.nan, "model_before": np.nan, "model_after": np.nan,
             "z_before": np.nan, "z_after": np.nan},
            schema=ALLAN_SCHEMA,
        )  # fmt: skip
        for k, parts in enumerate(curves.values()):
            parts.append(curve.with_columns(pl.col("adev") * (1 + k / 10)))
    fleet = fleet_frame({name: pl.concat(parts) for name, parts in curves.items()})
    return fleet, population_curves(fleet)


def test_fleet_rrd_has_a_tab_per_axis_holding_only_that_axis_units_and_population(
    tmp_path: Path, monkeypatch
) -> None:
    """fleet.rrd of units measured on gyro_x and accel_x: one tab per axis in report order, the
    viewer's panels collapsed and no view of its own guessing; each axis' view draws that axis'
    five unit curves, its population lines and a σ grid in its unit, all static (shown wherever
    the time cursor is).  An axis' view drawing the other axis' units or population, or none,
    passed the one-axis test."""
    from imupipe.fleet import rerun_view as fleet_view

    rec, sent = _KeepLogs(), []
    rec.save = rec.flush = rec.disconnect = lambda *a: None
    monkeypatch.setattr(fleet_view, "open_stream", lambda app: rec)
    monkeypatch.setattr(fleet_view, "send_blueprint", lambda r, bp: sent.append(bp))
    fleet, pop = _fleet({"accel_x": ("m/s²", 1e-4), "gyro_x": ("rad/s", 1e-3)})
    path = tmp_path / "fleet.rrd"
    assert fleet_view.write_fleet_rrd(fleet, pop, path) == path
    ((bp,),) = [sent]
    assert (bp.collapse_panels, bp.auto_views) == (True, False)
    views = _views(bp.root_container)
    assert [(v.origin, v.name) for v in views] == [
        (f"allan/{a}", f"{a}: log10 ADEV vs log10 τ") for a in ("gyro_x", "accel_x")
    ]
    for axis, unit in (("gyro_x", "rad/s"), ("accel_x", "m/s²")):
        base = f"allan/{axis}"
        units = sorted(p for p in rec.logged if p.startswith(f"{base}/units/"))
        assert units == [f"{base}/units/u{k}" for k in range(5)]
        for k in range(5):
            mine = fleet.filter((pl.col("axis") == axis) & (pl.col(UNIT_COLUMN) == f"u{k}"))
            expected = np.column_stack([np.log10(mine["tau"]), -np.log10(mine["adev"])])
            np.testing.assert_allclose(_points(rec.logged[f"{base}/units/u{k}"]), expected)
        own = pop.filter(pl.col("axis") == axis)
        for name in ("median", "lo", "hi"):
            expected = np.column_stack([np.log10(own["tau"]), -np.log10(own[name])])
            np.testing.assert_allclose(_points(rec.logged[f"{base}/population/{name}"]), expected)
        assert f"1e-3 {unit}" in _labels(rec.logged[f"{base}/grid_labels"])
    assert all(rec.static.values()) and len(rec.static) == 2 * (5 + 3 + 3 + 2)


def test_fleet_view_draws_thin_grey_units_under_the_blue_band_and_median() -> None:
    """The units thin and grey, under the population: the band's edges light blue, both as
    wide, under the wider median in the report's blue (tab:blue); each label's dot in its
    line's colour and width, drawn over everything."""
    from imupipe.fleet import rerun_view as fleet_view

    fleet, pop = _fleet({"gyro_x": ("rad/s", 1e-3)})
    rec = _KeepLogs()
    fleet_view._log_axis(rec, "gyro_x", fleet, pop)

    def rgb(path: str) -> tuple[int, int, int]:
        (c,) = set(rec.logged[path].colors.as_arrow_array().to_pylist())
        return c >> 24, (c >> 16) & 255, (c >> 8) & 255

    def width(path: str) -> float:  # UI points (stored negative: rerun's convention)
        return abs(rec.logged[path].radii.as_arrow_array().to_pylist()[0])

    def order(path: str) -> float:
        return rec.logged[path].draw_order.as_arrow_array().to_pylist()[0]

    units = [p for p in rec.logged if p.startswith("allan/gyro_x/units/")]
    lines = [f"allan/gyro_x/population/{n}" for n in ("median", "lo", "hi")]
    assert {rgb(p) for p in units} == {(150, 150, 150)}
    assert [rgb(p) for p in lines] == [(31, 119, 180), (120, 170, 210), (120, 170, 210)]
    assert {width(p) for p in units} == {1.0}
    assert [width(p) for p in lines] == [2.5, 1.5, 1.5]
    for line in lines:
        assert (rgb(f"{line}/label"), width(f"{line}/label")) == (rgb(line), width(line))
    assert {order(p) for p in units} == {1}
    assert {order(p) for p in lines} == {2}
    assert {order(f"{p}/label") for p in lines} == {3}


def _with_events(result, spans: list[tuple[int, int] | None], tau0: float, t0: float):
    """``result`` with disturbance events excised over sample ``spans`` (None: a step, kept)."""
    events = tuple(
        DisturbanceEvent(
            (a or 0) * tau0,
            1.0,
            ("gyro_x",),
            {},
            {},
            {},
            "transient" if a is not None else "step",
            None if a is None else (a, b),
            0.5,
        )
        for a, b in (s or (None, None) for s in spans)
    )
    detector = EventDetector(0.5, (0.5,), (100,), (6.0,), (4.5,), ("gyro_x",), ((),))
    return replace(result, events=EventsFound(detector, events, tau0, t0))


def test_excised_events_are_red_bars_below_the_signals_on_the_recording_timeline(
    tmp_path: Path, synthetic_result, rrd_chunks, signal_frames
) -> None:
    """Two excised events (and a kept step, not drawn) on a segment starting 3 s into the
    recording: each a bar from its first to its last excised sample's time, below the lowest
    value the gyro and accel plots draw, a NaN after it; not on temperature or supply."""
    frames = signal_frames(20_000)
    result = _with_events(synthetic_result(), [(1_000, 1_500), None, (6_000, 6_200)], 0.01, 3.0)
    sent: dict[str, tuple] = {}

    class Keep:
        def log(self, path, archetype, static=False):
            sent.setdefault(path, [None, None])[0] = archetype

        def send_columns(self, path, indexes, columns):
            sent.setdefault(path, [None, None])[1] = (indexes, columns)

    columns = signal_columns(frames)
    floors = rv._floors(frames, columns, rv._means(frames, columns))
    low = min(frames[c].min() - frames[c].mean() for c in ("gyro_x", "gyro_y", "gyro_z"))
    high = max(frames[c].max() - frames[c].mean() for c in ("gyro_x", "gyro_y", "gyro_z"))
    assert floors["gyro"] == pytest.approx(low - 0.05 * (high - low), rel=1e-9)
    assert set(floors) == {"gyro", "accel"}
    rv._log_events(Keep(), result, floors)
    assert set(sent) == {"signals/gyro/excised", "signals/accel/excised"}
    style, (indexes, cols) = sent["signals/gyro/excised"]
    assert style.names.as_arrow_array().to_pylist() == [rv.EXCISED_NAME]
    times = indexes[0].as_arrow_array().to_numpy().astype("int64") / 1e9
    np.testing.assert_allclose(times, [13.0, 18.0, 18.0, 63.0, 65.0, 65.0])
    (column,) = cols
    values = np.asarray(column.as_arrow_array().to_pylist()).ravel()
    np.testing.assert_array_equal(np.isnan(values), [False, False, True] * 2)
    assert values[0] == values[4] == floors["gyro"]
    path = write_rrd(result, frames, tmp_path / "events.rrd")
    assert _verify(path).returncode == 0
    assert rrd_chunks.rows(path)["/signals/accel/excised"] == 6
    plain = write_rrd(synthetic_result(), frames, tmp_path / "none.rrd")  # no events: no bars
    assert not any("excised" in e for e in rrd_chunks.rows(plain))


def test_the_sigma_axis_is_labelled_by_the_decades_the_curves_span_highest_first(
    synthetic_result,
) -> None:
    rec = _KeepLogs()
    rv._log_allan(rec, "accel", synthetic_result().by_sensor("accel"))
    grid = rec.logged["allan/accel/grid_labels"]
    labels, positions = _labels(grid), grid.positions.as_arrow_array().to_pylist()
    sigma = [
        (label, y) for label, (_, y) in zip(labels, positions, strict=True) if "τ" not in label
    ]
    # the scene's y is −log10 σ: 1e-1 at the top (y = 1), 1e-4 at the bottom (y = 4)
    assert sigma == [("1e-1 m/s²", 1.0), ("1e-2 m/s²", 2.0), ("1e-3 m/s²", 3.0), ("1e-4 m/s²", 4.0)]


def test_residual_z_is_drawn_upwards_when_positive_and_clipped_at_the_views_limit(
    synthetic_result,
) -> None:
    axis = synthetic_result().axes["accel_x"]
    z = np.where(np.arange(len(axis.curve.tau_s)) % 2 == 0, 2.0, -2.0)
    z[10] = 50.0  # beyond Z_LIMIT: drawn at the view's edge
    axis = replace(axis, loop=replace(axis.loop, after=replace(axis.loop.after, z=z)))
    ext = rv.residual_extent([axis])
    assert (ext.top, ext.bottom) == pytest.approx((-3.0, 3.0))  # ±10 at 0.3 scene units each
    rec = _KeepLogs()
    rv._log_residuals(rec, "accel", [axis])
    (strip,) = rec.logged["residual/accel/accel_x/z_after"].strips.as_arrow_array().to_pylist()
    ys = np.array([y for _, y in strip])
    assert len(ys) == len(z) - 1  # τ = 4320 s lies beyond the fit's range: not drawn
    np.testing.assert_allclose(ys[:4], [-0.6, 0.6, -0.6, 0.6])  # the scene's y points down
    assert ys[10] == pytest.approx(-3.0)


def test_signals_are_sent_at_their_own_times_and_enveloped_beyond_two_frames_a_bin(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, signal_frames
) -> None:
    import pyarrow as pa

    monkeypatch.setattr(rv, "ENVELOPE_BINS", 1_000)
    sent: list[tuple[str, list[int]]] = []

    class Sender:
        def send_columns(self, entity, indexes, columns) -> None:
            sent.append((entity, indexes[0].as_arrow_array().cast(pa.int64()).to_pylist()))

        def flush(self) -> None:
            pass

    frames = signal_frames(2_000)
    columns = rv.signal_columns(frames)
    rv._send_signals(Sender(), frames, columns, dict.fromkeys(frames.columns, 0.0), True)
    expected = np.round(frames["t_s"].to_numpy() * 1e9).astype(np.int64).tolist()
    assert sent and all(times == expected for _, times in sent)
    whole = rv.RrdWriter(tmp_path / "whole.rrd", frames)
    enveloped = rv.RrdWriter(tmp_path / "enveloped.rrd", signal_frames(2_001))
    step = float(frames["t_s"][1] - frames["t_s"][0])
    assert whole.bin_s is None  # 2 frames a bin at most: sent whole
    assert enveloped.bin_s == pytest.approx(3 * step)  # ceil(2001 / 1000) frames a bin
    whole.discard()
    enveloped.discard()


def _points(archetype: object) -> list[list[float]]:
    """Every (x, y) an archetype draws: a Points2D's positions or a LineStrips2D's vertices."""
    if hasattr(archetype, "positions") and archetype.positions is not None:
        return archetype.positions.as_arrow_array().to_pylist()
    return [p for strip in archetype.strips.as_arrow_array().to_pylist() for p in strip]


def test_the_allan_views_labels_and_legend_lie_in_its_bounds_around_the_grid(
    synthetic_result,
) -> None:
    """τ labels below the grid, σ labels left of it, the legend right of it, all inside the
    view's bounds (what the blueprint zooms the view to)."""
    axes = synthetic_result().by_sensor("accel")
    rec = _KeepLogs()
    rv._log_allan(rec, "accel", axes)
    ext = rv.allan_extent(axes)
    ((bounds,),) = [ext.bounds().range.as_arrow_array().to_pylist()]
    assert bounds == {
        "x_range": [ext.x0 - 1.1, ext.x1 + rv.LEGEND_WIDTH],
        "y_range": [ext.top - 0.3, ext.bottom + 0.5],
    }
    grid = rec.logged["allan/accel/grid_labels"]
    for label, (x, y) in zip(_labels(grid), _points(grid), strict=True):
        if label.startswith("τ"):
            assert ext.bottom < y < bounds["y_range"][1] and ext.x0 <= x <= ext.x1
        else:
            assert bounds["x_range"][0] < x < ext.x0 and ext.top <= y <= ext.bottom
    legend = [(p, a) for p, a in rec.logged.items() if p.startswith("allan/accel/legend/")]
    assert len(legend) == 2 * 7  # a sample and a label for each of the 7 entries
    for _, archetype in legend:
        for x, y in _points(archetype):
            assert ext.x1 < x < bounds["x_range"][1] and ext.top <= y <= ext.bottom
    centre = ext.x1 + rv.LEGEND_WIDTH / 2  # the labels centred over their samples
    dots = _points(rec.logged["allan/accel/legend/6/sample"])  # "after loop corrections"
    assert [x for x, _ in dots] == pytest.approx(np.linspace(centre - 1.0, centre + 1.0, 5))
    assert _points(rec.logged["allan/accel/legend/6/label"])[0][0] == pytest.approx(centre)


def test_the_model_before_the_loop_is_its_axis_colour_faded_halfway_to_white(
    synthetic_result,
) -> None:
    rec = _KeepLogs()
    rv._log_allan(rec, "accel", synthetic_result().by_sensor("accel"))
    before = rec.logged["allan/accel/accel_x/model_before"].colors.as_arrow_array().to_pylist()
    after = rec.logged["allan/accel/accel_x/model_after"].colors.as_arrow_array().to_pylist()
    rgba = [(c >> 24, (c >> 16) & 255, (c >> 8) & 255) for c in before + after]
    assert rgba == [(143, 187, 217), (31, 119, 180)]  # tab:blue, and halfway to white


def test_interval_bars_span_each_finite_interval_and_legend_samples_match_their_curves(
    synthetic_result,
) -> None:
    """A bar per τ whose interval is finite, from the lower to the upper end (−log10 σ in the
    scene); each legend sample is drawn as wide as the curves it names; the views hold no
    time (static: shown wherever the time cursor is)."""
    axes = synthetic_result().by_sensor("accel")
    curve = axes[0].curve
    lo, hi = np.array(curve.adev_lo, float), np.array(curve.adev_hi, float)
    hi[3] = np.nan  # an interval without an upper end: no bar
    axes[0] = replace(axes[0], curve=replace(curve, adev_hi=hi))
    rec = _KeepLogs()
    rv._log_allan(rec, "accel", axes)
    bars = rec.logged["allan/accel/accel_x/interval"].strips.as_arrow_array().to_pylist()
    keep = np.flatnonzero(np.isfinite(np.log10(lo)) & np.isfinite(hi))
    assert 3 not in keep and len(bars) == len(keep) >= len(curve.tau_s) - 3
    for bar, k in zip(bars, keep, strict=True):
        x = np.log10(curve.tau_s[k])
        expected = [[x, -np.log10(lo[k])], [x, -np.log10(hi[k])]]
        np.testing.assert_allclose(bar, expected, rtol=1e-6)  # float32 in the recording

    def radius(path: str) -> float:
        return rec.logged[path].radii.as_arrow_array().to_pylist()[0]

    assert radius("allan/accel/legend/0/sample") == radius("allan/accel/accel_x/adev")
    assert radius("allan/accel/legend/4/sample") == radius("allan/accel/accel_x/model_before")
    assert radius("allan/accel/legend/5/sample") == radius("allan/accel/accel_x/model_after")
    assert all(rec.static.values()) and len(rec.static) > 20


def test_the_measured_curve_is_drawn_over_its_bars_over_the_models_over_a_thin_grid(
    synthetic_result,
) -> None:
    rec = _KeepLogs()
    rv._log_allan(rec, "accel", synthetic_result().by_sensor("accel"))
    base = "allan/accel/accel_x"

    def order(path: str) -> float:
        return rec.logged[path].draw_order.as_arrow_array().to_pylist()[0]

    def radius(path: str) -> float:  # UI points (stored negative: rerun's convention)
        return abs(rec.logged[path].radii.as_arrow_array().to_pylist()[0])

    assert order("allan/accel/grid") < order(f"{base}/model_after") < order(f"{base}/interval")
    assert order(f"{base}/interval") < order(f"{base}/adev")
    curves = ("adev", "interval", "model_before", "model_after")
    assert radius("allan/accel/grid") <= min(radius(f"{base}/{c}") for c in curves)
