"""The ADIS16364 itself, shared by the recording and the analysis side: register map, burst
layout, scale factors and configuration (:mod:`.adis16364`), and the MCAP frame schema
(:mod:`.frame_schema`)."""
