"""The live view while recording: every frame streamed in SI, the Allan views redrawn as the
recording grows, the viewer process bound to 127.0.0.1."""

from __future__ import annotations

import os
import signal
import socket
import time
from pathlib import Path

import numpy as np
import pytest
import rerun as rr

from imupipe.api import record as api_record
from imupipe.device.adis16364 import config_for_rate
from imupipe.errors import ImupipeError
from imupipe.io.decode import decode
from imupipe.recording.recorder import record
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.report.rerun_live import LiveView, block_frame, start_viewer

CONFIG = config_for_rate(100.0)
FRAMES = 40_000  # three recorder chunks: 16384 + 16384 + 7232


def test_live_view_streams_every_frame_and_redraws_the_allan_views(
    tmp_path: Path, rrd_chunks
) -> None:
    rec = rr.RecordingStream("imupipe", make_default=False, make_thread_default=False)
    rec.save(tmp_path / "live.rrd")
    live = LiveView(VirtualADIS16364(CONFIG, None, seed=3), rec, adev_period_s=0.0)
    summary = record(tmp_path / "run.mcap", live, FRAMES)
    live.finish()
    assert summary.frames == FRAMES
    chunks = rrd_chunks.rows(tmp_path / "live.rrd")
    for plot in ("gyro", "accel", "temperature", "supply"):
        assert chunks[f"/signals/{plot}"] == FRAMES  # every frame, live
    lines = rrd_chunks.lines(tmp_path / "live.rrd")
    redraws = [e for e, _, _ in lines if e == "/allan/gyro/gyro_x/adev"]
    assert (
        len(redraws) >= 2
    )  # during the recording (period 0: after the first chunk) and at the end
    first_data = next(i for i, c in enumerate(lines) if "Scalars:scalars" in c[2])
    before = {e for e, _, cols in lines[:first_data]}
    assert {"/viewport", "/signals/gyro", "/signals/supply"} <= before  # layout and names first


def test_block_frame_is_the_decoded_recording(tmp_path: Path) -> None:
    """The live SI values are those `imupipe analyze` decodes from the file."""
    block = VirtualADIS16364(CONFIG, None, seed=4).frames(500)
    live = block_frame(block, CONFIG)
    record(tmp_path / "run.mcap", VirtualADIS16364(CONFIG, None, seed=4), 500)  # same bytes
    frames = decode(tmp_path / "run.mcap").frames
    for name in ("gyro_x", "accel_z", "temp_c", "supply_v"):
        np.testing.assert_array_equal(live[name].to_numpy(), frames[name].to_numpy())
    assert abs(live["accel_z"].mean() + 9.8) < 0.1  # m/s², not counts or g


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_serve_listens_on_loopback_only_and_is_stopped(tmp_path: Path) -> None:
    port = _free_port()
    proc = start_viewer("serve", port)
    try:
        assert proc.args[proc.args.index("--bind") + 1] == "127.0.0.1"
        deadline = time.monotonic() + 60
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert proc.poll() is None and time.monotonic() < deadline, "server not up"
                time.sleep(0.2)
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=30)


def test_unknown_view_mode_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ImupipeError, match="unknown view 'window'"):
        api_record(tmp_path / "run.mcap", duration="1s", view="window")
