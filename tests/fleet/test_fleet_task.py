"""One fleet task (:mod:`imupipe.fleet.task`) in this process: the unit's wall time, the
worker's memory limit, and a recording at a URL copied to a local folder under its own name."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import distributed
import fsspec
import pytest

from imupipe.analysis.analyze import AnalyzeOptions
from imupipe.errors import ImupipeError
from imupipe.fleet import task
from imupipe.fleet.discover import Recording


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> None:
    """The task's own clock reads 100 s when a unit starts and 103.25 s when it ends."""
    reads = iter([100.0, 103.25])
    monkeypatch.setattr(task, "time", SimpleNamespace(perf_counter=lambda: next(reads)))


def test_a_failed_units_seconds_are_its_wall_time(tmp_path: Path, clock: None) -> None:
    missing = tmp_path / "gone.mcap"
    rec = Recording("gone", str(missing), local=True, is_dir=False)
    outcome = task.analyze_unit(rec, str(tmp_path / "out"), AnalyzeOptions(loop=False))
    assert outcome.status == "failed" and outcome.error == f"{missing}: not a file"
    assert outcome.seconds == 3.25
    assert not (tmp_path / "out" / "gone").exists()


def test_a_units_seconds_and_report_are_its_own(
    tmp_path: Path, clock: None, small_recordings
) -> None:
    path = small_recordings.make("adis", tmp_path / "unit.mcap")
    rec = Recording("unit", str(path), local=True, is_dir=False)
    options = AnalyzeOptions(loop=False, rrd=False, figures=False)
    outcome = task.analyze_unit(rec, str(tmp_path / "out"), options)
    assert outcome.status == "ok" and outcome.error is None
    assert outcome.seconds == 3.25
    written = json.loads((tmp_path / "out" / "unit" / "report.json").read_text())
    assert outcome.report == written
    assert not list((tmp_path / "out" / task.STAGING).iterdir())  # published, not left staged


def test_the_workers_memory_limit_caps_the_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    assert task._worker_memory_limit() is None  # not inside a Dask worker
    worker = SimpleNamespace(memory_manager=SimpleNamespace(memory_limit=2_000_000_000))
    monkeypatch.setattr(distributed, "get_worker", lambda: worker)
    assert task._worker_memory_limit() == 2_000_000_000
    capped = task.budget_for_worker(AnalyzeOptions(), task._worker_memory_limit())
    assert capped.memory_budget_bytes == int(task.WORKER_MEMORY_SHARE * 2_000_000_000)
    worker.memory_manager.memory_limit = 0  # a worker started without a limit
    assert task._worker_memory_limit() is None


def test_a_url_is_copied_under_its_own_name() -> None:
    """A file keeps its name (a whole-file-compressed ``.mcap.zstd`` is told by its suffix), a
    rosbag2 directory its name and files; a URL that is not there is one line."""
    fs = fsspec.filesystem("memory")
    fs.pipe("/fleet/unit7/imu.mcap.zstd", b"compressed bytes")
    fs.pipe("/fleet/bag/metadata.yaml", b"rosbag2_bagfile_information:\n")
    fs.pipe("/fleet/bag/bag_0.mcap", b"mcap bytes")
    try:
        one = Recording("unit7", "memory://fleet/unit7/imu.mcap.zstd", local=False, is_dir=False)
        with task.local_copy(one) as path:
            assert path.name == "imu.mcap.zstd" and path.read_bytes() == b"compressed bytes"
        assert not path.exists()  # the temporary copy is removed after the analysis
        bag = Recording("bag", "memory://fleet/bag/", local=False, is_dir=True)
        with task.local_copy(bag) as path:
            assert path.name == "bag"
            assert sorted(p.name for p in path.iterdir()) == ["bag_0.mcap", "metadata.yaml"]
        gone = Recording("gone", "memory://fleet/gone.mcap", local=False, is_dir=False)
        with pytest.raises(ImupipeError, match=r"^memory://fleet/gone.mcap: cannot download: "):
            with task.local_copy(gone):
                pass
    finally:
        fs.rm("/fleet", recursive=True)
