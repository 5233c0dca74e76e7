"""One recording analysed: conditioning (:mod:`.condition`), the one orchestrator of the
stages for either column source (:mod:`.analyze`) and the result contract (:mod:`.results`)."""
