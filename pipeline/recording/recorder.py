"""Record frames from a source (the virtual ADIS16364 or a real one on SPI) into an MCAP file.

A source delivers :class:`~imupipe.device.adis16364.FrameBlock` s; each block becomes one zstd chunk
written by :class:`~imupipe.io.mcap_bulk.BulkWriter` and flushed at once.  When recording in real
time a chunk holds about one second of frames, so a recorder killed with SIGKILL loses at most
that second; SIGINT/SIGTERM stop after the current chunk and finish the file (summary, footer).
A full disk (or a file-size limit) stops the recording with an error; the chunks written so far
stay readable by a linear scan (no summary: there is no room to write one).
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import signal
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Protocol

from imupipe.device.adis16364 import DeviceConfig, FrameBlock
from imupipe.device.frame_schema import (
    DEFAULT_TOPIC,
    MESSAGE_ENCODING,
    METADATA_NAME,
    PROFILE,
    SCHEMA_ENCODING,
    SCHEMA_NAME,
    encode_frames,
    message_definition,
)
from imupipe.errors import ImupipeError
from imupipe.io.mcap_bulk import BulkWriter

FAST_CHUNK_FRAMES = 16384
"""Frames per chunk when simulating faster than real time (~1 MB uncompressed)."""


class FrameSource(Protocol):
    """Anything that produces ADIS16364 frames: ``frames(n)`` blocks until n frames are read."""

    config: DeviceConfig

    def frames(self, n: int) -> FrameBlock: ...


_NO_ROOM = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)
"""Write errors meaning the file cannot grow: disk full, file-size limit, quota."""


@dataclass(frozen=True)
class RecordSummary:
    """What was recorded: ``frames`` of the ``requested``, at ``rate_hz`` (Hz) made by
    ``rate_method`` (the sensor's SMPL_PRD divider or host polling); ``stop_signal`` is the
    signal that ended it early (None if complete)."""

    path: Path
    frames: int
    requested: int
    chunks: int
    duration_s: float
    rate_hz: float
    rate_method: str
    stop_signal: int | None = None


def parse_duration(text: str) -> float:
    """``"12h"``, ``"30m"``, ``"90s"``, ``"1.5h"`` or plain seconds → seconds."""
    units = {"h": 3600.0, "m": 60.0, "s": 1.0}
    text = text.strip().lower()
    try:
        if text and text[-1] in units:
            value = float(text[:-1]) * units[text[-1]]
        else:
            value = float(text)
    except ValueError:
        raise ImupipeError(f"cannot read duration {text!r} (use e.g. 12h, 30m, 90s)") from None
    if not math.isfinite(value) or value <= 0:
        raise ImupipeError(f"duration must be a positive, finite length, got {text!r}")
    return value


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Signals after which the recorder finishes the current chunk, the summary and the footer."""


@contextlib.contextmanager
def _stop_on_signals() -> Iterator[Callable[[], int | None]]:
    """Turn SIGINT/SIGTERM/SIGHUP into a signal number the recording loop polls between chunks
    (SIGHUP: the terminal closed or the SSH session dropped; the file is finished as for the
    others)."""
    stop: dict[str, int | None] = {"signum": None}

    def handler(signum, frame):
        stop["signum"] = signum

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield lambda: stop["signum"]
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


class FrameWriter:
    """An MCAP file of ADIS16364 frames being written: the ROS 2 schema, the channel (with its
    constant frame_id) and the ``adis16364`` device metadata are registered on construction;
    each :meth:`write` adds one chunk, flushed at once.

    Args:
        stream: a binary stream open for writing.
        config: the device configuration stored as metadata (scale factors, rates).
        topic: the channel's topic.
        compression: ``"zstd"``, ``"lz4"`` or ``""``.
    """

    def __init__(
        self,
        stream: BinaryIO,
        config: DeviceConfig,
        topic: str = DEFAULT_TOPIC,
        compression: str = "zstd",
    ) -> None:
        self.config = config
        self._writer = BulkWriter(stream, compression=compression, profile=PROFILE)
        schema_id = self._writer.register_schema(
            SCHEMA_NAME, SCHEMA_ENCODING, message_definition().encode()
        )
        self._channel = self._writer.register_channel(
            topic, MESSAGE_ENCODING, schema_id, {"frame_id": config.frame_id}
        )
        self._writer.add_metadata(METADATA_NAME, config.to_metadata())

    def write(self, block: FrameBlock) -> None:
        """One chunk holding ``block`` (log time = the frames' host stamps)."""
        payloads = encode_frames(block, self.config.frame_id)
        self._writer.write_chunk(self._channel, block.stamp_ns, payloads, block.counter)

    def finish(self) -> None:
        """Summary section and footer: the file is complete."""
        self._writer.finish()


def record(
    path: Path,
    source: FrameSource,
    n_frames: int,
    realtime: bool = False,
    topic: str = DEFAULT_TOPIC,
    progress: Callable[[int], None] | None = None,
) -> RecordSummary:
    """Record ``n_frames`` frames from ``source`` into ``path``.

    Args:
        realtime: pace a simulated source to its output rate (a real source paces itself);
            also selects ~1 s chunks so that a killed recorder loses at most ~1 s.
        progress: called with the number of frames recorded so far after each chunk.
    """
    config = source.config
    rate = config.output_rate_hz
    chunk_frames = max(1, round(rate)) if realtime else FAST_CHUNK_FRAMES
    path = Path(path)
    written = chunks = 0
    stop_signal: int | None = None
    try:
        stream = open(path, "wb")
    except OSError as exc:
        raise ImupipeError(f"cannot write {path}: {exc.strerror}") from None
    try:
        writer = FrameWriter(stream, config, topic)
        start_wall = time.monotonic()
        with _stop_on_signals() as stopped:
            while written < n_frames:
                stop_signal = stopped()
                if stop_signal is not None:
                    break
                block = source.frames(min(chunk_frames, n_frames - written))
                writer.write(block)
                written += len(block)
                chunks += 1
                if progress:
                    progress(written)
                if realtime and config.source == "sim":
                    ahead = written / rate - (time.monotonic() - start_wall)
                    if ahead > 0:
                        time.sleep(ahead)
        writer.finish()
    except OSError as exc:
        if exc.errno in _NO_ROOM:
            raise ImupipeError(
                f"no room to write {path} ({exc.strerror}): stopped after {written} frames; "
                "the chunks written so far remain readable (imupipe info/analyze recover them)"
            ) from None
        raise ImupipeError(f"error writing {path}: {exc.strerror or exc}") from None
    finally:
        with contextlib.suppress(OSError):
            stream.close()
    return RecordSummary(
        path, written, n_frames, chunks, written / rate, rate, config.rate_method, stop_signal
    )


def write_truth(path: Path, truth: dict) -> None:
    """Write the simulator's ground truth (parameters and effects) as JSON.

    Raises:
        ImupipeError: the file cannot be written.
    """
    try:
        Path(path).write_text(json.dumps(truth, indent=2, sort_keys=True) + "\n")
    except OSError as exc:
        raise ImupipeError(f"cannot write the truth file {path}: {exc.strerror or exc}") from None
