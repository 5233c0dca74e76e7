"""The noise model: IEEE Std 952 terms fitted with intervals (:mod:`.ieee952`), the candidate
effects the model may lack (:mod:`.effects`), and the closed loop that tests and adds them
(:mod:`.loop`)."""

from imupipe.model.ieee952 import NoiseTerm, NoiseTerms, fit_noise_terms
from imupipe.model.loop import AxisSignals, LoopResult, aux_block_means, close_loop

__all__ = [
    "AxisSignals",
    "LoopResult",
    "NoiseTerm",
    "NoiseTerms",
    "aux_block_means",
    "close_loop",
    "fit_noise_terms",
]
