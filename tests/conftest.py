"""Fixtures shared across the test tree: the in-process CLI runner and the small recordings
the column-source and low-memory tests analyse."""

from __future__ import annotations

import itertools
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from imupipe.api import analyze
from imupipe.cli import main
from imupipe.device.adis16364 import config_for_rate
from imupipe.io.decode import IMU_SCHEMA, TEMPERATURE_SCHEMA
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.recording.recorder import FrameWriter
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.testing.ros_cdr import imu_payloads, temperature_payloads


@pytest.fixture
def cli(capsys: pytest.CaptureFixture[str]) -> Callable[[list[str]], tuple[int, str, str]]:
    """``cli(args)``: :func:`imupipe.cli.main` run in this process on ``args``; returns
    (exit code, stdout, stderr)."""

    def in_process(args: list[str]) -> tuple[int, str, str]:
        old = sys.argv
        sys.argv = ["imupipe", *args]
        try:
            with pytest.raises(SystemExit) as exit_info:
                main()
        finally:
            sys.argv = old
        captured = capsys.readouterr()
        return exit_info.value.code, captured.out, captured.err

    return in_process


def write_imu_mcap(
    path: Path,
    imu: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    *,
    log_ns: np.ndarray | None = None,
    chunk: int | Sequence[int] | None = None,
    frame_id: str = "imu",
    no_estimate: tuple[bool, bool] = (False, False),
    temperature: tuple[str, np.ndarray, np.ndarray] | None = None,
) -> Path:
    """A ROS 2 MCAP as our :class:`BulkWriter` writes it (zstd chunks, schemas without text):
    ``imu`` {topic: (header stamps ns, gyro (n, 3) rad/s, accel (n, 3) m/s²)} as
    ``sensor_msgs/msg/Imu`` messages (:func:`imu_payloads` with ``frame_id`` and
    ``no_estimate``) logged at ``log_ns`` (default: the stamps), each topic in chunks of
    ``chunk`` messages (a sequence: the sizes of its successive chunks; None: one chunk), a
    topic's channel registered before its chunks.  ``temperature``: (topic, log times ns,
    ``sensor_msgs/msg/Temperature`` payloads), its channel registered after the first topic's,
    and after each chunk of that topic a chunk of those logged before its next chunk starts
    (all, with one chunk).  Returns ``path``."""
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        schema = w.register_schema(IMU_SCHEMA, "ros2msg", b"")
        for k, (topic, (stamps, gyro, accel)) in enumerate(imu.items()):
            cid = w.register_channel(topic, "cdr", schema)
            with_temperature = temperature is not None and k == 0
            if with_temperature:
                temp_topic, temp_log, temp_payloads = temperature
                temp_schema = w.register_schema(TEMPERATURE_SCHEMA, "ros2msg", b"")
                temp = w.register_channel(temp_topic, "cdr", temp_schema)
            log = stamps if log_ns is None else log_ns
            n = len(stamps)
            if chunk is None:
                starts = [0]
            elif isinstance(chunk, int):
                starts = list(range(0, n, chunk))
            else:
                starts = [0, *itertools.accumulate(chunk)][:-1]
            written = 0  # temperature messages
            for a, b in itertools.pairwise([*starts, n]):
                payloads = imu_payloads(
                    stamps[a:b], gyro[a:b], accel[a:b], frame_id=frame_id, no_estimate=no_estimate
                )
                w.write_chunk(cid, log[a:b], payloads)
                if with_temperature:
                    upto = np.searchsorted(temp_log, log[b]) if b < n else len(temp_log)
                    w.write_chunk(temp, temp_log[written:upto], temp_payloads[written:upto])
                    written = upto
        w.finish()
    return path


@pytest.fixture(scope="session")
def imu_mcap() -> Callable[..., Path]:
    """``imu_mcap(path, {topic: (stamps, gyro, accel)}, ...)``: :func:`write_imu_mcap`."""
    return write_imu_mcap


N = 24_000  # 100 Hz, 4 min


def recording(path: Path, rate_hz: float, frames: int, seed: int, edit=None) -> Path:
    """An ADIS16364 recording of the virtual device; ``edit(block)`` alters its words first."""
    config = config_for_rate(rate_hz)
    block = VirtualADIS16364(config, None, seed=seed).frames(frames)
    if edit is not None:
        edit(block)
    with open(path, "wb") as f:
        writer = FrameWriter(f, config)
        writer.write(block)
        writer.finish()
    return path


def adis_recording(path: Path) -> Path:
    def rail(block) -> None:  # ND + gyro_y at +8191 (rail): the frame is cut out
        block.burst[N // 3, 2] = 0x9FFF

    return recording(path, 100.0, N, seed=3, edit=rail)


def imu_bag(path: Path) -> Path:
    rng = np.random.default_rng(5)
    stamps = 1_700_000_000_000_000_000 + np.arange(N, dtype=np.int64) * 10_000_000
    stamps[N // 4 :] += 50_000_000  # a 5-frame gap
    gyro = rng.normal(0, 1e-3, (N, 3)) + np.cumsum(rng.normal(0, 1e-6, (N, 1)), axis=0)
    accel = rng.normal(0, 3e-3, (N, 3)) + np.array([0.0, 0.0, 9.81])
    accel[:, 1] = 0.25  # stuck
    gyro[N // 2, 0] = np.nan
    t_stamps = stamps[::100]
    temp = 25 + 0.01 * np.arange(len(t_stamps))
    temperature = ("/imu/temperature", t_stamps, temperature_payloads(t_stamps, temp))
    return write_imu_mcap(path, {"/imu/data": (stamps, gyro, accel)}, temperature=temperature)


def run(path: Path, out: Path, budget: int, **options) -> tuple[dict, pl.DataFrame]:
    analyze(path, out, rrd=False, figures=False, memory_budget_bytes=budget, **options)
    return json.loads((out / "report.json").read_text()), pl.read_parquet(out / "allan.parquet")


class SmallRecordings:
    """Builders of the small recordings that exercise conditioning and both column sources."""

    frames = N
    recording = staticmethod(recording)
    adis_recording = staticmethod(adis_recording)
    imu_bag = staticmethod(imu_bag)
    run = staticmethod(run)

    def make(self, kind: str, path: Path) -> Path:
        """``kind`` "adis" (our recorder, a railed frame) or "ros" (an Imu bag with a gap, a
        NaN, a stuck axis and a Temperature topic) written to ``path``."""
        return {"adis": adis_recording, "ros": imu_bag}[kind](path)


@pytest.fixture(scope="session")
def small_recordings() -> SmallRecordings:
    return SmallRecordings()


def _schema_errors(doc: object, schema: dict, root: dict, where: str = "$") -> list[str]:
    """Required keys, types, const/enum, items and additionalProperties of a JSON Schema subset
    (enough for report.schema.json and fleet.schema.json; jsonschema is not a dependency)."""
    if "$ref" in schema:
        schema = root["$defs"][schema["$ref"].rsplit("/", 1)[-1]]
    types = {
        "object": dict,
        "array": list,
        "string": str,
        "number": (int, float),
        "integer": int,
        "boolean": bool,
        "null": type(None),
    }
    errors = []
    if "type" in schema:
        allowed = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
        ok = any(  # a bool is an int to Python, not a number to JSON
            isinstance(doc, types[t]) and (t == "boolean" or not isinstance(doc, bool))
            for t in allowed
        )
        if not ok:
            return [f"{where}: {type(doc).__name__} is not {allowed}"]
    if "const" in schema and doc != schema["const"]:
        errors.append(f"{where}: {doc!r} != {schema['const']!r}")
    if "enum" in schema and doc not in schema["enum"]:
        errors.append(f"{where}: {doc!r} not in {schema['enum']}")
    if isinstance(doc, dict):
        errors += [f"{where}: missing {k}" for k in schema.get("required", []) if k not in doc]
        names = schema.get("propertyNames", {}).get("enum")
        errors += [f"{where}: key {k} not allowed" for k in doc if names and k not in names]
        props = schema.get("properties", {})
        extra = schema.get("additionalProperties")
        for key, value in doc.items():
            sub = props.get(key, extra if isinstance(extra, dict) else None)
            if sub is not None:
                errors += _schema_errors(value, sub, root, f"{where}.{key}")
    if isinstance(doc, list) and "items" in schema:
        for i, value in enumerate(doc):
            errors += _schema_errors(value, schema["items"], root, f"{where}[{i}]")
    return errors


@pytest.fixture(scope="session")
def schema_errors() -> Callable[..., list[str]]:
    """``schema_errors(doc, schema, root)``: what a JSON Schema subset finds wrong in ``doc``."""
    return _schema_errors
