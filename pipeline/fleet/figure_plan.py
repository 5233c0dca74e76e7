"""Which figures ``fleet.md`` gets, who draws them and where they are saved — without
matplotlib: the client plans the jobs, the fleet's workers draw them
(:mod:`imupipe.fleet.figures`, imported only where a job runs).  On the client, importing
matplotlib would delay the figure jobs by ~1 s at the end of every fleet."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

import polars as pl

from imupipe.fleet.curves import UNIT_COLUMN
from imupipe.fleet.population import TermStats, final_terms
from imupipe.vocab import AXES_OF, SENSOR_TITLES

FigureJob = tuple[str, tuple]
"""The name of a figure function of :mod:`imupipe.fleet.figures` and its arguments (picklable:
a job is sent to a worker)."""

Mapper = Callable[[Callable[[FigureJob], bytes | None], list[FigureJob]], Iterable[bytes | None]]
"""Runs the figure jobs, e.g. builtin ``map`` (in this process) or a Dask client's map+gather
(on the fleet's workers, in parallel)."""


def draw(job: FigureJob) -> bytes | None:
    """Run one figure job: its PNG, or None when the figure does not apply."""
    name, args = job
    figures = importlib.import_module("imupipe.fleet.figures")
    return getattr(figures, name)(*args)


CURVE_COLUMNS = (UNIT_COLUMN, "axis", "unit", "tau", "adev")
"""The columns of the fleet's curves an ADEV figure draws."""


def _final_terms_of(reports: Mapping[str, dict], axes: tuple[str, ...]) -> dict[str, dict]:
    """Each unit's final IEEE 952 terms on ``axes``, shaped as its report: all a strip plot
    reads of a report.json (~1 % of it)."""
    return {
        name: {
            "axes": {a: {"ieee952": final_terms(doc)} for a, doc in r["axes"].items() if a in axes}
        }
        for name, r in reports.items()
    }


def figure_jobs(
    fleet: pl.DataFrame, pop: pl.DataFrame, reports: Mapping[str, dict], stats: list[TermStats]
) -> list[tuple[str, str, FigureJob]]:
    """(caption, file name, job) of every fleet figure: per sensor, the ADEV overlay and the
    strip plots.  Each job carries only what its figure draws (its sensor's curves and final
    terms): a job with every report and curve was ~80 kB per unit, and Dask warned of a
    10 MB task graph at 120 units."""
    jobs: list[tuple[str, str, FigureJob]] = []
    for sensor in ("gyro", "accel"):
        axes = AXES_OF[sensor]
        mine = pl.col("axis").is_in(axes)
        jobs.append((
            f"{SENSOR_TITLES[sensor]}: Allan deviation of every unit",
            f"fleet_adev_{sensor}.png",
            ("adev_figure", (fleet.filter(mine).select(CURVE_COLUMNS), pop.filter(mine), sensor)),
        ))  # fmt: skip
        jobs.append((
            f"{SENSOR_TITLES[sensor]}: N, B, K per unit",
            f"fleet_terms_{sensor}.png",
            (
                "terms_figure",
                (_final_terms_of(reports, axes), [s for s in stats if s.axis in axes], sensor),
            ),
        ))  # fmt: skip
    return jobs


def save_figures(
    jobs: list[tuple[str, str, FigureJob]], pngs: Iterable[bytes | None], out_dir: Path
) -> dict[str, Path]:
    """Write the drawn figures (``pngs``, in the order of ``jobs``; None: not applicable) into
    ``out_dir``; returns {caption: path}."""
    written: dict[str, Path] = {}
    for (caption, name, _), png in zip(jobs, pngs, strict=True):
        if png is not None:
            written[caption] = out_dir / name
            written[caption].write_bytes(png)
    return written
