"""One recording analysed: conditioning (:mod:`.condition`), the one orchestrator of the
stages for either column source (:mod:`.analyze`) and the result contract (:mod:`.results`).

The names below load their module on first use (PEP 562): importing a submodule, e.g.
:mod:`.results` for a report's types, does not import the whole analysis (numba kernels,
scipy) with it."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

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

_MODULE_OF = {
    "AnalyzeOptions": "analyze",
    "ConditionedSeries": "condition",
    "ALLAN_SCHEMA": "results",
    "AnalysisResult": "results",
    "AxisResult": "results",
    "InputSummary": "results",
}


def __getattr__(name: str) -> Any:
    if name in _MODULE_OF:
        import importlib

        return getattr(importlib.import_module(f"imupipe.analysis.{_MODULE_OF[name]}"), name)
    raise AttributeError(f"module 'imupipe.analysis' has no attribute {name!r}")
