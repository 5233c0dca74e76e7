"""What a user takes away: report.json/.md and imu.yaml (:mod:`.report`), figures
(:mod:`.figures`), the Rerun recording (:mod:`.rerun_view`), the paper's values
(:mod:`.paper`), and the orchestrator's outputs writing them all (:mod:`.outputs`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from imupipe.report.report import format_table, write_report
    from imupipe.report.rerun_view import RrdWriter, open_viewer

__all__ = ["RrdWriter", "format_table", "open_viewer", "write_report"]


def __getattr__(name: str) -> Any:
    """PEP 562: each name loads its module on first use only — the Rerun names rerun-sdk
    (~0.3 s of CPU), so that ``imupipe info`` or ``analyze --no-rrd`` never import it, and the
    report's the analysis (numba, polars, scipy: ~0.9 s), so that a submodule such as
    :mod:`.exports` (``imupipe --help``, ``view``, ``export``) does not."""
    if name in ("RrdWriter", "open_viewer"):
        from imupipe.report import rerun_view

        return getattr(rerun_view, name)
    if name in ("format_table", "write_report"):
        from imupipe.report import report

        return getattr(report, name)
    raise AttributeError(f"module 'imupipe.report' has no attribute {name!r}")
