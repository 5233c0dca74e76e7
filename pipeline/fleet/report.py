"""The fleet report in the fleet's output folder, beside one folder per unit:

- ``fleet.json``: per unit its status (and one-line error), and per axis the final IEEE 952
  terms with their 95 % intervals (SI, each with its unit; after the closed loop when it ran)
  and the effects found; the population statistics per axis and term
  (:mod:`imupipe.fleet.population`) and the population's Allan-deviation curve per axis;
- ``fleet.parquet``: every unit's Allan curves, long form (:data:`FLEET_ALLAN_SCHEMA`);
- ``fleet.md`` with the figures of :mod:`imupipe.fleet.figures` (drawn on the workers);
- ``fleet.rrd``: the curves per unit in Rerun (:mod:`imupipe.fleet.rerun_view`).
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import polars as pl

from imupipe import __version__
from imupipe.analysis.results import jsonable
from imupipe.fleet.curves import fleet_frame, population_curves
from imupipe.fleet.figure_plan import Mapper, draw, figure_jobs, save_figures
from imupipe.fleet.population import CONFIDENCE, COVERAGE, TermStats, final_terms, population
from imupipe.fleet.task import UnitOutcome
from imupipe.report.datasheet import Datasheet
from imupipe.report.report import _fmt, _md_table
from imupipe.units import PAPER_UNIT, from_si
from imupipe.vocab import sensor_of

SCHEMA_VERSION = 1
_MD_SPECIAL = re.compile(r"([\\`*_{}\[\]<>#!~])")


def md_text(text: str) -> str:
    """Untrusted text (file names, error messages) as literal Markdown on one line."""
    return _MD_SPECIAL.sub(r"\\\1", " ".join(str(text).split()))


def _unit_json(outcome: UnitOutcome) -> dict:
    doc: dict = {
        "name": outcome.name,
        "source": outcome.source,
        "status": outcome.status,
        "error": outcome.error,
        "folder": outcome.name if outcome.status == "ok" else None,
        "seconds": outcome.seconds,
        "worker": outcome.worker,
        "axes": {},
    }
    if outcome.report is not None:
        doc["input"] = {k: outcome.report["input"][k] for k in ("topic", "frames", "rate_hz",
                                                               "duration_s")}  # fmt: skip
        doc["axes_moving_together"] = _moving_together(outcome.report)
        for axis, a in outcome.report["axes"].items():
            doc["axes"][axis] = {
                "sensor": a["sensor"],
                "terms_after_loop": "ieee952_after" in a,
                "terms": final_terms(a),
                "effects": a.get("effects", []),
            }
    return doc


def _moving_together(report: dict) -> list[dict] | None:
    """The unit's axis pairs that move together (report.json ``events.common_mode``: axes and
    strongest correlation), strongest first; None when the event search did not run."""
    events = report.get("events")
    if events is None:
        return None
    return [
        {"axes": p["axes"], "strongest": p["strongest"]} for p in events["common_mode"]["pairs"]
    ]


def _moving_together_cell(pairs: list[dict] | None) -> str:
    """fleet.md's cell of a unit's :func:`_moving_together` (None: not searched or failed):
    how many pairs move together and the strongest, "none", or "—"."""
    if pairs is None:
        return "—"
    if not pairs:
        return "none"
    top = pairs[0]
    return (
        f"{len(pairs)} pair{'s' * (len(pairs) > 1)} (strongest {'–'.join(top['axes'])} "
        f"r {top['strongest']['value']:.2f} at {top['strongest']['window_s']:g} s)"
    )


def _stats_json(s: TermStats) -> dict:
    doc = {
        "axis": s.axis,
        "term": s.term,
        "unit": s.unit,
        "units": s.units,
        "resolved": s.resolved,
        "median": s.median,
        "median_lower_bound": s.median_range[0] if s.median_range else None,
        "median_upper_bound": s.median_range[1] if s.median_range else None,
        "robust_spread": s.robust_spread,
        "tolerance": None
        if s.tolerance is None
        else {
            "lo": s.tolerance[0],
            "hi": s.tolerance[1],
            "coverage": COVERAGE,
            "confidence": CONFIDENCE,
            "method": s.method,
        },
        "outliers": list(s.outliers),
        "datasheet": None,
    }
    if s.datasheet is not None:
        doc["datasheet"] = {
            **asdict(s.datasheet),
            "population_pass": s.population_pass,
            "failing_units": list(s.failing_units),
        }
    return doc


def fleet_json(
    outcomes: Sequence[UnitOutcome],
    stats: list[TermStats],
    pop: pl.DataFrame,
    datasheet: Datasheet | None,
) -> dict:
    """The ``fleet.json`` document (module doc); SI units, no NaN."""
    curves = {
        axis: {
            "unit": part["unit"][0],
            **{c: part[c].to_list() for c in ("tau", "median", "lo", "hi", "units")},
        }
        for (axis,), part in pop.group_by("axis", maintain_order=True)
    }
    return jsonable(
        {
            "schema_version": SCHEMA_VERSION,
            "generator": {"name": "imupipe", "version": __version__},
            "recordings": len(outcomes),
            "analysed": sum(o.status == "ok" for o in outcomes),
            "failed": sum(o.status == "failed" for o in outcomes),
            "datasheet": None
            if datasheet is None
            else {"part": datasheet.part, "source": datasheet.source},
            "units": [_unit_json(o) for o in outcomes],
            "population": [_stats_json(s) for s in stats],
            "population_adev": curves,
        }
    )


def _in(value: float | None, unit: str) -> str:
    return "—" if value is None else _fmt(from_si(value, unit))


def _verdict(s: TermStats) -> str:
    if s.datasheet is None:
        return "—"
    d = s.datasheet
    verdict = {True: "pass", False: "**fail**", None: "—"}[s.population_pass]
    text = f"{d.kind} {_fmt(d.value)} {d.unit}: {verdict}"
    if s.failing_units:
        text += f" ({len(s.failing_units)} unit(s) above: {', '.join(s.failing_units)})"
    return text


def _median_cell(s: TermStats, unit: str) -> str:
    """The median, or the range it lies in when some units only bound the term: "≤ high" when
    its low end is 0, "low – high" otherwise."""
    if s.median_range is None:
        return _in(s.median, unit)
    low, high = s.median_range
    return f"≤ {_in(high, unit)}" if low == 0 else f"{_in(low, unit)} – {_in(high, unit)}"


def population_rows(stats: list[TermStats]) -> list[tuple[str, ...]]:
    """fleet.md's population table in the paper's units (:data:`PAPER_UNIT`)."""
    rows = []
    for s in stats:
        unit = PAPER_UNIT[sensor_of(s.axis)][s.term]
        ti = "—"
        if s.tolerance is not None:
            ti = f"[{_in(s.tolerance[0], unit)}, {_in(s.tolerance[1], unit)}]"
        spread = "—" if s.robust_spread is None else f"{100 * s.robust_spread:.2g} %"
        rows.append(
            (
                s.axis,
                s.term,
                unit,
                f"{s.resolved}/{s.units}",
                _median_cell(s, unit),
                spread,
                ti,
                ", ".join(s.outliers) or "none",
                _verdict(s),
            )
        )
    return rows


POPULATION_HEADER = (
    "axis",
    "term",
    "unit",
    "resolved",
    "median",
    "spread",
    "95 %/95 % tolerance",
    "outliers",
    "datasheet",
)


def fleet_markdown(
    outcomes: Sequence[UnitOutcome],
    stats: list[TermStats],
    figures: dict[str, Path],
    datasheet: Datasheet | None,
) -> str:
    """``fleet.md``: units and failures, the population table, the figures."""
    ok = [o for o in outcomes if o.status == "ok"]
    together = [None if o.report is None else _moving_together(o.report) for o in outcomes]
    failed = [o for o in outcomes if o.status == "failed"]
    methods = sorted({s.method for s in stats if s.method})
    md = [
        "# imupipe fleet report",
        "",
        f"{len(outcomes)} recordings: {len(ok)} analysed, {len(failed)} failed.",
        "",
        "## Units",
        "",
        _md_table(
            ("unit", "status", "source", "time", "effects found", "axes moving together"),
            [
                (
                    f"[{md_text(o.name)}]({o.name}/report.md)" if o.status == "ok" else o.name,
                    o.status,
                    md_text(o.source),
                    f"{o.seconds:.1f} s",
                    ", ".join(
                        sorted(
                            {
                                f"{axis}: {e['kind']}"
                                for axis, a in (o.report or {}).get("axes", {}).items()
                                for e in a.get("effects", [])
                            }
                        )
                    )
                    or "none",
                    _moving_together_cell(pairs),
                )
                for o, pairs in zip(outcomes, together, strict=True)
            ],
        ),
        "",
    ]
    searched = [pairs for pairs in together if pairs is not None]  # a failed unit has no report
    if searched:
        moving = sum(bool(pairs) for pairs in searched)
        md += [
            f"Axes that move together (a cause common to them: temperature, supply, the mount; "
            f"each unit's report.md says which and at what window lengths): on {moving} of the "
            f"{len(searched)} units searched.",
            "",
        ]
    if failed:
        md += ["## Failed recordings", ""]
        md += [f"- {md_text(o.name)}: {md_text(o.error or '')}" for o in failed] + [""]
    md += [
        "## Population",
        "",
        "Final IEEE 952 terms (after the closed loop where it ran) in the paper's units. "
        "resolved: units whose term was resolved / units analysed. A unit that only bounds a term "
        "is counted anywhere between 0 and its bound: where that moves the median, the median "
        "column gives the range it lies in (≤ the high end when the low end is 0); the spread "
        "only where neither the median nor the MAD can move, and below 93 units no tolerance "
        "interval (it needs every unit's value). spread: 1.4826·MAD/median. "
        f"Tolerance interval: holds {COVERAGE:.0%} of units with {CONFIDENCE:.0%} confidence, "
        f"by {'; '.join(methods) or '—'}. Outliers: units whose own 95 % interval lies outside "
        "the other units' tolerance interval.",
        "",
    ]
    if datasheet is not None:
        md += [f"Datasheet: {md_text(datasheet.part)}, {md_text(datasheet.source)}.", ""]
    md += [_md_table(POPULATION_HEADER, population_rows(stats)), ""]
    md += ["## Figures", ""]
    md += [f"![{name}]({path.name})" for name, path in figures.items()] + [""]
    md += ["Curves per unit in Rerun: `imupipe view fleet.rrd`.", ""]
    return "\n".join(md)


def write_fleet_report(
    outcomes: Sequence[UnitOutcome],
    out_dir: Path,
    datasheet: Datasheet | None = None,
    rrd: bool = True,
    mapper: Mapper = map,
) -> tuple[dict, list[TermStats]]:
    """Write fleet.json, fleet.parquet, fleet.md (+ figures) and fleet.rrd into ``out_dir``;
    returns the fleet.json document and the population statistics.  The figures are drawn by
    ``mapper`` (:data:`imupipe.fleet.figure_plan.Mapper`; a Dask client's map draws them on the
    fleet's workers while this process writes the rest)."""
    ok = [o for o in outcomes if o.status == "ok"]
    reports = {o.name: o.report for o in ok}
    stats = population(reports, datasheet)
    fleet = fleet_frame({o.name: o.allan for o in ok})
    pop = population_curves(fleet)
    jobs = figure_jobs(fleet, pop, reports, stats)
    pngs = mapper(draw, [job for *_, job in jobs])
    doc = fleet_json(outcomes, stats, pop, datasheet)
    (out_dir / "fleet.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    fleet.write_parquet(out_dir / "fleet.parquet")
    if rrd:
        # imported here, while the workers draw the figures: rerun takes ~0.5 s to import,
        # which, imported before the figure jobs were sent, delayed the report's end as much
        from imupipe.fleet.rerun_view import write_fleet_rrd

        write_fleet_rrd(fleet, pop, out_dir / "fleet.rrd")
    figures = save_figures(jobs, pngs, out_dir)
    (out_dir / "fleet.md").write_text(fleet_markdown(outcomes, stats, figures, datasheet))
    return doc, stats
