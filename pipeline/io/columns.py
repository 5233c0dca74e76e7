"""Column sources: where the analysis reads a recording's decoded columns from.

One interface, :class:`ColumnSource`, two implementations, chosen by :func:`open_columns` on
the estimated peak memory of a whole-frame analysis (:func:`peak_estimate`):

* :class:`InMemoryColumns` — the recording decoded once into one polars frame
  (:func:`imupipe.io.decode.decode`); every column handed out is a zero-copy view of it.
* :class:`SpilledColumns` — the recording read once (:func:`imupipe.io.decode.scan`) with
  every column appended to a file in a temporary directory (the system's, or ``tmp_dir``),
  which is removed when the ``with`` block ends, also on an exception or Ctrl-C.  The
  columns are memory-mapped and built one at a time (one axis of 24 h at 1 kHz: 691 MB),
  so the process never holds more than the conditioning columns or one axis.

Both hand out the same float64 samples, so the analysis gives the same numbers; only the raw
signals for ``recording.rrd`` differ: the spilled source gives a min/max envelope of
:data:`ENVELOPE_BINS` bins (stated by :meth:`ColumnSource.notes`).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import shutil
import tempfile
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from mcap.reader import make_reader

from imupipe.errors import InputError
from imupipe.io import db3_scan
from imupipe.io.db3_scan import is_db3
from imupipe.io.decode import ImuRecording, ScannedRecording, decode, scan
from imupipe.io.mcap_scan import chunk_limit
from imupipe.io.rosbag2 import storage_files
from imupipe.progress import StageProgress
from imupipe.vocab import AXES

CONDITION_COLUMNS = frozenset({"t_s", "counter", "flag_nd", "flag_ea", "saturated", "nonfinite"})
"""What conditioning reads (``nonfinite`` stands for the axes' NaN/inf test)."""
HOUSEKEEPING = ("temp_c", "supply_v")
"""The auxiliary channels (°C, V), nulls filled from their neighbours when handed out."""
SIGNALS = ("t_s", *AXES, *HOUSEKEEPING)
"""The raw signals shown in ``recording.rrd``."""
PEAK_BYTES_PER_FRAME = 210
"""Peak RSS of the in-memory analysis per decoded frame (measured: 12 h / 100 Hz, 4.32 M
frames, 0.87-0.91 GB)."""
FALLBACK_BYTES_PER_FRAME = 40
"""Without a readable MCAP summary, frames are estimated as file bytes / this (a ROS Imu message
is ~350 bytes and our ADIS frame ~60 before compression; zstd shrinks them at most ~8×)."""
SPILLED_PEAK_BYTES_PER_FRAME = 21
"""Peak RSS of the spilled source's analysis per decoded frame, one axis at a time (measured:
24 h / 1 kHz, 86.4 M frames, 1.81 GB with the kernels compiled, docs/performance.md)."""
SPILL_BYTES_PER_FRAME = 65
"""Disk a spilled frame takes at most: ROS Imu, two int64 time bases, six float64 axes and a
1-byte NaN flag (an ADIS16364 frame, in integer counts, takes 41)."""
ENVELOPE_BINS = 100_000
"""Bins of the min/max envelope the spilled source gives for the raw signals (2 points each)."""


def message_count(file: Path) -> int:
    """Messages in ``file`` from its MCAP summary statistics or its rosbag2 database's count,
    else estimated from its size."""
    try:
        if is_db3(file):
            return db3_scan.message_count(file)
        with open(file, "rb") as f:
            stats = make_reader(f).get_summary().statistics
        return int(stats.message_count)
    except Exception:  # damaged, summary-less or compressed file: estimate from its size
        return file.stat().st_size // FALLBACK_BYTES_PER_FRAME


def peak_estimate(files: list[Path]) -> int:
    """Estimated peak bytes of the in-memory analysis of a recording made of ``files``."""
    return PEAK_BYTES_PER_FRAME * sum(message_count(f) for f in files)


def fill_housekeeping(col: pl.Series) -> np.ndarray | None:
    """A housekeeping column as numpy, nulls filled from the neighbours; None if all null.

    Without nulls it is a zero-copy view of the column (a 12 h / 100 Hz column is 35 MB; the
    fill would copy it)."""
    if col.null_count() == len(col):
        return None
    if col.null_count():
        col = col.fill_null(strategy="forward").fill_null(strategy="backward")
    return col.to_numpy()


def envelope(y: np.ndarray, bins: int = ENVELOPE_BINS) -> np.ndarray:
    """Min/max of ``y`` over consecutive bins of ceil(len/bins) samples, interleaved
    (min_0, max_0, min_1, ...); ``y`` itself when it has no more than ``2 * bins`` samples."""
    if len(y) <= 2 * bins:
        return y
    starts = np.arange(0, len(y), -(-len(y) // bins))
    return np.column_stack([np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts)]).ravel()


def envelope_times(t_s: np.ndarray, bins: int = ENVELOPE_BINS) -> np.ndarray:
    """Stamps for :func:`envelope`: each bin's first stamp (min) and middle stamp (max)."""
    if len(t_s) <= 2 * bins:
        return t_s
    step = -(-len(t_s) // bins)
    starts = np.arange(0, len(t_s), step)
    middles = np.minimum(starts + step // 2, len(t_s) - 1)
    return np.column_stack([t_s[starts], t_s[middles]]).ravel()


M_MMAP_THRESHOLD = -3
"""glibc ``mallopt`` parameter: allocations at least this large are mmapped (malloc.h)."""


def release_freed_memory() -> None:
    """Make freed arrays leave the process (glibc only; elsewhere nothing is done).

    Per-chunk arrays (~0.5 MB) come from the C heap once glibc's dynamic mmap threshold has
    risen, and their free space stays resident (measured on 24 h / 1 kHz: a conditioning
    pass peaked at 3.5 GB with ~1.7 GB of live arrays).  A fixed 128 kB threshold mmaps them
    (returned on free), and ``malloc_trim`` hands back what the heap already holds."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(M_MMAP_THRESHOLD, 128 * 1024)
        libc.malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


class ColumnSource(ABC):
    """A decoded recording handed out column by column (contract of the columns:
    :data:`imupipe.io.decode.DECODED_SCHEMA`).  ``rows`` below are a slice of frames."""

    spilled: bool
    """True for the over-budget source (the caller may then keep its own memory low too)."""

    @abstractmethod
    def conditioning(self) -> ImuRecording:
        """The recording with at least :data:`CONDITION_COLUMNS` (or the axes instead of
        ``nonfinite``), for :func:`imupipe.analysis.condition.condition`."""

    @abstractmethod
    def column(self, name: str, rows: slice) -> np.ndarray | None:
        """Column ``name`` (an axis or :data:`HOUSEKEEPING`) over ``rows``, float64, nulls
        filled from the neighbours; None if the recording has no value in it."""

    @abstractmethod
    def signals(self, rows: slice) -> pl.DataFrame:
        """The raw :data:`SIGNALS` over ``rows`` for the Rerun recording."""

    @abstractmethod
    def peak_bytes(self, frames: int) -> int:
        """Estimated peak memory of analysing a recording of ``frames`` decoded frames from this
        source, one axis at a time."""

    @abstractmethod
    def notes(self, frames: int, rrd: bool, at_once: int = 1) -> list[str]:
        """Warnings for the report about how the data of a segment of ``frames`` was read
        (``at_once``: axes analysed at the same time)."""


class InMemoryColumns(ColumnSource):
    """The whole decoded frame in memory; columns are zero-copy slices of it."""

    spilled = False

    def __init__(self, rec: ImuRecording) -> None:
        self.rec = rec

    def conditioning(self) -> ImuRecording:
        return self.rec

    def column(self, name: str, rows: slice) -> np.ndarray | None:
        return fill_housekeeping(self.rec.frames[name].slice(rows.start, rows.stop - rows.start))

    def signals(self, rows: slice) -> pl.DataFrame:
        return self.rec.frames.slice(rows.start, rows.stop - rows.start)

    def peak_bytes(self, frames: int) -> int:
        return PEAK_BYTES_PER_FRAME * frames

    def notes(self, frames: int, rrd: bool, at_once: int = 1) -> list[str]:
        return []


class SpilledColumns(ColumnSource):
    """The recording's columns in files of a temporary directory, mapped one at a time."""

    spilled = True

    def __init__(self, scanned: ScannedRecording, estimate: int, budget: int) -> None:
        self.scanned = scanned
        self.estimate = estimate
        self.budget = budget

    def _frame(self, columns: frozenset[str]) -> pl.DataFrame:
        release_freed_memory()
        rec = self.scanned.recording(columns)
        assert rec is not None  # a spilled scan keeps both time bases
        return rec.frames

    def conditioning(self) -> ImuRecording:
        rec = self.scanned.recording(CONDITION_COLUMNS)
        assert rec is not None
        return rec

    def column(self, name: str, rows: slice) -> np.ndarray | None:
        """Only the rows' values are kept: a part of the column is copied out of its map (or
        out of the scaled ADIS16364 column), so nothing keeps the whole column alive."""
        frame = self._frame(frozenset({name}))
        x = fill_housekeeping(frame[name].slice(rows.start, rows.stop - rows.start))
        return x if x is None or len(x) == frame.height else x.copy()

    def signals(self, rows: slice) -> pl.DataFrame:
        """Each signal built alone (``t_s`` again: the caller need not keep the conditioning
        columns alive meanwhile) and reduced to its envelope before the next one."""
        shown = {"t_s": envelope_times(self._frame(frozenset({"t_s"}))["t_s"].to_numpy()[rows])}
        for name in SIGNALS[1:]:
            x = self.column(name, rows)
            if x is not None:
                shown[name] = envelope(x)
        return pl.DataFrame(shown)

    def peak_bytes(self, frames: int) -> int:
        return SPILLED_PEAK_BYTES_PER_FRAME * frames

    def notes(self, frames: int, rrd: bool, at_once: int = 1) -> list[str]:
        axes = "one axis" if at_once == 1 else f"{at_once} axes"
        out = [
            f"low-memory path: the whole frame would need ~{self.estimate / 1e9:.2f} GB (budget "
            f"{self.budget / 1e9:.2f} GB); decoded once into a temporary on-disk store "
            f"({self.disk_bytes() / 1e9:.2f} GB) and analysed {axes} at a time"
        ]
        if rrd and frames > 2 * ENVELOPE_BINS:
            out.append(
                f"recording.rrd shows the raw signals as a min/max envelope of {ENVELOPE_BINS} "
                f"bins ({-(-frames // ENVELOPE_BINS)} samples each) (low-memory path)"
            )
        return out

    def disk_bytes(self) -> int:
        """Bytes of the spilled columns on disk."""
        folder = self.scanned.channel.spill
        assert folder is not None
        return sum(f.stat().st_size for f in folder.parent.rglob("*.bin"))


@contextlib.contextmanager
def open_columns(
    path: Path,
    topic: str | None,
    progress: StageProgress,
    budget_bytes: int,
    tmp_dir: Path | None = None,
    temperature_topic: str | None = None,
) -> Iterator[ColumnSource]:
    """The column source for ``path``: in memory if the whole-frame analysis is estimated to
    fit in ``budget_bytes``, else spilled to a temporary directory in ``tmp_dir`` (default:
    the system's temporary directory) that is removed when the block ends, however it ends.
    Chunks declaring more than :func:`imupipe.io.mcap_scan.chunk_limit` of the budget are
    skipped unread; ``temperature_topic``: as :func:`imupipe.io.decode.decode`.

    Raises:
        InputError: unreadable recording (see :func:`imupipe.io.decode.decode`), or a
            ``tmp_dir`` that is no directory or has too little free space for the spill.
    """
    files = storage_files(Path(path))
    size = sum(f.stat().st_size for f in files)
    estimate = peak_estimate(files)
    limits = {"max_chunk_bytes": chunk_limit(budget_bytes), "temperature_topic": temperature_topic}
    if estimate <= budget_bytes:
        with progress.stage("decode", size, "bytes") as advance:
            yield InMemoryColumns(decode(path, topic=topic, progress=advance, **limits))
        return
    with _spill_directory(tmp_dir, estimate // PEAK_BYTES_PER_FRAME) as folder:
        with progress.stage("decode + spill", size, "bytes") as advance:
            scanned = _spill(path, topic, advance, folder, **limits)
        yield SpilledColumns(scanned, estimate, budget_bytes)


@contextlib.contextmanager
def _spill_directory(tmp_dir: Path | None, frames: int) -> Iterator[Path]:
    """A new temporary directory for the spilled columns of ``frames`` frames; removed after."""
    parent = Path(tmp_dir) if tmp_dir is not None else Path(tempfile.gettempdir())
    if not parent.is_dir():
        raise InputError(f"{parent}: not a directory (--tmp-dir)")
    need, free = frames * SPILL_BYTES_PER_FRAME, shutil.disk_usage(parent).free
    if free < need:
        raise InputError(
            f"{parent}: {free / 1e9:.1f} GB free, the low-memory path needs ~{need / 1e9:.1f} GB "
            "of temporary disk (choose another place with --tmp-dir)"
        )
    with tempfile.TemporaryDirectory(prefix="imupipe-columns-", dir=parent) as folder:
        yield Path(folder)


def _spill(
    path: Path,
    topic: str | None,
    progress: Callable[[int], None],
    folder: Path,
    **limits: Any,
) -> ScannedRecording:
    """Scan ``path`` once, every decode column (and ``nonfinite``) spilled into ``folder``
    (``limits``: ``max_chunk_bytes`` and ``temperature_topic`` of :func:`scan`)."""
    columns = frozenset({*CONDITION_COLUMNS, *AXES, *HOUSEKEEPING, "stamp_ns", "diag_stat"})
    try:
        return scan(path, topic, progress, columns, spill_dir=folder, **limits)
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        raise InputError(f"{folder}: cannot write the temporary columns: {exc.strerror}") from None
