"""Fuzzing the decoder (issue 5): truncations, bit flips, random bytes and random schemas/records.

Whatever the bytes, stage 1 (:func:`imupipe.io.decode.decode`) and ``imupipe info``
(:func:`imupipe.io.info.describe`) either return or raise our clean
:class:`~imupipe.errors.ImupipeError` (one line, exit 2 at the command line): no other exception
may escape.  Each property runs a fixed number of cases (``EXAMPLES``, derandomised so a run is
reproducible); the count actually run is printed (``pytest -s``).
"""

from __future__ import annotations

import io
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.writer import Writer

from imupipe.device.adis16364 import DeviceConfig, FrameBlock
from imupipe.device.frame_schema import (
    DEFAULT_TOPIC,
    MESSAGE_ENCODING,
    METADATA_NAME,
    SCHEMA_ENCODING,
    SCHEMA_NAME,
    encode_frames,
    message_definition,
)
from imupipe.errors import ImupipeError
from imupipe.io.decode import IMU_SCHEMA, TEMPERATURE_SCHEMA, decode
from imupipe.io.info import describe
from imupipe.recording.recorder import FrameWriter

EXAMPLES = 50
FUZZ = settings(
    max_examples=EXAMPLES,
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
T0 = 1_700_000_000_000_000_000
RAN: Counter[str] = Counter()


def frames(n: int, start: int = 0) -> FrameBlock:
    rng = np.random.default_rng(start)
    return FrameBlock(
        stamp_ns=T0 + (start + np.arange(n, dtype=np.int64)) * 10_000_000,
        counter=(start + np.arange(n)).astype(np.uint32),
        burst=rng.integers(0, 1 << 16, size=(n, 11), dtype=np.uint16),
        diag_stat=np.zeros(n, np.uint16),
        diag_valid=np.ones(n, bool),
    )


def recording(compression: str) -> tuple[bytes, int]:
    """Three chunks of our frames; returns the file and the offset where the chunks begin."""
    buf = io.BytesIO()
    writer = FrameWriter(buf, DeviceConfig(frame_id="imu"), compression=compression)
    data_start = buf.tell()
    for k in range(3):
        writer.write(frames(40, 40 * k))
    writer.finish()
    return buf.getvalue(), data_start


FILES = {c: recording(c) for c in ("zstd", "lz4", "")}


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One folder for every case's file (pytest keeps the last three runs' folders only)."""
    return tmp_path_factory.mktemp("fuzz")


def only_clean_errors(work: Path, data: bytes, kind: str, intact: bytes | None = None) -> None:
    """Decode and describe ``data``; anything but success or ImupipeError fails the test.  With
    ``intact`` (the file before the damage, every chunk CRC-checked): a decode whose frames
    differ from the intact file's must also warn — damage is never silently read as data."""
    path = work / "fuzz.mcap"
    path.write_bytes(data)
    for stage in (decode, describe):
        try:
            out = stage(path)
        except ImupipeError as exc:
            assert "\n" not in str(exc)
        else:
            if stage is decode and intact is not None and not out.warnings:
                assert out.frames.equals(intact_frames(intact, work), null_equal=True)
    RAN[kind] += 1


_INTACT: dict[bytes, object] = {}


def intact_frames(data: bytes, work: Path) -> object:
    """The decoded frame of an undamaged file (computed once per file)."""
    if data not in _INTACT:
        path = work / "intact.mcap"
        path.write_bytes(data)
        _INTACT[data] = decode(path).frames
    return _INTACT[data]


def report_count(kind: str) -> None:
    """Runs after the property of the same kind (file order): print how many cases it ran."""
    if RAN[kind] == 0:
        pytest.skip(f"the {kind} property was not selected in this run")
    print(f"fuzz {kind}: {RAN[kind]} cases ran")
    assert RAN[kind] >= EXAMPLES // 2  # hypothesis really generated the cases


compression = st.sampled_from(sorted(FILES))


@FUZZ
@given(compression, st.floats(0, 1, exclude_max=True))
def test_truncated_anywhere(work: Path, comp: str, where: float) -> None:
    data, _ = FILES[comp]
    only_clean_errors(work, data[: int(where * len(data))], "truncation")


def test_truncation_count() -> None:
    report_count("truncation")


@FUZZ
@given(
    compression,
    st.lists(
        st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 7)), min_size=1, max_size=8
    ),
)
def test_bit_flips_in_the_data_section(
    work: Path, comp: str, flips: list[tuple[float, int]]
) -> None:
    data, start = FILES[comp]
    buf = bytearray(data)
    for where, bit in flips:
        buf[start + int(where * (len(buf) - start))] ^= 1 << bit
    only_clean_errors(work, bytes(buf), "bit flip", intact=data)


def test_bit_flip_count() -> None:
    report_count("bit flip")


@FUZZ
@given(compression, st.floats(0, 1, exclude_max=True), st.binary(min_size=1, max_size=64))
def test_random_bytes_overwrite_the_data_section(
    work: Path, comp: str, where: float, junk: bytes
) -> None:
    data, start = FILES[comp]
    at = start + int(where * (len(data) - start))
    only_clean_errors(work, data[:at] + junk + data[at + len(junk) :], "overwrite", intact=data)


def test_overwrite_count() -> None:
    report_count("overwrite")


@FUZZ
@given(st.booleans(), st.binary(max_size=2048))
def test_random_files(work: Path, with_magic: bool, junk: bytes) -> None:
    only_clean_errors(work, (b"\x89MCAP0\r\n" if with_magic else b"") + junk, "random file")


def test_random_file_count() -> None:
    report_count("random file")


ADIS_MIN_PAYLOAD = len(encode_frames(frames(1), "").tobytes())


IMU_MIN_PAYLOAD = 4 + 4 + 4 + 4 + 8 * (4 + 9 + 3 + 9 + 3 + 9)
"""CDR header, stamp, empty frame_id (length + NUL, padded), then 37 float64 (sensor_msgs/Imu)."""
CDR_LE = b"\x00\x01\x00\x00"


def producer_file(schema: str, encoding: str, payloads: list[bytes], chunked: bool) -> bytes:
    """Another producer's file: the mcap library's own Writer, arbitrary message bytes."""
    buf = io.BytesIO()
    w = Writer(buf, use_chunking=chunked)
    w.start(profile="ros2", library="fuzz")
    sid = w.register_schema(schema, "ros2msg", b"")
    cid = w.register_channel("/imu/data", encoding, sid)
    for i, p in enumerate(payloads):
        w.add_message(cid, log_time=T0 + i, data=p, publish_time=T0 + i)
    w.finish()
    return buf.getvalue()


@FUZZ
@given(
    st.sampled_from([IMU_SCHEMA, TEMPERATURE_SCHEMA, "std_msgs/msg/String", ""]),
    st.sampled_from(["cdr", "json", ""]),
    st.lists(
        st.tuples(
            st.sampled_from([CDR_LE, b""]), st.binary(min_size=IMU_MIN_PAYLOAD, max_size=400)
        ),
        max_size=12,
    ),
    st.booleans(),
)
def test_random_schemas_and_records(
    work: Path, schema: str, encoding: str, payloads: list[tuple[bytes, bytes]], chunked: bool
) -> None:
    """Messages of at least a sensor_msgs/Imu's size, random bytes behind a CDR header or not."""
    data = producer_file(schema, encoding, [a + b for a, b in payloads], chunked)
    only_clean_errors(work, data, "random schema")


def test_random_schema_count() -> None:
    report_count("random schema")


@FUZZ
@given(
    st.sampled_from([IMU_SCHEMA, TEMPERATURE_SCHEMA, SCHEMA_NAME]),
    st.lists(st.binary(max_size=ADIS_MIN_PAYLOAD), min_size=1, max_size=8),
    st.dictionaries(st.sampled_from(sorted(DeviceConfig().to_metadata())), st.text(max_size=8)),
)
def test_short_messages_and_bad_metadata(
    work: Path, schema: str, payloads: list[bytes], meta: dict[str, str]
) -> None:
    buf = io.BytesIO()
    w = Writer(buf)
    w.start(profile="ros2", library="fuzz")
    sid = w.register_schema(schema, SCHEMA_ENCODING, message_definition().encode())
    cid = w.register_channel(DEFAULT_TOPIC, MESSAGE_ENCODING, sid)
    w.add_metadata(METADATA_NAME, {**DeviceConfig().to_metadata(), **meta})
    for i, p in enumerate(payloads):
        w.add_message(cid, log_time=T0 + i, data=p, publish_time=T0 + i)
    w.finish()
    only_clean_errors(work, buf.getvalue(), "short message")


def test_short_message_count() -> None:
    report_count("short message")
