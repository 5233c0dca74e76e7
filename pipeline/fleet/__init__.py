"""Fleets: many recordings analysed on a Dask cluster, with a population report (issue 14).

discover (which recordings) → cluster (LocalCluster or an existing scheduler) → task (one
``imupipe analyze`` per recording, on a worker) → population (statistics per axis and term,
datasheet) → report (fleet.json, fleet.parquet, fleet.md + figures, fleet.rrd); :mod:`.run`
ties them together.
"""
