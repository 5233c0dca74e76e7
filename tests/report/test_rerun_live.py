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


class _Stream:
    """Stands in for the viewer's RecordingStream: keeps what is sent and logged."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, np.ndarray, np.ndarray]] = []
        self.logged: dict[str, object] = {}

    def send_columns(self, entity, indexes, columns) -> None:
        import pyarrow as pa

        times = np.array(indexes[0].as_arrow_array().cast(pa.int64()).to_pylist())
        (column,) = list(columns)
        values = np.array(column.as_arrow_array().to_pylist(), dtype=float)
        self.sent.append((entity, times, values))

    def log(self, path, archetype, static=False) -> None:
        self.logged[path] = archetype

    def flush(self) -> None:
        pass

    def disconnect(self) -> None:
        pass


def test_live_signals_are_sent_at_their_stamps_minus_the_first_blocks_mean(monkeypatch) -> None:
    """Each block goes out at its stamps from the first frame's, each centred plot minus the
    first block's mean; an Allan redraw starts after every block once the last one is done
    (period 0), each view holding its own sensor's axes, with the summary's length and rate."""
    from imupipe.report import rerun_live

    monkeypatch.setattr(rerun_live, "send_blueprint", lambda rec, bp: None)
    stream = _Stream()
    device = VirtualADIS16364(CONFIG, None, seed=5)
    live = LiveView(device, stream, adev_period_s=0.0)
    reference = VirtualADIS16364(CONFIG, None, seed=5)
    blocks, draws = [], []
    draw = live._draw_allan
    monkeypatch.setattr(live, "_draw_allan", lambda parts: draws.append(1) or draw(parts))
    for n in (300, 200, 100):
        blocks.append(reference.frames(n))
        live.frames(n)
        live._allan.join()
    assert len(draws) == 3
    first = block_frame(blocks[0], CONFIG)
    t0 = int(blocks[0].stamp_ns[0])
    gyro = [(t, v) for entity, t, v in stream.sent if entity == "signals/gyro"]
    assert len(gyro) == 3
    for (times, values), block in zip(gyro, blocks, strict=True):
        np.testing.assert_array_equal(times, block.stamp_ns - t0)
        frame = block_frame(block, CONFIG)
        expected = frame.select(["gyro_x", "gyro_y", "gyro_z"]).to_numpy() - np.array(
            [first[c].mean() for c in ("gyro_x", "gyro_y", "gyro_z")]
        )
        np.testing.assert_allclose(values, expected, rtol=1e-6, atol=1e-9)
    (temperature,) = [v for entity, _, v in stream.sent[:4] if entity == "signals/temperature"]
    np.testing.assert_array_equal(temperature.ravel(), first["temp_c"].to_numpy())  # not centred
    for sensor, other in (("gyro", "accel"), ("accel", "gyro")):
        views = {p.split("/")[2] for p in stream.logged if p.startswith(f"allan/{sensor}/")}
        assert {f"{sensor}_{a}" for a in "xyz"} <= views
        assert not any(v.startswith(other) for v in views)
    text = stream.logged["summary"].text.as_arrow_array().to_pylist()[0]
    assert text.startswith("Recording: 600 frames (0.00167 h at the nominal 100 Hz) so far.")


def test_the_allan_views_start_at_min_frames(monkeypatch) -> None:
    from imupipe.analysis.analyze import MIN_FRAMES
    from imupipe.report import rerun_live

    monkeypatch.setattr(rerun_live, "send_blueprint", lambda rec, bp: None)
    for n, drawn in ((MIN_FRAMES - 1, False), (MIN_FRAMES, True)):
        stream = _Stream()
        live = LiveView(VirtualADIS16364(CONFIG, None, seed=6), stream, adev_period_s=1e9)
        live.frames(n)
        live.finish()
        assert ("summary" in stream.logged) is drawn


def test_block_frame_reads_the_three_temperature_words_not_the_aux_adc(tmp_path: Path) -> None:
    from imupipe.recording.recorder import FrameWriter

    block = VirtualADIS16364(CONFIG, None, seed=7).frames(200)
    block.burst[:, 10] = 0x0ABC  # AUX_ADC, the word after the three temperatures
    with open(tmp_path / "aux.mcap", "wb") as f:
        writer = FrameWriter(f, CONFIG)
        writer.write(block)
        writer.finish()
    decoded = decode(tmp_path / "aux.mcap").frames["temp_c"].to_numpy()
    np.testing.assert_array_equal(block_frame(block, CONFIG)["temp_c"].to_numpy(), decoded)
