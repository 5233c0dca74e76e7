"""Fakes and bulk encoders used by the tests and benchmarks only (never by the pipeline)."""

from imupipe.testing.ros_cdr import imu_payloads, temperature_payloads

__all__ = ["imu_payloads", "temperature_payloads"]
