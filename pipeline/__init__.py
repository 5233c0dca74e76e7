"""imupipe: record ADIS16364 frames into MCAP and analyse IMU noise (overlapping Allan
deviation, IEEE Std 952 terms with intervals, a closed loop that finds what the model misses).

The public API (imported on first use, so that ``imupipe.errors`` stays light)::

    import imupipe
    result = imupipe.analyze("run.mcap")          # writes run.imupipe/, returns AnalysisResult
    result.to_dict()["axes"]["gyro_x"]["ieee952"]  # report.json, SI units
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"
__all__ = [
    "AnalysisResult",
    "ImupipeError",
    "RecordSummary",
    "__version__",
    "analyze",
    "analyze_fleet",
    "record",
]

if TYPE_CHECKING:
    from imupipe.analysis.results import AnalysisResult
    from imupipe.api import analyze, analyze_fleet, record
    from imupipe.errors import ImupipeError
    from imupipe.recording.recorder import RecordSummary

_LAZY = {
    "analyze": "imupipe.api",
    "record": "imupipe.api",
    "analyze_fleet": "imupipe.api",
    "AnalysisResult": "imupipe.analysis.results",
    "RecordSummary": "imupipe.recording.recorder",
    "ImupipeError": "imupipe.errors",
}


def lazy_names(package: str, module_of: dict[str, str]) -> Callable[[str], Any]:
    """A package's ``__getattr__`` (PEP 562) that loads each name of ``module_of`` (name →
    module) on first access, so that importing the package, or one of its submodules, does
    not import what its names need (numba, polars, rerun-sdk...)."""

    def load(name: str) -> Any:
        if name in module_of:
            import importlib

            return getattr(importlib.import_module(module_of[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return load


__getattr__ = lazy_names("imupipe", _LAZY)
