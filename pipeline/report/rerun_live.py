"""A live Rerun view while recording (``imupipe record --view`` / ``--serve``).

:class:`LiveView` wraps a frame source.  Each block the recorder takes from the source also goes
to Rerun as SI signals, with the same entities, layout and series names as ``recording.rrd``
(:mod:`imupipe.report.rerun_view`).  The overlapping Allan deviation of everything recorded so
far, with its IEEE 952 fit, replaces the Allan views every :data:`ADEV_PERIOD_S` seconds of wall
time, and once more at the end.  The user can watch the night's curve form.  The Allan
deviation is computed on a thread of its own (its kernel releases the GIL), so the recorder never
waits for it.

The viewer is a separate ``rerun`` process bound to 127.0.0.1 (:func:`start_viewer`): either a
window (``view``) or a gRPC server (``serve``).  A viewer connects to the server with
``rerun --connect rerun+http://127.0.0.1:PORT/proxy``.  The process outlives the recording, so
the user keeps what was streamed.
"""

from __future__ import annotations

import subprocess
import threading
import time
from typing import Literal

import numpy as np
import polars as pl
import rerun as rr

from imupipe.analysis.analyze import MIN_FRAMES, axis_result
from imupipe.device import adis16364 as adis
from imupipe.device.adis16364 import FrameBlock
from imupipe.io.decode import _adis_frame
from imupipe.recording.recorder import FrameSource
from imupipe.report.rerun_streams import open_stream, send_blueprint
from imupipe.report.rerun_view import (
    SENSORS,
    SIGNAL_PLOTS,
    TIMELINE,
    _log_allan,
    blueprint,
    log_series_styles,
)
from imupipe.stats.allan import allan_curves, tau_factors
from imupipe.vocab import AXES, sensor_of

ADEV_PERIOD_S = 60.0
"""Wall-clock seconds between two updates of the Allan views."""
SIGNAL_COLUMNS = frozenset({*AXES, "temp_c", "supply_v"})


def viewer_url(port: int) -> str:
    """The gRPC address that a viewer, or :func:`start_viewer` itself, listens on."""
    return f"rerun+http://127.0.0.1:{port}/proxy"


def start_viewer(mode: Literal["view", "serve"], port: int) -> subprocess.Popen:
    """Start a ``rerun`` window (``view``) or a gRPC server (``serve``) on 127.0.0.1:``port``.

    The process runs in its own session, so it outlives the recorder."""
    from imupipe.report.rerun_view import rerun_executable

    args = [rerun_executable(), "--bind", "127.0.0.1", "--port", str(port), "--expect-data-soon"]
    if mode == "serve":
        args.append("--serve-grpc")
    return subprocess.Popen(
        args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )


def block_frame(block: FrameBlock, config: adis.DeviceConfig) -> pl.DataFrame:
    """One block's frames in SI: gyro_x..z rad/s, accel_x..z m/s², temp_c °C, supply_v V.

    Uses the burst word order of :data:`imupipe.device.adis16364.BURST_WORDS` (supply, 6
    inertial words, the three gyro temperature words, ...) and the scale factors of
    :mod:`imupipe.io.decode`."""
    counts, _, _ = adis.decode_burst(block.burst)
    cols = {name: counts[1 + i] for i, name in enumerate(AXES)}
    cols |= {"temp_c": counts[7:10].sum(axis=0, dtype=np.int32), "supply_v": counts[0]}
    return _adis_frame(cols, config, len(block), SIGNAL_COLUMNS)


class LiveView:
    """A frame source that also streams what it delivers to ``rec`` (see the module docstring).

    Args:
        source: the wrapped source (the virtual ADIS16364 or a real one).
        rec: where to stream: a :class:`rerun.RecordingStream` connected to a viewer, or saving
            to a file.
        adev_period_s: wall-clock seconds between Allan updates.
    """

    def __init__(
        self,
        source: FrameSource,
        rec: rr.RecordingStream,
        adev_period_s: float = ADEV_PERIOD_S,
    ) -> None:
        self._source = source
        self.config = source.config
        self._rec = rec
        self._period = adev_period_s
        self._tau0 = 1.0 / self.config.output_rate_hz
        self._t0_ns: int | None = None
        self._parts: dict[str, list[np.ndarray]] = {name: [] for name in AXES}
        self._offsets: dict[str, float] = {}
        self._last_adev = time.monotonic()
        self._allan: threading.Thread | None = None

    def __getattr__(self, name: str):
        """Everything else (e.g. the simulator's ``truth()``) from the wrapped source."""
        return getattr(self._source, name)

    def _start(self, first: pl.DataFrame) -> None:
        """Series names and the layout, before the first data.  Gyro and accel are drawn minus
        the mean of the first block (the live plots cannot know the whole run's mean)."""
        columns = {p.title: list(p.columns) for p in SIGNAL_PLOTS}
        self._offsets = {
            c: float(first[c].mean()) if p.centred else 0.0 for p in SIGNAL_PLOTS for c in p.columns
        }
        log_series_styles(self._rec, columns, self._offsets, ", first block")
        self._rec.flush()
        send_blueprint(self._rec, blueprint(None, list(columns)))

    def frames(self, n: int) -> FrameBlock:
        """``n`` frames from the wrapped source, streamed before they are returned."""
        block = self._source.frames(n)
        if not len(block):
            return block
        frame = block_frame(block, self.config)
        if self._t0_ns is None:
            self._t0_ns = int(block.stamp_ns[0])
            self._start(frame)
        t_ns = (block.stamp_ns - self._t0_ns).astype("timedelta64[ns]")
        for plot in SIGNAL_PLOTS:
            offset = np.array([self._offsets[c] for c in plot.columns])
            self._rec.send_columns(
                plot.entity,
                indexes=[rr.TimeColumn(TIMELINE, duration=t_ns)],
                columns=rr.Scalars.columns(scalars=frame.select(plot.columns).to_numpy() - offset),
            )
        for name in AXES:
            self._parts[name].append(frame[name].to_numpy())
        due = time.monotonic() - self._last_adev >= self._period
        if due and (self._allan is None or not self._allan.is_alive()):
            self._last_adev = time.monotonic()
            parts = {name: list(p) for name, p in self._parts.items()}
            self._allan = threading.Thread(
                target=self._draw_allan, args=(parts,), name="live-allan", daemon=True
            )
            self._allan.start()  # the recorder goes on: a real sensor must not wait
        return block

    def _draw_allan(self, parts: dict[str, list[np.ndarray]]) -> None:
        """Replace the Allan views with the deviation and IEEE 952 fit of the frames in
        ``parts`` (blocks by axis).  τ0 is the nominal output period (``imupipe analyze``
        checks the recording's own stamps)."""
        ys = [np.concatenate(parts[name]) if parts[name] else None for name in AXES]
        n = 0 if ys[0] is None else len(ys[0])
        if n < MIN_FRAMES:
            return
        curves = allan_curves(ys, self._tau0, tau_factors(n))
        axes = [
            axis_result(name, y, curve, self._tau0, None, None, loop=False)
            for name, y, curve in zip(AXES, ys, curves, strict=True)
        ]
        for sensor in SENSORS:
            _log_allan(self._rec, sensor, [a for a in axes if sensor_of(a.name) == sensor])
        text = (
            f"Recording: {n} frames ({n * self._tau0 / 3600:.3g} h at the nominal "
            f"{1 / self._tau0:.4g} Hz) so far.  The Allan deviation of everything recorded is "
            f"redrawn every {self._period:g} s.  Run `imupipe analyze` on the file for the noise "
            "terms with their intervals and the closed loop."
        )
        self._rec.log("summary", rr.TextDocument(text, media_type="text/markdown"), static=True)
        self._rec.flush()

    def finish(self) -> None:
        """The Allan views of the whole recording; flush and disconnect (the viewer stays)."""
        if self._allan is not None:
            self._allan.join()
        self._draw_allan(self._parts)
        self._rec.flush()
        self._rec.disconnect()


def open_live_view(source: FrameSource, mode: Literal["view", "serve"], port: int) -> LiveView:
    """Start the viewer process (:func:`start_viewer`) and wrap ``source`` to stream to it."""
    start_viewer(mode, port)
    rec = open_stream("imupipe")
    rec.connect_grpc(viewer_url(port))
    return LiveView(source, rec)
