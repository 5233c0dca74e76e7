"""What a user takes away: report.json/.md and imu.yaml (:mod:`.report`), figures
(:mod:`.figures`), the Rerun recording (:mod:`.rerun_view`), the paper's values
(:mod:`.paper`), and the orchestrator's outputs writing them all (:mod:`.outputs`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from imupipe.report.report import format_table, write_report

if TYPE_CHECKING:
    from imupipe.report.rerun_view import RrdWriter, open_viewer

__all__ = ["RrdWriter", "format_table", "open_viewer", "write_report"]


def __getattr__(name: str) -> Any:
    """PEP 562: the Rerun names load rerun-sdk (~0.3 s of CPU) on first use only, so that
    ``imupipe info`` or ``analyze --no-rrd`` never import it."""
    if name in ("RrdWriter", "open_viewer"):
        from imupipe.report import rerun_view

        return getattr(rerun_view, name)
    raise AttributeError(f"module 'imupipe.report' has no attribute {name!r}")
