"""``fleet.rrd``: every unit's Allan curves in Rerun (rerun-sdk 0.41).

One 2-D view per axis at (log10 τ, −log10 σ), the convention of
:mod:`imupipe.report.rerun_view` (Rerun has no log axes; 2-D views point y down): each unit's
curve under ``allan/<axis>/units/<unit>`` and the population median and 95 % band edges under
``allan/<axis>/population``, with labelled decade grid lines.  Rerun draws a strip's label at
its middle, where every unit's curve passes: the units' labels piled up there over the
median's, so a unit is named by its entity path (shown on hover and in the streams panel),
and the population's lines are labelled at their long-τ end, where the band is widest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import polars as pl
import rerun as rr
import rerun.blueprint as rrb

from imupipe.fleet.curves import UNIT_COLUMN
from imupipe.report.rerun_streams import open_stream, release_closed_streams, send_blueprint
from imupipe.report.rerun_view import _log10, _strip, decade_grid, log_extent
from imupipe.vocab import AXES

UNIT_COLOR = (150, 150, 150)
MEDIAN_COLOR = (31, 119, 180)
BAND_COLOR = (120, 170, 210)


def _log_axis(rec: rr.RecordingStream, axis: str, fleet: pl.DataFrame, pop: pl.DataFrame) -> None:
    base = f"allan/{axis}"
    xs, ys = [], []
    for (name,), unit in fleet.group_by(UNIT_COLUMN, maintain_order=True):
        x, y = _log10(unit["tau"].to_numpy()), _log10(unit["adev"].to_numpy())
        xs.append(x)
        ys.append(y)
        rec.log(
            f"{base}/units/{rr.escape_entity_path_part(str(name))}",
            rr.LineStrips2D(
                [_strip(x, y)],
                colors=UNIT_COLOR,
                radii=rr.Radius.ui_points(1.0),
                draw_order=1,
            ),
            static=True,
        )
    x = _log10(pop["tau"].to_numpy())
    for name, color, width, label in (
        ("median", MEDIAN_COLOR, 2.5, "population median"),
        ("lo", BAND_COLOR, 1.5, "2.5 % of units below"),
        ("hi", BAND_COLOR, 1.5, "2.5 % of units above"),
    ):
        strip = _strip(x, _log10(pop[name].to_numpy()))
        rec.log(
            f"{base}/population/{name}",
            rr.LineStrips2D([strip], colors=color, radii=rr.Radius.ui_points(width), draw_order=2),
            static=True,
        )  # labelled at its long-τ end, where the band is widest: at the middle they overlap
        rec.log(
            f"{base}/population/{name}/label",
            rr.Points2D(
                strip[-1:],
                colors=color,
                radii=rr.Radius.ui_points(width),
                labels=label,
                draw_order=3,
            ),
            static=True,
        )
    decade_grid(rec, base, log_extent(np.concatenate(xs), np.concatenate(ys)), fleet["unit"][0])


def write_fleet_rrd(fleet: pl.DataFrame, pop: pl.DataFrame, path: Path) -> Path | None:
    """Write ``fleet.rrd`` (module doc); None when no unit was analysed."""
    axes = [a for a in AXES if a in set(fleet["axis"].unique())]
    if not axes:
        return None
    rec = open_stream("imupipe_fleet")
    rec.save(path)
    for axis in axes:
        _log_axis(
            rec,
            axis,
            fleet.filter(pl.col("axis") == axis),
            pop.filter(pl.col("axis") == axis),
        )
    views = [
        rrb.Spatial2DView(origin=f"allan/{a}", name=f"{a}: log10 ADEV vs log10 τ") for a in axes
    ]
    send_blueprint(rec, rrb.Blueprint(rrb.Tabs(*views), collapse_panels=True, auto_views=False))
    rec.flush()
    rec.disconnect()
    del rec
    release_closed_streams()
    return path
