"""Axes that move together: a cause common to several axes, read from the event detector's
windows (issue 13: trace what the per-axis model leaves to a physical effect).

The per-axis loop models each axis alone.  A cause shared by several axes — a temperature or
supply change moving every bias, a vibration or tilt of the mount — shows as a correlation of
their level fluctuations, which no per-axis term can show.  The event detector
(:mod:`imupipe.analysis.events`) already measures it: at each window length L it correlates
the axes' robust z-scores of their window means about the local level (z clipped at ±3, so a
few events barely move it; :func:`imupipe.analysis.events.axis_correlation`).  Here each of
those correlations is tested against independence:

* Fisher's transform (Fisher 1921; e.g. Kendall & Stuart, *The Advanced Theory of
  Statistics*, vol. 1, §16.33): under independence atanh(r) · √(ν − 3) is about N(0, 1), with
  ν = the scale's degrees of freedom (0.95 × J / 2 for J half-overlapping windows,
  :func:`imupipe.analysis.events.scale_dof`); two-sided p = 2 Φ̄(|atanh r| √(ν − 3)).
* Family-wise: Bonferroni over every scale and axis pair tested; a pair moves together when
  its smallest p times the number of tests is at most :data:`ALPHA`.

Calibration (session 53, 12 clean 2 h / 100 Hz recordings of the independent generator,
axes independent, 9 scales × 15 pairs): the correlations' spread was 0.73–0.94 of the
√(ν − 3) the test assumes at every scale, no |z| beyond 3.29 in 1,620 — the test is
conservative, as a Bonferroni rule over correlated windows should be.

Units: window lengths in s, correlations dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Protocol

import numpy as np
from scipy import special

ALPHA = 1e-3
"""Family-wise probability of naming a pair that does not move together (as the detector's
record-wide false-alarm probability)."""


@dataclass(frozen=True)
class PairMotion:
    """One axis pair whose level fluctuations are correlated (report.json
    ``events.common_mode.pairs``)."""

    axes: tuple[str, str]
    window_s: tuple[float, ...]
    """Every window length tested (s)."""
    correlation: tuple[float, ...]
    """The pair's correlation at each window length (dimensionless)."""
    significant_s: tuple[float, ...]
    """The window lengths at which the correlation passes the family-wise test (s)."""
    p_value: float
    """Family-wise p-value of the pair (Bonferroni over scales and pairs, at most 1)."""

    @property
    def strongest(self) -> tuple[float, float]:
        """(window s, correlation) where |correlation| is largest among the significant."""
        at = [k for k, w in enumerate(self.window_s) if w in self.significant_s]
        k = max(at, key=lambda j: abs(self.correlation[j]))
        return self.window_s[k], self.correlation[k]

    def as_dict(self) -> dict:
        return {
            "axes": list(self.axes),
            "p_value": self.p_value,
            "significant_window_s": list(self.significant_s),
            "strongest": dict(zip(("window_s", "value"), self.strongest, strict=True)),
            "correlation": [
                {"window_s": w, "value": r}
                for w, r in zip(self.window_s, self.correlation, strict=True)
            ],
        }


@dataclass(frozen=True)
class CommonMode:
    """The axis pairs that move together in one record (report.json ``events.common_mode``)."""

    pairs: tuple[PairMotion, ...]
    tests: int
    """Correlations tested (scales × pairs): the Bonferroni count."""
    alpha: float = ALPHA

    def strongest(self, limit: int) -> str:
        """The ``limit`` strongest pairs as text, "a–b r 0.85 at 64 s, …" (and how many more)."""
        texts = [
            f"{a}–{b} r {r:.2f} at {w:g} s" for (a, b), (w, r) in
            ((p.axes, p.strongest) for p in self.pairs[:limit])
        ]  # fmt: skip
        more = len(self.pairs) - limit
        return ", ".join(texts) + (f" and {more} more pair{'s' * (more > 1)}" if more > 0 else "")

    def warning(self) -> str | None:
        """One warning line when some pairs move together (None otherwise)."""
        if not self.pairs:
            return None
        return (
            f"axes that move together: {self.strongest(3)} (correlation of their level "
            f"fluctuations, family-wise p ≤ {self.alpha:g}): a cause common to them "
            "(temperature or the supply moving every bias at long windows, a vibration or tilt "
            "of the mount at short ones); the noise terms treat each axis alone"
        )

    def as_dict(self) -> dict:
        return {
            "alpha": self.alpha,
            "tests": self.tests,
            "rule": (
                "a pair of axes moves together when the correlation of their level "
                "fluctuations (the event detector's window z-scores, clipped at 3) at some "
                "window length has a two-sided Fisher p-value, 2 Phi(-|atanh r| sqrt(dof - 3)) "
                "with the scale's degrees of freedom, of at most alpha / tests (Bonferroni "
                "over window lengths and pairs)"
            ),
            "pairs": [p.as_dict() for p in self.pairs],
        }


class PairCorrelations(Protocol):
    """What the test reads (:class:`imupipe.analysis.events.EventDetector` has it): the axes,
    the window lengths (s), each length's degrees of freedom and each axis pair's correlation
    at each length (C(A, 2) values per length, in :func:`np.triu_indices` order)."""

    axes: tuple[str, ...]
    scales_s: tuple[float, ...]
    pair_correlation: tuple[tuple[float, ...], ...]

    @property
    def dof(self) -> tuple[float, ...]: ...


def fisher_p(r: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """Two-sided p-value of correlations ``r`` against 0 with ``dof`` degrees of freedom
    (Fisher's z: atanh(r) √(ν − 3) ~ N(0, 1); 1 where ν ≤ 3)."""
    r = np.clip(np.abs(np.asarray(r, dtype=float)), 0.0, 1 - 1e-15)
    dof = np.asarray(dof, dtype=float)
    z = np.arctanh(r) * np.sqrt(np.maximum(dof - 3, 0.0))
    return np.where(dof > 3, 2 * special.ndtr(-z), 1.0)


def critical_correlation(dof: np.ndarray, tests: int, alpha: float = ALPHA) -> np.ndarray:
    """|r| at which a correlation with ``dof`` degrees of freedom passes the family-wise test
    of ``tests`` correlations: tanh(Φ̄⁻¹(α / (2 · tests)) / √(ν − 3)) (1 where ν ≤ 3)."""
    dof = np.asarray(dof, dtype=float)
    z = -special.ndtri(alpha / (2 * max(tests, 1)))
    with np.errstate(divide="ignore"):
        return np.where(dof > 3, np.tanh(z / np.sqrt(np.maximum(dof - 3, 0.0))), 1.0)


def common_mode(detector: PairCorrelations, alpha: float = ALPHA) -> CommonMode:
    """The pairs of ``detector.axes`` whose level fluctuations are correlated (module
    docstring), strongest first."""
    pairs = list(combinations(detector.axes, 2))
    if not pairs or not detector.pair_correlation:
        return CommonMode((), 0, alpha)
    r = np.array(detector.pair_correlation, dtype=float)  # (scales, pairs)
    p = fisher_p(r, np.array(detector.dof)[:, None])
    tests = r.size
    family = np.minimum(p * tests, 1.0)
    found = []
    for j, axes in enumerate(pairs):
        significant = family[:, j] <= alpha
        if np.any(significant):
            found.append(
                PairMotion(
                    axes,
                    tuple(detector.scales_s),
                    tuple(float(v) for v in r[:, j]),
                    tuple(w for w, s in zip(detector.scales_s, significant, strict=True) if s),
                    float(np.min(family[:, j])),
                )
            )
    found.sort(key=lambda m: -abs(m.strongest[1]))
    return CommonMode(tuple(found), tests, alpha)
