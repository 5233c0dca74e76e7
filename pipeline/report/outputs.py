"""The outputs of ``imupipe analyze`` in one folder: what the orchestrator
(:func:`imupipe.analysis.analyze.analyze`) hands its results to.

report.json/.md, figures, allan.parquet and imu.yaml (:func:`imupipe.report.report.
write_report`) and, unless turned off, recording.rrd (:class:`imupipe.report.rerun_view.
RrdWriter`: its raw signals are sent when the segment is known, the analysis views at the end).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import polars as pl

from imupipe.analysis.results import AnalysisResult
from imupipe.jit import usable_cores
from imupipe.progress import StageProgress
from imupipe.report.report import write_report

if TYPE_CHECKING:
    from imupipe.report.datasheet import Datasheet
    from imupipe.report.rerun_view import RrdWriter


class ReportOutputs:
    """Writes the reports (and ``recording.rrd`` once :meth:`begin` was called) into
    ``out_dir``; implements :class:`imupipe.analysis.analyze.Outputs`."""

    def __init__(
        self,
        out_dir: Path,
        figures: bool = True,
        rrd_full: bool = False,
        datasheet: Datasheet | None = None,
        processes: int | None = None,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.processes = usable_cores() if processes is None else processes
        """Processes drawing the figures (default: the usable cores)."""
        self.figures = figures
        self.rrd_full = rrd_full
        self.datasheet = datasheet
        self.rrd: RrdWriter | None = None

    def begin(self, signals: pl.DataFrame) -> None:
        from imupipe.report.rerun_view import RrdWriter  # rerun-sdk only when asked for

        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.rrd = RrdWriter(self.out_dir / "recording.rrd", signals, self.rrd_full)

    def finish(self, result: AnalysisResult, progress: StageProgress) -> None:
        with progress.stage("report", 2 if self.rrd else 1, "files") as advance:
            write_report(
                result, self.out_dir, self.figures, self.datasheet, processes=self.processes
            )
            advance(1)
            if self.rrd:
                self.rrd.finish(result)
                advance(2)

    def discard(self) -> None:
        if self.rrd:
            self.rrd.discard()
