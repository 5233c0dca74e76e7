"""What a user takes away: report.json/.md and imu.yaml (:mod:`.report`), figures
(:mod:`.figures`), the Rerun recording (:mod:`.rerun_view`), the paper's values
(:mod:`.paper`), and the orchestrator's outputs writing them all (:mod:`.outputs`)."""

from imupipe.report.report import format_table, write_report
from imupipe.report.rerun_view import RrdWriter, open_viewer

__all__ = ["RrdWriter", "format_table", "open_viewer", "write_report"]
