"""PNG figures of ``fleet.md`` (matplotlib, Agg backend), drawn where
:func:`imupipe.fleet.figure_plan.draw` runs a job (on the fleet's workers).

- ``fleet_adev_<sensor>.png``: one panel per axis, every unit's overlapping Allan deviation
  (thin lines) over the population median and its 95 % band (:mod:`imupipe.fleet.curves`);
- ``fleet_terms_<sensor>.png``: strip plots of N, B and K, one panel per term: each unit's value
  with its 95 % interval per axis, the population's 95 %/95 % tolerance interval (shaded) and
  the datasheet value (dashed) when one was given.
"""

from __future__ import annotations

import io
from collections.abc import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import polars as pl
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from imupipe.fleet.curves import UNIT_COLUMN
from imupipe.fleet.population import TermStats, final_terms
from imupipe.report.figures import log_labels, sparse_log_ticks
from imupipe.units import PAPER_UNIT, from_si
from imupipe.vocab import AXES_OF, SENSOR_TITLES

STRIP_TERMS: tuple[tuple[str, str], ...] = (
    ("random_walk", "N"),
    ("bias_instability", "B"),
    ("rate_random_walk", "K"),
)


_MARGINS = {"left": 0.07, "right": 0.99, "bottom": 0.12, "top": 0.86, "wspace": 0.28}
"""Fixed margins of the one-row figures: a layout engine costs an extra draw of every tick."""
SHOWN_OPAQUE = 30
"""Units drawn fully opaque (curves at 0.7); a larger fleet's units fade as 1/n, so that a
thousand overlapping curves or intervals do not become one black mass over the population's
median and band (whose edges are drawn on top)."""


VIEW_MARGIN = 1.3
"""A strip plot's view spans its units' intervals, bounds and datasheet values, × / ÷ this: not
the tolerance interval, which from two or three units (Howe's k = 37.7 or 9.9 on log values)
spans up to 18 decades and flattened every unit into one line at the panel's middle."""


def _unit_alpha(units: int, opaque: float = 1.0) -> float:
    """Opacity of each unit's curve or interval in a fleet of ``units`` (:data:`SHOWN_OPAQUE`)."""
    return opaque * min(1.0, SHOWN_OPAQUE / max(units, 1))


def _png(fig: Figure) -> bytes:
    """The figure encoded as PNG (100 dpi), then closed."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    return buffer.getvalue()


def adev_figure(fleet: pl.DataFrame, pop: pl.DataFrame, sensor: str) -> bytes | None:
    """PNG: every unit's ADEV per axis of ``sensor`` with the population median and 95 % band
    (None without any such axis)."""
    axes = [a for a in AXES_OF[sensor] if a in set(fleet["axis"].unique())]
    if not axes:
        return None
    fig, panels = plt.subplots(
        1, len(axes), figsize=(4.2 * len(axes), 4.2), squeeze=False, gridspec_kw=_MARGINS
    )
    units = fleet[UNIT_COLUMN].n_unique()
    for ax, axis in zip(panels[0], axes, strict=True):
        part = fleet.filter(pl.col("axis") == axis)
        curves = [
            np.column_stack([unit["tau"], unit["adev"]])
            for _, unit in part.group_by(UNIT_COLUMN, maintain_order=True)
        ]  # one artist for all units: a line each costs ~0.1 s per unit to lay out and draw
        alpha = _unit_alpha(units, 0.7)
        ax.add_collection(LineCollection(curves, colors="0.45", linewidths=0.7, alpha=alpha))
        p = pop.filter(pl.col("axis") == axis)
        ax.fill_between(p["tau"], p["lo"], p["hi"], color="tab:blue", alpha=0.25, lw=0)
        for edge in ("lo", "hi"):
            ax.plot(p["tau"], p[edge], color="tab:blue", lw=0.8, zorder=3)
        ax.plot(p["tau"], p["median"], color="tab:blue", lw=2.0, zorder=3)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.autoscale_view()
        ax.set_title(axis)
        ax.set_xlabel("averaging time τ [s]")
        ax.grid(True, which="major", lw=0.4, alpha=0.6)
        sparse_log_ticks(ax.xaxis, ax.yaxis)
    unit = fleet.filter(pl.col("axis") == axes[0])["unit"][0]
    panels[0][0].set_ylabel(f"Allan deviation σ(τ) [{unit}]")
    panels[0][0].plot([], [], color="0.45", lw=0.7, label="each unit")
    panels[0][0].plot([], [], color="tab:blue", lw=2.0, label="population median")
    panels[0][0].fill_between([], [], [], color="tab:blue", alpha=0.25, label="95 % of units")
    panels[0][0].legend(fontsize=7)
    fig.suptitle(f"{SENSOR_TITLES[sensor]}: Allan deviation of {units} units")
    return _png(fig)


def terms_figure(reports: Mapping[str, dict], stats: list[TermStats], sensor: str) -> bytes | None:
    """PNG: strip plots of N, B, K, each unit's interval per axis, tolerance interval,
    datasheet (None without any axis of ``sensor``)."""
    axes = [a for a in AXES_OF[sensor] if any(a in r["axes"] for r in reports.values())]
    if not axes:
        return None
    by_key = {(s.axis, s.term): s for s in stats}
    names = sorted(reports)
    offsets = np.linspace(-0.3, 0.3, len(names)) if len(names) > 1 else np.zeros(1)
    fig, panels = plt.subplots(
        1, len(STRIP_TERMS), figsize=(4.2 * len(STRIP_TERMS), 4.2), gridspec_kw=_MARGINS
    )
    for ax, (term, symbol) in zip(panels, STRIP_TERMS, strict=True):
        unit = PAPER_UNIT[sensor][term]
        # one artist per kind of point and panel: an errorbar per unit costs seconds to lay out
        points: dict[bool, list[tuple[float, float, float, float]]] = {False: [], True: []}
        bounds: list[tuple[float, float]] = []
        extent: list[float] = []  # what the view must hold (VIEW_MARGIN)
        for i, axis in enumerate(axes):
            st = by_key.get((axis, term))
            if st is not None and st.tolerance is not None:
                lo, hi = (from_si(v, unit) for v in st.tolerance)
                ax.fill_between([i - 0.4, i + 0.4], lo, hi, color="tab:blue", alpha=0.15, lw=0)
                ax.hlines([lo, hi], i - 0.4, i + 0.4, "tab:blue", lw=0.8, zorder=3)
            if st is not None and st.datasheet is not None:
                sheet = from_si(st.datasheet.si(), unit)
                ax.hlines(sheet, i - 0.45, i + 0.45, "tab:red", "--")
                extent.append(sheet)
            for off, name in zip(offsets, names, strict=True):
                doc = reports[name]["axes"].get(axis)
                if doc is None:
                    continue
                t = final_terms(doc)[term]
                x = i + off
                if t["value"] is not None:
                    v = from_si(t["value"], unit)
                    lo = from_si(t["lo"] if t["lo"] is not None else t["value"], unit)
                    hi = from_si(t["hi"] if t["hi"] is not None else t["value"], unit)
                    outlier = st is not None and name in st.outliers
                    points[outlier].append((x, v, v - lo, hi - v))
                    extent += [lo, hi]
                elif t["hi"] is not None:  # unresolved: its upper bound
                    bounds.append((x, from_si(t["hi"], unit)))
                    extent.append(bounds[-1][1])
        for outlier, rows in points.items():
            if rows:
                x, v, below, above = np.array(rows).T
                ax.errorbar(
                    x, v, yerr=[below, above], fmt="o", ms=3.5, capsize=2,
                    color="tab:orange" if outlier else "k",
                    alpha=1.0 if outlier else _unit_alpha(len(names)), zorder=4 if outlier else 2,
                )  # fmt: skip
        if bounds:
            x, v = np.array(bounds).T
            ax.plot(x, v, "v", color="0.5", ms=4, ls="none", alpha=_unit_alpha(len(names)))
        ax.set_xticks(range(len(axes)), axes)
        ax.set_yscale("log")  # spans about a decade: matplotlib's minor ticks label it
        positive = [y for y in extent if y > 0]
        if positive:
            ax.set_ylim(min(positive) / VIEW_MARGIN, max(positive) * VIEW_MARGIN)
        log_labels(ax.yaxis)
        ax.set_title(f"{symbol} [{unit}]")
        ax.grid(True, axis="y", which="major", lw=0.4, alpha=0.6)
    shown = [by_key[(a, t)] for a in axes for t, _ in STRIP_TERMS if (a, t) in by_key]
    panels[0].errorbar([], [], yerr=[], fmt="o", color="k", label="unit, 95 % interval")
    if any(st.outliers for st in shown):
        panels[0].errorbar([], [], yerr=[], fmt="o", color="tab:orange", label="outlier unit")
    panels[0].plot([], [], "v", color="0.5", label="unresolved: upper bound")
    panels[0].fill_between([], [], [], color="tab:blue", alpha=0.15, label="95 %/95 % tolerance")
    if any(st.datasheet is not None for st in shown):
        panels[0].plot([], [], "--", color="tab:red", label="datasheet")
    panels[0].legend(fontsize=7)
    fig.suptitle(f"{SENSOR_TITLES[sensor]}: noise terms of {len(names)} units")
    return _png(fig)
