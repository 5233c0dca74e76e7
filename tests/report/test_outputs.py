"""The outputs of ``imupipe analyze`` in one folder (:class:`imupipe.report.outputs.ReportOutputs`):
what is written by default, into a folder that may not exist yet, with the report's progress."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from pathlib import Path

from imupipe.report.outputs import ReportOutputs


class Stages:
    """A stand-in for :class:`imupipe.progress.StageProgress` that keeps what it was told."""

    def __init__(self) -> None:
        self.told: list[tuple[str, float, str, list[float]]] = []

    @contextlib.contextmanager
    def stage(self, name: str, total: float, unit: str = ""):
        done: list[float] = []
        self.told.append((name, total, unit, done))
        yield done.append


def test_defaults_are_figures_and_the_light_rrd(tmp_path: Path) -> None:
    outputs = ReportOutputs(tmp_path / "out")
    assert outputs.figures is True and outputs.rrd_full is False and outputs.rrd is None


def test_the_report_and_rrd_are_two_steps_of_one_bar(
    tmp_path: Path, synthetic_result, signal_frames
) -> None:
    out = tmp_path / "a" / "b" / "out"  # parents made as needed
    outputs = ReportOutputs(out, figures=False, processes=1)
    outputs.begin(signal_frames(500))
    stages = Stages()
    outputs.finish(synthetic_result(), stages)
    assert stages.told == [("report", 2, "files", [1, 2])]
    assert (out / "report.json").is_file() and (out / "recording.rrd").stat().st_size > 0
    assert not (out / "figures").exists()


def test_without_an_rrd_the_report_is_the_one_step(tmp_path: Path, synthetic_result) -> None:
    outputs = ReportOutputs(tmp_path / "out", figures=False, processes=1)
    stages = Stages()
    outputs.finish(synthetic_result(), stages)
    assert stages.told == [("report", 1, "files", [1])]
    assert not (tmp_path / "out" / "recording.rrd").exists()


def test_rerun_is_imported_only_when_an_rrd_is_written() -> None:
    """The rerun SDK (and the datasheet module) stay unimported by the outputs' module: an
    analysis without --rrd never pays for them."""
    code = "import sys, imupipe.report.outputs; print('rerun' in sys.modules)"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "False"


def test_an_existing_folder_is_written_into(tmp_path: Path, signal_frames) -> None:
    """The staging folder exists before the rrd is begun (:mod:`imupipe.report.staging`)."""
    outputs = ReportOutputs(tmp_path, figures=False, processes=1)
    outputs.begin(signal_frames(100))
    outputs.discard()
    assert not (tmp_path / "recording.rrd").exists()
