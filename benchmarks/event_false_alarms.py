"""Benchmark: the event detector's false-alarm rate on clean recordings, and its tilt detection.

``clean``: short clean six-axis recordings from three sources, each run through
:func:`imupipe.analysis.events.find_events` twice — with the two-axis threshold set for the
axes' measured correlation (the detector) and as if the axes were independent (the rule before
issue 13 item 1's fix) — at the detector's α = 10⁻³ and at α = 0.1, where a few hundred
recordings can show whether the bound holds (an honest rule alarms on ≤ α of them):

* ``independent``: :func:`independent_generator.generate` (axes independent);
* ``correlated``: the same, with a shared mechanical noise on the accelerometers and on the
  gyros (each triple mixed with a common series of the same noise type, pair correlation
  ``--rho``), as a table disturbance or a common vibration would give;
* ``simulator``: our virtual ADIS16364 with the lab temperature profile coupled into all six
  axes (one temperature: correlated slow wander).

Each clean recording also counts whether :func:`imupipe.analysis.common_mode.common_mode`
names an axis pair that moves together at each α (on ``independent`` a false finding).

``tilt``: 2 h / 100 Hz recordings of the independent generator with its 360 s tilt episode at
``--sizes`` (× 3 × the accelerometers' ADEV at 360 s); a tilt is found when an event overlaps
its interval on accel_x or accel_y.

    python benchmarks/event_false_alarms.py clean --seeds 70 --hours 0.5
    python benchmarks/event_false_alarms.py tilt --seeds 10 --sizes 0.5 1 2 3
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from scipy import stats

from imupipe.analysis import events as ev
from imupipe.analysis.common_mode import common_mode
from imupipe.model.effects import spike_candidate
from imupipe.recording.scenario import Scenario, Temperature
from imupipe.vocab import AXES

sys.path.insert(0, str(Path(__file__).resolve().parent))
import independent_generator as ig
from false_positive_rate import LAB_TEMPERATURE, record

ALPHAS = (1e-3, 0.1)
RATE_HZ = 100.0
COUPLING = {  # paper units (°/s, mg) per °C: one temperature coupled into every axis
    "gyro_x": 0.004, "gyro_y": -0.003, "gyro_z": 0.002,
    "accel_x": 0.3, "accel_y": -0.2, "accel_z": 0.25,
}  # fmt: skip


@contextmanager
def independent_axes() -> Iterator[None]:
    """The detector with every measured axis correlation read as 0 (the rule before)."""
    saved = ev.axis_correlation
    ev.axis_correlation = lambda z: np.zeros(z.shape[1] * (z.shape[1] - 1) // 2)
    try:
        yield
    finally:
        ev.axis_correlation = saved


def clean_recording(source: str, seed: int, hours: float, rho: float) -> np.ndarray:
    """(n, 6) SI rates of one clean recording from ``source``."""
    if source == "simulator":
        temperature = Temperature(
            points=LAB_TEMPERATURE.points,
            amplitude_c=LAB_TEMPERATURE.amplitude_c,
            period_s=LAB_TEMPERATURE.period_s,
            coefficients=COUPLING,
        )
        return record(Scenario(temperature=temperature), seed, hours, RATE_HZ)[0]
    y, _, _ = ig.generate(hours, RATE_HZ, seed)
    if source == "correlated":
        common, _, _ = ig.generate(hours, RATE_HZ, seed + 1_000_000)
        for j, k in ((0, 0), (1, 0), (2, 0), (3, 3), (4, 3), (5, 3)):  # common gyro / accel
            mean = y[:, j].mean()
            y[:, j] = (
                mean
                + np.sqrt(1 - rho) * (y[:, j] - mean)
                + np.sqrt(rho) * (common[:, k] - common[:, k].mean())
            )
    return y


def alarms(y: np.ndarray) -> dict[str, object]:
    """Events found at each α, with the measured correlations and as if independent."""
    means = {
        a: ev.fine_means(y[:, j], 1 / RATE_HZ, spike_candidate(y[:, j], 1 / RATE_HZ))
        for j, a in enumerate(AXES)
    }
    b = ev.fine_block(1 / RATE_HZ)
    out: dict[str, object] = {}
    for alpha in ALPHAS:
        found, det = ev.find_events(means, b / RATE_HZ, b, len(y), false_alarm=alpha)
        with independent_axes():
            before, _ = ev.find_events(means, b / RATE_HZ, b, len(y), false_alarm=alpha)
        out[f"after_{alpha:g}"] = found
        out[f"before_{alpha:g}"] = before
        out[f"common_mode_{alpha:g}"] = common_mode(det, alpha).pairs
        out["max_correlation"] = max(det.correlation)
    return out


def _clean_job(job: tuple[str, int, float, float]) -> tuple[str, int, dict]:
    source, seed, hours, rho = job
    return source, seed, alarms(clean_recording(source, seed, hours, rho))


def _tilt_job(job: tuple[float, int]) -> tuple[float, int, dict, dict]:
    size, seed = job
    y, _, truth = ig.generate(2.0, RATE_HZ, seed, "tilt", size)
    return size, seed, truth.effect, alarms(y)


def _hit(events: list[ev.DisturbanceEvent], effect: dict) -> bool:
    """An event overlapping the tilt on accel_x or accel_y."""
    t0, t1 = effect["time_s"], effect["time_s"] + effect["duration_s"]
    return any(
        e.start_s < t1 and e.start_s + e.duration_s > t0 and {"accel_x", "accel_y"} & set(e.axes)
        for e in events
    )


def interval(k: int, n: int) -> str:
    lo, hi = stats.binomtest(k, n).proportion_ci(0.95)
    return f"{k}/{n} (95 % CI {lo:.3f}–{hi:.3f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=["clean", "tilt"])
    parser.add_argument("--seeds", type=int, default=70, help="recordings per source / size")
    parser.add_argument("--hours", type=float, default=0.5, help="clean recordings' length")
    parser.add_argument("--rho", type=float, default=0.5, help="correlated source's pair rho")
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.5, 1.0, 2.0, 3.0])
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    with ProcessPoolExecutor(args.jobs) as pool:
        if args.mode == "clean":
            sources = ("independent", "correlated", "simulator")
            jobs = [(s, 100 + i, args.hours, args.rho) for s in sources for i in range(args.seeds)]
            rows = list(pool.map(_clean_job, jobs))
            for source in (*sources, "all"):
                sel = [r for s, _, r in rows if source in (s, "all")]
                rho = np.median([r["max_correlation"] for r in sel])
                print(f"{source}: {len(sel)} recordings, median max |rho| {rho:.2f}")
                for key in [f"{w}_{a:g}" for a in ALPHAS for w in ("before", "after")]:
                    k = sum(bool(r[key]) for r in sel)
                    print(f"  {key}: recordings with an event {interval(k, len(sel))}")
                for alpha in ALPHAS:  # axes that move together (imupipe.analysis.common_mode)
                    k = sum(bool(r[f"common_mode_{alpha:g}"]) for r in sel)
                    named = interval(k, len(sel))
                    print(f"  common_mode_{alpha:g}: recordings with a pair {named}")
            for s, seed, r in rows:
                for e in r["after_0.001"]:
                    print(f"  false event: {s} seed {seed} {e.kind} {e.axes} at {e.start_s} s")
        else:
            jobs = [(size, 200 + i) for size in args.sizes for i in range(args.seeds)]
            rows = list(pool.map(_tilt_job, jobs))
            for size in args.sizes:
                sel = [(eff, r) for s, _, eff, r in rows if s == size]
                for key in ("before_0.001", "after_0.001"):
                    k = sum(_hit(r[key], eff) for eff, r in sel)
                    print(f"tilt size {size:g}: {key} found {interval(k, len(sel))}")


if __name__ == "__main__":
    main()
