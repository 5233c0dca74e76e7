"""Several axes analysed at once (``workers`` / ``--jobs``): the same results in the same
order as one at a time, the same error, nothing left behind, and the memory budget obeyed."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numba
import psutil
import pytest

import imupipe
from imupipe import jit
from imupipe.analysis import analyze as orchestrator
from imupipe.analysis import workers
from imupipe.analysis.analyze import AnalyzeOptions, axis_concurrency
from imupipe.errors import ImupipeError
from imupipe.fleet.task import budget_for_worker
from imupipe.vocab import AXES


def axis_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("imupipe-axis")]


@pytest.mark.parametrize("kind", ["adis", "ros"])
def test_two_workers_give_the_serial_results(
    tmp_path: Path, kind: str, small_recordings, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = small_recordings.make(kind, tmp_path / "in.mcap")
    budget = AnalyzeOptions().memory_budget_bytes
    serial, serial_allan = small_recordings.run(path, tmp_path / "one", budget, workers=1)
    ran_on: list[str] = []
    axis_result = orchestrator.axis_result

    def spy(name, *args, **kwargs):
        ran_on.append(threading.current_thread().name)
        return axis_result(name, *args, **kwargs)

    monkeypatch.setattr(orchestrator, "axis_result", spy)
    pooled, pooled_allan = small_recordings.run(path, tmp_path / "two", budget, workers=2)
    assert ran_on and all(t.startswith("imupipe-axis") for t in ran_on)
    assert pooled == serial
    assert list(pooled["axes"]) == list(serial["axes"])  # AXES order
    assert pooled_allan.equals(serial_allan)
    assert not axis_threads()


def failing_axes(monkeypatch: pytest.MonkeyPatch, error: type[BaseException]) -> None:
    axis_result = orchestrator.axis_result

    def fail(name, *args, **kwargs):
        if name in ("gyro_y", "accel_x"):
            raise error(f"{name} failed")
        return axis_result(name, *args, **kwargs)

    monkeypatch.setattr(orchestrator, "axis_result", fail)


@pytest.mark.parametrize("jobs", [1, 2])
def test_failing_axis_raises_the_serial_error(
    tmp_path: Path, jobs: int, small_recordings, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = small_recordings.make("adis", tmp_path / "in.mcap")
    failing_axes(monkeypatch, ImupipeError)
    with pytest.raises(ImupipeError, match=r"^gyro_y failed$"):  # the first in AXES order
        small_recordings.run(path, tmp_path / "out", 2_000_000_000, workers=jobs)
    assert not axis_threads()


def test_interrupt_in_a_worker_leaves_no_thread_process_or_spill(
    tmp_path: Path, small_recordings, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = small_recordings.make("adis", tmp_path / "in.mcap")
    spill = tmp_path / "spill"
    spill.mkdir()
    failing_axes(monkeypatch, KeyboardInterrupt)
    seen: list[int] = []
    concurrency = orchestrator.axis_concurrency
    monkeypatch.setattr(
        orchestrator, "axis_concurrency", lambda *a: seen.append(concurrency(*a)) or seen[-1]
    )
    # over the budget (spilled source), with room for two axes at once
    budget = 2 * orchestrator.AXIS_BYTES_PER_SAMPLE * small_recordings.frames
    before = {p.pid for p in psutil.Process().children(recursive=True)}  # an earlier test's
    with pytest.raises(KeyboardInterrupt):
        imupipe.analyze(path, out=tmp_path / "out", workers=2, memory_budget_bytes=budget,
                        tmp_dir=spill, figures=False)  # fmt: skip
    assert seen == [2]
    assert not axis_threads()
    assert {p.pid for p in psutil.Process().children(recursive=True)} <= before
    assert list(spill.iterdir()) == []
    assert not (tmp_path / "out" / "recording.rrd").exists()


def test_spilled_source_note_names_the_axes_at_once(tmp_path: Path, small_recordings) -> None:
    path = small_recordings.make("adis", tmp_path / "in.mcap")
    budget = 2 * orchestrator.AXIS_BYTES_PER_SAMPLE * small_recordings.frames
    report, _ = small_recordings.run(path, tmp_path / "out", budget, workers=2)
    (note,) = [w for w in report["input"]["warnings"] if w.startswith("low-memory path")]
    assert note.endswith("analysed 2 axes at a time")


def test_axes_at_once_obeys_workers_axes_and_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(workers, "usable_cores", lambda: 4)
    assert workers.axes_at_once(None, 6, 100, 10_000) == 4  # default: the usable cores
    assert workers.axes_at_once(3, 6, 100, 10_000) == 3
    assert workers.axes_at_once(8, 6, 100, 10_000) == 6  # no more than the axes
    assert workers.axes_at_once(4, 6, 100, 299) == 3  # two more axes fit in 299 bytes
    assert workers.axes_at_once(4, 6, 100, 99) == 1
    assert workers.axes_at_once(4, 6, 100, -5_000) == 1  # over the budget already
    assert workers.axes_at_once(4, 6, 1, 3) == 4  # axes of one byte: three more fit in 3
    assert workers.axes_at_once(4, 6, 1, 0) == 1  # no byte to spare
    assert workers.axes_at_once(4, 6, 0, 3) == 4  # axes that need no memory: a byte each
    assert workers.axes_at_once(0, 6, 100, 10_000) == 1  # at least one


def test_a_failing_axis_leaves_the_axes_not_started_unrun() -> None:
    """Two workers, six axes: the first fails while those running beside it are held for a
    second: the error comes back and the axes still waiting are never run (not analysed
    to be thrown away: Ctrl-C or a failure returns without them)."""
    started: list[int] = []
    release = threading.Event()
    timer = threading.Timer(1.0, release.set)  # (a second for the pool to cancel the rest)

    def axis(i: int) -> int:
        started.append(i)
        if i == 0:
            raise ImupipeError("gyro_x failed")
        release.wait(10.0)
        return i

    timer.start()
    try:
        with pytest.raises(ImupipeError, match="gyro_x failed"), workers.axis_pool(2) as run:
            list(run(axis, range(6)))
    finally:
        timer.cancel()
    assert {0, 1} <= set(started) <= {0, 1, 2}  # (the third: if a worker took it in time)
    assert not axis_threads()


def test_axis_concurrency_budgets_memory(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    samples = 1_000_000
    axis = orchestrator.AXIS_BYTES_PER_SAMPLE * samples
    options = AnalyzeOptions(workers=6, memory_budget_bytes=10 * axis)
    assert axis_concurrency(options, 8 * axis, samples) == 3
    assert axis_concurrency(options, 10 * axis, samples) == 1
    assert axis_concurrency(AnalyzeOptions(workers=1), 0, samples) == 1
    with pytest.raises(ImupipeError, match="workers must be at least 1, not 0"):
        axis_concurrency(AnalyzeOptions(workers=0), 0, samples)


def test_pool_workers_share_the_cores_with_their_kernels(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(jit, "usable_cores", lambda: 6)
    monkeypatch.setattr(workers, "usable_cores", lambda: 6)
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 8)
    with workers.axis_pool(2) as run:
        counts = list(run(lambda _: jit.cores_here(), range(4)))
    assert counts == [3, 3, 3, 3]
    assert jit.cores_here() == min(6, numba.config.NUMBA_NUM_THREADS)  # the caller's own
    with workers.axis_pool(1) as run:
        assert (
            list(run(lambda _: threading.current_thread().name, range(2)))
            == [threading.current_thread().name] * 2
        )


def test_fleet_worker_analyses_one_axis_at_a_time() -> None:
    assert budget_for_worker(AnalyzeOptions(), None).workers == 1
    assert budget_for_worker(AnalyzeOptions(workers=4), 1_000_000_000).workers == 1


def test_cli_jobs_reaches_the_analysis(
    tmp_path: Path, small_recordings, cli, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = small_recordings.make("adis", tmp_path / "in.mcap")
    code, _, err = cli(["analyze", str(path), "-o", str(tmp_path / "out"), "--jobs", "0"])
    assert code == 2 and "--jobs" in err
    asked: list[int | None] = []
    concurrency = orchestrator.axis_concurrency

    def spy(options: AnalyzeOptions, *args) -> int:
        asked.append(options.workers)
        return concurrency(options, *args)

    monkeypatch.setattr(orchestrator, "axis_concurrency", spy)
    out = tmp_path / "out"
    code, _, _ = cli(["analyze", str(path), "-o", str(out), "--jobs", "2", "--no-rrd", "-q"])
    assert code == 0 and asked == [2]
    assert json.loads((out / "report.json").read_text())["axes"].keys() == set(AXES)
