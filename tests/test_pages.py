"""imupipe.pages: an analysis allocates its large arrays without numpy's huge-page advice, and
leaves numpy's setting as it found it; the ``imupipe analyze`` command has glibc reuse freed
large blocks, a spilled analysis has them returned."""

from __future__ import annotations

import gc
import platform
import subprocess
import sys
from pathlib import Path

import pytest

import imupipe.analysis.analyze as orchestrator
import imupipe.io.columns as columns
from imupipe import pages
from imupipe.pages import REUSED_BLOCK_BYTES, _toggle, small_pages


def huge_pages_on() -> bool:
    """numpy's current huge-page setting, read without changing it."""
    toggle = _toggle()
    assert toggle is not None  # numpy >= 1.26 has it (pyproject's floor)
    before = toggle(True)
    toggle(before)
    return before


@pytest.mark.parametrize("initial", [True, False])
def test_small_pages_switches_off_and_restores(initial: bool) -> None:
    toggle = _toggle()
    saved = toggle(initial)
    try:
        with small_pages():
            assert huge_pages_on() is False
        assert huge_pages_on() is initial
        with pytest.raises(RuntimeError), small_pages():
            raise RuntimeError  # restored on the way out of an error too
        assert huge_pages_on() is initial
    finally:
        toggle(saved)


def test_analysis_runs_on_small_pages(
    tmp_path: Path, small_recordings, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[bool] = []
    condition = orchestrator.condition

    def spy(*args, **kwargs):
        seen.append(huge_pages_on())
        return condition(*args, **kwargs)

    monkeypatch.setattr(orchestrator, "condition", spy)
    rec = small_recordings.make("adis", tmp_path / "adis.mcap")
    before = huge_pages_on()
    small_recordings.run(rec, tmp_path / "out", 1 << 40)
    assert seen == [False]
    assert huge_pages_on() is before


def test_decode_runs_on_small_pages(
    tmp_path: Path, small_recordings, monkeypatch: pytest.MonkeyPatch
) -> None:
    import imupipe.io.decode as dec

    seen: list[tuple[str, bool]] = []

    def spy(name: str):
        original = getattr(dec, name)

        def spied(*args, **kwargs):
            seen.append((name, huge_pages_on()))
            return original(*args, **kwargs)

        monkeypatch.setattr(dec, name, spied)

    spy("scan")
    spy("_adis_frame")  # where the counts become 35 MB SI columns at 12 h / 100 Hz
    rec = small_recordings.make("adis", tmp_path / "adis.mcap")
    before = huge_pages_on()
    assert dec.decode(rec).frames.height == small_recordings.frames
    assert seen == [("scan", False), ("_adis_frame", False)]
    assert huge_pages_on() is before


def test_overlapping_analyses_share_the_switch_and_the_last_restores_it() -> None:
    toggle = _toggle()
    saved = toggle(True)
    try:
        first, second = small_pages(), small_pages()
        first.__enter__()
        second.__enter__()
        first.__exit__(None, None, None)  # the first leaves while the second still runs
        assert huge_pages_on() is False
        second.__exit__(None, None, None)
        assert huge_pages_on() is True  # numpy's setting from before the first
    finally:
        toggle(saved)


REFAULT = """
import resource, sys
import numpy as np
from imupipe import pages

getattr(pages, sys.argv[1])()
size = int(sys.argv[2])
with pages.small_pages():  # 4 KiB pages, as in an analysis: one fault per page
    np.ones(size // 8)  # allocated, touched, freed
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    again = np.ones(size // 8)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def refaults(policy: str, size: int) -> int:
    """Page faults of filling a ``size``-byte array again after one of that size was freed,
    in a fresh process under ``policy`` (a function of imupipe.pages)."""
    run = subprocess.run(
        [sys.executable, "-c", REFAULT, policy, str(size)], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    return int(run.stdout)


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's mallopt")
def test_freed_column_is_reused_in_memory_and_returned_when_spilled() -> None:
    column = 35_000_000  # a float64 column of 12 h at 100 Hz
    page_count = column // 4096
    assert refaults("reuse_freed_memory", column) < page_count // 20  # still resident
    assert refaults("release_freed_memory", column) > page_count * 9 // 10  # fresh pages again
    # a block beyond what the heap keeps is still mapped and unmapped on its own
    assert refaults("reuse_freed_memory", REUSED_BLOCK_BYTES + (8 << 20)) > page_count


def test_the_command_sets_its_process_policies_and_a_spilled_analysis_returns_freed_blocks(
    tmp_path: Path, small_recordings, monkeypatch: pytest.MonkeyPatch, cli
) -> None:
    calls: list[str] = []
    monkeypatch.setattr(pages, "reuse_freed_memory", lambda: calls.append("reuse"))
    monkeypatch.setattr(gc, "freeze", lambda: calls.append("freeze"))
    monkeypatch.setattr(columns, "release_freed_memory", lambda: calls.append("release"))
    rec = small_recordings.make("adis", tmp_path / "adis.mcap")
    small_recordings.run(rec, tmp_path / "library", 1 << 40)
    assert calls == []  # the library leaves an in-memory analysis' process as it found it
    command = ["analyze", str(rec), "-q", "--no-rrd", "--no-loop"]
    code, _, err = cli([*command, "--out", str(tmp_path / "cmd")])
    assert code == 0, err
    assert calls == ["reuse", "freeze"]  # the imports' objects out of the collector's passes too
    calls.clear()
    needs = columns.peak_estimate([rec])  # in memory, but no room left for kept blocks
    code, _, err = cli(
        [*command, "--out", str(tmp_path / "tight"), "--memory-budget-gb", str(needs / 1e9)]
    )
    assert code == 0, err
    assert calls == ["freeze"]
    calls.clear()
    code, _, err = cli([*command, "--out", str(tmp_path / "spilled"), "--memory-budget-gb", "1e-9"])
    assert code == 0, err
    assert calls and set(calls) == {"release", "freeze"}  # sized to its budget, wherever it runs
