"""Fakes and bulk encoders used by the tests and benchmarks only (never by the pipeline)."""
