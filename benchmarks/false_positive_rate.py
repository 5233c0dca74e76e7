"""Benchmark: false-positive rate of the closed loop (issue 4) on clean simulated recordings.

Each seed records ``--hours`` of the virtual ADIS16364 (paper noise: white, flicker, rate random
walk; no effect) at ``--rate`` Hz with a realistic slow lab temperature profile (warm-up of
2.5 °C in 30 min, then a slow wander and a ±0.3 °C air-conditioning cycle of 50 min) on the TEMP
registers and a constant supply; every axis goes through :func:`imupipe.model.loop.close_loop`.
Prints the share of axes with any accepted effect (target ≤ 5 %), per kind and per axis, with
a 95 % Clopper–Pearson interval, and the loop's mean time per recording.

    /work/venv/bin/python benchmarks/false_positive_rate.py [--seeds 40] [--hours 3] [--rate 10]
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import numpy as np
from scipy import stats

from imupipe.device.adis16364 import (
    SUPPLY_V_PER_LSB,
    TEMP_C_PER_LSB,
    TEMP_ZERO_C,
    DeviceConfig,
    burst_counts,
)
from imupipe.model.loop import AxisSignals, aux_block_means, close_loop
from imupipe.recording.scenario import Scenario, Temperature, si_per_unit
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.stats.allan import allan_curves
from imupipe.vocab import AXES, sensor_of

LAB_TEMPERATURE = Temperature(
    points=((0.0, 21.0), (1800.0, 23.5), (5400.0, 24.0), (10800.0, 23.6), (43200.0, 24.2)),
    amplitude_c=0.3,
    period_s=3000.0,
)


def record(
    scenario: Scenario, seed: int, hours: float, rate_hz: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(y (n, 6) SI, temperature °C, supply V, tau0 s) decoded from the simulator's words."""
    config = DeviceConfig(output_rate_hz=rate_hz)
    counts = burst_counts(
        VirtualADIS16364(config, scenario, seed).frames(int(hours * 3600 * rate_hz)).burst
    )
    lsb = np.array([config.gyro_scale_dps] * 3 + [1.0] * 3) * [si_per_unit(a) for a in AXES]
    y = counts[:, 1:7] * lsb
    temp = TEMP_ZERO_C + counts[:, 7] * TEMP_C_PER_LSB
    supply = counts[:, 0] * SUPPLY_V_PER_LSB
    return y, temp, supply, 1.0 / rate_hz


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--first-seed", type=int, default=1000)
    parser.add_argument("--hours", type=float, default=3.0)
    parser.add_argument("--rate", type=float, default=10.0)
    args = parser.parse_args()
    scenario = Scenario(temperature=LAB_TEMPERATURE)
    kinds: Counter[str] = Counter()
    per_axis: Counter[str] = Counter()
    hits, seconds = 0, 0.0
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        y, temp, supply, tau0 = record(scenario, seed, args.hours, args.rate)
        start = time.perf_counter()
        curves = allan_curves(y, tau0)
        for i, (axis, curve) in enumerate(zip(AXES, curves, strict=True)):
            sig = AxisSignals(
                axis,
                sensor_of(axis),
                y[:, i],
                tau0,
                aux_block_means(temp, tau0),
                aux_block_means(supply, tau0),
            )
            accepted = [e.kind for e in close_loop(sig, curve).accepted]
            kinds.update(accepted)
            per_axis[axis] += bool(accepted)
            hits += bool(accepted)
            if accepted:
                print(f"seed {seed} {axis}: accepted {accepted}")
        seconds += time.perf_counter() - start
    total = args.seeds * len(AXES)
    lo, hi = stats.binomtest(hits, total).proportion_ci(0.95)
    print(f"{args.seeds} clean recordings x {len(AXES)} axes ({args.hours} h at {args.rate} Hz)")
    share = f"{hits}/{total} = {hits / total:.1%}"
    print(f"axes with an accepted effect: {share} (95 % CI {lo:.1%}–{hi:.1%})")
    print("per kind:", dict(kinds) or "none")
    print("per axis:", {a: per_axis[a] for a in AXES})
    print(f"loop + allan time per recording: {seconds / args.seeds:.2f} s")


if __name__ == "__main__":
    main()
