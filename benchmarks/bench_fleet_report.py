"""Fleet report at scale: the population statistics and the whole fleet report of hundreds to
thousands of units, against the population's definition computed one unit at a time.

    python benchmarks/bench_fleet_report.py [--units 250 1000 2000] [--baseline-max 2000]

Three simulated ADIS16364 recordings (10 min at 100 Hz, seeds 0-2) are analysed once; each
fleet of ``--units`` units repeats their report.json and Allan curves, every unit's terms
(value and interval) and curves scaled by its own log-normal factor (σ = 5 %), so that the
units differ as a lot's do.  Timed in this process:

* ``population()`` (:mod:`imupipe.fleet.population`: median, spread, 95 %/95 % tolerance
  interval, outlier units for 6 axes × 5 terms), against the baseline: the outlier rule as the
  module defines it, one tolerance interval of the other units per unit (a sort and a rank
  each; what imupipe computed until session 25), for fleets up to ``--baseline-max`` units.
  The two must name the same outliers (checked).
* ``write_fleet_report`` (fleet.json, fleet.parquet, fleet.md with its four figures drawn in
  this process, fleet.rrd), the whole report a fleet writes once its units are analysed; its
  first call also pays the imports of matplotlib and rerun-sdk.
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
from pathlib import Path

import numpy as np
import polars as pl

from imupipe.api import analyze, record
from imupipe.fleet.population import (
    UnitTerm,
    _interval,
    final_terms,
    order_statistic_rank,
    population,
    tolerance_interval,
)
from imupipe.fleet.report import write_fleet_report
from imupipe.fleet.task import UnitOutcome
from imupipe.vocab import AXES, TERM_NAMES

MIN_OTHERS = 3


def tolerance_anew(values: list[float]) -> tuple[float, float]:
    """:func:`tolerance_interval` with its order-statistic rank computed, not remembered."""
    x = np.sort(values)
    r = order_statistic_rank.__wrapped__(x.size)
    return (float(x[r - 1]), float(x[x.size - r])) if r else tolerance_interval(x)[0]


def outliers_by_definition(units: list[UnitTerm]) -> tuple[str, ...]:
    """The baseline: each unit's interval against the tolerance interval of the others,
    computed anew for every unit."""
    out = []
    for u in units:
        mine = _interval(u)
        others = [o.value for o in units if o.value is not None and o.unit != u.unit]
        if mine is None or len(others) < MIN_OTHERS:
            continue
        lo, hi = tolerance_anew(others)
        if mine[1] < lo or mine[0] > hi:
            out.append(u.unit)
    return tuple(out)


def baseline_outliers(reports: dict[str, dict]) -> list[tuple[str, ...]]:
    """The baseline's outliers per (axis, term), in :func:`population`'s order."""
    out = []
    for axis in AXES:
        for term in TERM_NAMES:
            units = []
            for name, report in reports.items():
                t = final_terms(report["axes"][axis])[term]
                units.append(UnitTerm(name, t["value"], t["lo"], t["hi"]))
            out.append(outliers_by_definition(units))
    return out


def seed_outcomes(folder: Path) -> list[tuple[dict, pl.DataFrame]]:
    """report.json and Allan curves of three simulated 10-min recordings."""
    seeds = []
    for seed in range(3):
        path = folder / f"unit{seed}.mcap"
        record(path, duration="10m", rate_hz=100.0, seed=seed)
        result = analyze(path, folder / f"unit{seed}.imupipe", rrd=False, figures=False)
        seeds.append((result.to_dict(), result.to_polars()))
    return seeds


def scaled(report: dict, curves: pl.DataFrame, factor: float) -> tuple[dict, pl.DataFrame]:
    """A unit's report and curves with every term and deviation scaled by ``factor``."""
    report = copy.deepcopy(report)
    for axis in report["axes"].values():
        for key in ("ieee952", "ieee952_after"):
            for term in (axis.get(key) or {}).values():
                for field in ("value", "lo", "hi"):
                    if term.get(field) is not None:
                        term[field] *= factor
    adev = [c for c in curves.columns if c in ("adev", "lo", "hi", "adev_after")]
    return report, curves.with_columns(pl.col(c) * factor for c in adev)


def fleet(seeds: list[tuple[dict, pl.DataFrame]], n: int) -> list[UnitOutcome]:
    rng = np.random.default_rng(n)
    outcomes = []
    for k in range(n):
        report, curves = scaled(*seeds[k % len(seeds)], float(rng.lognormal(0.0, 0.05)))
        name = f"unit{k:05d}"
        outcomes.append(UnitOutcome(name, f"{name}.mcap", "ok", None, report, curves, 0.0, ""))
    return outcomes


def timed(f):
    start = time.perf_counter()
    value = f()
    return time.perf_counter() - start, value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, nargs="+", default=[250, 1000, 2000])
    ap.add_argument("--baseline-max", type=int, default=2000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="imupipe-fleet-report-") as tmp:
        seeds = seed_outcomes(Path(tmp))
        for run, n in enumerate(args.units):
            outcomes = fleet(seeds, n)
            reports = {o.name: o.report for o in outcomes}
            order_statistic_rank.cache_clear()  # each size pays for its ranks
            ours, stats = timed(lambda r=reports: population(r))
            found = sum(len(s.outliers) for s in stats)
            line = f"{n:6d} units: population() {ours:7.3f} s ({found} outlier unit-terms)"
            if n <= args.baseline_max:
                base, expected = timed(lambda r=reports: baseline_outliers(r))
                assert [s.outliers for s in stats] == expected, "outliers differ"
                line += f", baseline {base:7.2f} s: {base / ours:6.0f}x"
            out = Path(tmp) / f"fleet{run}"
            out.mkdir()
            whole, _ = timed(lambda o=outcomes, d=out: write_fleet_report(o, d))
            print(f"{line}; whole fleet report {whole:6.2f} s", flush=True)


if __name__ == "__main__":
    main()
