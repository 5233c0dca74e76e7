"""What a user takes away: report.json/.md and imu.yaml (:mod:`.report`), figures
(:mod:`.figures`), the Rerun recording (:mod:`.rerun_view`), the paper's values
(:mod:`.paper`), and the orchestrator's outputs writing them all (:mod:`.outputs`)."""
