"""The accelerometers' figures drawn in a forked child while this process draws the
gyroscopes': the same files and captions, the child's error raised here, no child left."""

from __future__ import annotations

from pathlib import Path

import psutil
import pytest

from imupipe.report import figures


def children() -> set[int]:
    """This process' child processes (an earlier test in the same process may have left a
    long-lived one, e.g. multiprocessing's resource tracker after a Dask cluster)."""
    return {p.pid for p in psutil.Process().children(recursive=True)}


def test_two_processes_draw_the_same_figures(tmp_path: Path, synthetic_result) -> None:
    result = synthetic_result()
    before = children()
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    one = figures.write_figures(result, tmp_path / "one", processes=1)
    two = figures.write_figures(result, tmp_path / "two", processes=2)
    assert list(one) == ["Gyroscopes: allan", "Accelerometers: allan", "Accelerometers: loop"]
    assert list(two) == list(one)  # the stand-in's gyroscopes have no loop
    for caption, path in two.items():
        assert path.parent == tmp_path / "two"
        assert path.read_bytes() == one[caption].read_bytes()
    assert children() <= before


def test_child_error_is_raised_here(
    tmp_path: Path, synthetic_result, monkeypatch: pytest.MonkeyPatch
) -> None:
    allan_figure = figures.allan_figure

    def fail_on_accel(result, sensor, path):
        if sensor == "accel":
            raise OSError(f"cannot write {path.name}")
        return allan_figure(result, sensor, path)

    monkeypatch.setattr(figures, "allan_figure", fail_on_accel)  # the child is forked: seen
    before = children()
    with pytest.raises(OSError, match=r"cannot write allan_accel\.png"):
        figures.write_figures(synthetic_result(), tmp_path, processes=2)
    assert children() <= before
    assert (tmp_path / "allan_gyro.png").is_file()  # drawn here meanwhile


@pytest.mark.parametrize("processes", [1, 2])
def test_axes_that_move_together_add_their_figure_last(
    tmp_path: Path, synthetic_result, processes: int
) -> None:
    """A result whose detector names a pair: common_mode.png, captioned "Axes that move
    together", after the sensors' figures, drawn by this process with either process count."""
    from dataclasses import replace

    from imupipe.analysis import events as ev

    det = ev.EventDetector(
        0.5, (0.5,), (206,), (6.0,), (5.0,), ("accel_x", "accel_y"), ((0.9,),)
    )  # dof 97.85, one test: r 0.9 is named
    result = replace(synthetic_result(), events=ev.EventsFound(det, (), 0.01, 0.0))
    written = figures.write_figures(result, tmp_path, processes=processes)
    assert list(written) == [
        "Gyroscopes: allan",
        "Accelerometers: allan",
        "Accelerometers: loop",
        "Axes that move together",
    ]
    assert written["Axes that move together"] == tmp_path / "common_mode.png"
    assert (tmp_path / "common_mode.png").stat().st_size > 10_000


@pytest.mark.parametrize("processes", [None, 1, 2, 3])
def test_the_accelerometers_are_drawn_in_a_child_only_with_two_or_more_processes(
    tmp_path: Path, synthetic_result, monkeypatch: pytest.MonkeyPatch, processes: int | None
) -> None:
    """Which process draws each sensor's figures (its pid written beside them): this one for
    both with 1 process (the default, None here); with 2 or more, a forked child for the
    accelerometers."""
    import os

    allan_figure = figures.allan_figure

    def drawing(result, sensor, path):
        (path.parent / f"{sensor}.pid").write_text(str(os.getpid()))
        return allan_figure(result, sensor, path)

    monkeypatch.setattr(figures, "allan_figure", drawing)  # the child is forked: seen
    if processes is None:
        figures.write_figures(synthetic_result(), tmp_path)
    else:
        figures.write_figures(synthetic_result(), tmp_path, processes=processes)
    pids = {s: int((tmp_path / f"{s}.pid").read_text()) for s in ("gyro", "accel")}
    assert pids["gyro"] == os.getpid()
    assert (pids["accel"] == os.getpid()) is (processes in (None, 1))
