"""What a user takes away: report.json/.md and imu.yaml (:mod:`.report`), figures
(:mod:`.figures`), the Rerun recording (:mod:`.rerun_view`), the paper's values
(:mod:`.paper`), and the orchestrator's outputs writing them all (:mod:`.outputs`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imupipe import lazy_names

if TYPE_CHECKING:
    from imupipe.report.report import format_table, write_report
    from imupipe.report.rerun_view import RrdWriter, open_viewer

__all__ = ["RrdWriter", "format_table", "open_viewer", "write_report"]

# Each name loads its module on first use: the Rerun names rerun-sdk (~0.3 s of CPU), so that
# ``imupipe info`` or ``analyze --no-rrd`` never import it; the report's names the analysis
# (numba, polars, scipy: ~0.9 s), so that a submodule such as :mod:`.exports` (``imupipe
# --help``, ``view``, ``export``) does not.
__getattr__ = lazy_names(
    "imupipe.report",
    {
        "RrdWriter": "imupipe.report.rerun_view",
        "open_viewer": "imupipe.report.rerun_view",
        "format_table": "imupipe.report.report",
        "write_report": "imupipe.report.report",
    },
)
