"""One fleet task (:mod:`imupipe.fleet.task`): the options a worker's analysis gets and a
unit's wall time on a clock whose start is not large beside the unit's duration (session 54's
mutation sample of the module, docs/mutation.md)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import distributed
import pytest

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.errors import ImupipeError
from imupipe.fleet import task
from imupipe.fleet.discover import Recording


def test_a_workers_analysis_is_one_axis_at_a_time_with_no_compiling_child(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Whatever the fleet's options ask, a worker (one core) analyses one axis at a time,
    starts no child compiling numba kernels and plans for 60 % of its memory limit."""
    seen: list[AnalyzeOptions] = []

    def analysis(path, opts, progress, outputs, label):
        seen.append(opts)
        raise ImupipeError(f"{path}: stopped here")

    worker = SimpleNamespace(memory_manager=SimpleNamespace(memory_limit=1_000_000_000))
    monkeypatch.setattr(distributed, "get_worker", lambda: worker)
    monkeypatch.setattr(task, "run_analysis", analysis)
    path = tmp_path / "unit.mcap"
    path.write_bytes(b"")
    rec = Recording("unit", str(path), local=True, is_dir=False)
    options = AnalyzeOptions(loop=False, workers=4, compile_ahead=True)
    outcome = task.analyze_unit(rec, str(tmp_path / "out"), options)
    assert outcome.status == "failed" and outcome.error == f"{path}: stopped here"
    assert not (tmp_path / "out" / "unit").exists()
    assert len(seen) == 1
    assert seen[0].workers == 1
    assert seen[0].compile_ahead is False
    assert seen[0].memory_budget_bytes == 600_000_000


def test_a_worker_without_a_memory_limit_still_analyses_one_axis_at_a_time() -> None:
    budget = AnalyzeOptions(workers=4, memory_budget_bytes=123_456_789)
    alone = task.budget_for_worker(budget, None)
    assert alone.workers == 1 and alone.memory_budget_bytes == 123_456_789
    roomy = task.budget_for_worker(budget, 10_000_000_000)  # 60 % of it is more than asked
    assert roomy.workers == 1 and roomy.memory_budget_bytes == 123_456_789


@pytest.mark.parametrize("start", [2.0, 0.5])
def test_a_failed_units_seconds_are_its_wall_time_whatever_the_clocks_origin(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, start: float
) -> None:
    """``perf_counter`` has no fixed origin: a unit that ran 3.25 s is 3.25 s even when the
    clock read less than that when it started (a worker on a freshly booted machine)."""
    reads = iter([start, start + 3.25])
    monkeypatch.setattr(task, "time", SimpleNamespace(perf_counter=lambda: next(reads)))
    missing = tmp_path / "gone.mcap"
    rec = Recording("gone", str(missing), local=True, is_dir=False)
    outcome = task.analyze_unit(rec, str(tmp_path / "out"), AnalyzeOptions(loop=False))
    assert outcome.status == "failed" and outcome.error == f"{missing}: not a file"
    assert outcome.seconds == 3.25
