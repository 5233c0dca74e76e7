"""Every unit's Allan curves in one long frame (``fleet.parquet``) and the population's curve
per axis: the median and the 95 % band (2.5th–97.5th percentiles of the units) of the Allan
deviation at each τ.

Units of different lengths or rates have different τ grids, so each unit's curve is
interpolated linearly in (log τ, log σ) — where a power-law noise is a straight line — onto a
common grid of :data:`GRID_PER_DECADE` τ per decade, inside its own measured τ range only.
The population curve is given where at least half of the units have a value (the longest τ of
a few long recordings is not the population's).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import polars as pl

from imupipe.analysis.results import ALLAN_SCHEMA

UNIT_COLUMN = "unit_name"
FLEET_ALLAN_SCHEMA = pl.Schema({UNIT_COLUMN: pl.String, **ALLAN_SCHEMA})
"""The contract of ``fleet.parquet``: the fleet unit's name, then :data:`ALLAN_SCHEMA`."""

POPULATION_SCHEMA = pl.Schema(
    {
        "axis": pl.String,
        "unit": pl.String,
        "tau": pl.Float64,
        "median": pl.Float64,
        "lo": pl.Float64,
        "hi": pl.Float64,
        "units": pl.Int64,
    }
)
"""The population curve: τ (s), median and 95 % band of the units' ADEV (axis unit), and how
many units cover that τ."""

GRID_PER_DECADE = 10
BAND_PERCENTILES = (2.5, 97.5)


def fleet_frame(curves: Mapping[str, pl.DataFrame]) -> pl.DataFrame:
    """One long frame of every unit's Allan curves (:data:`FLEET_ALLAN_SCHEMA`)."""
    frames = [pl.DataFrame(schema=FLEET_ALLAN_SCHEMA)]
    frames += [
        df.select(pl.lit(name, dtype=pl.String).alias(UNIT_COLUMN), pl.all())
        for name, df in curves.items()
    ]
    return pl.concat(frames)


def _grid(tau: np.ndarray) -> np.ndarray:
    lo, hi = np.log10(tau.min()), np.log10(tau.max())
    n = max(2, int(np.ceil((hi - lo) * GRID_PER_DECADE)) + 1)
    return np.logspace(lo, hi, n)


def population_curves(fleet: pl.DataFrame) -> pl.DataFrame:
    """Median and 95 % band of the units' ADEV per axis on a common τ grid (module doc)."""
    out = [pl.DataFrame(schema=POPULATION_SCHEMA)]
    valid = fleet.filter(pl.col("adev").is_finite() & (pl.col("adev") > 0))
    for (axis,), part in valid.group_by("axis", maintain_order=True):
        grid = _grid(part["tau"].to_numpy())
        lg = np.log10(grid)
        rows = []
        for _, unit in part.group_by(UNIT_COLUMN, maintain_order=True):
            lt, la = np.log10(unit["tau"].to_numpy()), np.log10(unit["adev"].to_numpy())
            order = np.argsort(lt)
            lt, la = lt[order], la[order]
            y = np.interp(lg, lt, la)
            y[(lg < lt[0] - 1e-12) | (lg > lt[-1] + 1e-12)] = np.nan
            rows.append(y)
        logs = np.vstack(rows)
        count = np.isfinite(logs).sum(axis=0)
        keep = 2 * count >= len(rows)
        logs = logs[:, keep]
        with np.errstate(all="ignore"):
            median = 10 ** np.nanmedian(logs, axis=0)
            lo, hi = 10 ** np.nanpercentile(logs, BAND_PERCENTILES, axis=0)
        out.append(
            pl.DataFrame(
                {
                    "axis": axis,
                    "unit": part["unit"][0],
                    "tau": grid[keep],
                    "median": median,
                    "lo": lo,
                    "hi": hi,
                    "units": count[keep].astype(np.int64),
                },
                schema=POPULATION_SCHEMA,
            )
        )
    return pl.concat(out)
