"""imupipe.pages: an analysis (and a decode) allocates its large arrays without numpy's
huge-page advice, and leaves numpy's setting as it found it; the ``imupipe analyze`` command
freezes its imports' objects out of the garbage collector's full passes."""

from __future__ import annotations

import gc
from pathlib import Path

import pytest

import imupipe.analysis.analyze as orchestrator
from imupipe.pages import _toggle, small_pages


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


def test_the_command_freezes_its_imports_out_of_the_collectors_passes_the_library_does_not(
    tmp_path: Path, small_recordings, monkeypatch: pytest.MonkeyPatch, cli
) -> None:
    calls: list[str] = []
    monkeypatch.setattr(gc, "freeze", lambda: calls.append("freeze"))
    rec = small_recordings.make("adis", tmp_path / "adis.mcap")
    small_recordings.run(rec, tmp_path / "library", 1 << 40)
    assert calls == []  # a long-lived process would keep pending cyclic garbage forever
    command = ["analyze", str(rec), "-q", "--no-rrd", "--no-loop", "--out", str(tmp_path / "cmd")]
    code, _, err = cli(command)
    assert code == 0, err
    assert calls == ["freeze"]
