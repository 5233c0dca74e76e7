"""Rerun streams are let go once a recording is written: a fleet worker writes one
``recording.rrd`` per unit in one process, and rerun-sdk 0.41 keeps each stream (two threads,
and every array logged) until it is swept (:mod:`imupipe.report.rerun_streams`)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import polars as pl
import rerun as rr
from rerun.recording_stream import bindings

from imupipe.fleet.curves import UNIT_COLUMN
from imupipe.fleet.rerun_view import write_fleet_rrd
from imupipe.report.rerun_view import write_rrd


def _stream_threads() -> int:
    """Threads of this process that rerun starts per recording stream (Linux task names); a
    thread that ends between the listing and the read of its name is not counted."""
    count = 0
    for task in os.listdir("/proc/self/task"):
        try:
            name = Path(f"/proc/self/task/{task}/comm").read_text()
        except FileNotFoundError:
            continue
        count += name.startswith(("RecordingStream", "ChunkBatcher"))
    return count


def test_recordings_written_one_after_another_leave_no_stream_behind(
    tmp_path: Path, synthetic_result, signal_frames, rrd_chunks
) -> None:
    result, frames = synthetic_result(), signal_frames(3_000)
    before = _stream_threads()  # rerun's own threads (tokio, jemalloc) are not counted
    for k in range(3):
        path = write_rrd(result, frames, tmp_path / f"unit{k}.rrd")
    assert _stream_threads() <= before  # was 2 more per file, and 2 per blueprint sent
    viewports = [
        i for i, (entity, _, _) in enumerate(rrd_chunks.lines(path)) if entity == "/viewport"
    ]
    last_data = max(i for i, (_, _, cols) in enumerate(rrd_chunks.lines(path)) if "Scalars" in cols)
    assert len(viewports) == 2 and viewports[-1] > last_data  # the layout first and last
    assert rrd_chunks.activations(path) == [(True, True), (True, True)]  # each shown at once


def test_the_fleet_recording_leaves_no_stream_behind(tmp_path: Path, rrd_chunks) -> None:
    tau = np.geomspace(0.01, 100.0, 20)
    fleet = pl.DataFrame(
        {
            UNIT_COLUMN: ["a"] * 20 + ["b"] * 20,
            "axis": ["gyro_x"] * 40,
            "unit": ["rad/s"] * 40,
            "tau": np.r_[tau, tau],
            "adev": np.r_[1e-3 / np.sqrt(tau), 1.2e-3 / np.sqrt(tau)],
        }
    )
    pop = fleet.group_by("axis", "tau", maintain_order=True).agg(
        pl.col("adev").median().alias("median"),
        pl.col("adev").min().alias("lo"),
        pl.col("adev").max().alias("hi"),
    )
    write_fleet_rrd(fleet, pop, tmp_path / "warm.rrd")
    before = _stream_threads()
    path = write_fleet_rrd(fleet, pop, tmp_path / "fleet.rrd")
    assert _stream_threads() <= before
    assert rrd_chunks.activations(path) == [(True, True)]


def test_a_callers_own_recordings_are_left_alone(
    tmp_path: Path, synthetic_result, signal_frames
) -> None:
    """The sweep would unset the process's global recording, and a stream made a default would
    replace the caller's: a script that logs to its own ``rr.init`` (or thread-local) recording
    and calls imupipe keeps logging to it, and no blueprint recording is left set."""
    own = rr.RecordingStream("caller", make_default=False, make_thread_default=False)
    mine = rr.RecordingStream("caller_thread", make_default=False, make_thread_default=False)
    rr.set_global_data_recording(own)
    rr.set_thread_local_data_recording(mine)
    try:
        write_rrd(synthetic_result(), signal_frames(3_000), tmp_path / "recording.rrd")
        still = rr.get_global_data_recording()
        assert still is not None and still.get_recording_id() == own.get_recording_id()
        here = rr.get_thread_local_data_recording()
        assert here is not None and here.get_recording_id() == mine.get_recording_id()
        assert bindings.get_global_blueprint_recording() is None
        assert bindings.get_thread_local_blueprint_recording() is None
    finally:
        rr.set_global_data_recording(None)
        rr.set_thread_local_data_recording(None)
