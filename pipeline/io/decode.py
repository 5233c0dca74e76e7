"""Stage 1 — decode: MCAP bytes → a polars frame of IMU samples in SI units.

Two kinds of IMU channel are understood:

* ``imupipe_msgs/msg/Adis16364Frame`` (our recorder): raw burst words → physical units with the
  scale factors of the file's ``adis16364`` metadata record (14-/12-bit sign handling and the
  ND/EA flags in :mod:`imupipe.device.adis16364`);
* ``sensor_msgs/msg/Imu`` from any ROS 2 driver, with ``sensor_msgs/msg/Temperature`` on a
  sibling topic used as the temperature channel when present.

Messages are decoded a chunk at a time, however the topics interleave (see
:mod:`imupipe.io.mcap_scan`): each payload's ``frame_id`` length gives, per message, where the
fields after the header start, and each field is gathered from all of the chunk's messages at
once (:func:`imupipe.io.mcap_walk.gather`: the bytes are copied, so the values are exact).

Output contract (:class:`ImuRecording`): ``frames`` has one row per message, sorted as recorded,
with the columns of :data:`DECODED_SCHEMA`: ``stamp_ns`` (i64, header stamp), ``gyro_x/y/z``
(rad/s), ``accel_x/y/z`` (m/s²), ``temp_c`` (°C, null if absent), ``supply_v`` (V, null if
absent), ``counter`` (u32, null for ROS), ``flag_nd``, ``flag_ea``, ``saturated`` (bool),
``diag_stat`` (u16), ``t_s`` (f64, seconds since the first frame on the chosen time base,
:attr:`ImuRecording.time_source`).  The MCAP log time only serves to choose the time base and is
not kept (35 MB for 12 h at 100 Hz).

Reading and building are two steps: :func:`scan` reads the file once into the channel's raw
columns (in memory, or appended to files in a spill directory), and
:meth:`ScannedRecording.recording` builds the frame, or a subset of its columns, from them.
:func:`decode` does both.
"""

from __future__ import annotations

import itertools
import mmap
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np
import polars as pl
from mcap.records import Channel, Schema

from imupipe.device import adis16364 as adis
from imupipe.device.frame_schema import METADATA_NAME, SCHEMA_NAME, TAIL_SIZE, decode_frames
from imupipe.errors import ConfigError, InputError
from imupipe.io.mcap_scan import CONVERT_ROS1, MAX_CHUNK_BYTES
from imupipe.io.mcap_walk import CDR_HEAD, CdrLayout
from imupipe.io.rosbag2 import bag_files, message_compression, opened
from imupipe.pages import small_pages
from imupipe.units import RAD_PER_DEG, STANDARD_GRAVITY
from imupipe.vocab import AXES

IMU_SCHEMA = "sensor_msgs/msg/Imu"
TEMPERATURE_SCHEMA = "sensor_msgs/msg/Temperature"
MESSAGE_ENCODING_READ = "cdr"
"""The one message encoding read (MCAP spec, "Well-known message encodings": ``cdr``, what ROS 2
writes); an IMU type in another (``ros1``, ``json``, ``protobuf``…) is named in the error."""
IMU_KINDS = ("adis16364", "imu")
"""The kinds of channel (of :func:`scan`'s schema names) that are IMU topics."""
OTHER_IMU_SCHEMAS = ("sensor_msgs/Imu",)
"""ROS 1's name of the IMU message (schema encoding ``ros1msg``, message encoding ``ros1``: a
ROS 1 bag converted to MCAP); not read, but named when a file has no IMU topic imupipe reads."""

_IMU_TAIL = 8 * (4 + 9 + 3 + 9 + 3 + 9)  # orientation..linear_acceleration_covariance, bytes
_IMU_GYRO = 8 * (4 + 9)  # offset of angular_velocity within the tail
_IMU_ACCEL = 8 * (4 + 9 + 3 + 9)
LAYOUTS = {
    "adis16364": CdrLayout(4, TAIL_SIZE, ((0, TAIL_SIZE),)),
    # each vector and its covariance's element 0: gyro @0, @24; accel @32, @56 (one copy each)
    "imu": CdrLayout(8, _IMU_TAIL, ((_IMU_GYRO, 32), (_IMU_ACCEL, 32))),
    "temperature": CdrLayout(8, 16, ((0, 8),)),
}
"""By kind of channel, what the scan copies of each message (:mod:`imupipe.io.mcap_walk`):
the header, then for our frames every field after it (``Adis16364Frame.msg``, aligned to 4),
for ``Imu`` angular_velocity and linear_acceleration (3 float64 each, fields aligned to 8), each
with element 0 of its covariance (:data:`NO_ESTIMATE`), for ``Temperature`` the temperature
(float64; the variance follows)."""


DECODED_SCHEMA = pl.Schema(
    {
        "stamp_ns": pl.Int64,
        **dict.fromkeys(AXES, pl.Float64),
        "temp_c": pl.Float64,
        "supply_v": pl.Float64,
        "counter": pl.UInt32,
        "flag_nd": pl.Boolean,
        "flag_ea": pl.Boolean,
        "saturated": pl.Boolean,
        "diag_stat": pl.UInt16,
        "t_s": pl.Float64,
    }
)
"""The contract of :attr:`ImuRecording.frames` (whole decode; a ``columns`` subset has these
columns' types, and ``nonfinite``, when asked for, is UInt8: :func:`nonfinite_bits`)."""


def nonfinite_bits(axes: Iterable[np.ndarray], n: int) -> np.ndarray:
    """Which axes of each of ``n`` frames are NaN/inf: uint8 (n,), bit i set where the i-th of
    ``axes`` (the columns of :data:`AXES`, in order) is, so that an axis a sensor does not
    provide (NaN in every frame) can be told from a bad frame
    (:func:`imupipe.analysis.condition.condition`)."""
    bits = np.zeros(n, np.uint8)
    for i, values in enumerate(axes):
        bits |= (~np.isfinite(values)).view(np.uint8) << np.uint8(i)
    return bits


@dataclass(frozen=True)
class ImuRecording:
    """The decoded IMU channel of one recording (columns: :data:`DECODED_SCHEMA`)."""

    frames: pl.DataFrame
    path: Path
    topic: str
    source: str
    time_source: str
    device: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    topics: list[str] = field(default_factory=list)
    temperature_topic: str | None = None
    frame_ids: tuple[str, ...] = ()
    """The distinct ``header.frame_id`` values among the first :data:`FRAME_ID_SAMPLE`
    messages of an Imu topic (more than one: messages of several sensors on one topic?)."""


NO_ESTIMATE = -1.0
"""Element 0 of an Imu message's covariance that marks its vector as no estimate: "If you have
no estimate for one of the data elements (e.g. your IMU doesn't produce an orientation
estimate), please set element 0 of the associated covariance matrix to -1. If you are
interpreting this message, please check for a value of -1 in the first element of each
covariance matrix, and disregard the associated estimate." (``sensor_msgs/msg/Imu.msg``,
common_interfaces).  Such a message's angular velocity or linear acceleration is read as NaN, a
missing value (:func:`_no_estimate_warnings`)."""
NO_ESTIMATE_FIELDS = {
    "angular_velocity": ("angular_velocity_covariance", AXES[:3]),
    "linear_acceleration": ("linear_acceleration_covariance", AXES[3:]),
}
"""The Imu vectors whose no-estimate mark is read: (its covariance field, the axes it holds)."""


FRAME_ID_SAMPLE = 64
"""Messages of each topic whose ``header.frame_id`` is read: several IMUs publishing on one
topic interleave from the start."""


@dataclass(frozen=True)
class _CdrMessages:
    """Well-formed little-endian CDR messages of one channel from one chunk: per message, its
    :data:`CDR_HEAD` header bytes then the fields of its :class:`CdrLayout`."""

    rows: np.ndarray  # (n, layout.width) uint8
    log_time: np.ndarray  # (n,) int64, ns

    def __len__(self) -> int:
        return len(self.rows)

    def repeats(self, before: np.ndarray | None) -> np.ndarray:
        """Which messages repeat the one before them (``before``: the row of the message
        preceding the first, if any) in every byte read: the same stamp and values, one
        message recorded twice (bool, n).  Only rows whose stamp repeats are compared whole."""
        stamp = self.rows[:, 4:12].view("<i8")[:, 0]
        same = np.flatnonzero(stamp[1:] == stamp[:-1]) + 1
        out = np.zeros(len(self), dtype=bool)
        out[same] = (self.rows[same] == self.rows[same - 1]).all(axis=1)
        out[0] = before is not None and np.array_equal(self.rows[0], before)
        return out

    def __getitem__(self, keep: np.ndarray) -> _CdrMessages:
        return _CdrMessages(self.rows[keep], self.log_time[keep])

    def stamps(self) -> np.ndarray:
        """header.stamp (sec i32 @4, nanosec u32 @8 of the payload) → ns, int64."""
        sec = self.rows[:, 4:8].view("<i4")[:, 0].astype(np.int64)
        return sec * 1_000_000_000 + self.rows[:, 8:12].view("<u4")[:, 0]

    def f64(self, field: int, count: int) -> np.ndarray:
        """``(n, count)`` float64 from byte ``field`` of the layout's fields (as copied)."""
        return self.rows[:, CDR_HEAD + field : CDR_HEAD + field + 8 * count].view("<f8")


_DECODE_ROWS = 1 << 15
_DECODE_BATCHES = 16
"""Messages of a topic decoded at once: up to :data:`_DECODE_ROWS` messages or the batches of
:data:`_DECODE_BATCHES` chunks are joined (~2 MB of Imu rows) so that the numpy calls per
batch do not add up to more than the copying (measured: 1/3 of the decode's main-thread CPU
on a busy bag when each chunk's ~1700 Imu rows were decoded alone).  A batch's rows are a
view of all the rows made from its chunk, which the batches of a sparse topic keep alive: so
few batches at a time, not a sparse topic's whole file."""


_FIRST_MAP_BYTES = 32 << 20
"""Bytes first reserved for a column (virtual: only the pages written cost memory)."""


class _Column:
    """One decoded column, collected batch by batch into one private anonymous mapping
    (mmap(2)) that doubles when full by mremap(2), which moves pages without copying them.

    The column is then one array without ever being joined: no copy, no second column at the
    peak, and its untouched tail costs no memory.  Its pages are 4 KiB ones: numpy asks for
    transparent huge pages for arrays of 4 MB or more (madvise(2) MADV_HUGEPAGE), and where
    the kernel compacts memory on such faults (``/sys/kernel/mm/transparent_hugepage/defrag``:
    madvise) filling them stalled on a loaded machine (measured, busy bag: decode 2.5-2.8 s wall
    with numpy blocks, 0.8-0.9 s with these).  Collecting the batches' arrays and concatenating
    them instead peaks at twice the column, and small arrays freed between live ones stay
    resident on the C heap (measured: 400 MB of 20 kB parts joined → RSS 0.43 → 0.83 GB)."""

    def __init__(self) -> None:
        self.map: mmap.mmap | None = None
        self.dtype = np.dtype(np.float64)
        self.row_shape: tuple[int, ...] = ()
        self.rows = 0

    def _rows(self, start: int, count: int) -> np.ndarray:
        """Rows ``start`` to ``start + count`` of the mapping, as an array (a view: the mapping
        cannot grow while it lives)."""
        per_row = int(np.prod(self.row_shape, dtype=np.int64))
        at = start * per_row * self.dtype.itemsize
        view = np.frombuffer(self.map, self.dtype, count * per_row, at)
        return view.reshape(count, *self.row_shape)

    def add(self, v: np.ndarray) -> None:
        """Append the rows of ``v`` (same dtype and row shape on every call)."""
        if self.map is None:
            self.dtype, self.row_shape = v.dtype, v.shape[1:]
            self.map = mmap.mmap(-1, _FIRST_MAP_BYTES, flags=mmap.MAP_PRIVATE)
        end = (self.rows + len(v)) * (v[:1].nbytes if len(v) else 0)
        if end > len(self.map):
            self.map.resize(max(end, 2 * len(self.map)))
        self._rows(self.rows, len(v))[:] = v
        self.rows += len(v)

    def join(self) -> np.ndarray:
        """All rows as one array (the column leaves: call once)."""
        rows = self._rows(0, self.rows)
        self.map = None  # the array keeps the mapping alive
        return rows


class _SpilledColumn:
    """One decoded column appended run by run to a file: the bytes go to the page cache, not
    to this process' memory, and :meth:`join` maps the file copy-on-write (writes made to the
    map, e.g. ``t_s`` over the stamps' buffer, stay private to it) as often as it is asked."""

    def __init__(self, file: Path) -> None:
        self.file = file
        self.sink: BinaryIO | None = None
        self.dtype = np.dtype(np.float64)
        self.row_shape: tuple[int, ...] = ()
        self.rows = 0

    def add(self, v: np.ndarray) -> None:
        """Append the rows of ``v`` (same dtype and row shape on every call)."""
        if self.sink is None:
            self.sink = open(self.file, "wb")  # closed by seal()
            self.dtype, self.row_shape = v.dtype, v.shape[1:]
        self.sink.write(memoryview(np.ascontiguousarray(v)).cast("B"))
        self.rows += len(v)

    def seal(self) -> None:
        """Close the file: no more rows."""
        if self.sink is not None:
            self.sink.close()

    def join(self) -> np.ndarray:
        """All rows, as a copy-on-write memory map of the file."""
        if not self.rows:
            return np.empty((0, *self.row_shape), self.dtype)
        return np.memmap(self.file, self.dtype, "c", shape=(self.rows, *self.row_shape))


CLOCK_RESET_NS = 1_000_000_000
"""A time stamp this far (ns) before the one before it is a reset of the clock that stamps the
messages (a driver restarted with the sensor's clock from 0), not a late stamp."""
MAX_CLOCK_RESETS = 10
"""Header-stamp clock resets placed by the log time (:func:`_placed_after_resets`); with more,
the stamps are the interleaved clocks of several sensors, or broken."""


class _Steps:
    """The non-increasing steps x[i + 1] <= x[i] of a series seen batch by batch, those going
    back by more than :data:`CLOCK_RESET_NS` (resets), and whether any value is non-zero."""

    def __init__(self) -> None:
        self.last: int | None = None
        self.count = 0
        self.resets = 0
        self.nonzero = False
        self.values = 0

    def add(self, x: np.ndarray) -> None:
        self.values += len(x)
        if len(x):
            steps = np.diff(x, prepend=x[0] if self.last is None else self.last)
            self.count += int(np.count_nonzero(steps <= 0)) - int(self.last is None)
            self.resets += int(np.count_nonzero(steps < -CLOCK_RESET_NS))
            self.last = int(x[-1])
            self.nonzero = self.nonzero or bool(x.any())


_TIMES = ("stamp_ns", "log_time_ns")
_BASE_COLUMNS = {
    "stamp_ns": frozenset({"stamp_ns"}),
    "log_time_ns": frozenset({"log_time_ns"}),
    "placed_stamp_ns": frozenset(_TIMES),
}
"""The raw columns each time base is made of (:meth:`ScannedRecording._time_base`)."""


class _Columns:
    """Accumulates decoded column arrays of one channel, batch by batch, in memory or (``spill``,
    a directory) in files; the two candidate time bases are also followed by :class:`_Steps`,
    and not kept when named in ``skip``."""

    def __init__(self, skip: frozenset[str] = frozenset(), spill: Path | None = None) -> None:
        self.columns: dict[str, _Column | _SpilledColumn] = {}
        self.steps = {name: _Steps() for name in _TIMES}
        self.skip = skip
        self.spill = spill
        self.rows = 0
        self.no_estimate: defaultdict[str, int] = defaultdict(int)
        """Messages whose vector (a key of :data:`NO_ESTIMATE_FIELDS`) is marked no estimate."""
        self.repeated = 0
        """Messages dropped as repeats of the one before (:meth:`_CdrMessages.repeats`)."""
        self.last_row: np.ndarray | None = None

    def without_repeats(self, m: _CdrMessages) -> _CdrMessages:
        """``m`` without the messages that repeat the one before them, counted."""
        if not len(m):
            return m
        repeats = m.repeats(self.last_row)
        self.last_row = m.rows[-1].copy()
        if not repeats.any():
            return m
        self.repeated += int(repeats.sum())
        return m[~repeats]

    def add(self, **cols: np.ndarray) -> None:
        for k, v in cols.items():
            if k in self.steps:
                self.steps[k].add(v)
            if k not in self.skip:
                if k not in self.columns:
                    self.columns[k] = (
                        _Column() if self.spill is None else _SpilledColumn(self.spill / f"{k}.bin")
                    )
                self.columns[k].add(v)
                self.rows = self.columns[k].rows

    def seal(self) -> None:
        for column in self.columns.values():
            if isinstance(column, _SpilledColumn):
                column.seal()

    def concat(self, names: frozenset[str] | None = None) -> dict[str, np.ndarray]:
        """One array per column (``names`` only, if given).  In memory, each column's blocks
        are released as it is joined (once: the columns leave); spilled, each is mapped anew."""
        keys = [k for k in self.columns if names is None or k in names]
        if self.spill is None:
            return {k: self.columns.pop(k).join() for k in keys}
        return {k: self.columns[k].join() for k in keys}


_RAIL = (1 << 13) - 1
"""ADIS16364 14-bit full scale: the inertial outputs saturate at -8192..8191 counts."""


def _decode_adis(m: _CdrMessages, out: _Columns, columns: frozenset[str] | None) -> None:
    """Decode ADIS16364 frames into the columns ``columns`` needs (None: all of them).

    The burst words are decoded batch by batch and kept as integer counts (an axis costs 2 bytes
    a frame until :func:`_adis_frame` scales it): the (n, 11) words of a whole recording are
    never held.  Stamps are kept only for ``t_s`` / ``stamp_ns``."""
    block = decode_frames(m.rows)
    counts, new_data, alarm = adis.decode_burst(block.burst)

    def wanted(*names: str) -> bool:
        return columns is None or not columns.isdisjoint(names)

    if wanted("t_s", "stamp_ns"):
        out.add(stamp_ns=block.stamp_ns)
    if wanted("t_s"):
        out.add(log_time_ns=m.log_time)
    out.add(**{name: counts[1 + i] for i, name in enumerate(AXES) if wanted(name)})
    if wanted("temp_c"):  # the three TEMP words (one per gyro)
        out.add(temp_c=counts[7:10].sum(axis=0, dtype=np.int32))
    if wanted("supply_v"):
        out.add(supply_v=counts[0])
    if wanted("counter"):
        out.add(counter=block.counter)
    if wanted("flag_nd"):
        out.add(flag_nd=new_data)
    if wanted("flag_ea"):
        out.add(flag_ea=alarm)
    if wanted("saturated"):
        inertial = counts[1:7]
        out.add(saturated=((inertial >= _RAIL) | (inertial <= -_RAIL - 1)).any(axis=0))
    if wanted("diag_stat"):
        out.add(diag_stat=block.diag_stat)


def _decode_imu(m: _CdrMessages, out: _Columns, columns: frozenset[str] | None) -> None:
    """Decode the fields of Imu messages that ``columns`` needs (None: all of them).

    A subset keeps the stamps only for ``t_s`` / ``stamp_ns`` / ``temp_c`` (interpolated on the
    time base) and the log time for ``t_s`` / ``temp_c``, each axis only when named, and
    ``nonfinite`` (which axes are NaN/inf, :func:`nonfinite_bits`: 1 byte per frame) instead of
    the axes for conditioning.  A vector
    whose covariance's element 0 is :data:`NO_ESTIMATE` is read as NaN (counted in
    ``out.no_estimate``)."""
    every = columns is None
    vectors = m.f64(0, 8).reshape(len(m), 2, 4)  # per vector: x, y, z, covariance[0]
    for k, vector in enumerate(NO_ESTIMATE_FIELDS):
        marked = vectors[:, k, 3] == NO_ESTIMATE
        if marked.any():
            vectors[marked, k, :3] = np.nan  # the rows are this decode's own copy
            out.no_estimate[vector] += int(marked.sum())
    axes = [vectors[:, i // 3, i % 3] for i in range(len(AXES))]  # views into the rows
    if every or columns & {"t_s", "stamp_ns", "temp_c"}:
        out.add(stamp_ns=m.stamps())
    if every or columns & {"t_s", "temp_c"}:  # (both choose the time base)
        out.add(log_time_ns=m.log_time)
    if not every and "nonfinite" in columns:
        out.add(nonfinite=nonfinite_bits(axes, len(m)))
    for i, name in enumerate(AXES):  # each axis a contiguous column, as the frame holds it
        if every or name in columns:
            out.add(**{name: axes[i]})


def _decode_temperature(m: _CdrMessages, out: _Columns) -> None:
    """Both time bases are kept: the temperature is placed on the IMU's (:func:`_temperature`)."""
    out.add(stamp_ns=m.stamps(), log_time_ns=m.log_time, temp_c=m.f64(0, 1)[:, 0])


def _adis_frame(
    cols: dict[str, np.ndarray], device: adis.DeviceConfig, n: int, columns: frozenset[str] | None
) -> pl.DataFrame:
    """Counts → SI columns with the device's scale factors: the decode contract's columns, or
    only ``columns`` of them (``nonfinite`` is all 0: the words are integers), ``n`` rows.
    Each integer column leaves ``cols`` (the caller's dict) as it is scaled, and stamps not
    asked for as soon as :func:`decode` has made ``t_s``."""
    if columns is not None and "stamp_ns" not in columns:
        cols.pop("stamp_ns", None)
    scale = dict.fromkeys(AXES[:3], device.gyro_scale_dps * RAD_PER_DEG)  # rad/s per LSB
    scale |= dict.fromkeys(AXES[3:], adis.ACCEL_MG_PER_LSB * 1e-3 * STANDARD_GRAVITY)  # m/s²
    makers = {
        "stamp_ns": lambda: cols.pop("stamp_ns"),
        **{name: (lambda name=name: cols.pop(name) * scale[name]) for name in AXES},
        "temp_c": lambda: cols.pop("temp_c") * (adis.TEMP_C_PER_LSB / 3) + adis.TEMP_ZERO_C,
        "supply_v": lambda: cols.pop("supply_v") * adis.SUPPLY_V_PER_LSB,
        **{k: (lambda k=k: cols.pop(k)) for k in ("counter", "flag_nd", "flag_ea", "saturated")},
        "diag_stat": lambda: cols.pop("diag_stat"),
        "nonfinite": lambda: pl.repeat(0, n, dtype=pl.UInt8, eager=True),
    }
    wanted = [k for k in makers if (k != "nonfinite" if columns is None else k in columns)]
    return pl.DataFrame({k: makers[k]() for k in wanted})


_CHUNK = 1 << 20
"""Rows per step of the time-base and temperature arithmetic: temporaries of 8 MB, not of the
whole column (a 24 h / 1 kHz column is 691 MB)."""


def _map_chunks(
    x: np.ndarray, f: Callable[[np.ndarray], np.ndarray], out: np.ndarray
) -> np.ndarray:
    """``out[i] = f(x[i])``, :data:`_CHUNK` rows at a time; returns ``out``.

    ``out`` may be ``x``'s own memory (e.g. ``x.view(np.float64)`` of an int64 ``x``): each
    chunk is read whole by ``f`` before it is overwritten, so the result costs no new column."""
    for i in range(0, len(x), _CHUNK):
        out[i : i + _CHUNK] = f(x[i : i + _CHUNK])
    return out


def _imu_frame(
    cols: dict[str, np.ndarray],
    temp_c: np.ndarray | None,
    n: int,
    columns: frozenset[str] | None = None,
) -> pl.DataFrame:
    """The decode contract's columns for an Imu channel, or only ``columns`` of them (plus
    ``nonfinite`` when asked for; ``t_s`` is added by :func:`decode`), ``n`` rows; ``temp_c``:
    the temperature at each frame (:func:`_temperature`), None when there is none.

    Columns an Imu message does not carry are built as polars constants (an all-null Float64
    ``supply_v`` is a validity bitmap of n/8 bytes, not an n × 8-byte NaN array).  Stamps not
    asked for leave ``cols`` (the caller's dict) before the frame is built."""
    if columns is not None and "stamp_ns" not in columns:
        cols.pop("stamp_ns", None)  # only needed for t_s and temp_c, already made

    data = {name: cols[name] for name in AXES if columns is None or name in columns}
    makers = {
        "stamp_ns": lambda: cols["stamp_ns"],
        **{name: (lambda v=v: v) for name, v in data.items()},
        "temp_c": lambda: (
            pl.repeat(None, n, dtype=pl.Float64, eager=True)
            if temp_c is None
            else pl.Series(temp_c, nan_to_null=True)
        ),
        "supply_v": lambda: pl.repeat(None, n, dtype=pl.Float64, eager=True),
        "counter": lambda: pl.repeat(None, n, dtype=pl.UInt32, eager=True),
        "flag_nd": lambda: pl.repeat(True, n, dtype=pl.Boolean, eager=True),
        "flag_ea": lambda: pl.repeat(False, n, dtype=pl.Boolean, eager=True),
        "saturated": lambda: pl.repeat(False, n, dtype=pl.Boolean, eager=True),
        "diag_stat": lambda: pl.repeat(0, n, dtype=pl.UInt16, eager=True),
        "nonfinite": lambda: cols["nonfinite"],
    }
    wanted = [k for k in makers if (k != "nonfinite" if columns is None else k in columns)]
    return pl.DataFrame({k: makers[k]() for k in wanted})


def _no_estimate_warnings(counts: dict[str, int], rows: int) -> list[str]:
    """One warning per Imu vector marked no estimate (:data:`NO_ESTIMATE`) in ``counts`` of
    ``rows`` messages."""
    out = []
    for vector, marked in counts.items():
        covariance, axes = NO_ESTIMATE_FIELDS[vector]
        where = "every message" if marked == rows else f"{marked} of {rows} messages"
        out.append(
            f"{covariance}[0] is -1 in {where}: the driver marks its {vector} as no estimate "
            f"(sensor_msgs/msg/Imu: 'disregard the associated estimate'); {', '.join(axes)} "
            "read as missing there"
        )
    return out


def _namespace(topic: str) -> str:
    return topic.rpartition("/")[0]


def _frame_id_or_none(payload: np.ndarray) -> str | None:
    """``header.frame_id`` of a CDR payload (u32 length with its NUL at byte 12, then the
    bytes); None when the length does not fit the payload."""
    size = int(payload[12:16].view("<u4")[0]) if len(payload) >= 16 else 0
    if not 1 <= size <= len(payload) - 16:
        return None
    return payload[16 : 16 + size - 1].tobytes().decode("utf-8", "replace")


def _frame_id(payload: np.ndarray) -> str:
    """:func:`_frame_id_or_none`, empty when the length does not fit the payload."""
    return _frame_id_or_none(payload) or ""


def _frame_ids(payloads: list[np.ndarray]) -> tuple[str, ...]:
    """The distinct ``header.frame_id`` values of the CDR ``payloads`` whose frame_id length
    fits them (:func:`_frame_id_or_none`), sorted."""
    return tuple(sorted({f for p in payloads if (f := _frame_id_or_none(p)) is not None}))


def _sibling_temperature(
    imu_topic: str, temp_topics: list[str], frame_ids: dict[str, str]
) -> str | None:
    """The Temperature topic of the IMU, the first by name of those in the IMU topic's
    namespace or below it (``/imu/data`` → ``/imu/temperature``) or sharing its non-empty
    ``frame_id``; None when there is none: a temperature elsewhere (``/battery/temperature``,
    frame ``battery``) belongs to another device."""
    ns, frame = _namespace(imu_topic), frame_ids.get(imu_topic, "")
    own = sorted(
        t
        for t in temp_topics
        if _namespace(t) == ns
        or (ns and t.startswith(ns + "/"))
        or (frame and frame_ids.get(t) == frame)
    )
    return own[0] if own else None


def _uses_log_time(steps: dict[str, _Steps], warnings: list[str]) -> bool:
    """Whether the time base is the MCAP log time: when the header stamps are unset or less
    monotonic than the log time (else header.stamp)."""
    stamp_bad, log_bad = steps["stamp_ns"].count, steps["log_time_ns"].count
    if not steps["stamp_ns"].nonzero or stamp_bad > max(10 * log_bad, 10):
        warnings.append(
            "header.stamp is unset or not monotonic "
            f"({stamp_bad} non-increasing steps); using MCAP log time as the time base"
        )
        return True
    return False


def _to_mend(steps: dict[str, _Steps]) -> bool:
    """Whether header stamps are mended (:func:`_placed_after_resets`): they step back by more
    than :data:`CLOCK_RESET_NS` somewhere."""
    return steps["stamp_ns"].resets > 0


def _places(steps: dict[str, _Steps]) -> bool:
    """Whether the log time places the runs of reset stamps: it never steps back by more than
    :data:`CLOCK_RESET_NS` (a log time copied from the stamps would step back with them) and
    advances (:func:`_advances`)."""
    return steps["log_time_ns"].resets == 0 and _advances(steps["log_time_ns"])


def _median_ns(x: np.ndarray) -> int:
    """The (upper) median of int64 nanoseconds, exact: not through float64, whose spacing is
    256 ns at the ~1.7e18 ns since 1970 of a log time."""
    return int(np.partition(x, len(x) // 2)[len(x) // 2])


STRAY_WINDOW = 9
"""Messages (odd) whose median ``log - stamp`` a stamp is compared with
(:func:`_stray_stamps`): runs of up to half of it are strays, longer ones resets."""


def _stray_stamps(stamps: np.ndarray, log: np.ndarray) -> np.ndarray:
    """Indices of the messages whose stamp is more than :data:`CLOCK_RESET_NS` off what the log
    time and their neighbours' stamps say: ``log - stamp`` (latency plus the clock's offset)
    differs by more than that from its median over the :data:`STRAY_WINDOW` messages centred
    on it (the first or last ones at the record's ends).  A stamp left at 0, or a second's or
    an hour's error, in one message or a few among good ones; a reset of the clock shifts
    every message after it, and none is a stray.  Only messages near a step of more than
    :data:`CLOCK_RESET_NS` (which every stray makes) are looked at."""
    half = STRAY_WINDOW // 2
    steps = np.flatnonzero(np.abs(np.diff(stamps)) > CLOCK_RESET_NS)
    near = np.unique(steps[:, None] + np.arange(-half, half + 2))
    near = near[(near >= 0) & (near < len(stamps))]
    start = np.clip(near - half, 0, max(len(stamps) - STRAY_WINDOW, 0))  # inside at the ends
    window = np.minimum(start[:, None] + np.arange(STRAY_WINDOW), len(stamps) - 1)
    offset = log[window] - stamps[window]
    mid = np.partition(offset, half, axis=1)[:, half]
    return near[np.abs(log[near] - stamps[near] - mid) > CLOCK_RESET_NS]


def _mended_strays(stamps: np.ndarray, log: np.ndarray, warnings: list[str]) -> np.ndarray:
    """A copy of ``stamps`` with each stray (:func:`_stray_stamps`) replaced by the stamps of
    its nearest good neighbours, interpolated by message index (ns, int64 arithmetic), or
    by the log time less its neighbours' median latency at the record's ends."""
    half = STRAY_WINDOW // 2
    out = stamps.copy()
    stray = _stray_stamps(stamps, log)
    if not len(stray):
        return out
    n = len(out)
    runs = np.split(stray, np.flatnonzero(np.diff(stray) > 1) + 1)  # consecutive strays
    for run in runs:
        lo, hi = int(run[0]) - 1, int(run[-1]) + 1  # good: the runs are maximal
        span = int(stamps[hi]) - int(stamps[lo]) if lo >= 0 and hi < n else 0
        if 0 < span <= (hi - lo) * CLOCK_RESET_NS:  # (not across a reset)
            out[run] = stamps[lo] + span * (run - lo) // (hi - lo)
        else:
            near = np.setdiff1d(np.arange(max(lo - half, 0), min(hi + half, n - 1) + 1), run)
            out[run] = log[run] - _median_ns(log[near] - stamps[near])
    off = (stamps[stray[0]] - out[stray[0]]) / 1e9
    warnings.append(
        f"{len(stray)} message(s) have a header.stamp more than {CLOCK_RESET_NS / 1e9:g} s off "
        f"their neighbours' (message {stray[0]} by {off:.6g} s{'' if len(stray) == 1 else ', …'}"
        "): each is replaced by its neighbours' stamps, interpolated"
    )
    return out


def _advances(steps: _Steps) -> bool:
    """Whether a log time tells when messages arrived: at most 90 % of its steps are not
    forward (a writer that set every log time to 0, or to one value per second, does not;
    receive times a few messages share, as in bursts, do)."""
    return steps.count <= 0.9 * max(steps.values - 1, 1)


def _placed_after_resets(
    cols: dict[str, np.ndarray], steps: dict[str, _Steps], warnings: list[str]
) -> np.ndarray:
    """A channel's header stamps (``cols``' ``stamp_ns``, ns) mended, a new array: strays
    replaced by the MCAP log time (``log_time_ns``; :func:`_mended_strays`), then, after 1 to
    :data:`MAX_CLOCK_RESETS` clock resets (a step back by more than :data:`CLOCK_RESET_NS`),
    each run moved onto the first run's clock: by the difference of the runs' median
    ``log - stamps`` (the receive latency, the same on both sides, cancels), the time between
    the runs then the log time's, a gap like any other; or, where the channel's ``steps`` say
    the log time cannot place them (it resets with the stamps, or does not advance:
    :func:`_places`), one sample after the run before (the runs' median step
    later: one frame lost, so that no Allan term spans the join).  Either instead of a jump
    back by the clock's age that would shorten the record and raise its rate.  More resets
    are the interleaved clocks of several sensors, or broken stamps: left as they are
    (conditioning names the steps back)."""
    log = cols["log_time_ns"]
    out = _mended_strays(cols["stamp_ns"], log, warnings)
    resets = np.flatnonzero(np.diff(out) < -CLOCK_RESET_NS) + 1
    if not 0 < len(resets) <= MAX_CLOCK_RESETS:
        return out
    edges = [0, *resets.tolist(), len(out)]
    runs = list(itertools.pairwise(edges))
    back = (out[resets - 1] - out[resets]) / 1e9
    if _places(steps):
        offsets = [_median_ns(log[a:b] - out[a:b]) for a, b in runs]
        for (a, b), offset in zip(runs, offsets, strict=True):
            out[a:b] += offset - offsets[0]
        how = "the messages after each jump are placed by the MCAP log time"
    else:
        forward = np.diff(out)
        forward = forward[(forward > 0) & (forward <= CLOCK_RESET_NS)]
        period = _median_ns(forward) if len(forward) else 0  # (none: a duplicate stamp, flagged)
        for a, b in runs[1:]:
            out[a:b] += out[a - 1] + 2 * period - out[a]
        how = (
            "the log time cannot place the runs (it resets with the stamps, or does not "
            "advance): each is joined one sample after the run before, the time between them "
            "unknown"
        )
    warnings.append(
        f"header.stamp jumps back {len(resets)} time(s) (by {back[0]:.6g} s at message "
        f"{resets[0]}{'' if len(resets) == 1 else ', …'}: the clock that stamps them was reset, "
        f"e.g. a driver restarted with the sensor's clock): {how}"
    )
    return out


def _temperature_times(
    temperature: _Columns,
    base: str,
    x: np.ndarray,
    log: np.ndarray | None,
    warnings: list[str],
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Where to read the Temperature topic at each IMU frame: (the frames' times, its messages'
    times on the same clock, their °C), ns int64.  The frames' times are ``x`` (the IMU's time
    base ``base``: see :meth:`ScannedRecording.recording`) and the messages' the same base
    (their log time; or their stamps, placed after their own clock resets as the IMU's are).
    When none of its messages falls within the frames' span (stamped by another clock: the
    host's, the IMU by the sensor's), both are their log times (``log``, the IMU's, if kept),
    with a warning; None, with a warning, if that does not help either, or without messages.
    A message whose temperature is NaN or infinite (a driver's "not available") leaves it
    unknown (NaN: null in the frame) between its neighbours, with a warning; all of them, the
    temperature is not used.  Before session 41 an infinite one stopped the analysis with an
    internal error in the loop's regression, and NaN ones were not warned about."""
    temp = temperature.concat()
    if base == "log_time_ns":
        at = temp["log_time_ns"]
    elif base == "placed_stamp_ns" and _to_mend(temperature.steps):
        at = _placed_after_resets(temp, temperature.steps, [])
    else:
        at = temp["stamp_ns"]
    celsius = temp["temp_c"]
    finite = np.isfinite(celsius)
    if not finite.all():
        bad = len(celsius) - int(np.count_nonzero(finite))
        warnings.append(
            f"{bad} of the temperature topic's {len(celsius)} message(s) are NaN or infinite: "
            + ("the temperature is unknown (null) between their neighbours" if finite.any()
               else "the temperature is not used")
        )  # fmt: skip
        if not finite.any():
            return None
        celsius = np.where(finite, celsius, np.nan)  # inf: unknown, as NaN
    if not len(at):
        return None
    if not _overlaps(at, x):
        clock = "log time" if base == "log_time_ns" else "header.stamp"
        if log is None or base == "log_time_ns" or not _overlaps(temp["log_time_ns"], log):
            warnings.append(
                f"the temperature topic's {len(at)} message(s) are stamped outside the IMU's "
                f"time span ({clock}: another clock?): the temperature is not used"
            )
            return None
        warnings.append(
            f"the temperature topic's {len(at)} message(s) are stamped outside the IMU's time "
            f"span ({clock}: another clock?): it is placed by the MCAP log time"
        )
        x, at = log, temp["log_time_ns"]
    return x, at, celsius


def _temperature(times: tuple[np.ndarray, np.ndarray, np.ndarray], out: np.ndarray) -> np.ndarray:
    """The temperature (°C) at each IMU frame from its :func:`_temperature_times`, written into
    ``out`` (f64, may be the frames' times' own memory) and returned: linear interpolation,
    held before the first message and after the last."""
    x, at, celsius = times
    order = np.argsort(at, kind="stable")
    origin = x[0]  # times as f64 after it: ns exact, not to 256 ns as ~1.7e18 ns since 1970
    xp, fp = (at[order] - origin).astype(np.float64), celsius[order]
    return _map_chunks(x, lambda s: np.interp((s - origin).astype(np.float64), xp, fp), out)


def _overlaps(at: np.ndarray, x: np.ndarray) -> bool:
    """Whether any of the times ``at`` lies within the span of the times ``x``."""
    return bool(((at >= x.min()) & (at <= x.max())).any())


def _seconds(cols: dict[str, np.ndarray], use_log: bool, keep_stamps: bool) -> np.ndarray:
    """Seconds since the first frame (f64) on the chosen base, written over a buffer that is not
    needed afterwards: the log time, else the stamps themselves when ``keep_stamps`` is false;
    whichever is overwritten leaves ``cols``.  The time base costs no extra full-length array
    (24 h at 1 kHz: 691 MB each)."""
    log = cols.pop("log_time_ns", None)
    base = log if use_log else cols.pop("placed_stamp_ns", cols["stamp_ns"])
    if log is not None:
        out = log.view(np.float64)
    elif not keep_stamps:
        out = cols.pop("stamp_ns").view(np.float64)
    else:
        out = np.empty(len(base))
    first = base[0]
    return _map_chunks(base, lambda b: (b - first) / 1e9, out)


def _same_device(
    path: Path, seen: dict[str, dict[str, str]], new: dict[str, dict[str, str]], file: Path
) -> None:
    """Refuse split files whose ``adis16364`` metadata differ: each file's counts would need
    its own scale factors (e.g. two gyro ranges), and one factor for all would be wrong.

    Raises:
        InputError: naming the keys that differ.
    """
    before, after = seen.get(METADATA_NAME), new.get(METADATA_NAME)
    if before is None or after is None or before == after:
        return
    keys = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
    raise InputError(
        f"{path}: {file.name} carries different '{METADATA_NAME}' metadata than the files "
        f"before it ({', '.join(keys)}): one scale for all would be wrong; analyse the files "
        "separately"
    )


@dataclass(frozen=True)
class ScannedRecording:
    """The IMU channel of a recording read once (:func:`scan`): its raw run columns (integer
    counts for ADIS16364 frames), not yet scaled, time-based or framed.

    In memory, :meth:`recording` may be called once (the columns leave as the frame is built);
    spilled (``scan(..., spill_dir=...)``), as often as wanted, each call mapping the files
    anew (the spill directory must outlive the calls and their frames)."""

    path: Path
    topic: str
    kind: str  # "adis16364" or "imu"
    channel: _Columns
    temperature: _Columns | None
    device: adis.DeviceConfig | None
    device_meta: dict[str, str]
    warnings: list[str]
    topics: list[str]
    temperature_topic: str | None = None
    frame_ids: tuple[str, ...] = ()

    @property
    def rows(self) -> int:
        """Frames of the channel."""
        return self.channel.rows

    def _time_base(self, warnings: list[str]) -> str:
        """What the frames are timed on: ``log_time_ns`` when the header stamps are unset or
        broken (:func:`_uses_log_time`, whose warning is added), ``placed_stamp_ns`` after
        clock resets or stray stamps (:func:`_to_mend`), else ``stamp_ns``."""
        if _uses_log_time(self.channel.steps, warnings):
            return "log_time_ns"
        return "placed_stamp_ns" if _to_mend(self.channel.steps) else "stamp_ns"

    def _raw(self, columns: frozenset[str] | None, base: str | None) -> frozenset[str] | None:
        """The raw columns a spilled channel maps to build ``columns`` on the time ``base``
        (None: all kept)."""
        if self.channel.spill is None or columns is None:
            return None
        raw = columns | (_BASE_COLUMNS[base] if base else frozenset())
        if self.temperature is not None and columns & {"t_s", "temp_c"}:  # (the log time
            # places a temperature stamped by another clock)
            raw |= {"log_time_ns"}
        return frozenset(raw)

    def recording(self, columns: frozenset[str] | None = None) -> ImuRecording | None:
        """The frame of the decode contract, or of ``columns`` only (``nonfinite``:
        :func:`nonfinite_bits`, if named); None if ``t_s`` needs the log time that the scan
        only counted (``keep_one_time_base``): the file must then be read again, keeping it.
        Header stamps whose clock was reset (at most :data:`MAX_CLOCK_RESETS` times) are placed
        by the log time after each reset (:func:`_placed_after_resets`)."""
        warnings = list(self.warnings) + _no_estimate_warnings(self.channel.no_estimate, self.rows)
        if self.channel.repeated:
            warnings.append(
                f"{self.channel.repeated} message(s) repeat the one before them byte for byte "
                "(the same stamp and values: recorded twice?): each is read once"
            )
        timed = columns is None or "t_s" in columns
        warm = self.temperature is not None and (columns is None or "temp_c" in columns)
        noted = warnings if timed else []  # the time base's notes go with t_s
        base = self._time_base(noted) if timed or warm else None
        if base in ("log_time_ns", "placed_stamp_ns") and "log_time_ns" in self.channel.skip:
            return None
        n = self.rows
        cols = self.channel.concat(self._raw(columns, base))
        if base == "placed_stamp_ns":
            cols[base] = _placed_after_resets(cols, self.channel.steps, noted)
        temp_c, temperature_topic = None, self.temperature_topic
        if self.temperature is not None and base is not None:  # (warned with t_s, as the
            # spilled source's conditioning reads it without temp_c)
            reuse = warm and not timed and base not in columns  # (columns: not None untimed)
            x = cols.pop(base) if reuse else cols[base]
            log = cols.get("log_time_ns")
            times = _temperature_times(self.temperature, base, x, log, warnings)
            if times is None:  # not used: report.json's temperature_topic is null
                temperature_topic = None
            if warm and times is not None:
                temp_c = _temperature(times, x.view(np.float64) if reuse else np.empty(n))
        t_s, time_source = None, ""
        if timed:
            keep_stamps = columns is None or "stamp_ns" in columns
            t_s = _seconds(cols, base == "log_time_ns", keep_stamps)
            time_source = "log_time" if base == "log_time_ns" else "header.stamp"
        if self.device is not None:
            frames = _adis_frame(cols, self.device, n, columns)
            source = SCHEMA_NAME
        else:
            frames = _imu_frame(cols, temp_c, n, columns)
            source = IMU_SCHEMA
        if t_s is not None:  # (a frame of no other column has no rows to broadcast t_s to)
            t_col = pl.Series("t_s", t_s)
            frames = frames.with_columns(t_col) if frames.width else t_col.to_frame()
        return ImuRecording(
            frames=frames,
            path=self.path,
            topic=self.topic,
            source=source,
            time_source=time_source,
            device=self.device_meta,
            warnings=warnings,
            topics=self.topics,
            temperature_topic=temperature_topic,
            frame_ids=self.frame_ids,
        )


def decode(
    path: Path,
    topic: str | None = None,
    progress: Callable[[int], None] | None = None,
    columns: frozenset[str] | None = None,
    keep_one_time_base: bool = False,
    max_chunk_bytes: int = MAX_CHUNK_BYTES,
    temperature_topic: str | None = None,
) -> ImuRecording:
    """Decode the IMU channel of an MCAP file or rosbag2 directory (contract: module docstring).

    ``columns`` restricts the frame to those contract columns, plus ``nonfinite`` (which axes
    are NaN/inf: :func:`nonfinite_bits`) if named, so that only what a step needs is held; None
    gives the whole contract.  ``keep_one_time_base``: for ``t_s``, keep only the header stamps
    while reading (both bases' monotonicity is counted on the way) and read the file again for
    the log time in the rare case the stamps are unset or broken — one int64 column less at the
    peak.
    ``max_chunk_bytes``: chunks declaring more uncompressed bytes are skipped unread
    (:func:`imupipe.io.mcap_scan.chunk_limit` of the memory budget).
    ``temperature_topic``: the Temperature topic to use for an Imu topic (default: the one in
    its namespace or with its frame_id, :func:`_sibling_temperature`).

    Its arrays are allocated on small pages (:func:`imupipe.pages.small_pages`, as an analysis
    does): 12 h of ADIS16364 frames at 100 Hz decoded in 0.76-3.49 s with numpy's huge-page
    advice (the scaled SI columns are 35 MB each; 0.22-2.60 s of it in the kernel, the first
    call of a process 2.30-3.49 s), in 0.79-1.37 s on small pages (0.30-0.58 s in the kernel);
    six calls in each of two fresh processes per code, alternated.  A busy ROS 2 Imu bag, whose
    columns are never scaled, decodes as fast either way.

    Raises:
        InputError: not a file, not MCAP, no IMU topic, ambiguous or unknown ``topic``.
    """
    with small_pages():
        scanned = scan(
            path,
            topic,
            progress,
            columns,
            keep_one_time_base,
            max_chunk_bytes=max_chunk_bytes,
            temperature_topic=temperature_topic,
        )
        rec = scanned.recording(columns)
    if rec is None:  # the log time was counted, not kept: read again, keeping it
        topic = scanned.topic
        del scanned
        return decode(
            path,
            topic,
            progress,
            columns,
            max_chunk_bytes=max_chunk_bytes,
            temperature_topic=temperature_topic,
        )
    return rec


def scan(
    path: Path,
    topic: str | None = None,
    progress: Callable[[int], None] | None = None,
    columns: frozenset[str] | None = None,
    keep_one_time_base: bool = False,
    spill_dir: Path | None = None,
    max_chunk_bytes: int = MAX_CHUNK_BYTES,
    temperature_topic: str | None = None,
) -> ScannedRecording:
    """Read the recording once into the raw columns that ``columns`` needs (see
    :func:`decode`), in memory, or appended to files in ``spill_dir`` (one sub-directory per
    channel; the caller owns and removes the directory).

    Raises:
        InputError: as :func:`decode`.
    """
    path = Path(path)
    files, file_warnings = bag_files(path)
    kinds = {SCHEMA_NAME: "adis16364", IMU_SCHEMA: "imu", TEMPERATURE_SCHEMA: "temperature"}
    unread_imu: dict[str, str] = {}  # topic -> its IMU type and encoding, which are not read

    def read_kind(channel: Channel, schema: Schema | None) -> str | None:
        """The kind of a channel's messages, None for one not read (noting an IMU one)."""
        if schema is None:
            return None
        kind = kinds.get(schema.name)
        if kind is not None and channel.message_encoding == MESSAGE_ENCODING_READ:
            return kind
        if kind in IMU_KINDS or schema.name in OTHER_IMU_SCHEMAS:
            unread_imu.setdefault(
                channel.topic, f"{schema.name} in {channel.message_encoding!r} encoding"
            )
        return None

    def layout(channel: Channel, schema: Schema | None) -> CdrLayout | None:
        if (read := read_kind(channel, schema)) is None:
            return None
        kind = topic_kind.setdefault(channel.topic, read)
        if kind != read:  # its messages cannot share one set of columns
            raise InputError(
                f"{path}: topic {channel.topic!r} carries two message types "
                f"({kind} and {read}); refusing to mix them"
            )
        return LAYOUTS[kind]

    skip = frozenset({"log_time_ns"} if keep_one_time_base else ())

    def new_channel() -> _Columns:
        if spill_dir is None:
            return _Columns(skip)
        folder = Path(spill_dir) / f"channel{len(channels)}"
        folder.mkdir()
        return _Columns(skip, folder)

    channels: dict[str, _Columns] = defaultdict(new_channel)
    topic_kind: dict[str, str] = {}
    all_topics: set[str] = set()
    metadata: dict[str, dict[str, str]] = {}
    warnings: list[str] = list(file_warnings)
    done = 0
    decoders = {
        "adis16364": lambda m, out: _decode_adis(m, out, columns),
        "imu": lambda m, out: _decode_imu(m, out, columns),
        "temperature": _decode_temperature,
    }
    malformed: dict[str, int] = defaultdict(int)
    waiting: dict[str, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)  # (rows, log
    waiting_rows: dict[str, int] = defaultdict(int)  # time) of batches not decoded yet, by topic

    def decode_waiting(name: str) -> None:
        batches = waiting.pop(name)
        waiting_rows.pop(name)
        rows = np.concatenate([r for r, _ in batches])
        log_time = np.concatenate([t for _, t in batches]).view(np.int64)
        messages = _CdrMessages(rows, log_time)
        if topic_kind[name] in IMU_KINDS:  # the same sample recorded twice is one sample
            messages = channels[name].without_repeats(messages)
        decoders[topic_kind[name]](messages, channels[name])

    frame_ids: dict[str, str] = {}  # the header.frame_id of each topic's first message
    frame_sets: dict[str, tuple[str, ...]] = {}  # those of its first FRAME_ID_SAMPLE messages
    compression = message_compression(path)
    for file in files:
        offset = done
        with opened(
            file,
            compression,
            progress=progress and (lambda n, o=offset: progress(o + n)),
            max_chunk_bytes=max_chunk_bytes,
        ) as scanner:
            report = scanner.report
            for batch in scanner.cdr_batches(layout):
                name = report.channels[batch.channel_id].topic
                if batch.bad:
                    malformed[name] += batch.bad
                if batch.first is not None:
                    if name not in frame_ids:
                        frame_ids[name] = _frame_id(batch.first)
                        frame_sets[name] = _frame_ids(batch.payloads(FRAME_ID_SAMPLE))
                    waiting[name].append((batch.rows, batch.log_time))
                    waiting_rows[name] += len(batch)
                    if waiting_rows[name] >= _DECODE_ROWS or len(waiting[name]) >= _DECODE_BATCHES:
                        decode_waiting(name)
        for name in list(waiting):
            decode_waiting(name)
        done += report.file_bytes
        _same_device(path, metadata, report.metadata, file)
        metadata.update(report.metadata)
        prefix = f"{file.name}: " if len(files) > 1 else ""
        warnings.extend(prefix + d for d in report.damage())
        for c in report.channels.values():
            all_topics.add(c.topic)
            if kind := read_kind(c, report.schemas.get(c.schema_id)):
                topic_kind[c.topic] = kind

    warnings.extend(
        f"{topic}: {count} malformed messages (size does not match the schema) skipped"
        for topic, count in malformed.items()
    )
    imu_topics = sorted(t for t, k in topic_kind.items() if k in IMU_KINDS)
    if not imu_topics:
        listed = ", ".join(sorted(all_topics)) if all_topics else "none"
        unread = "; ".join(f"{t} is {why}" for t, why in sorted(unread_imu.items()))
        if unread:
            raise InputError(
                f"{path}: no IMU topic imupipe can read ({unread}): imupipe reads ROS 2 "
                f"messages ({IMU_SCHEMA}, {MESSAGE_ENCODING_READ!r}); {CONVERT_ROS1}"
            )
        raise InputError(f"{path}: no IMU topic (topics in the file: {listed})")
    if topic is None:
        with_data = [t for t in imu_topics if t in channels]
        if len(with_data) > 1:
            raise InputError(
                f"{path}: several IMU topics, choose one with --topic: " + ", ".join(with_data)
            )
        topic = with_data[0] if with_data else imu_topics[0]
    if topic not in imu_topics:
        raise InputError(
            f"{path}: topic {topic!r} is not an IMU topic (IMU topics: {', '.join(imu_topics)})"
        )
    if topic not in channels:
        why = f" ({warnings[0]}{'; …' if len(warnings) > 1 else ''})" if warnings else ""
        raise InputError(f"{path}: topic {topic} has no readable messages{why}")
    for columns_of_channel in channels.values():
        columns_of_channel.seal()
    device = None
    device_meta: dict[str, str] = {}
    temp_topic = None
    if topic_kind[topic] == "adis16364":
        if METADATA_NAME not in metadata:
            raise InputError(
                f"{path}: ADIS16364 frames without the '{METADATA_NAME}' metadata record "
                "(scale factors unknown)"
            )
        device_meta = metadata[METADATA_NAME]
        try:
            device = adis.DeviceConfig.from_metadata(device_meta)
            device.gyro_scale_dps  # noqa: B018 (validates SENS_AVG)
        except (KeyError, ValueError) as exc:
            raise InputError(
                f"{path}: unreadable '{METADATA_NAME}' metadata record ({exc!r}): scale factors "
                "unknown"
            ) from None
        except ConfigError as exc:  # a register value the part does not accept
            raise InputError(
                f"{path}: invalid '{METADATA_NAME}' metadata record ({exc}): scale factors unknown"
            ) from None
        temperature = None
    else:
        temp_topics = [t for t, k in topic_kind.items() if k == "temperature" and t in channels]
        if temperature_topic is not None and temperature_topic not in temp_topics:
            raise InputError(
                f"{path}: --temperature-topic {temperature_topic!r} is not a Temperature topic "
                f"with messages (Temperature topics: {', '.join(sorted(temp_topics)) or 'none'})"
            )
        temp_topic = temperature_topic or _sibling_temperature(topic, temp_topics, frame_ids)
        temperature = channels[temp_topic] if temp_topic else None
    return ScannedRecording(
        path=path,
        topic=topic,
        kind=topic_kind[topic],
        channel=channels[topic],
        temperature=temperature,
        device=device,
        device_meta=device_meta,
        warnings=warnings,
        topics=imu_topics,
        temperature_topic=temp_topic,
        frame_ids=frame_sets.get(topic, ()) if topic_kind[topic] == "imu" else (),
    )
