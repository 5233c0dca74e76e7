"""The stand-in analysis result shared by the report tests: six axes with the paper's N and B as
truth and a loop result on accel_x, built without running an analysis."""

from __future__ import annotations

import dataclasses
import math
import re
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from scipy.stats import chi2

from imupipe.analysis.results import AnalysisResult, AxisResult, InputSummary
from imupipe.device.frame_schema import SCHEMA_NAME
from imupipe.model import ieee952
from imupipe.model.loop import AcceptedEffect, Goodness, LoopResult, RejectedCandidate
from imupipe.report.rerun_view import rerun_executable
from imupipe.stats import allan
from imupipe.units import SI_UNIT, to_si

RATE_HZ = 100.0
FRAMES = 4_320_000
CONFIDENCE = 0.683
FLICKER_PLATEAU = math.sqrt(2 * math.log(2) / math.pi)
# Paper (section 4) values used as the synthetic truth: N and B per axis, in the paper's units.
TRUTH = {
    "gyro_x": (0.05, "°/√s", 0.008, "°/s"),
    "gyro_y": (0.05, "°/√s", 0.008, "°/s"),
    "gyro_z": (0.05, "°/√s", 0.008, "°/s"),
    "accel_x": (0.29, "mg/√s", 0.107, "mg"),
    "accel_y": (0.27, "mg/√s", 0.161, "mg"),
    "accel_z": (0.28, "mg/√s", 0.135, "mg"),
}
K_GYRO_X = 2e-6  # rad/s²/√Hz, resolved on gyro_x only; the other axes report K as null


def _curve(n: float, b: float, k: float) -> object:
    """An AllanCurve from the IEEE 952 model sqrt(N²/τ + (0.664 B)² + K² τ/3) with chi-square
    intervals for a rough EDF (enough for reporting; the real EDF is the allan module's job)."""
    m = np.unique(np.round(np.logspace(0, math.log10(FRAMES / 10), 60)).astype(np.int64))
    tau = m / RATE_HZ
    adev = np.sqrt(n**2 / tau + (FLICKER_PLATEAU * b) ** 2 + k**2 * tau / 3)
    n_terms = FRAMES - 2 * m
    edf = np.maximum(n_terms / m, 1.0)
    edf[-1] = np.nan  # one unresolved interval: must come out as null
    p = (1 - CONFIDENCE) / 2
    lo = adev * np.sqrt(edf / chi2.ppf(1 - p, edf))
    hi = adev * np.sqrt(edf / chi2.ppf(p, edf))
    return allan.AllanCurve(
        tau_s=tau,
        adev=adev,
        adev_lo=lo,
        adev_hi=hi,
        edf=edf,
        n_terms=n_terms,
        alpha=np.zeros_like(tau),
        confidence=CONFIDENCE,
    )


def _term(value: float | None, unit: str, rel: float = 0.02, reason: str | None = None):
    if value is None:
        return ieee952.NoiseTerm(None, None, None, unit, reason)
    return ieee952.NoiseTerm(value, value * (1 - rel), value * (1 + rel), unit, None)


def _terms(sensor: str, n: float, b: float, k: float | None):
    units = SI_UNIT[sensor]
    return ieee952.NoiseTerms(
        quantization=_term(None, units["quantization"], reason="below tau0"),
        random_walk=_term(n, units["random_walk"]),
        bias_instability=_term(b, units["bias_instability"]),
        rate_random_walk=_term(k, units["rate_random_walk"], reason="recording too short"),
        rate_ramp=_term(None, units["rate_ramp"], reason="recording too short"),
    )


def _synthetic_result(with_loop: bool = True) -> AnalysisResult:
    """Six axes with the paper's N and B as truth; a loop result on accel_x."""
    axes = {}
    for name, (n, n_unit, b, b_unit) in TRUTH.items():
        sensor = "gyro" if name.startswith("gyro") else "accel"
        n_si, b_si = to_si(n, n_unit), to_si(b, b_unit)
        k = K_GYRO_X if name == "gyro_x" else None
        curve = _curve(n_si, b_si, k or 0.0)
        axes[name] = AxisResult(
            name=name,
            sensor=sensor,
            unit=SI_UNIT[sensor]["mean"],
            mean=to_si(0.331, "°/s") if sensor == "gyro" else to_si(0.0273, "g"),
            rms=to_si(0.52, "°/s") if sensor == "gyro" else to_si(3.0, "mg"),
            curve=curve,
            terms=_terms(sensor, n_si, b_si, k),
        )
    if with_loop:
        ax = axes["accel_x"]
        rng = np.random.default_rng(1)
        z_before = rng.normal(0, 1, ax.curve.tau_s.size) + np.linspace(0, 5, ax.curve.tau_s.size)
        effect = AcceptedEffect(
            kind="temperature",
            params={"coefficient": 1.2e-4},
            intervals={"coefficient": [1.1e-4, 1.3e-4]},
            evidence={"coherence": 0.9},
            error_before=4.2,
            error_after=1.03,
        )
        z_after = rng.normal(0, 1, ax.curve.tau_s.size)
        axes["accel_x"] = dataclasses.replace(
            ax,
            loop=LoopResult(
                name="accel_x",
                tau_s=ax.curve.tau_s,
                adev_before=ax.curve.adev,
                adev_after=ax.curve.adev * 0.97,
                terms_before=dataclasses.replace(ax.terms, deviance_per_dof=4.2),
                terms_after=ax.terms,
                model_adev_before=ax.curve.adev * 0.9,
                model_adev_after=ax.curve.adev,
                before=Goodness(4.2, 168.0, 40, 0.0, z_before, 5.9, 4000.0, 3.1, 4, (0.01, 4000.0)),
                after=Goodness(1.03, 39.14, 38, 0.41, z_after, 2.2, 80.0, 0.9, 0, (0.01, 4000.0)),
                accepted=[effect],
                rejected=[RejectedCandidate("sinusoid", {}, {}, {}, "ΔBIC 2.1 < 10")],
            ),
        )
    inp = InputSummary(
        path="run.mcap",
        topic="/imu/adis16364",
        frames=FRAMES,
        rate_hz=RATE_HZ,
        duration_s=FRAMES / RATE_HZ,
        segments=[{"start_s": 0.0, "end_s": FRAMES / RATE_HZ, "frames": FRAMES}],
        warnings=["2 gaps; analysed the longest clean segment"],
        source=SCHEMA_NAME,
    )
    return AnalysisResult(input=inp, axes=axes, device={"prod_id": "16364"})


@dataclass(frozen=True)
class StandInTruth:
    """What the stand-in result was built from (SI)."""

    rate_hz: float = RATE_HZ
    frames: int = FRAMES
    k_gyro_x: float = K_GYRO_X  # rad/s²/√Hz


def _signal_frames(n: int, ros: bool = False) -> pl.DataFrame:
    """``n`` frames at 100 Hz of white noise on the six axes, a wandering temperature and a
    5 V supply (``ros``: no supply column and a null temperature, as a ROS bag decodes)."""
    rng = np.random.default_rng(7)
    cols = {"t_s": np.arange(n) / 100.0}
    for name in ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"):
        cols[name] = rng.normal(0.0, 1e-2, n)
    cols["temp_c"] = 25.0 + np.cumsum(rng.normal(0, 1e-3, n))
    frame = pl.DataFrame(cols)
    if ros:  # a ROS bag without SUPPLY_OUT and with a null temperature column
        return frame.with_columns(pl.lit(None, dtype=pl.Float64).alias("temp_c"))
    return frame.with_columns(supply_v=pl.Series(np.full(n, 5.0)))


@pytest.fixture(scope="session")
def signal_frames() -> Callable[..., pl.DataFrame]:
    """``signal_frames(n, ros=False)``: the raw frames a Rerun recording is written from."""
    return _signal_frames


@pytest.fixture(scope="session")
def synthetic_result() -> Callable[..., AnalysisResult]:
    """``synthetic_result(with_loop=True)``: the stand-in :class:`AnalysisResult`."""
    return _synthetic_result


@pytest.fixture(scope="session")
def stand_in_truth() -> StandInTruth:
    return StandInTruth()


@dataclass(frozen=True)
class RrdChunks:
    """The chunks of a ``.rrd`` as ``rerun rrd print`` lists them (the real viewer's reader)."""

    @staticmethod
    def printed(path: Path) -> str:
        """What `rerun rrd print` lists of the file."""
        return subprocess.run(
            [rerun_executable(), "rrd", "print", str(path)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout

    @staticmethod
    def lines(path: Path) -> list[tuple[str, int, str]]:
        """(entity path, rows, data columns) of every chunk in file order (`rerun rrd print`)."""
        found = (
            re.match(r"Chunk\(\S+\) with (\d+) rows .* - (/\S+) - (.*)", x)
            for x in RrdChunks.printed(path).splitlines()
        )
        return [(m[2], int(m[1]), m[3]) for m in found if m]

    @staticmethod
    def activations(path: Path) -> list[tuple[bool, bool]]:
        """(make_active, make_default) of every blueprint activation, in file order."""
        found = re.findall(
            r"BlueprintActivationCommand\(.*make_active: (\w+), make_default: (\w+)\)",
            RrdChunks.printed(path),
        )
        return [(active == "true", default == "true") for active, default in found]

    @staticmethod
    def rows(path: Path) -> dict[str, int]:
        """{entity path: rows of its data} of the data (not blueprint) chunks, summed."""
        chunks: dict[str, int] = {}
        for entity, rows, columns in RrdChunks.lines(path):
            if entity.split("/")[1] in ("signals", "allan", "residual", "summary"):
                rows = rows if "Scalars:scalars" in columns else 0
                chunks[entity] = chunks.get(entity, 0) + rows
        return chunks


@pytest.fixture(scope="session")
def rrd_chunks() -> RrdChunks:
    """``rrd_chunks.lines(path)``: (entity, rows, columns) per chunk in file order;
    ``rrd_chunks.rows(path)``: data rows per entity."""
    return RrdChunks()
