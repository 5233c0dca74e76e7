"""Memory of :func:`imupipe.io.decode.decode` with a column subset (only what a step needs).

A 24 h / 1 kHz recording has 86.4 M frames: one float64 column is 691 MB, and the 2 GB budget
of issue 5 leaves room for about two.  The peak of a decoding pass is measured in a fresh
interpreter (the kernel's high-water mark VmHWM, reset just before the call, minus the RSS
then; not ``ru_maxrss``, which starts at the RSS of the forking pytest worker) on a
ROS Imu bag cut into chunks of 2000 messages, as in rosbag2's 768 KiB chunks: each run's
arrays are then 16 kB, small enough to live on the C heap.  The subsets also decode exactly
what the whole decode gives for those columns.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from imupipe.io import decode as dec
from imupipe.io.decode import decode
from imupipe.testing.ros_cdr import temperature_payloads

T0_NS = 1_700_000_000_000_000_000
CHUNK = 2_000


def write_bag(
    imu_mcap, path: Path, n: int, stamps_set: bool = True, nan_at: int | None = None
) -> Path:
    """An Imu bag of ``n`` messages at 1 kHz in chunks of :data:`CHUNK` messages, and one
    Temperature message per chunk.  The samples repeat from chunk to chunk (they compress well:
    the bag stays small; their values do not matter here)."""
    rng = np.random.default_rng(2)
    gyro = rng.integers(-2, 3, (CHUNK, 3)) * 1e-3
    accel = rng.integers(-2, 3, (CHUNK, 3)) * 1e-2 + [0.0, 0.0, 9.81]
    gyro, accel = (np.tile(a, (-(-n // CHUNK), 1))[:n] for a in (gyro, accel))
    if nan_at is not None:
        gyro[nan_at, 1] = np.nan
    log = T0_NS + np.arange(n, dtype=np.int64) * 1_000_000
    first = log[::CHUNK]  # a Temperature message with each chunk's first
    temp = 20.0 + np.arange(0, n, CHUNK) / n
    temp[0] = np.nan  # first one: NaN → null
    stamps = log if stamps_set else np.zeros_like(log)
    return imu_mcap(
        path,
        {"/imu/data": (stamps, gyro, accel)},
        log_ns=log,
        chunk=CHUNK,
        temperature=("/imu/temperature", first, temperature_payloads(first, temp)),
    )


N_BIG = 3_000_000
"""Messages of the measured bag: a float64 column of 24 MB."""
OVERHEAD = 16e6
"""Bytes allowed beyond the columns: the scanner's chunks in flight (~11 MB measured with
the bag's chunks) and the chunked arithmetic's temporaries (set to 0.5 MB below)."""
MEASURE = """
import sys
from pathlib import Path
import polars as pl
import imupipe.io.decode as dec
from imupipe.io.mcap_scan import McapScanner
from imupipe.io.columns import release_freed_memory

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key))

dec._CHUNK = 1 << 16  # temporaries of 0.5 MB: the fixed costs stay small next to 24 MB columns
pl.repeat(None, 1, dtype=pl.UInt32, eager=True)  # polars' first call commits ~9 MB (once)
next(  # so does loading the compiled walks (numba, LLVM): ~40 MB, once
    McapScanner(Path(sys.argv[1])).cdr_batches(
        lambda c, s: dec.LAYOUTS["imu"] if s.name == dec.IMU_SCHEMA else None
    )
)
release_freed_memory()  # as the spilled column source does before building a column
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # VmHWM := VmRSS (proc(5), Linux >= 4.0)
before = status("VmRSS:")
rec = dec.decode(Path(sys.argv[1]), columns=frozenset(sys.argv[2].split(",")))
print(status("VmHWM:") - before, rec.frames.height)
"""


@pytest.fixture(scope="module")
def big_bag(tmp_path_factory: pytest.TempPathFactory, imu_mcap) -> Path:
    return write_bag(imu_mcap, tmp_path_factory.mktemp("mem") / "big.mcap", N_BIG)


@pytest.mark.parametrize(
    ("columns", "columns_alive"),
    [
        ("gyro_x", 1),  # the axis, collected in one growing mapping: no joining copy
        # the time base is chosen for the temperature too; temp_c goes over the stamps' buffer,
        # supply_v is a null constant
        ("temp_c,supply_v", 2),
        # stamps and log time are both needed to choose the time base; t_s goes over one
        ("t_s,counter,flag_nd,flag_ea,saturated,nonfinite", 2),
    ],
)
@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc/self/statm")
def test_decode_pass_peak(big_bag: Path, columns: str, columns_alive: int) -> None:
    env = {**os.environ, "PYTHONPATH": str(Path(dec.__file__).parents[1])}
    out = subprocess.run(
        [sys.executable, "-c", MEASURE, str(big_bag), columns],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    extra, rows = map(int, out.stdout.split())
    assert rows == N_BIG
    column = 8 * N_BIG
    assert extra <= 1.15 * columns_alive * column + OVERHEAD, (
        f"peak {extra / 1e6:.0f} MB for float64 columns of {column / 1e6:.0f} MB"
    )


SUBSETS = [
    frozenset({"t_s", "counter", "flag_nd", "flag_ea", "saturated", "nonfinite"}),
    frozenset({"temp_c", "supply_v"}),
    frozenset({"t_s", "temp_c"}),
    frozenset({"stamp_ns", "temp_c", "t_s", "diag_stat"}),
    frozenset({"gyro_y"}),
    frozenset({"t_s"}),  # alone: the spilled source's rrd time column
]


@pytest.mark.parametrize("stamps_set", [True, False])
def test_subsets_equal_the_whole_decode(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, stamps_set: bool, imu_mcap
) -> None:
    """Columns grown, t_s and temp_c on the time base: the same values (bit for bit), dtypes
    and nulls as the whole decode, on either time base."""
    monkeypatch.setattr(dec, "_FIRST_MAP_BYTES", 40_000)  # each column grows several times
    monkeypatch.setattr(dec, "_CHUNK", 3_000)  # several steps of the chunked arithmetic
    path = write_bag(imu_mcap, tmp_path / "small.mcap", 21_500, stamps_set, nan_at=7_777)
    whole = decode(path)
    assert whole.time_source == ("header.stamp" if stamps_set else "log_time")
    f = whole.frames
    assert f.height == 21_500
    # before the 2nd Temperature message: NaN → null (on the log time when the stamps are unset)
    assert f["temp_c"].null_count() == CHUNK
    assert f["supply_v"].dtype == pl.Float64 and f["supply_v"].null_count() == f.height
    assert f["flag_nd"].all() and not f["flag_ea"].any() and not f["saturated"].any()
    assert f["diag_stat"].dtype == pl.UInt16 and f["diag_stat"].max() == 0
    assert np.isnan(f["gyro_y"][7_777])
    stamps = f["stamp_ns"].to_numpy() if stamps_set else np.arange(21_500) * 1_000_000
    expected_t = (stamps - stamps[0]) / 1e9
    np.testing.assert_array_equal(f["t_s"].to_numpy(), expected_t)
    for columns in SUBSETS:
        for keep_one in (False, True):  # True: log time counted, not kept (read again if unset)
            part = decode(path, columns=columns, keep_one_time_base=keep_one)
            assert part.time_source == (whole.time_source if "t_s" in columns else "")
            assert sorted(part.frames.columns) == sorted(columns)
            # which axes are NaN/inf, bit i for AXES[i]: gyro_y (bit 1) of frame 7777
            bits = np.zeros(f.height, np.uint8)
            bits[7_777] = 0b10
            expected = f.with_columns(nonfinite=pl.Series(bits))
            assert part.frames.equals(expected.select(part.frames.columns)), (columns, keep_one)
            if "t_s" in columns:  # the time-base warning, once (not twice after a re-read)
                assert part.warnings == whole.warnings


def test_column_grows_and_joins_like_concatenate(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(dec, "_FIRST_MAP_BYTES", 1_000)  # grown by doubling and by a big part
    rng = np.random.default_rng(0)
    for shape, dtype in (((), np.int64), ((3,), np.float64), ((), np.bool_)):
        parts = [rng.normal(size=(k, *shape)).astype(dtype) for k in (7, 300, 0, 1, 126, 2_000)]
        column = dec._Column()
        for p in parts:
            column.add(p)
        joined = column.join()
        assert joined.dtype == dtype and column.map is None
        np.testing.assert_array_equal(joined, np.concatenate(parts))


def test_adis_subsets_equal_the_whole_decode(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, small_recordings
):
    """ADIS16364 frames are decoded run by run into the asked columns only (integer counts,
    scaled at the end): the same values, dtypes and flags as the whole decode."""
    monkeypatch.setattr(dec, "_FIRST_MAP_BYTES", 40_000)
    path = small_recordings.adis_recording(tmp_path / "adis.mcap")
    f = decode(path).frames
    assert f["saturated"].sum() == 1 and f["flag_nd"].all()
    assert f["gyro_y"].max() == pytest.approx(8191 * 0.05 * np.pi / 180)  # the rail, rad/s
    for columns in [*SUBSETS, frozenset({"counter", "supply_v", "flag_ea", "saturated"})]:
        part = decode(path, columns=columns, keep_one_time_base=True).frames
        assert sorted(part.columns) == sorted(columns)
        expected = f.with_columns(nonfinite=pl.repeat(0, f.height, dtype=pl.UInt8, eager=True))
        assert part.equals(expected.select(part.columns)), columns


def test_a_topic_is_decoded_16_chunks_or_32768_messages_at_a_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, imu_mcap
) -> None:
    """The chunks of a topic wait and are decoded together once they hold
    :data:`imupipe.io.decode._DECODE_ROWS` (32 768) messages or are
    :data:`~imupipe.io.decode._DECODE_BATCHES` (16) chunks, the rest at the end of the file:
    neither chunk by chunk (numpy's calls per batch then cost a third of the decode's CPU on a
    busy bag) nor a sparse topic's whole file at once (memory).  20 chunks of 100 messages,
    then 3 of 20 000: 16 × 100, then 4 × 100 + 2 × 20 000 (past 32 768), then the last."""
    sizes: list[int] = []
    decode_imu = dec._decode_imu

    def counted(m, out, columns) -> None:
        sizes.append(len(m))
        decode_imu(m, out, columns)

    monkeypatch.setattr(dec, "_decode_imu", counted)
    chunks = [100] * 20 + [20_000] * 3
    n = sum(chunks)
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 1_000_000
    gyro = np.zeros((n, 3))
    gyro[:, 2] = np.arange(n)
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": (stamps, gyro, np.zeros((n, 3)))}, chunk=chunks)
    rec = decode(path, columns=frozenset({"gyro_z"}))
    assert sizes == [1_600, 400 + 40_000, 20_000]
    np.testing.assert_array_equal(rec.frames["gyro_z"].to_numpy(), np.arange(n))
