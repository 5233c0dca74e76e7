"""One recording analysed: conditioning (:mod:`.condition`), the one orchestrator of the
stages for either column source (:mod:`.analyze`) and the result contract (:mod:`.results`).

The names below load their module on first use (PEP 562): importing a submodule, e.g.
:mod:`.results` for a report's types, does not import the whole analysis (numba kernels,
scipy) with it."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imupipe import lazy_names

if TYPE_CHECKING:
    from imupipe.analysis.analyze import AnalyzeOptions
    from imupipe.analysis.condition import ConditionedSeries
    from imupipe.analysis.results import ALLAN_SCHEMA, AnalysisResult, AxisResult, InputSummary

__all__ = [
    "ALLAN_SCHEMA",
    "AnalysisResult",
    "AnalyzeOptions",
    "AxisResult",
    "ConditionedSeries",
    "InputSummary",
]

__getattr__ = lazy_names(
    "imupipe.analysis",
    {
        "AnalyzeOptions": "imupipe.analysis.analyze",
        "ConditionedSeries": "imupipe.analysis.condition",
        **dict.fromkeys(
            ("ALLAN_SCHEMA", "AnalysisResult", "AxisResult", "InputSummary"),
            "imupipe.analysis.results",
        ),
    },
)
