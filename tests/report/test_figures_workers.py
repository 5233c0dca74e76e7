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
