"""The noise model: IEEE Std 952 terms fitted with intervals (:mod:`.ieee952`), the candidate
effects the model may lack (:mod:`.effects`), and the closed loop that tests and adds them
(:mod:`.loop`)."""
