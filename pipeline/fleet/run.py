"""``imupipe fleet``: one analysis per recording as Dask tasks, then the fleet report.

The recordings are listed (:mod:`imupipe.fleet.discover`), a datasheet if given is read, and
only then is the cluster started (:mod:`imupipe.fleet.cluster`), so bad arguments fail before
any worker starts.  Each recording is one task (:func:`imupipe.fleet.task.analyze_unit`);
results are collected as they complete (``distributed.as_completed``), counting recordings on
the progress bar.  A worker that dies mid-task is replaced by Dask rescheduling its task on
another worker; a task that kills ``distributed.scheduler.allowed-failures`` + 1 workers (4 by
default) is reported as that unit's failure.
"""

from __future__ import annotations

import shutil
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from distributed import Client, as_completed

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.fleet.cluster import fleet_client
from imupipe.fleet.discover import Recording, discover
from imupipe.fleet.population import TermStats
from imupipe.fleet.report import write_fleet_report
from imupipe.fleet.task import STAGING, UnitOutcome, analyze_unit, one_line
from imupipe.progress import StageProgress
from imupipe.report.datasheet import load_datasheet


@dataclass(frozen=True)
class FleetResult:
    """The units' outcomes (in recording order), the population statistics, the fleet.json
    document, where it was written, and the wall time (s)."""

    units: list[UnitOutcome]
    population: list[TermStats]
    document: dict
    out_dir: Path
    seconds: float

    @property
    def failed(self) -> list[UnitOutcome]:
        return [u for u in self.units if u.status == "failed"]


def _lost(rec: Recording, exc: BaseException, seconds: float) -> UnitOutcome:
    """The outcome of a task that did not return (its workers died: KilledWorker)."""
    return UnitOutcome(rec.name, rec.location, "failed", one_line(exc), None, None, seconds, "")


def run_fleet(
    recordings: Sequence[str | Path],
    out: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    datasheet: str | Path | None = None,
    options: AnalyzeOptions | None = None,
    progress: bool = False,
) -> FleetResult:
    """Analyse every recording that ``recordings`` name on a Dask cluster and write the fleet
    report into ``out`` (each unit in ``out/<unit>/``, what ``imupipe analyze`` writes).

    Args:
        recordings: MCAP files, rosbag2 directories, folders, globs, fsspec URLs.
        scheduler: address of an existing Dask scheduler (default: ``DASK_SCHEDULER_ADDRESS``,
            else a LocalCluster started and stopped here).
        workers: LocalCluster worker processes (default one per core); with a scheduler, wait
            for that many workers.
        datasheet: TOML datasheet to check the units against (:mod:`imupipe.report.datasheet`).
        options: the analysis options of every unit (as ``imupipe analyze``).

    Raises:
        ImupipeError: no recordings, bad datasheet, unreachable scheduler.  Failed recordings
            do not raise: they are in ``FleetResult.failed`` and the reports.
    """
    t0 = time.perf_counter()
    recs = discover([str(r) for r in recordings])
    sheet = load_datasheet(Path(datasheet)) if datasheet is not None else None
    out_dir = Path(out).absolute()
    out_dir.mkdir(parents=True, exist_ok=True)
    options = options or AnalyzeOptions()
    run_id = uuid.uuid4().hex[:8]
    outcomes: dict[str, UnitOutcome] = {}
    with fleet_client(scheduler, workers) as client:
        futures = {
            client.submit(
                analyze_unit,
                rec,
                str(out_dir),
                options,
                key=f"imupipe-analyze-{rec.name}-{run_id}",
                pure=False,
            ): rec
            for rec in recs
        }
        with (
            StageProgress(quiet=not progress) as bars,
            bars.stage("fleet", len(recs), "recordings") as advance,
        ):
            for done, future in enumerate(as_completed(futures), start=1):
                rec = futures[future]
                if future.status == "finished":
                    outcomes[rec.name] = future.result()
                else:
                    outcomes[rec.name] = _lost(rec, future.exception(), time.perf_counter() - t0)
                future.release()
                advance(done)
        shutil.rmtree(out_dir / STAGING, ignore_errors=True)  # left by workers killed mid-task
        units = [outcomes[r.name] for r in recs]
        doc, stats = write_fleet_report(
            units, out_dir, sheet, rrd=options.rrd, mapper=partial(_on_workers, client)
        )
    return FleetResult(units, stats, doc, out_dir, time.perf_counter() - t0)


def _on_workers(client: Client, func: Callable, jobs: list) -> Iterator:
    """The fleet report's figures drawn on the cluster's workers, in parallel, while the
    client writes the rest of the report: submitted now, gathered when iterated.  The jobs'
    data go to the workers as scattered data, not inside the task graph (Dask's advice; the
    graph of a large fleet's figures would otherwise carry all their curves)."""
    futures = client.map(func, client.scatter(jobs, hash=False), pure=False)
    return (future.result() for future in futures)
