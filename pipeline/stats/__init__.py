"""Statistics that know nothing of IMUs: overlapping Allan variance with confidence intervals
(:mod:`.allan`), equivalent degrees of freedom and noise identification (:mod:`.edf`), the
correlation of Allan variance estimates across τ (:mod:`.avar_covariance`), robust location and
scale (:mod:`.robust`)."""

from imupipe.stats.allan import AllanCurve, SparseCorrection, allan_curves, oadev, tau_factors
from imupipe.stats.avar_covariance import avar_correlation
from imupipe.stats.edf import chi2_interval, edf_oadev, noise_ids
from imupipe.stats.robust import mad, median

__all__ = [
    "AllanCurve",
    "SparseCorrection",
    "allan_curves",
    "avar_correlation",
    "chi2_interval",
    "edf_oadev",
    "mad",
    "median",
    "noise_ids",
    "oadev",
    "tau_factors",
]
