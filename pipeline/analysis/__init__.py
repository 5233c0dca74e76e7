"""One recording analysed: conditioning (:mod:`.condition`), the orchestrator
(:mod:`.analyze`) and the result contract (:mod:`.results`)."""
