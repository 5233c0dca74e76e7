"""One recording analysed: conditioning (:mod:`.condition`), the one orchestrator of the
stages for either column source (:mod:`.analyze`) and the result contract (:mod:`.results`)."""

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
