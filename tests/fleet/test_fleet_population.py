"""Fleet building blocks without a cluster: discovery, population statistics, datasheet,
the Markdown escaping of untrusted names."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import polars as pl
import pytest

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.analysis.results import ALLAN_SCHEMA
from imupipe.errors import DatasheetError, FleetError
from imupipe.fleet.curves import UNIT_COLUMN, fleet_frame, population_curves
from imupipe.fleet.discover import MAX_NAME, discover, unique_names
from imupipe.fleet.population import (
    BOUNDED_ORDER_METHOD,
    HOWE_METHOD,
    ORDER_METHOD,
    UnitTerm,
    _without_each,
    howe_k,
    order_statistic_rank,
    outlier_units,
    population,
    term_stats,
    tolerance_interval,
)
from imupipe.fleet.report import md_text
from imupipe.fleet.task import budget_for_worker
from imupipe.report.datasheet import Spec, load_datasheet, parse_datasheet
from imupipe.units import RAD_PER_DEG

if TYPE_CHECKING:
    from matplotlib.axes import Axes

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(("n", "table"), [(5, 5.079), (10, 3.379), (20, 2.752)])
def test_howe_k_matches_the_exact_two_sided_table(n, table):
    # exact 95 %/95 % two-sided normal tolerance factors (Odeh 1978; NIST e-Handbook 7.2.6.3);
    # Howe's approximation is within 0.3 % of them
    assert howe_k(n) == pytest.approx(table, rel=3e-3)


def test_order_statistics_need_93_units_at_95_95():
    # the classical minimum sample size for a distribution-free 95 %/95 % two-sided interval
    assert order_statistic_rank(92) is None
    assert order_statistic_rank(93) == 1
    x = np.arange(1.0, 94.0)
    (lo, hi), method = tolerance_interval(x)
    assert (lo, hi, method) == (1.0, 93.0, ORDER_METHOD)


def test_order_statistic_rank_is_the_binomial_one_for_every_n():
    # the coverage of (X(r), X(n+1-r)) is at least p with probability P(Bin(n, p) <= n - 2r)
    # (Hahn & Meeker 1991, §5.3): the largest r with that >= 95 %, computed independently
    from scipy import stats

    for n in (93, 130, 153, 200, 311, 500):
        r = np.arange(1, n // 2 + 1)
        ok = r[stats.binom.cdf(n - 2 * r, n, 0.95) >= 0.95]
        assert order_statistic_rank(n) == int(ok[-1]), n
    assert order_statistic_rank(153) == 2 and order_statistic_rank(500) == 8


def test_small_population_uses_howe_on_log_values():
    values = [1.0, 2.0, 4.0]  # log10 mean log10(2), sd log10(2)
    (lo, hi), method = tolerance_interval(values)
    k = howe_k(3)
    assert method == HOWE_METHOD
    assert lo == pytest.approx(2.0 / 2.0**k)
    assert hi == pytest.approx(2.0 * 2.0**k)
    assert tolerance_interval([1.0]) is None


def _units(values, rel=0.05):
    return [UnitTerm(f"u{i}", v, v * (1 - rel), v * (1 + rel)) for i, v in enumerate(values)]


def test_outlier_is_a_unit_whose_interval_misses_the_others_tolerance_interval():
    rng = np.random.default_rng(1)
    values = list(1e-3 * np.exp(rng.normal(0, 0.05, 12)))
    units = [*_units(values), UnitTerm("hot", 2e-3, 1.9e-3, 2.1e-3)]
    stats = term_stats("gyro_x", "random_walk", "rad/s/sqrt(Hz)", units)
    assert stats.outliers == ("hot",)
    # the same estimate with a wide interval (a short recording) is not called an outlier
    wide = [*_units(values), UnitTerm("hot", 2e-3, 0.8e-3, 4e-3)]
    assert term_stats("gyro_x", "random_walk", "rad/s/sqrt(Hz)", wide).outliers == ()
    assert stats.resolved == 13 and stats.units == 13
    assert stats.median == pytest.approx(float(np.median([*values, 2e-3])))


def test_robust_spread_is_scaled_mad_over_median():
    stats = term_stats("gyro_x", "random_walk", "u", _units([2.0, 2.6, 3.0, 3.5, 10.0]))
    assert stats.median == 3.0  # absolute deviations 1, 0.4, 0, 0.5, 7: MAD 0.5
    assert stats.robust_spread == pytest.approx(1.4826 * 0.5 / 3.0)


def test_an_outlier_needs_three_other_units():
    # two others give Howe's k of 37.7: with fewer than three the unit is never tested
    far = UnitTerm("far", 1e3, 0.99e3, 1.01e3)
    two = [*_units([1.0, 1.1]), far]
    assert term_stats("gyro_x", "random_walk", "u", two).outliers == ()
    three = [*_units([1.0, 1.1, 1.05]), far]
    assert term_stats("gyro_x", "random_walk", "u", three).outliers == ("far",)


def _outliers_by_definition(units):
    """The module's definition, one tolerance interval of the others per unit."""
    out = []
    for u in units:
        others = [o.value for o in units if o.value is not None and o.unit != u.unit]
        mine = (0.0, u.hi) if u.value is None and u.hi is not None else (u.lo, u.hi)
        if (u.value is None and u.hi is None) or len(others) < 3:
            continue
        (lo, hi), _ = tolerance_interval(others)
        if mine[1] < lo or mine[0] > hi:
            out.append(u.unit)
    return tuple(out)


@pytest.mark.parametrize("n", [3, 4, 5, 40, 93, 94, 95, 150, 400])
def test_leave_one_out_outliers_equal_the_definition_at_every_fleet_size(n):
    # the others' order statistics are read off the sorted population instead of sorting it
    # again for every unit: the same units whatever the size (Howe below 94, Wilks above),
    # with ties, unresolved units (with and without a bound) and narrow intervals at the tails
    rng = np.random.default_rng(n)
    values = np.round(1e-3 * np.exp(rng.normal(0, 0.3, n)), 5)  # rounding makes ties
    rel = rng.choice([0.001, 0.02, 0.3], n)
    units = [
        UnitTerm(f"u{i}", v, v * (1 - r), v * (1 + r))
        for i, (v, r) in enumerate(zip(values, rel, strict=True))
    ]
    units[1] = UnitTerm("u1", None, None, 1e-4)  # unresolved, its bound under everyone
    units[2] = UnitTerm("u2", None, None, None)
    units.append(UnitTerm("hot", 9e-3, 8.9e-3, 9.1e-3))
    expected = _outliers_by_definition(units)
    assert outlier_units(units) == expected
    if n >= 40:
        assert "hot" in expected and "u1" in expected  # the test sees both kinds of outlier
    if n >= 150:  # the extremes of a wide population, inside the others' interval or not
        assert len(expected) >= 3
    x = np.sort(values)  # and every interval itself, not only the decisions it makes
    each = [list(tolerance_interval(np.delete(x, j))[0]) for j in range(n)]
    assert _without_each(x).tolist() == each


def test_the_rank_is_computed_once_per_population_size():
    order_statistic_rank.cache_clear()
    units = _units(list(np.linspace(1.0, 2.0, 300)))
    outlier_units(units)
    assert order_statistic_rank.cache_info().misses == 2  # n = 300 (unresolved) and 299


def _sheet(tmp_path, body):
    path = tmp_path / "sheet.toml"
    path.write_text(body)
    return load_datasheet(path)


def test_datasheet_pass_fail(tmp_path):
    sheet = _sheet(
        tmp_path,
        'part = "ADIS"\n[gyro]\nrandom_walk = { value = 2.0, unit = "°/√h" }\n'
        'bias_instability = { value = 0.007, unit = "°/s", kind = "max" }\n',
    )
    limit = 2.0 * RAD_PER_DEG / 60.0
    assert sheet.get("gyro", "random_walk").si() == pytest.approx(limit)
    # median below the typical value: pass; one unit's whole interval above it: failing unit
    bad = UnitTerm("bad", 1.5 * limit, 1.2 * limit, 1.8 * limit)
    units = [*_units([0.5 * limit, 0.6 * limit, 0.7 * limit]), bad]
    st = term_stats("gyro_x", "random_walk", "u", units, sheet.get("gyro", "random_walk"))
    assert st.population_pass is True
    assert st.failing_units == ("bad",)
    # a unit whose interval straddles the value does not fail
    edge = [UnitTerm("edge", 1.1 * limit, 0.9 * limit, 1.3 * limit)]
    st = term_stats("gyro_x", "random_walk", "u", edge, sheet.get("gyro", "random_walk"))
    assert st.failing_units == () and st.population_pass is False  # median above typical
    # a max value is checked against the upper tolerance bound, not the median
    b = 0.007 * RAD_PER_DEG
    st = term_stats("gyro_x", "bias_instability", "u", _units([0.5 * b, 0.6 * b, 0.9 * b]),
                    sheet.get("gyro", "bias_instability"))  # fmt: skip
    assert st.median < b and st.tolerance[1] > b and st.population_pass is False


def test_units_that_only_bound_a_term_give_the_range_the_median_lies_in(tmp_path):
    # two of five units resolve B (their noise lifted it above their bound): their median
    # (3.0) would read as the lot's; the lot's median lies between the median of all five
    # with the bounded units at 0 (0.0) and at their bound (2.0)
    units = [
        *_units([2.0, 4.0]),
        *(UnitTerm(f"b{k}", None, None, hi) for k, hi in enumerate((1.0, 1.5, 2.5))),
    ]
    st = term_stats("gyro_x", "bias_instability", "u", units)
    assert (st.median, st.median_range, st.resolved, st.units) == (None, (0.0, 2.0), 2, 5)
    assert st.robust_spread is None and st.tolerance is None
    # half or more resolved: [0, 0, 2, 4] -> 1.0 and [1, 1.5, 2, 4] -> 1.75, not the resolved 3.0
    st = term_stats("gyro_x", "bias_instability", "u", units[:4])
    assert (st.median, st.median_range) == (None, (1.0, 1.75))
    assert st.robust_spread is None and st.tolerance is None  # Howe's needs every value
    # bounds under the median do not move it: [0, 2, 4, 5, 6] and [0.5, 2, 4, 5, 6] -> 4.0
    low = [*_units([2.0, 4.0, 5.0, 6.0]), UnitTerm("b", None, None, 0.5)]
    st = term_stats("gyro_x", "bias_instability", "u", low)
    assert st.median == 4.0
    # nor the MAD: deviations 2, 0, 1, 2 and the bounded unit's 3.5 to 4 -> 2.0 either way
    assert st.robust_spread == pytest.approx(1.4826 * 2.0 / 4.0)
    # a bound above the median (4) puts that unit 0 to 6 from it: the MAD is 0 or 3, unknown
    wide = [*_units([1.0, 4.0, 4.0, 9.0]), UnitTerm("b", None, None, 10.0)]
    st = term_stats("gyro_x", "bias_instability", "u", wide)
    assert (st.median, st.robust_spread) == (4.0, None)
    # one resolved unit has no spread (its MAD of 0 is not a spread of 0 %)
    one = term_stats("gyro_x", "bias_instability", "u", _units([2.0]))
    assert (one.median, one.robust_spread, one.tolerance) == (2.0, None, None)
    # no outlier of a lot whose tolerance interval is not known
    far = [*_units([2.0, 2.2, 2.4, 2.6]), UnitTerm("far", 2e3, 1.9e3, 2.1e3)]
    bounded = [UnitTerm(f"c{k}", None, None, 3.0) for k in range(6)]
    assert outlier_units(far + bounded) == ("far",)  # the rule alone would name it
    assert term_stats("gyro_x", "bias_instability", "u", far + bounded).outliers == ()
    sheet = _sheet(
        tmp_path,
        'part = "P"\n[gyro]\nbias_instability = { value = 0.25, unit = "rad/s" }\n'
        'rate_random_walk = { value = 3.0, unit = "rad/s^2/sqrt(Hz)", kind = "max" }\n',
    )
    assert sheet.get("gyro", "bias_instability").si() == 0.25
    typical = sheet.get("gyro", "bias_instability")
    assert term_stats("gyro_x", "bias_instability", "u", units, typical).population_pass is None
    low = [
        *_units([0.1, 0.2]),
        *(UnitTerm(f"b{k}", None, None, hi) for k, hi in enumerate((0.05, 0.3, 0.4))),
    ]
    assert term_stats("gyro_x", "bias_instability", "u", low, typical).population_pass is True
    # a typical value under the whole range fails the lot: [0.3, 0.3, 0.5] -> [0.3, 0.4]
    high = [*_units([0.3, 0.5]), UnitTerm("b", None, None, 0.4)]
    st = term_stats("gyro_x", "bias_instability", "u", high, typical)
    assert (st.median_range, st.population_pass) == ((0.3, 0.4), False)
    # a maximum: decided by the extremes (a resolved unit above it fails the lot)
    top = sheet.get("gyro", "rate_random_walk")
    assert term_stats("gyro_x", "rate_random_walk", "u", units, top).population_pass is False
    assert term_stats("gyro_x", "rate_random_walk", "u", units[1:], top).population_pass is False
    under = [*units[:1], *units[2:]]  # 2.0 resolved; bounds 1.0, 1.5, 2.5: max 2.5 <= 3
    assert term_stats("gyro_x", "rate_random_walk", "u", under, top).population_pass is True
    assert term_stats("gyro_x", "rate_random_walk", "u", units[:4], top).population_pass is False
    straddle = [*_units([2.0, 2.5]), UnitTerm("b", None, None, 3.5)]  # max 2.5 <= 3 < 3.5
    assert term_stats("gyro_x", "rate_random_walk", "u", straddle, top).population_pass is None


def test_the_distribution_free_interval_counts_bounded_units_at_zero_and_at_their_bound():
    # 250 units (r = 3): 248 resolved 1..248 and two bounded at 0.5 and 500; the lot's third
    # smallest is at least 1 (0, 0, 1 with the bounded units at 0) and its third largest at
    # most 247 (247, 248, 500 with them at their bound)
    values = [float(v) for v in range(1, 249)]
    units = [*_units(values), UnitTerm("b0", None, None, 0.5), UnitTerm("b1", None, None, 500.0)]
    assert order_statistic_rank(250) == 3
    st = term_stats("gyro_x", "random_walk", "u", units)
    assert st.tolerance == (1.0, 247.0) and st.method == BOUNDED_ORDER_METHOD
    assert st.median is None and st.median_range == (123.5, 124.5)  # the 125th and 126th
    # as many bounded units as the rank: the lower end is 0, no interval
    three = [*units, UnitTerm("b2", None, None, 0.7)]
    assert term_stats("gyro_x", "random_walk", "u", three).tolerance is None
    four = [*three, UnitTerm("b3", None, None, 0.8)]  # more bounded units than the rank
    assert term_stats("gyro_x", "random_walk", "u", four).tolerance is None
    # a maximum is judged by that interval's upper end
    sheet = Spec(value=247.0, unit="rad/s/sqrt(Hz)", kind="max")
    assert term_stats("gyro_x", "random_walk", "u", units, sheet).population_pass is True


def test_the_median_range_reaches_fleet_json_and_fleet_md():
    from imupipe.fleet.report import _stats_json, population_rows

    def rw(units):
        return term_stats("gyro_x", "random_walk", "rad/s/sqrt(Hz)", units)

    half = rw([*_units([2e-3, 4e-3]), UnitTerm("b", None, None, 1e-3)])  # [0, 2, 4], [1, 2, 4]
    most = rw([*_units([2e-3]), *(UnitTerm(f"b{k}", None, None, 1e-3) for k in range(2))])
    exact = rw(_units([2e-3, 4e-3, 5e-3]))
    doc = _stats_json(most)
    assert (doc["median"], doc["median_lower_bound"], doc["median_upper_bound"]) == (
        None, 0.0, 1e-3
    )  # fmt: skip
    assert _stats_json(half)["median"] == 2e-3 and _stats_json(half)["median_upper_bound"] is None
    straddle = rw([*_units([2e-3, 4e-3]), UnitTerm("b", None, None, 3e-3)])  # 2 and 3 (e-3)
    assert (_stats_json(straddle)["median_lower_bound"], _stats_json(straddle)["median"]) == (
        2e-3, None
    )  # fmt: skip
    deg = 180 / math.pi  # rad/s/sqrt(Hz) -> the paper's °/√s
    rows = {i: r[4:6] for i, r in enumerate(population_rows([most, straddle, exact, half]))}
    assert rows[0] == (f"≤ {1e-3 * deg:.4g}", "—")
    assert rows[1] == (f"{2e-3 * deg:.4g} – {3e-3 * deg:.4g}", "—")
    # the robust spread: 1.4826 × the MAD (1e-3) over the median (4e-3), in %
    assert exact.robust_spread == pytest.approx(1.4826 * 1e-3 / 4e-3, rel=1e-4)
    assert rows[2] == (f"{4e-3 * deg:.4g}", "37 %")
    lo, hi = exact.tolerance
    assert lo < 4e-3 < hi
    assert population_rows([exact])[0][6] == f"[{lo * deg:.4g}, {hi * deg:.4g}]"
    assert _stats_json(exact)["tolerance"] | {"method": None} == {
        "lo": lo, "hi": hi, "coverage": 0.95, "confidence": 0.95, "method": None
    }  # fmt: skip
    assert rows[3] == (f"{2e-3 * deg:.4g}", "—")  # exact, but no spread with a bound


def test_fleet_json_with_a_datasheet_and_a_failed_unit_matches_its_schema(tmp_path, schema_errors):
    """fleet.json as the schema (schemas/fleet.schema.json) declares it, with every branch a
    population can take: a datasheet verdict, a tolerance interval, terms only bounded, a failed
    unit; and what the schema's subset check finds wrong in a broken copy."""
    from imupipe.fleet.report import fleet_json
    from imupipe.fleet.task import UnitOutcome

    schema = json.loads((ROOT / "schemas" / "fleet.schema.json").read_text())
    sheet = _sheet(tmp_path, 'part = "A"\n[gyro]\nrandom_walk = { value = 2.0, unit = "°/√h" }\n')
    spec = sheet.get("gyro", "random_walk")
    lot = _units([0.5 * spec.si(), 0.6 * spec.si(), 0.7 * spec.si()])
    stats = [
        term_stats("gyro_x", "random_walk", "rad/s/sqrt(Hz)", lot, spec),
        term_stats("gyro_x", "rate_ramp", "rad/s^2", [UnitTerm("b", None, None, 1e-7)]),
    ]
    failed = UnitOutcome("bad", "bad.mcap", "failed", "not MCAP", None, None, 0.1, "h:1")
    n = {"value": 1e-4, "lo": 9e-5, "hi": 1.1e-4, "unit": "rad/s/sqrt(Hz)", "reason": None}
    temp = {"kind": "temperature", "params": {"coefficient": 2e-5}, "error_before": 4.1,
            "error_after": 1.02}  # fmt: skip
    report = {
        "input": {"topic": "/imu", "frames": 360_000, "rate_hz": 100.0, "duration_s": 3600.0},
        "axes": {
            "gyro_x": {"sensor": "gyro", "ieee952": {"random_walk": n}},  # no loop run
            "gyro_y": {  # the loop's terms after an effect are the unit's final ones
                "sensor": "gyro",
                "ieee952": {"random_walk": {**n, "value": 3e-4}},
                "ieee952_after": {"random_walk": n},
                "effects": [temp],
            },
        },
    }
    top = {"window_s": 64.0, "value": 0.85}
    pair = {"axes": ["accel_x", "accel_y"], "p_value": 1e-20, "strongest": top,
            "significant_window_s": [64.0], "correlation": [top]}  # fmt: skip
    report["events"] = {"common_mode": {"pairs": [pair]}}
    good = UnitOutcome("good", "s3://lot/good.mcap", "ok", None, report, None, 2.5, "h:2")
    curve = {"tau": [1.0], "median": [1e-3], "lo": [float("nan")], "hi": [2e-3], "units": [3]}
    pop = pl.DataFrame({"axis": ["gyro_x"], "unit": ["rad/s"], **curve})
    doc = json.loads(json.dumps(fleet_json([failed, good], stats, pop, sheet)))
    assert doc["units"][1]["input"] == report["input"] and doc["units"][1]["folder"] == "good"
    assert doc["units"][1]["axes"] == {
        "gyro_x": {"sensor": "gyro", "terms_after_loop": False, "terms": {"random_walk": n},
                   "effects": []},
        "gyro_y": {"sensor": "gyro", "terms_after_loop": True, "terms": {"random_walk": n},
                   "effects": [temp]},
    }  # fmt: skip
    assert doc["units"][0]["axes"] == {} and doc["units"][0]["folder"] is None
    assert doc["units"][1]["axes_moving_together"] == [
        {"axes": ["accel_x", "accel_y"], "strongest": top}
    ]
    assert "axes_moving_together" not in doc["units"][0]  # failed: nothing was searched
    assert schema_errors(doc, schema, schema) == []
    assert doc["population"][0]["datasheet"]["population_pass"] is True
    assert doc["population_adev"]["gyro_x"]["lo"] == [None]  # NaN written as null
    doc["units"][0]["status"] = "skipped"
    doc["population"][0]["datasheet"]["population_pass"] = "yes"
    doc["population_adev"]["gyro_q"] = doc["population_adev"]["gyro_x"]
    assert schema_errors(doc, schema, schema) == [
        "$.units[0].status: 'skipped' not in ['ok', 'failed']",
        "$.population[0].datasheet.population_pass: str is not ['boolean', 'null']",
        "$.population_adev: key gyro_q not allowed",
    ]


def test_population_verdicts_at_their_boundaries(tmp_path):
    # a typical value equal to the median passes; a kind spelled out in the file is the same
    # as the default (compared by value)
    sheet = _sheet(
        tmp_path,
        'part = "P"\n[gyro]\nrandom_walk = { value = 2.0, unit = "rad/s/sqrt(Hz)", '
        'kind = "typical" }\nbias_instability = { value = 2.0, unit = "rad/s", kind = "max" }\n',
    )
    typical, top = sheet.get("gyro", "random_walk"), sheet.get("gyro", "bias_instability")
    at = _units([1.0, 2.0, 3.0])
    assert term_stats("gyro_x", "random_walk", "u", at, typical).population_pass is True
    # a maximum over the upper tolerance end fails, under it passes
    tight = [UnitTerm(f"u{i}", v, v, v) for i, v in enumerate((1.0, 1.01, 1.02, 0.99))]
    st = term_stats("gyro_x", "bias_instability", "u", tight, top)
    assert st.tolerance[1] < 2.0 and st.population_pass is True
    # one unit: at the maximum passes, above it fails
    one = [UnitTerm("u", 2.0, 1.0, 3.0)]
    assert term_stats("gyro_x", "bias_instability", "u", one, top).population_pass is True
    over = [UnitTerm("u", 2.5, 1.0, 3.0)]
    assert term_stats("gyro_x", "bias_instability", "u", over, top).population_pass is False
    under = [UnitTerm("u", 1.5, 1.0, 3.0)]
    assert term_stats("gyro_x", "bias_instability", "u", under, top).population_pass is True
    # a median range from the typical value up is undecided: [2, 2, 4] and [2, 3, 4]
    above = [*_units([2.0, 4.0]), UnitTerm("b", None, None, 3.0)]
    st = term_stats("gyro_x", "random_walk", "u", above, typical)
    assert (st.median_range, st.population_pass) == ((2.0, 3.0), None)
    # a unit fails only when its whole interval is above the value, not from its edge on
    edge = [*_units([1.0, 1.1, 1.2]), UnitTerm("edge", 3.0, 2.0, 4.0)]
    assert term_stats("gyro_x", "random_walk", "u", edge, typical).failing_units == ()
    # every unit only bounds it: a maximum between the bounds is undecided, not failed
    bounded = [UnitTerm("b0", None, None, 0.3), UnitTerm("b1", None, None, 0.7)]
    half = _sheet(
        tmp_path,
        'part = "P"\n[gyro]\nbias_instability = { value = 0.5, unit = "rad/s", kind = "max" }\n',
    ).get("gyro", "bias_instability")
    assert term_stats("gyro_x", "bias_instability", "u", bounded, half).population_pass is None


def test_the_spread_with_bounded_units_is_the_mad_of_every_lot_they_allow():
    # brute force: each bounded unit anywhere on a grid of [0, b] holding 0, b and the median
    # (where |x - median| has its extremes); the spread is given exactly when every such lot
    # has the same MAD, and is then that MAD
    rng = np.random.default_rng(26)
    given = unknown = 0
    for _ in range(400):
        values = [float(v) for v in rng.integers(1, 10, rng.integers(3, 8))]
        bounds = [
            float(b) for b in rng.choice([0.5, 2.0, 4.0, 5.0, 7.0, 12.0, 20.0], rng.integers(1, 3))
        ]
        units = [*_units(values), *(UnitTerm(f"b{k}", None, None, b) for k, b in enumerate(bounds))]
        st = term_stats("gyro_x", "random_walk", "u", units)
        if st.median is None:
            continue
        grids = [np.unique(np.r_[np.linspace(0, b, 9), min(b, st.median)]) for b in bounds]
        mads = set()
        for xs in itertools.product(*grids):
            lot = np.array([*values, *xs])
            assert np.median(lot) == st.median
            mads.add(float(np.median(np.abs(lot - st.median))))
        if len(mads) == 1:
            given += 1
            assert st.robust_spread == pytest.approx(1.4826 * mads.pop() / st.median, rel=1e-12)
        else:
            unknown += 1
            assert st.robust_spread is None
    assert given > 30 and unknown > 30  # both outcomes exercised


def test_spread_of_two_units_and_outliers_with_as_many_bounded_as_resolved():
    two = term_stats("gyro_x", "random_walk", "u", _units([2.0, 4.0]))
    assert two.robust_spread == pytest.approx(1.4826 * 1.0 / 3.0)
    # four resolved, four bounded: the lot's tolerance interval is that of the resolved units,
    # and a unit far outside it is named
    far = [*_units([2.0, 2.2, 2.4, 2.6]), UnitTerm("far", 2e3, 1.9e3, 2.1e3)]
    bounded = [UnitTerm(f"c{k}", None, None, 3.0) for k in range(5)]
    assert term_stats("gyro_x", "random_walk", "u", far + bounded).outliers == ("far",)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("[gyro]\nrandom_wlk = { value = 1.0, unit = 'rad' }\n", "use N, B, K or rms"),
        ("[gyro]\nrandom_walk = { value = 1.0, unit = 'furlong' }\n", "unit 'furlong' unknown"),
        ("[magnetometer]\nrandom_walk = { value = 1.0, unit = 'rad' }\n", "unknown section"),
        ("[gyro]\nrandom_walk = { value = -1.0, unit = 'rad' }\n", "is not a number >= 0"),
        ("[gyro]\nrandom_walk = { value = inf, unit = 'rad' }\n", "value inf is not a number"),
        ("[gyro]\nrandom_walk = { value = '1.0', unit = 'rad' }\n", "value '1.0' is not a"),
        ("[gyro]\nrandom_walk = { value = 1.0 }\n", r"must be \{value = \.\.\., unit"),
        ("[gyro]\nrandom_walk = { value = 1.0, unit = 'rad', note = 'x' }\n", "must be"),
        ("[gyro]\nrandom_walk = { value = 1.0, unit = 'rad', kind = 'min' }\n", "kind"),
        ("[gyro\n", "not TOML"),
        ("part = 'x'\n", r"no \[gyro\] or \[accel\] values"),
    ],
)
def test_bad_datasheet_is_one_clear_error(tmp_path, body, message):
    with pytest.raises(DatasheetError, match=message):
        _sheet(tmp_path, body)


def test_a_datasheet_value_of_zero_is_a_value():
    sheet = parse_datasheet("[gyro]\nrate_random_walk = { value = 0, unit = 'rad' }\n", "x")
    assert sheet.specs[("gyro", "rate_random_walk")].value == 0.0


def test_population_uses_terms_after_the_loop():
    def doc(before, after):
        term = {"value": before, "lo": before, "hi": before, "unit": "u", "reason": None}
        final = {**term, "value": after, "lo": after, "hi": after}
        terms = {t: term for t in ("quantization", "random_walk", "bias_instability",
                                   "rate_random_walk", "rate_ramp")}  # fmt: skip
        after = {**terms, "random_walk": final}
        return {"axes": {"gyro_x": {"ieee952": terms, "ieee952_after": after}}}

    stats = population({"a": doc(1.0, 3.0), "b": doc(1.0, 5.0)})
    rw = next(s for s in stats if s.term == "random_walk")
    assert rw.median == 4.0 and rw.axis == "gyro_x"
    assert next(s for s in stats if s.term == "quantization").median == 1.0
    # axes no unit has (a one-axis recording: gyro_x only, or accel_z only) are skipped
    accel_z = {"a": {"axes": {"accel_z": doc(1.0, 3.0)["axes"]["gyro_x"]}}}
    assert {(s.axis, s.term) for s in population(accel_z)} == {
        ("accel_z", t) for t in ("quantization", "random_walk", "bias_instability",
                                 "rate_random_walk", "rate_ramp")
    }  # fmt: skip


def test_discover_files_bags_folders_globs(tmp_path):
    (tmp_path / "a.mcap").write_bytes(b"x")
    bag = tmp_path / "site" / "robot 7"
    bag.mkdir(parents=True)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "robot 7_0.mcap").write_bytes(b"x")
    (tmp_path / "site" / "a.mcap").write_bytes(b"x")
    (tmp_path / "site" / "notes.txt").write_text("not a recording")
    (tmp_path / "site" / "humble.db3").write_bytes(b"x")  # rosbag2's SQLite storage, bare
    recs = discover([str(tmp_path / "site"), str(tmp_path / "*.mcap"), str(tmp_path / "a.mcap")])
    # the bag once (not its split file), the nested a.mcap, the top a.mcap once (glob + file)
    assert [(r.name, r.is_dir, r.local) for r in recs] == [
        ("robot_7", True, True),
        ("site_a", False, True),  # two a.mcap: told apart by their folders
        ("humble", False, True),
        (f"{tmp_path.name}_a", False, True),
    ]
    assert recs[0].location == str(bag)
    with pytest.raises(FleetError, match="no recording"):
        discover([str(tmp_path / "missing")])
    with pytest.raises(FleetError, match="no recording"):
        discover([str(tmp_path / "site" / "*.bag")])
    (tmp_path / "ros1" / "day 2").mkdir(parents=True)  # ROS 1 bags only: named, not read
    for name in ("a.bag", "day 2/b.bag"):
        (tmp_path / "ros1" / name).write_bytes(b"#ROSBAG V2.0\n")
    with pytest.raises(FleetError) as refused:
        discover([str(tmp_path / "ros1")])
    assert str(refused.value) == (
        f"{tmp_path / 'ros1'}: no recording there (no such path, or no MCAP file or bag); it "
        "holds 2 ROS 1 bag(s): a ROS 1 bag converts to a ROS 2 one with `rosbags-convert "
        "--src BAG --dst DIR`"
    )


def test_discover_follows_links_to_bags_and_folders_once(tmp_path):
    """A folder of symbolic links (to a rosbag2 directory, to a folder of MCAP files, to a
    file) yields every linked recording, named by its link, once: a link back up the tree and
    a second link to the same folder add nothing (fsspec's ``find`` lists a link to a
    directory as a leaf: until session 50 such units were dropped without a word)."""
    store = tmp_path / "store"
    bag = store / "imu1"
    bag.mkdir(parents=True)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "imu1_0.mcap").write_bytes(b"x")
    (store / "sims").mkdir()
    (store / "sims" / "sim_0.mcap").write_bytes(b"x")
    (store / "lone.mcap").write_bytes(b"x")
    fleet = tmp_path / "fleet"
    fleet.mkdir()
    (fleet / "unit_a").symlink_to(bag)
    (fleet / "simulated").symlink_to(store / "sims")
    (fleet / "again").symlink_to(store / "sims")  # the same folder twice
    (fleet / "up").symlink_to(fleet)  # two loops: followed, they would branch 2**40 times
    (fleet / "z_up").symlink_to(fleet)
    (fleet / "b.mcap").symlink_to(store / "lone.mcap")
    recs = discover([str(fleet)])
    assert [(r.name, r.is_dir) for r in recs] == [
        ("sim_0", False),
        ("b", False),
        ("unit_a", True),
    ]
    assert recs[0].location == str(fleet / "again" / "sim_0.mcap")  # listed before "simulated"
    assert recs[2].location == str(fleet / "unit_a")
    assert [r.name for r in discover([str(fleet / "unit_a"), str(bag)])] == ["unit_a"]


def test_unit_names_are_safe_and_unique():
    assert unique_names(["/x/../a b.mcap", "/y/a b.mcap", "/z/a_b-2.mcap", "/w/.hidden"]) == [
        "x_a_b",
        "y_a_b",
        "a_b-2",
        "hidden",
    ]


def test_a_folder_is_used_up_to_a_name_of_exactly_max_name_characters():
    fits = "f" * (MAX_NAME - len("_calib"))  # with it, the name is MAX_NAME long: used
    names = unique_names([f"{fits}/calib.mcap", f"g{fits[1:]}/calib.mcap"])
    assert names == [f"{fits}_calib", f"g{fits[1:]}_calib"] and len(names[0]) == MAX_NAME
    over = fits + "f"  # one character more: the folders are not used, the names numbered
    assert unique_names([f"{over}/calib.mcap", f"g{over[1:]}/calib.mcap"]) == ["calib", "calib-2"]


def test_recordings_named_alike_are_told_apart_by_their_folders():
    # one calibration bag per robot and week (files or rosbag2 folders): the unit names say
    # which robot, with as few folders as it takes, and stay unique for a fleet of any size
    bags = [f"fleet/robot-{i}/calib.mcap" for i in range(1000)]
    assert unique_names(bags)[:2] == ["robot-0_calib", "robot-1_calib"]
    assert len(set(unique_names(bags))) == 1000
    weeks = ["b/robot-1/w48", "b/robot-2/w48", "b/robot-1/w49", "b/x/robot-1/w48"]
    assert unique_names(weeks) == ["b_robot-1_w48", "robot-2_w48", "w49", "x_robot-1_w48"]
    # folders that would make a name too long for a file system are not used
    deep = "/".join(f"level-{k:03d}" for k in range(40))
    long_ones = unique_names([f"site-a/{deep}/calib.mcap", f"site-b/{deep}/calib.mcap"])
    assert long_ones == ["calib", "calib-2"]
    assert len(unique_names([f"{deep}/{k}/calib.mcap" for k in "ab"])[0]) <= MAX_NAME
    # the same path twice (two file systems), and a name made equal to another one
    assert unique_names(["a/u.mcap", "a/u.mcap", "a/b/u.mcap", "a_u.mcap"]) == [
        "u",
        "u-2",
        "b_u",
        "a_u",
    ]


def test_md_text_escapes_markup():
    assert md_text("a|b`c`<script>\n[x](y)") == r"a|b\`c\`\<script\> \[x\](y)"


def test_the_client_plans_the_figures_without_importing_matplotlib(tmp_path):
    """The fleet's client writes the report while its workers draw the figures: importing
    matplotlib there (~1 s) would delay the figure jobs at the end of every fleet."""
    import subprocess
    import sys

    code = (
        "import sys; from pathlib import Path; import imupipe.fleet.run; "
        "from imupipe.fleet.report import write_fleet_report; "
        "from imupipe.fleet.task import UnitOutcome; jobs = []; "
        "u = UnitOutcome('a', 'a.mcap', 'failed', 'not MCAP', None, None, 0.1, 'h:1'); "
        f"write_fleet_report([u], Path({str(tmp_path)!r}), rrd=False, "
        "mapper=lambda f, js: jobs.extend(js) or [None] * len(js)); "
        "print([name for name, _ in jobs], 'matplotlib' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split("] ")[1].strip() == "False"
    assert out.stdout.count("adev_figure") == 2 and out.stdout.count("terms_figure") == 2


def test_population_curve_is_the_median_and_band_of_the_units():
    tau = np.array([1.0, 10.0, 100.0])

    def curve(scale):
        n = len(tau)
        return pl.DataFrame(
            {"axis": ["gyro_x"] * n, "unit": ["rad/s"] * n, "tau": tau,
             "adev": scale / np.sqrt(tau), "lo": np.nan, "hi": np.nan, "edf": 1.0,
             "terms": 1, "alpha": 0.0,
             "adev_after": np.nan, "model_before": np.nan, "model_after": np.nan,
             "z_before": np.nan, "z_after": np.nan},
            schema=ALLAN_SCHEMA,
        )  # fmt: skip

    fleet = fleet_frame({"a": curve(1.0), "b": curve(2.0), "c": curve(4.0)})
    assert fleet["unit_name"].to_list() == ["a"] * 3 + ["b"] * 3 + ["c"] * 3
    pop = population_curves(fleet)
    at10 = pop.filter((pl.col("tau") - 10.0).abs() < 1e-9)
    assert at10["median"][0] == pytest.approx(2.0 / math.sqrt(10.0))
    assert at10["units"][0] == 3
    # 2.5th/97.5th percentiles of log10 values (0, log 2, log 4) -> close to the extremes
    assert at10["lo"][0] == pytest.approx(10 ** (0.05 * math.log10(2)) / math.sqrt(10.0))
    # a τ that only one of three units reaches is not the population's
    longer = curve(1.0).with_columns(pl.col("tau") * 10)
    pop = population_curves(fleet_frame({"a": longer, "b": curve(2.0), "c": curve(4.0)}))
    assert pop["tau"].max() == pytest.approx(100.0)
    # ... but one of two units is half of them: "at least half" keeps it
    pop = population_curves(fleet_frame({"a": longer, "b": curve(2.0)}))
    assert pop["tau"].max() == pytest.approx(1000.0) and pop["units"][-1] == 1


def test_a_large_fleets_units_fade_and_its_outliers_and_tolerance_stay_on_top(monkeypatch):
    # 300 units' intervals drawn opaque are one black mass over the tolerance band
    from imupipe.fleet import figures
    from imupipe.vocab import TERM_NAMES

    drawn = []
    monkeypatch.setattr(figures, "_png", lambda fig: drawn.append(fig) or b"")
    rng = np.random.default_rng(3)

    def report(n):
        terms = {t: {"value": n, "lo": 0.99 * n, "hi": 1.01 * n, "unit": "u"} for t in TERM_NAMES}
        return {"axes": {"gyro_x": {"ieee952": terms}}}

    reports = {f"u{i}": report(float(v)) for i, v in enumerate(rng.lognormal(0, 0.05, 300))}
    reports["hot"] = report(2.0)
    figures.terms_figure(reports, population(reports), "gyro")
    panel = drawn[0].axes[0]  # N
    lines = [ln for ln in panel.lines if len(ln.get_xdata()) > 0]
    units, hot = (next(ln for ln in lines if ln.get_color() == c) for c in ("k", "tab:orange"))
    assert units.get_alpha() == pytest.approx(30 / 301)
    assert len(units.get_xdata()) + len(hot.get_xdata()) == 301  # "hot" and the tails' few
    assert hot.get_alpha() == 1.0 and hot.get_zorder() > units.get_zorder()
    edges = [c for c in panel.collections if c.get_zorder() == 3]
    assert len(edges) == 1 and len(edges[0].get_segments()) == 2  # the tolerance's lo and hi
    assert figures._unit_alpha(24) == 1.0


def test_a_strip_plot_shows_its_units_not_a_tolerance_interval_of_two(monkeypatch):
    # Howe's interval of two units spans ~18 decades here: the view follows the units
    from imupipe.fleet import figures
    from imupipe.vocab import TERM_NAMES

    drawn = []
    monkeypatch.setattr(figures, "_png", lambda fig: drawn.append(fig) or b"")

    def report(n):
        terms = {t: {"value": n, "lo": 0.9 * n, "hi": 1.1 * n, "unit": "u"} for t in TERM_NAMES}
        return {"axes": {"gyro_x": {"ieee952": terms}}}

    reports = {"a": report(1e-5), "b": report(2e-5)}
    stats = population(reports)
    (ti,) = [st.tolerance for st in stats if st.term == "random_walk"]
    assert ti[1] / ti[0] > 1e6
    figures.terms_figure(reports, stats, "gyro")
    lo, hi = drawn[0].axes[0].get_ylim()
    unit = 180 / math.pi  # rad → ° (the paper's unit)
    assert lo == pytest.approx(0.9e-5 * unit / 1.3) and hi == pytest.approx(2.2e-5 * unit * 1.3)


def _curves(axes: tuple[str, ...], scales: dict[str, float]) -> pl.DataFrame:
    """Fleet curves (``fleet_frame``) of one unit per ``scales`` entry: adev = scale / √τ times
    1, 2, 3... on each of ``axes`` in turn (so that a panel holding another axis' curves shows),
    in its sensor's unit."""
    tau = np.array([0.1, 1.0, 10.0, 100.0])

    def curve(scale: float) -> pl.DataFrame:
        frames = []
        for k, axis in enumerate(axes):
            n, unit = len(tau), "m/s^2" if axis.startswith("accel") else "rad/s"
            frames.append(
                pl.DataFrame(
                    {
                        "axis": [axis] * n,
                        "unit": [unit] * n,
                        "tau": tau,
                        "adev": (k + 1) * scale / np.sqrt(tau),
                        "lo": np.nan,
                        "hi": np.nan,
                        "edf": 1.0,
                        "terms": 1,
                        "alpha": 0.0,
                        "adev_after": np.nan,
                        "model_before": np.nan,
                        "model_after": np.nan,
                        "z_before": np.nan,
                        "z_after": np.nan,
                    },
                    schema=ALLAN_SCHEMA,
                )
            )
        return pl.concat(frames)

    return fleet_frame({name: curve(s) for name, s in scales.items()})


def _drawn(monkeypatch: pytest.MonkeyPatch) -> list:
    """The figures the fleet's figure functions draw (their PNG encoding replaced)."""
    from imupipe.fleet import figures

    drawn: list = []
    monkeypatch.setattr(figures, "_png", lambda fig: drawn.append(fig) or b"png")
    return drawn


def _margins(fig) -> tuple[float, ...]:
    """A fleet figure's subplot margins: (left, right, bottom, top, wspace) of its grid."""
    pars = fig.axes[0].get_gridspec().get_subplot_params(fig)
    return (pars.left, pars.right, pars.bottom, pars.top, pars.wspace)


def test_the_adev_figure_draws_each_axis_units_over_the_population_band_and_median(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """fleet_adev_<sensor>.png: one 4.2 in panel per axis of the sensor present, in the fixed
    margins; each holds that axis' units only (grey, 0.7 wide, 0.7 opaque) over its population's
    95 % band and edges (blue, 0.25 opaque; 0.8 wide) and median (2.0 wide); the sensor's unit
    on the first panel with the legend's three entries; no figure for a sensor without axes."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_hex

    from imupipe.fleet import figures

    drawn = _drawn(monkeypatch)
    fleet = _curves(("accel_x", "gyro_x", "gyro_y"), {"a": 1.0, "b": 2.0, "c": 4.0})
    pop = population_curves(fleet)
    assert figures.adev_figure(fleet, pop, "gyro") == b"png"
    gyro_only = fleet.filter(pl.col("axis") != "accel_x")
    assert figures.adev_figure(gyro_only, pop, "accel") is None
    (fig,) = drawn
    assert tuple(fig.get_size_inches()) == pytest.approx((8.4, 4.2))
    assert _margins(fig) == (0.07, 0.99, 0.12, 0.86, 0.28)
    assert fig.get_suptitle() == "Gyroscopes: Allan deviation of 3 units"
    assert [ax.get_title() for ax in fig.axes] == ["gyro_x", "gyro_y"]
    for ax, axis in zip(fig.axes, ("gyro_x", "gyro_y"), strict=True):
        assert (ax.get_xscale(), ax.get_yscale()) == ("log", "log")
        assert ax.get_xlabel() == "averaging time τ [s]"
        grid = [*ax.xaxis.get_gridlines(), *ax.yaxis.get_gridlines()]
        assert {(g.get_linewidth(), g.get_alpha()) for g in grid} == {(0.4, 0.6)}
        mine = fleet.filter(pl.col("axis") == axis)
        (units,) = [c for c in ax.collections if isinstance(c, LineCollection)]
        segments = units.get_segments()
        assert len(segments) == 3
        for seg, (_, unit) in zip(
            segments, mine.group_by(UNIT_COLUMN, maintain_order=True), strict=True
        ):
            assert seg.tolist() == np.column_stack([unit["tau"], unit["adev"]]).tolist()
        assert units.get_linewidth().tolist() == [0.7]
        assert units.get_alpha() == pytest.approx(0.7)
        assert units.get_edgecolor()[0][:3].tolist() == pytest.approx([0.45] * 3)
        p = pop.filter(pl.col("axis") == axis)
        (band,) = [c for c in ax.collections if c is not units and len(c.get_paths()) > 0]
        ys = band.get_paths()[0].vertices[:, 1]
        assert (ys.min(), ys.max()) == pytest.approx((p["lo"].min(), p["hi"].max()))
        assert band.get_alpha() == 0.25 and to_hex(band.get_facecolor()[0]) == to_hex("tab:blue")
        assert band.get_linewidth().tolist() == [0]  # no edge: the edges are the lines below
        lines = [ln for ln in ax.lines if len(ln.get_xdata()) > 0]
        assert [ln.get_ydata().tolist() for ln in lines] == [
            p["lo"].to_list(),
            p["hi"].to_list(),
            p["median"].to_list(),
        ]
        assert [(ln.get_linewidth(), ln.get_zorder(), ln.get_color()) for ln in lines] == [
            (0.8, 3, "tab:blue"), (0.8, 3, "tab:blue"), (2.0, 3, "tab:blue")
        ]  # fmt: skip
        lo, hi = ax.get_ylim()  # the view holds every unit's curve
        assert lo <= mine["adev"].min() and hi >= mine["adev"].max()
    assert [ax.get_ylabel() for ax in fig.axes] == ["Allan deviation σ(τ) [rad/s]", ""]
    legend = fig.axes[0].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == [
        "each unit", "population median", "95 % of units"
    ]  # fmt: skip
    assert fig.axes[1].get_legend() is None
    assert {t.get_fontsize() for t in legend.get_texts()} == {7}
    grey, median = legend.get_lines()
    assert (grey.get_linewidth(), grey.get_color()) == (0.7, "0.45")
    assert (median.get_linewidth(), median.get_color()) == (2.0, "tab:blue")
    # a fleet of 60: each unit's curve fades to 0.7 × 30 / 60
    figures.adev_figure(_curves(("gyro_z",), {f"u{k}": 1.0 + k for k in range(60)}), pop, "gyro")
    (units,) = [c for c in drawn[1].axes[0].collections if isinstance(c, LineCollection)]
    assert len(units.get_segments()) == 60 and units.get_alpha() == pytest.approx(0.35)
    assert tuple(drawn[1].get_size_inches()) == pytest.approx((4.2, 4.2))


def _strip_reports(names: dict[str, tuple[float | None, float | None, float | None]]) -> dict:
    """report.json per unit: every term (value, lo, hi) on gyro_x and twice that on gyro_y."""
    from imupipe.vocab import TERM_NAMES

    def report(value: float | None, lo: float | None, hi: float | None) -> dict:
        def twice(x: float | None) -> float | None:
            return None if x is None else 2 * x

        axes = {}
        for axis, f in (("gyro_x", lambda x: x), ("gyro_y", twice)):
            terms = {t: {"value": f(value), "lo": f(lo), "hi": f(hi), "unit": "u"}
                     for t in TERM_NAMES}  # fmt: skip
            axes[axis] = {"ieee952": terms}
        return {"axes": axes}

    return {name: report(*v) for name, v in names.items()}


def _data(ax: Axes) -> dict[str, list[float]]:
    """A strip panel's errorbars with data, per kind (colour): x, y, the bar's lower and upper
    end of each point, in a row."""
    out: dict[str, list[float]] = {}
    for c in ax.containers:
        line = c.lines[0]
        if len(line.get_xdata()) == 0:
            continue
        (bars,) = c.lines[2]
        ends = [(s[0][1], s[1][1]) for s in bars.get_segments()]
        points = zip(line.get_xdata(), line.get_ydata(), ends, strict=True)
        out[line.get_color()] = [float(v) for x, y, (lo, hi) in points for v in (x, y, lo, hi)]
    return out


def test_the_terms_figure_places_each_units_interval_bound_tolerance_and_datasheet(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """fleet_terms_<sensor>.png: three 4.2 in panels (N, B, K in the paper's units); per axis
    (x = 0, 1), each unit at its own offset (−0.3, 0, +0.3 for three) with its 95 % interval
    (black; an outlier orange, on top), an unresolved unit's upper bound (grey ▽), the tolerance
    interval (blue, ±0.4) and the datasheet value (red dashes, ±0.45); their legend entries."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import to_hex

    from imupipe.fleet import figures

    drawn = _drawn(monkeypatch)
    f = 180 / math.pi  # rad → °
    reports = _strip_reports(
        {"a": (1e-4, 0.9e-4, 1.2e-4), "b": (2e-4, None, None), "c": (None, None, 3e-4)}
    )
    stats = [
        dataclasses.replace(
            st, tolerance=(0.5e-4, 4e-4), outliers=("b",), datasheet=Spec(0.02, "°/√s")
        )
        if (st.axis, st.term) == ("gyro_x", "random_walk")
        else st
        for st in population(reports)
    ]
    assert figures.terms_figure(reports, stats, "gyro") == b"png"
    assert figures.terms_figure(reports, stats, "accel") is None
    (fig,) = drawn
    assert tuple(fig.get_size_inches()) == pytest.approx((12.6, 4.2))
    assert _margins(fig) == (0.07, 0.99, 0.12, 0.86, 0.28)
    assert fig.get_suptitle() == "Gyroscopes: noise terms of 3 units"
    assert [ax.get_title() for ax in fig.axes] == ["N [°/√s]", "B [°/s]", "K [°/s/√s]"]
    for ax in fig.axes:
        assert [t.get_text() for t in ax.get_xticklabels()] == ["gyro_x", "gyro_y"]
        assert ax.get_xticks().tolist() == [0, 1]
    n, b, _ = fig.axes
    # N: "a" black on both axes, "b" an outlier on gyro_x only, with no interval
    data = _data(n)
    assert data.keys() == {"k", "tab:orange"}
    assert data["k"] == pytest.approx([-0.3, 1e-4 * f, 0.9e-4 * f, 1.2e-4 * f,
                                       0.7, 2e-4 * f, 1.8e-4 * f, 2.4e-4 * f,
                                       1.0, 4e-4 * f, 4e-4 * f, 4e-4 * f])  # fmt: skip
    assert data["tab:orange"] == pytest.approx([0.0, 2e-4 * f, 2e-4 * f, 2e-4 * f])
    kinds = {
        c.lines[0].get_color(): c.lines[0] for c in n.containers if len(c.lines[0].get_xdata())
    }
    # matplotlib draws an errorbar's points 0.1 above its zorder: the outliers (4) on top
    assert [(kinds[k].get_alpha(), kinds[k].get_zorder()) for k in ("k", "tab:orange")] == [
        (1.0, pytest.approx(2.1)), (1.0, pytest.approx(4.1))
    ]  # fmt: skip
    assert kinds["k"].get_marker() == "o" and kinds["k"].get_markersize() == 3.5
    caps = next(c for c in n.containers if c.lines[0] is kinds["k"]).lines[1]
    assert [cap.get_markersize() for cap in caps] == [4, 4]  # capsize 2 (points): 4 wide
    (bound,) = [ln for ln in n.lines if ln.get_marker() == "v" and len(ln.get_xdata())]
    assert bound.get_xydata().ravel().tolist() == pytest.approx([0.3, 3e-4 * f, 1.3, 6e-4 * f])
    assert (bound.get_color(), bound.get_markersize(), bound.get_alpha()) == ("0.5", 4, 1.0)
    # the tolerance interval of gyro_x: shaded and edged over ±0.4; the datasheet over ±0.45
    bars = {k.lines[2][0] for k in n.containers}
    edges = {
        to_hex(c.get_color()[0]): c
        for c in n.collections
        if isinstance(c, LineCollection) and c not in bars and len(c.get_segments())
    }
    assert edges.keys() == {to_hex("tab:blue"), to_hex("tab:red")}
    tolerance, sheet = edges[to_hex("tab:blue")], edges[to_hex("tab:red")]
    assert np.ravel(tolerance.get_segments()).tolist() == pytest.approx(
        [-0.4, 0.5e-4 * f, 0.4, 0.5e-4 * f, -0.4, 4e-4 * f, 0.4, 4e-4 * f]
    )
    assert (tolerance.get_linewidth().tolist(), tolerance.get_zorder()) == ([0.8], 3)
    assert np.ravel(sheet.get_segments()).tolist() == pytest.approx([-0.45, 0.02, 0.45, 0.02])
    assert sheet.get_linestyle()[0][1] is not None  # dashed
    shaded = [c for c in n.collections if not isinstance(c, LineCollection)]
    (band,) = [c for c in shaded if c.get_paths() and len(c.get_paths()[0].vertices)]
    xs, ys = band.get_paths()[0].vertices.T
    assert (xs.min(), xs.max(), ys.min(), ys.max()) == pytest.approx(
        (-0.4, 0.4, 0.5e-4 * f, 4e-4 * f)
    )
    assert band.get_linewidth().tolist() == [0]
    # B has neither, and no outlier: only its units, black
    assert {to_hex(c.get_color()[0]) for c in b.collections if len(c.get_paths())} == {"#000000"}
    legend = n.get_legend()
    assert {t.get_fontsize() for t in legend.get_texts()} == {7}
    assert sorted(t.get_text() for t in legend.get_texts()) == sorted([
        "unit, 95 % interval", "outlier unit", "unresolved: upper bound",
        "95 %/95 % tolerance", "datasheet",
    ])  # fmt: skip
    assert b.get_legend() is None


def test_a_one_unit_terms_figure_draws_the_unit_on_its_axis(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A fleet of one unit: its point at each axis' tick (no offset), its interval as given;
    the legend has no outlier or datasheet entry (there are none)."""
    from imupipe.fleet import figures

    drawn = _drawn(monkeypatch)
    f = 180 / math.pi
    reports = _strip_reports({"solo": (1e-4, 0.9e-4, 1.2e-4)})
    figures.terms_figure(reports, population(reports), "gyro")
    n = drawn[0].axes[0]
    data = _data(n)
    assert data.keys() == {"k"}
    assert data["k"] == pytest.approx([0.0, 1e-4 * f, 0.9e-4 * f, 1.2e-4 * f,
                                       1.0, 2e-4 * f, 1.8e-4 * f, 2.4e-4 * f])  # fmt: skip
    assert drawn[0].get_suptitle() == "Gyroscopes: noise terms of 1 units"
    assert [t.get_text() for t in n.get_legend().get_texts()] == [
        "unresolved: upper bound", "95 %/95 % tolerance", "unit, 95 % interval"
    ]  # fmt: skip


def test_figure_jobs_carry_only_what_their_figure_draws():
    # a job with every report and curve was ~80 kB per unit: Dask warned of a 10 MB graph
    # at 120 units; the figures drawn from the slim jobs are the same PNGs
    from imupipe.fleet import figures
    from imupipe.fleet.figure_plan import CURVE_COLUMNS, draw, figure_jobs
    from imupipe.vocab import AXES, AXES_OF, TERM_NAMES

    rng = np.random.default_rng(5)
    tau = np.geomspace(0.01, 100.0, 9)

    def unit(scale):
        terms = {t: {"value": scale, "lo": 0.9 * scale, "hi": 1.1 * scale, "unit": "u"}
                 for t in TERM_NAMES}  # fmt: skip
        doc = {"ieee952": terms, "ieee952_after": terms, "effects": [{"evidence": "x" * 4000}]}
        curve = pl.DataFrame(
            {"axis": np.repeat(AXES, len(tau)), "unit": "u", "tau": np.tile(tau, len(AXES)),
             "adev": scale / np.sqrt(np.tile(tau, len(AXES))), "lo": np.nan, "hi": np.nan,
             "edf": 1.0, "terms": 1, "alpha": 0.0, "adev_after": np.nan, "model_before": np.nan,
             "model_after": np.nan, "z_before": np.nan, "z_after": np.nan},
            schema=ALLAN_SCHEMA,
        )  # fmt: skip
        return {"axes": dict.fromkeys(AXES, doc)}, curve

    units = {f"u{i}": unit(float(v)) for i, v in enumerate(rng.lognormal(0, 0.05, 40))}
    reports = {name: r for name, (r, _) in units.items()}
    fleet = fleet_frame({name: c for name, (_, c) in units.items()})
    pop, stats = population_curves(fleet), population(reports)
    jobs = figure_jobs(fleet, pop, reports, stats)
    for _, _, job in jobs:
        name, (data, *_, sensor) = job
        if name == "adev_figure":
            assert data.columns == list(CURVE_COLUMNS)
            assert set(data["axis"]) == set(AXES_OF[sensor])
            assert draw(job) == figures.adev_figure(fleet, pop, sensor)
        else:
            assert {a for r in data.values() for a in r["axes"]} == set(AXES_OF[sensor])
            assert all(set(d) == {"ieee952"} for r in data.values() for d in r["axes"].values())
            assert draw(job) == figures.terms_figure(reports, stats, sensor)


def test_worker_memory_caps_the_analysis_budget():
    options = AnalyzeOptions(memory_budget_bytes=2_000_000_000)
    assert budget_for_worker(options, None) == AnalyzeOptions(workers=1)  # a worker is one core
    assert budget_for_worker(options, 10_000_000_000).memory_budget_bytes == 2_000_000_000
    assert budget_for_worker(options, 1_000_000_000).memory_budget_bytes == 600_000_000


def test_bad_arguments_fail_before_any_worker_starts(tmp_path, monkeypatch):
    from imupipe.fleet import run

    def no_cluster(*args, **kwargs):
        raise AssertionError("the cluster must not start")

    monkeypatch.setattr(run, "fleet_client", no_cluster)
    rec = tmp_path / "a.mcap"
    rec.write_bytes(b"x")
    sheet = tmp_path / "sheet.toml"
    sheet.write_text("[gyro]\nrandom_walk = { value = 1.0, unit = 'furlong' }\n")
    with pytest.raises(DatasheetError, match="unknown"):
        run.run_fleet([rec], tmp_path / "out", datasheet=sheet)
    with pytest.raises(FleetError, match="no recording"):
        run.run_fleet([tmp_path / "nothing_here"], tmp_path / "out")


def test_a_local_cluster_that_does_not_start_is_one_line(tmp_path, monkeypatch, cli):
    """Dask's start-up timeout (seen at load 30 on two cores) is the fleet's one-line error and
    exit 2, not an internal error."""
    import imupipe.fleet.cluster as cluster

    def too_slow(**kwargs):
        raise TimeoutError("Nanny failed to start in 60 seconds")

    monkeypatch.setattr(cluster, "LocalCluster", too_slow)
    (tmp_path / "u.mcap").write_bytes(b"\x89MCAP0\r\n")
    args = ["fleet", str(tmp_path / "u.mcap"), "--out", str(tmp_path / "f"), "--workers", "2"]
    code, _, err = cli([*args, "-q"])
    assert code == 2
    assert err == (
        "imupipe: error: the local Dask cluster of 2 worker(s) did not start: Nanny failed to "
        "start in 60 seconds (is the machine overloaded? --workers fewer, or --scheduler an "
        "existing cluster)\n"
    )


class _SchedulerStandIn:
    """A stand-in for ``distributed.Client`` of an existing scheduler: records how it was
    reached and awaited; ``wait_for_workers`` times out above ``joined`` workers."""

    calls: ClassVar[list[tuple]] = []
    joined: ClassVar[int] = 2
    refuse: ClassVar[Exception | None] = None

    def __init__(self, address: str, timeout: str) -> None:
        if self.refuse is not None:
            raise self.refuse
        self.calls.append(("connect", address, timeout))

    def __enter__(self) -> _SchedulerStandIn:
        return self

    def __exit__(self, *exc: object) -> None:
        self.calls.append(("close",))

    def wait_for_workers(self, n: int, timeout: str) -> None:
        self.calls.append(("wait", n, timeout))
        if n > self.joined:
            raise TimeoutError("Only 2/3 workers arrived after 60.0s")


def test_an_existing_scheduler_is_tried_for_10_s_and_its_workers_awaited_60_s(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``--scheduler`` (or DASK_SCHEDULER_ADDRESS when none is given): the client tries 10 s to
    reach it; with ``--workers N`` it waits 60 s for N workers and fails in one line naming
    them; without, it waits for none.  A refused or timed-out connection is one line too, and
    ``--workers`` below 1 is refused before anything is reached."""
    import dask.config

    import imupipe.fleet.cluster as cluster

    calls: list[tuple] = []
    monkeypatch.setattr(_SchedulerStandIn, "calls", calls)
    monkeypatch.setattr(cluster, "Client", _SchedulerStandIn)
    address = "tcp://127.0.0.1:8786"
    with cluster.fleet_client(address, 2) as client:
        assert isinstance(client, _SchedulerStandIn)
    assert calls == [("connect", address, "10.0s"), ("wait", 2, "60.0s"), ("close",)]
    calls.clear()
    with pytest.raises(FleetError) as err, cluster.fleet_client(address, 3):
        pass
    assert str(err.value) == f"{address}: fewer than 3 workers joined within 60 s"
    assert calls == [("connect", address, "10.0s"), ("wait", 3, "60.0s"), ("close",)]
    calls.clear()
    with dask.config.set({"scheduler-address": "tcp://127.0.0.1:9999"}):
        assert cluster.scheduler_address(address) == address  # the argument wins
        with cluster.fleet_client():
            pass
    assert calls == [("connect", "tcp://127.0.0.1:9999", "10.0s"), ("close",)]
    for refusal in (OSError("Connection refused"), TimeoutError("Timed out trying to connect")):
        monkeypatch.setattr(_SchedulerStandIn, "refuse", refusal)
        with pytest.raises(FleetError) as err, cluster.fleet_client(address):
            pass
        assert str(err.value) == f"cannot reach the Dask scheduler at {address}: {refusal}"
    for workers in (0, -1):
        with pytest.raises(FleetError) as err, cluster.fleet_client(address, workers):
            pass
        assert str(err.value) == f"--workers must be at least 1, not {workers}"


@pytest.mark.parametrize(
    ("error", "hint"),
    [
        (OSError("[Errno 98] Address already in use"), "is the machine overloaded? --workers "
         "fewer, or --scheduler an existing cluster"),
        (RuntimeError("Nanny failed to start."), 'from a script: is imupipe.analyze_fleet '
         'called under `if __name__ == "__main__":`?'),
        # a timeout without a message is named by its type, not an empty reason
        (TimeoutError(), "is the machine overloaded? --workers fewer, or --scheduler an "
         "existing cluster"),
    ],
)  # fmt: skip
def test_each_way_the_local_cluster_fails_to_start_is_one_fleet_error(
    monkeypatch: pytest.MonkeyPatch, error: Exception, hint: str
) -> None:
    """A port taken (OSError) or a worker dying as it starts (RuntimeError; Dask's start-up
    timeout: ``test_a_local_cluster_that_does_not_start_is_one_line``): one FleetError naming
    the workers, Dask's reason and what to try."""
    import imupipe.fleet.cluster as cluster

    def failing(**kwargs: object) -> None:
        raise error

    monkeypatch.setattr(cluster, "LocalCluster", failing)
    with pytest.raises(FleetError) as err, cluster.fleet_client(workers=3):
        pass
    reason = str(error) or "TimeoutError"
    assert str(err.value) == (
        f"the local Dask cluster of 3 worker(s) did not start: {reason} ({hint})"
    )


def test_fleet_md_says_which_units_axes_move_together():
    """The units table: a unit's pairs moving together (how many, the strongest), "none" when
    the search named none, "—" when it did not run; and a line counting the units."""
    from imupipe.fleet.report import fleet_markdown
    from imupipe.fleet.task import UnitOutcome

    def unit(name: str, pairs: list[dict] | None) -> UnitOutcome:
        report = {"axes": {}, "input": {}}
        if pairs is not None:
            report["events"] = {"common_mode": {"pairs": pairs}}
        return UnitOutcome(name, f"{name}.mcap", "ok", None, report, None, 1.0, "h:1")

    def pair(a: str, b: str, r: float) -> dict:
        return {"axes": [a, b], "strongest": {"window_s": 64.0, "value": r}}

    moving = [pair("accel_x", "accel_y", 0.85), pair("gyro_x", "accel_z", 0.41)]
    bad = UnitOutcome("u5", "u5.mcap", "failed", "u5.mcap: not MCAP", None, None, 0.2, "h:1")
    units = [unit("u1", moving), unit("u2", []), unit("u3", None), unit("u4", moving[1:]), bad]
    md = fleet_markdown(units, [], {}, None)
    rows = [line for line in md.splitlines() if line.startswith("| [u")]
    assert rows[0].endswith("| none | 2 pairs (strongest accel_x–accel_y r 0.85 at 64 s) |")
    assert rows[1].endswith("| none | none |") and rows[2].endswith("| none | — |")
    assert rows[3].endswith("| 1 pair (strongest gyro_x–accel_z r 0.41 at 64 s) |")
    assert "| u5 | failed | u5.mcap | 0.2 s | none | — |" in md  # not linked: no folder
    assert "): on 2 of the 3 units searched." in md  # the failed unit was not searched
    assert md.count("u5.mcap: not MCAP") == 1 and "## Failed recordings" in md
    assert "by —. Outliers" in md  # no tolerance interval computed
    assert "5 recordings: 4 analysed, 1 failed." in md
