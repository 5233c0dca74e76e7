"""One fleet task: analyse one recording on a Dask worker, exactly as ``imupipe analyze`` does.

The task runs where the worker is.  A local recording is read in place (on an existing cluster
the path must be visible to the workers: a shared file system); a URL (``s3://...``) is first
downloaded by the worker into a local temporary folder (fsspec, the worker's own credentials)
and deleted after the analysis.  Reports are written into a staging folder under the fleet's
output and moved into place only when complete, so a worker killed mid-task (Dask then runs the
task again elsewhere) never leaves a half-written unit folder behind.

A recording that fails does not fail the task: its error becomes the unit's one-line
``error`` and the fleet goes on.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import tempfile
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import fsspec
import polars as pl

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.analysis.analyze import analyze as run_analysis
from imupipe.errors import ImupipeError
from imupipe.fleet.discover import Recording
from imupipe.progress import StageProgress
from imupipe.report.datasheet import load_datasheet
from imupipe.report.outputs import ReportOutputs

WORKER_MEMORY_SHARE = 0.6
"""Fraction of a Dask worker's memory limit one analysis may plan for: above it the recording
takes ``imupipe analyze``'s low-memory path (decoded once into a temporary on-disk store, one
axis in memory at a time, same results) instead of the nanny restarting the worker at 95 %."""

STAGING = ".staging"


@dataclass(frozen=True)
class UnitOutcome:
    """What one recording gave: ``status`` "ok" with its ``report`` (report.json) and ``allan``
    curves (allan.parquet), or "failed" with a one-line ``error``; ``seconds`` of wall time on
    ``worker`` (host:pid)."""

    name: str
    source: str
    status: Literal["ok", "failed"]
    error: str | None
    report: dict | None
    allan: pl.DataFrame | None
    seconds: float
    worker: str


def one_line(exc: BaseException) -> str:
    """An exception as one line; internal errors (not an ImupipeError) say so and name the type,
    as ``imupipe`` itself does."""
    text = " ".join(str(exc).split())
    if isinstance(exc, ImupipeError):
        return text
    return f"internal error: {type(exc).__name__}: {text}"


def _worker_memory_limit() -> int | None:
    """The memory limit (bytes) of the Dask worker running this task, if any."""
    try:
        from distributed import get_worker

        return get_worker().memory_manager.memory_limit or None
    except ValueError:  # not inside a worker (the sequential path, tests)
        return None


def budget_for_worker(options: AnalyzeOptions, memory_limit: int | None) -> AnalyzeOptions:
    """``options`` for one Dask worker: one axis at a time (a worker is one core:
    :data:`imupipe.fleet.cluster.SINGLE_THREAD_ENV`), and the memory budget lowered to
    :data:`WORKER_MEMORY_SHARE` of the worker's limit when that is smaller."""
    options = replace(options, workers=1)
    if memory_limit is None:
        return options
    cap = int(WORKER_MEMORY_SHARE * memory_limit)
    return replace(options, memory_budget_bytes=min(options.memory_budget_bytes, cap))


@contextlib.contextmanager
def local_copy(rec: Recording) -> Iterator[Path]:
    """The recording as a local path: itself, or a temporary download of the URL."""
    if rec.local:
        yield Path(rec.location)
        return
    with tempfile.TemporaryDirectory(prefix="imupipe-fleet-") as tmp:
        fs, path = fsspec.core.url_to_fs(rec.location)
        target = Path(tmp) / path.rstrip("/").rsplit("/", 1)[-1]
        try:
            fs.get(path, str(target), recursive=rec.is_dir)
        except (OSError, ValueError) as exc:
            raise ImupipeError(f"{rec.location}: cannot download: {one_line(exc)}") from exc
        yield target


def publish(staging: Path, target: Path) -> None:
    """Move a finished staging folder to ``target``, replacing an older result."""
    if target.exists():
        shutil.rmtree(target)
    os.replace(staging, target)


def analyze_unit(rec: Recording, out_root: str, options: AnalyzeOptions) -> UnitOutcome:
    """Analyse ``rec`` into ``out_root/<rec.name>/`` (what ``imupipe analyze`` writes) and
    return its outcome; never raises for a bad recording."""
    t0 = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    root = Path(out_root)
    staging = root / STAGING / f"{rec.name}-{uuid.uuid4().hex}"
    # a worker is one core: no child compiling numba kernels ahead beside it
    opts = replace(budget_for_worker(options, _worker_memory_limit()), compile_ahead=False)
    try:
        sheet = None if opts.datasheet is None else load_datasheet(opts.datasheet)
        outputs = ReportOutputs(
            staging, opts.figures, opts.rrd_full, datasheet=sheet, processes=opts.workers
        )
        with local_copy(rec) as path:  # the outputs name the URL, not the temporary copy
            label = None if rec.local else rec.location
            result = run_analysis(path, opts, StageProgress(quiet=True), outputs, label)
        publish(staging, root / rec.name)
    except Exception as exc:  # any failure is this unit's, never the fleet's
        shutil.rmtree(staging, ignore_errors=True)
        return UnitOutcome(
            rec.name, rec.location, "failed", one_line(exc), None, None,
            time.perf_counter() - t0, worker,
        )  # fmt: skip
    return UnitOutcome(
        rec.name, rec.location, "ok", None, result.to_dict(), result.to_polars(),
        time.perf_counter() - t0, worker,
    )  # fmt: skip
