"""Coverage of the closed loop's ``frequency_hz`` (and, for a spread line, ``width_hz``)
interval for a spread line and for a tone, and N after the loop against the truth.

The setting of tests/model/test_loop_vibration.py: 3.6 h at 10 Hz of the paper's gyro noise
(``PaperGyro`` of tests/model/conftest.py) plus, per seed, either a damped oscillator at 0.05 Hz
with width 0.002 Hz and rms 3 N (``spread``) or a 0.05 Hz sinusoid of amplitude 6 B and random
phase (``tone``); each recording goes through ``close_loop`` and the first accepted line is
scored: does its 95 % interval hold 0.05 Hz, what kind is it, how wide is the interval.  A
measurement, not a test::

    python benchmarks/narrowband_coverage.py --seeds 20 spread tone
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import signal

sys.path.insert(0, str(Path(__file__).parents[1] / "tests" / "model"))
from conftest import PaperGyro  # the tests' noise builder, not a copy

from imupipe.model.loop import AxisSignals, close_loop
from imupipe.stats.allan import allan_curves

TAU0, N = 0.1, 2**17
F0, Q = 0.05, 25.0
EXPECTED = {"spread": "narrowband", "tone": "sinusoid"}


def recording(case: str, seed: int, gyro: PaperGyro) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y = gyro.rate(N, TAU0, rng)
    if case == "spread":
        r = np.exp(-np.pi * F0 / Q * TAU0)
        ar = [1, -2 * r * np.cos(2 * np.pi * F0 * TAU0), r * r]
        x = signal.lfilter([1.0], ar, rng.standard_normal(N))
        return y + 3 * gyro.n * x / x.std()
    t = np.arange(N) * TAU0
    return y + 6 * gyro.b * np.sin(2 * np.pi * F0 * t + rng.uniform(0, 2 * np.pi))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cases", nargs="+", choices=sorted(EXPECTED))
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--first-seed", type=int, default=100)
    args = p.parse_args()
    gyro = PaperGyro()
    for case in args.cases:
        covered, right, widths, width_covered, n_errors = 0, 0, [], 0, []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            y = recording(case, seed, gyro)
            res = close_loop(AxisSignals("gyro_x", "gyro", y, TAU0, None, None),
                             allan_curves(y, TAU0)[0])  # fmt: skip
            lines = [e for e in res.accepted if e.kind in ("narrowband", "sinusoid")]
            if not lines:
                print(f"{case} {seed}: no line accepted", flush=True)
                continue
            line = lines[0]
            lo, hi = line.intervals["frequency_hz"]
            covered += lo < F0 < hi
            right += line.kind == EXPECTED[case]
            widths.append(hi - lo)
            w_lo, w_hi = line.intervals.get("width_hz", (np.nan, np.nan))
            width_covered += bool(w_lo < F0 / Q < w_hi)
            n_errors.append(res.terms_after.random_walk.value / gyro.n - 1)
            print(f"{case} {seed}: {line.kind} {line.params['frequency_hz']:.6f} Hz "
                  f"[{lo:.6f}, {hi:.6f}], width {line.params.get('width_hz', np.nan):.3g} Hz "
                  f"[{w_lo:.3g}, {w_hi:.3g}], N {n_errors[-1]:+.2%}", flush=True)  # fmt: skip
        print(f"{case}: interval covers {F0} Hz on {covered}/{args.seeds}, kind "
              f"{EXPECTED[case]} on {right}/{args.seeds}, median interval width "
              f"{np.median(widths):.3g} Hz; width interval covers {F0 / Q:g} Hz on "
              f"{width_covered}/{args.seeds}; N within 2 % on "
              f"{sum(abs(e) <= 0.02 for e in n_errors)}/{len(n_errors)}")  # fmt: skip


if __name__ == "__main__":
    main()
