"""run_fleet on an in-process Dask cluster with stand-ins for the unit's analysis and the fleet
report: which recordings are submitted, how their outcomes (and tasks that did not return) come
back, the progress bar, and the FleetResult (session 54's mutation sample of fleet/run.py)."""

from __future__ import annotations

import contextlib
import itertools
import time
import types
from pathlib import Path

import pytest
from distributed import Client, LocalCluster

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.fleet import run
from imupipe.fleet.task import STAGING, UnitOutcome


@contextlib.contextmanager
def _in_process(scheduler=None, workers=None):
    with (
        LocalCluster(
            n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


class _Fleet:
    """The stand-ins' record: what the report and the progress bar were given."""

    def __init__(self) -> None:
        self.report: dict = {}
        self.bar: dict = {"advanced": []}


@pytest.fixture
def fleet(monkeypatch: pytest.MonkeyPatch) -> _Fleet:
    seen = _Fleet()

    def analyze_unit(rec, out_root, options):
        if rec.name.startswith("bad"):
            raise ValueError(f"{rec.name} is\n  broken")
        return UnitOutcome(
            rec.name, rec.location, "ok", None, {"to": (out_root, options)}, None, 0.5, "w:1"
        )

    def write_fleet_report(units, out_dir, sheet, rrd, mapper):
        seen.report = {"units": list(units), "out_dir": out_dir, "sheet": sheet, "rrd": rrd}
        seen.report["mapped"] = list(mapper(len, [[1, 2], [3]]))
        return {"document": True}, ["stats"]

    class Progress:
        def __init__(self, quiet: bool = False) -> None:
            seen.bar["quiet"] = quiet

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return None

        @contextlib.contextmanager
        def stage(self, name, total, unit=""):
            seen.bar["stage"] = (name, total, unit)
            yield seen.bar["advanced"].append

    monkeypatch.setattr(run, "fleet_client", _in_process)
    monkeypatch.setattr(run, "analyze_unit", analyze_unit)
    monkeypatch.setattr(run, "write_fleet_report", write_fleet_report)
    monkeypatch.setattr(run, "StageProgress", Progress)
    return seen


def _recordings(folder: Path, *names: str) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / f"{name}.mcap" for name in names]
    for path in paths:
        path.write_bytes(b"\x89MCAP0\r\n")
    return paths


def test_every_recording_is_analysed_once_and_its_outcome_kept_in_order(tmp_path, fleet):
    recs = _recordings(tmp_path / "in", "unit_c", "unit_a", "unit_b")
    out = tmp_path / "deep" / "fleet"  # parents created
    options = AnalyzeOptions(rrd=False)
    started = time.perf_counter()
    result = run.run_fleet(recs, out, options=options)
    assert result.seconds == pytest.approx(time.perf_counter() - started, abs=0.5)

    assert [u.report for u in result.units] == [{"to": (str(out.absolute()), options)}] * 3
    assert [(u.name, u.status, u.source) for u in result.units] == [
        ("unit_c", "ok", str(recs[0])),
        ("unit_a", "ok", str(recs[1])),
        ("unit_b", "ok", str(recs[2])),
    ]
    assert result.failed == []
    assert (result.document, result.population, result.out_dir) == (
        {"document": True},
        ["stats"],
        out.absolute(),
    )
    assert fleet.report["units"] == result.units and fleet.report["out_dir"] == out.absolute()
    assert fleet.report["sheet"] is None and fleet.report["rrd"] is False
    assert fleet.report["mapped"] == [2, 1]  # the figures' jobs run on the workers, in order
    # the bar counts recordings, one step per completed task, quiet unless asked
    assert fleet.bar["stage"] == ("fleet", 3, "recordings")
    assert fleet.bar["advanced"] == [1, 2, 3]
    assert fleet.bar["quiet"] is True


def test_a_task_that_does_not_return_is_that_units_one_line_failure(tmp_path, fleet):
    recs = _recordings(tmp_path / "in", "bad_unit", "good_unit")
    started = time.perf_counter()
    result = run.run_fleet(recs, tmp_path / "out", progress=True)
    wall = time.perf_counter() - started
    bad, good = result.units
    assert (bad.name, bad.source, bad.status) == ("bad_unit", str(recs[0]), "failed")
    assert bad.error == "internal error: ValueError: bad_unit is broken"
    assert (bad.report, bad.allan, bad.worker) == (None, None, "")
    assert 0 <= bad.seconds <= wall
    assert (good.name, good.status, good.error, good.report["to"][1]) == (
        "good_unit",
        "ok",
        None,
        AnalyzeOptions(),
    )
    assert result.failed == [bad]
    assert fleet.report["rrd"] is True  # the default options draw fleet.rrd
    assert fleet.bar["quiet"] is False


def test_an_existing_output_folder_is_reused_and_leftover_staging_removed(tmp_path, fleet):
    recs = _recordings(tmp_path / "in", "unit_a")
    out = tmp_path / "out"
    (out / STAGING / "unit_a").mkdir(parents=True)  # left by a worker killed mid-task
    result = run.run_fleet(recs, out, options=AnalyzeOptions(rrd=False))
    assert [u.status for u in result.units] == ["ok"]
    assert not (out / STAGING).exists()
    # and again, into the same folder, now without a staging folder
    result = run.run_fleet(recs, out, options=AnalyzeOptions(rrd=False))
    assert [u.status for u in result.units] == ["ok"]


def test_a_datasheet_is_read_and_given_to_the_report(tmp_path, fleet):
    recs = _recordings(tmp_path / "in", "unit_a")
    sheet = tmp_path / "sheet.toml"
    sheet.write_text("[gyro]\nrandom_walk = { value = 0.1, unit = '°/√h' }\n")
    run.run_fleet(recs, tmp_path / "out", datasheet=sheet)
    assert fleet.report["sheet"] is not None


def test_a_lost_units_seconds_and_the_fleets_are_counted_from_the_start(
    tmp_path, fleet, monkeypatch
):
    """A clock that ticks one second per reading: started at 100 s, the lost unit read at
    101 s, the fleet's end at 102 s."""
    ticks = itertools.count(100.0)
    monkeypatch.setattr(run, "time", types.SimpleNamespace(perf_counter=lambda: next(ticks)))
    recs = _recordings(tmp_path / "in", "bad_unit")
    result = run.run_fleet(recs, tmp_path / "out")
    assert [(u.status, u.seconds) for u in result.units] == [("failed", 1.0)]
    assert result.seconds == 2.0
