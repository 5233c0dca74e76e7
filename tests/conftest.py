"""Fixtures shared across the test tree: the in-process CLI runner and the small recordings
the column-source and low-memory tests analyse."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
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
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        imu = w.register_channel("/imu/data", "cdr", w.register_schema(IMU_SCHEMA, "ros2msg", b""))
        tmp = w.register_channel(
            "/imu/temperature", "cdr", w.register_schema(TEMPERATURE_SCHEMA, "ros2msg", b"")
        )
        w.write_chunk(imu, stamps, imu_payloads(stamps, gyro, accel))
        w.write_chunk(tmp, t_stamps, temperature_payloads(t_stamps, temp))
        w.finish()
    return path


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
