"""Statistics that know nothing of IMUs: overlapping Allan variance with confidence intervals
(:mod:`.allan`), equivalent degrees of freedom and noise identification (:mod:`.edf`), robust
location and scale (:mod:`.robust`)."""
