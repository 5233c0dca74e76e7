"""The output folder replaced all at once (imupipe.report.staging): what is refused, the
permissions the new folder gets, the swap and its fallback, and which unfinished folders of
earlier runs are cleared away.  (Interrupted and killed runs: tests/test_hostile.py.)"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from imupipe.errors import OutputError
from imupipe.report import staging
from imupipe.report.staging import staged_output


def previous(out: Path, *names: str) -> Path:
    """An earlier analysis' folder holding ``names`` (report.json among them or not)."""
    out.mkdir(parents=True)
    for name in names:
        (out / name).write_text(name)
    return out


def test_a_folder_holding_anything_but_reports_is_refused_even_beside_a_report(
    tmp_path: Path,
) -> None:
    out = previous(tmp_path / "out", "report.json", "notes.txt")
    with pytest.raises(OutputError, match="holds files an analysis does not write"):
        with staged_output(out):
            pass
    assert (out / "notes.txt").read_text() == "notes.txt"  # the user's file is untouched


@pytest.mark.parametrize("exchange", [True, False])
def test_the_new_folder_replaces_the_old_with_the_umasks_permissions(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exchange: bool
) -> None:
    """Relative ``--out`` (the swap's paths are resolved from the working directory), an
    existing output replaced by the atomic exchange or, where that is not supported, by two
    renames; nothing else left beside it."""
    monkeypatch.chdir(tmp_path)
    if not exchange:
        monkeypatch.setattr(staging, "_exchange", lambda a, b: False)
    previous(Path("out"), "report.json", "recording.rrd")
    old_mask = os.umask(0o022)
    try:
        with staged_output(Path("out")) as tmp:
            (tmp / "report.json").write_text("new")
    finally:
        os.umask(old_mask)
    assert sorted(p.name for p in Path("out").iterdir()) == ["report.json"]
    assert Path("out/report.json").read_text() == "new"
    assert Path("out").stat().st_mode & 0o777 == 0o755
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_the_exchange_swaps_two_folders_and_reports_a_missing_one(tmp_path: Path) -> None:
    a, b = previous(tmp_path / "a", "x"), previous(tmp_path / "b", "y")
    assert staging._exchange(a, b) is True
    assert [p.name for p in a.iterdir()] == ["y"] and [p.name for p in b.iterdir()] == ["x"]
    with pytest.raises(FileNotFoundError):
        staging._exchange(a, tmp_path / "missing")


def test_unfinished_folders_of_finished_runs_are_cleared_not_those_of_running_ones(
    tmp_path: Path,
) -> None:
    """``.out.partial-<pid>-<random>``: removed when the process is gone (or is this one, whose
    earlier run ended), kept while another process that may still be writing it runs."""
    out = tmp_path / "out"
    running = subprocess.Popen(["sleep", "30"])
    try:
        dead = subprocess.Popen(["true"])
        dead.wait()
        folders = {
            "dead": tmp_path / f".out.partial-{dead.pid}-a1b2c3",
            "mine": tmp_path / f".out.partial-{os.getpid()}-d4e5f6",
            "running": tmp_path / f".out.partial-{running.pid}-g7h8i9",
            "init": tmp_path / ".out.partial-1-j0k1l2",  # a running process older than this one
        }
        for folder in folders.values():
            folder.mkdir()
        with staged_output(out) as tmp:
            (tmp / "report.json").write_text("{}")
        assert {name for name, f in folders.items() if f.exists()} == {"running", "init"}
    finally:
        running.kill()
        running.wait()
