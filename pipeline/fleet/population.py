"""Population statistics of a fleet, per axis and IEEE 952 term.

For each (axis, term) over the units whose term is resolved:

- **median** and **robust spread** (1.4826 · MAD / median: the relative standard deviation a
  normal population with that MAD has);
- a two-sided **95 %/95 % tolerance interval** (an interval that holds at least 95 % of the
  part's units, with 95 % confidence).  With n ≥ 93 units it is distribution-free: the order
  statistics (X₍ᵣ₎, X₍ₙ₊₁₋ᵣ₎) with the largest r whose coverage, distributed as
  Beta(n + 1 − 2r, 2r), reaches 95 % with 95 % confidence (Wilks 1941; Hahn & Meeker,
  *Statistical Intervals*, 1991, §5.3).  With fewer it assumes the term is log-normal across
  units (noise coefficients are positive scale factors) and uses Howe's k-factor on log10
  values: k = √((n − 1)(1 + 1/n) z²₍₁₊ₚ₎/₂ / χ²₁₋ᵧ,ₙ₋₁) (Howe 1969, JASA 64:610; NIST/SEMATECH
  e-Handbook §7.2.6.3);
- **outlier units**: a unit whose own 95 % interval lies entirely outside the tolerance interval
  of the *other* units (leave-one-out, so an outlier does not widen the interval it is tested
  against; needs at least 3 other units).  Accounting for the unit's uncertainty this way, a
  short recording with a wide interval is not called an outlier for its noisy estimate alone;
- against a **datasheet** value (:mod:`imupipe.report.datasheet`): a unit fails when its interval
  lies entirely above the value (its lower bound exceeds it); the population fails a
  ``typical`` value when its median exceeds it, a ``max`` value when the upper tolerance bound
  does.

Units that only bound a term (an upper bound: a rate random walk, or B on short records) are
counted anywhere between 0 and their bound.  The median is given when that does not move it;
otherwise the range it lies in (:class:`TermStats`).  The spread likewise, where the MAD
cannot move either; Howe's interval needs every unit's value and is left out; the
distribution-free interval counts those units at 0 for its lower end and at their bound for its
upper one.  When fewer units resolve the term than only bound it, no unit is called an outlier
of it; the datasheet verdicts follow the ranges.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from imupipe.report.datasheet import Datasheet, Spec
from imupipe.stats.robust import MAD_TO_SIGMA
from imupipe.vocab import AXES, TERM_NAMES, sensor_of

COVERAGE = 0.95
CONFIDENCE = 0.95
MIN_OTHERS_FOR_OUTLIER = 3
HOWE_METHOD = "Howe k-factor on log10 values (log-normal across units)"
ORDER_METHOD = "order statistics (distribution-free, Wilks)"
BOUNDED_ORDER_METHOD = (
    f"{ORDER_METHOD}; units that only bound the term counted at 0 below and at their bound above"
)


@dataclass(frozen=True)
class UnitTerm:
    """One unit's estimate of a term (SI): ``value`` with its 95 % interval; an unresolved term
    has ``value`` None and at most an upper bound ``hi``."""

    unit: str
    value: float | None
    lo: float | None
    hi: float | None


@dataclass(frozen=True)
class TermStats:
    """The population of one (axis, term): counts, median and robust spread (SI, fraction),
    95 %/95 % tolerance interval and its method, outlier units, datasheet verdicts.

    A unit that only bounds the term (value None, upper bound ``hi``) has its true value
    somewhere in [0, hi].  The lot's median then lies between the median of the resolved
    values with those units at 0 and with them at their bound: ``median`` when the two are
    equal, else None and ``median_range`` = (low, high).  This matters most when few units
    resolve the term: those are the ones whose noise lifted it above their bound (120 units of
    2 min: B "resolved" on 2, their median 3× the true B), and the range is [0, bound).
    ``robust_spread`` likewise: given when the median is and the bounded units' possible
    deviations from it do not move the MAD."""

    axis: str
    term: str
    unit: str
    units: int
    resolved: int
    median: float | None
    median_range: tuple[float, float] | None
    robust_spread: float | None
    tolerance: tuple[float, float] | None
    method: str | None
    outliers: tuple[str, ...]
    datasheet: Spec | None
    population_pass: bool | None
    failing_units: tuple[str, ...]


def howe_k(n: int, coverage: float = COVERAGE, confidence: float = CONFIDENCE) -> float:
    """Howe's (1969) two-sided normal tolerance factor for ``n`` observations."""
    z = stats.norm.ppf((1 + coverage) / 2)
    chi2 = stats.chi2.ppf(1 - confidence, n - 1)
    return float(math.sqrt((n - 1) * (1 + 1 / n) * z * z / chi2))


@functools.cache
def order_statistic_rank(
    n: int, coverage: float = COVERAGE, confidence: float = CONFIDENCE
) -> int | None:
    """Largest r with P(coverage of (X₍ᵣ₎, X₍ₙ₊₁₋ᵣ₎) ≥ ``coverage``) ≥ ``confidence``, or None
    when even the extremes (r = 1) are not enough (n < 93 at 95 %/95 %).  Computed once per
    n (n/2 Beta tail probabilities: ~1 ms at n = 1000)."""
    r = np.arange(1, n // 2 + 1)
    conf = stats.beta.sf(coverage, n + 1 - 2 * r, 2 * r)
    ok = r[conf >= confidence]
    return int(ok[-1]) if ok.size else None


def tolerance_interval(values: Sequence[float]) -> tuple[tuple[float, float], str] | None:
    """Two-sided 95 %/95 % tolerance interval of positive ``values`` (module doc), or None for
    fewer than 2."""
    x = np.sort(np.asarray(values, dtype=float))
    n = x.size
    if n < 2:
        return None
    r = order_statistic_rank(n)
    if r is not None:
        return (float(x[r - 1]), float(x[n - r])), ORDER_METHOD
    logs = np.log10(x)
    k = howe_k(n)
    mean, sd = logs.mean(), logs.std(ddof=1)
    return (float(10 ** (mean - k * sd)), float(10 ** (mean + k * sd))), HOWE_METHOD


def _interval(u: UnitTerm) -> tuple[float, float] | None:
    """The unit's 95 % interval; an unresolved term spans [0, upper bound]."""
    if u.value is None:
        return None if u.hi is None else (0.0, u.hi)
    lo = u.lo if u.lo is not None else u.value
    hi = u.hi if u.hi is not None else u.value
    return lo, hi


def _without_each(x: np.ndarray) -> np.ndarray:
    """``(n, 2)``: row j is the tolerance interval of the sorted values ``x`` without
    ``x[j]`` (n ≥ 3).  With order statistics (n − 1 ≥ 93) the k-th of the others is
    ``x[k]`` below j and ``x[k + 1]`` from j on, so all n intervals cost O(n) after the sort,
    not n sorts: a fleet of 1,000 units spent 12.6 s of its report here, and 10,000 would
    have spent ~20 min.  Below 93 units each is Howe's interval of the others (at most 92
    values each)."""
    n = x.size
    r = order_statistic_rank(n - 1)
    if r is None:
        return np.array([tolerance_interval(np.delete(x, j))[0] for j in range(n)])
    j = np.arange(n)
    lo, hi = r - 1, n - 1 - r  # the others' order statistics X(r), X(n - r), 0-based
    return np.column_stack((np.where(j > lo, x[lo], x[lo + 1]), np.where(j > hi, x[hi], x[hi + 1])))


def _bounded_order_interval(
    values: Sequence[float], bounds: Sequence[float]
) -> tuple[tuple[float, float], str] | None:
    """The distribution-free 95 %/95 % interval of a lot some of whose units only bound the term
    (at most ``bounds``): its r-th smallest unit is at least the r-th of the values with those
    units at 0 and its r-th largest at most the r-th largest with them at their bound, so the
    interval between those two holds the lot's own.  None below 93 units (Howe's interval needs
    every value) or when the bounded units reach the lower order statistic (it is then 0)."""
    n = len(values) + len(bounds)
    r = order_statistic_rank(n)
    if r is None or len(bounds) >= r:
        return None
    low = np.sort(np.asarray(values, dtype=float))[r - 1 - len(bounds)]
    high = np.sort(np.asarray([*values, *bounds], dtype=float))[n - r]
    return (float(low), float(high)), BOUNDED_ORDER_METHOD


def _robust_spread(values: Sequence[float], bounds: Sequence[float], median: float) -> float | None:
    """1.4826 · MAD / ``median`` of the lot (fraction), or None when the units that only bound
    the term (at most ``bounds``) could move the MAD.  A unit in [0, b] is at least
    max(median − b, 0) from the median and, for the MAD, at most the median: a farther one
    (x > 2·median) cannot move it, since on values ≥ 0 more than half the lot lies in
    [0, 2·median] and the MAD is at most the median.  The MAD with every such unit at its least
    and at its most deviation brackets the lot's."""
    dev = np.abs(np.asarray(values, dtype=float) - median)
    least = np.maximum(median - np.asarray(bounds, dtype=float), 0.0)
    mad = float(np.median(np.concatenate((dev, least))))
    if mad != float(np.median(np.concatenate((dev, np.full(len(bounds), median))))):
        return None
    return MAD_TO_SIGMA * mad / median


def _verdict_of_range(low: float, high: float, limit: float) -> bool | None:
    """Pass when a quantity known to lie in [``low``, ``high``] is at most ``limit``, fail when
    it exceeds it, None when the range straddles it."""
    if high <= limit:
        return True
    return False if low > limit else None


def outlier_units(units: Sequence[UnitTerm]) -> tuple[str, ...]:
    """Units whose 95 % interval misses the others' tolerance interval (module doc): the
    resolved others of a resolved unit are all the resolved units but itself, those of an
    unresolved one all of them."""
    resolved = [u for u in units if u.value is not None]
    n = len(resolved)
    if n < MIN_OTHERS_FOR_OUTLIER:
        return ()
    values = np.array([u.value for u in resolved], dtype=float)
    order = np.argsort(values, kind="stable")
    sorted_at = dict(zip((resolved[k].unit for k in order), range(n), strict=True))
    without = _without_each(values[order]) if n > MIN_OTHERS_FOR_OUTLIER else None
    everyone = tolerance_interval(values)
    out = []
    for u in units:
        mine = _interval(u)
        if mine is None:
            continue
        if u.value is None:
            ti = everyone[0]
        elif without is None:  # only n - 1 others
            continue
        else:
            ti = without[sorted_at[u.unit]]
        if mine[1] < ti[0] or mine[0] > ti[1]:
            out.append(u.unit)
    return tuple(out)


def final_terms(axis_doc: dict) -> dict:
    """A report.json axis' final IEEE 952 terms: after the closed loop when it ran."""
    return axis_doc.get("ieee952_after") or axis_doc["ieee952"]


def term_stats(
    axis: str,
    term: str,
    si_unit: str,
    units: Sequence[UnitTerm],
    datasheet: Spec | None = None,
) -> TermStats:
    """The population statistics of one (axis, term) (module doc)."""
    values = [u.value for u in units if u.value is not None]
    bounds = [u.hi for u in units if u.value is None and u.hi is not None]
    counted = values or bounds
    low = float(np.median(values + [0.0] * len(bounds))) if counted else None
    high = float(np.median(values + bounds)) if counted else None
    median = low if low == high else None
    median_range = None if low == high else (low, high)
    spread = _robust_spread(values, bounds, median) if median and len(values) >= 2 else None
    ti = tolerance_interval(values) if not bounds else _bounded_order_interval(values, bounds)
    population_pass, failing = None, ()
    if datasheet is not None and counted:
        limit = datasheet.si()
        failing = tuple(u.unit for u in units if (iv := _interval(u)) is not None and iv[0] > limit)
        if datasheet.kind == "typical":  # the median, or the range it lies in
            population_pass = _verdict_of_range(low, high, limit)
        elif ti is not None:  # a maximum: the upper tolerance end, counting bounds at the bound
            population_pass = ti[0][1] <= limit
        elif not bounds:  # one unit
            population_pass = max(values) <= limit
        else:  # every unit under it, or a resolved unit above it
            population_pass = _verdict_of_range(
                max(values, default=0.0), max(values + bounds), limit
            )
    return TermStats(
        axis=axis,
        term=term,
        unit=si_unit,
        units=len(units),
        resolved=len(values),
        median=median,
        median_range=median_range,
        robust_spread=spread,
        tolerance=ti[0] if ti else None,
        method=ti[1] if ti else None,
        outliers=() if len(values) < len(bounds) else outlier_units(units),
        datasheet=datasheet,
        population_pass=population_pass,
        failing_units=failing,
    )


def population(reports: dict[str, dict], datasheet: Datasheet | None = None) -> list[TermStats]:
    """Statistics per axis (report order) and term over the ``reports`` (report.json per unit
    name) of the units that were analysed."""
    out = []
    for axis in AXES:
        docs = {name: r["axes"][axis] for name, r in reports.items() if axis in r["axes"]}
        if not docs:
            continue
        for term in TERM_NAMES:
            terms = {name: final_terms(doc)[term] for name, doc in docs.items()}
            units = [UnitTerm(n, t["value"], t["lo"], t["hi"]) for n, t in terms.items()]
            si_unit = next(iter(terms.values()))["unit"]
            sheet = datasheet.get(sensor_of(axis), term) if datasheet else None
            out.append(term_stats(axis, term, si_unit, units, sheet))
    return out
