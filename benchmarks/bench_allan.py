"""Benchmark: overlapping Allan deviation, ours vs allantools.oadev, same data and tau grid.

Data: 12 h at 100 Hz (4.32 M samples) x 6 axes of simulated IMU rates (white noise plus a
slow random walk, mean removed so allantools' undetrended phase loses no digits).  Both run
in this process on the default tau grid (:func:`imupipe.stats.allan.tau_factors`); prints the time
of each, the speed ratio and the largest relative difference.

    python benchmarks/bench_allan.py [--samples N] [--axes K]
"""

from __future__ import annotations

import argparse
import time

import allantools
import numpy as np

from imupipe.stats.allan import oadev, tau_factors


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4_320_000)
    parser.add_argument("--axes", type=int, default=6)
    args = parser.parse_args()

    tau0 = 0.01
    rng = np.random.default_rng(12)
    y = rng.standard_normal((args.samples, args.axes)) * 1e-3
    y += np.cumsum(rng.standard_normal((args.samples, args.axes)), axis=0) * 1e-7
    y -= y.mean(axis=0)
    m = tau_factors(args.samples)

    oadev(y[:1000], tau0, m[:3])  # compile (numba caches the machine code on disk)
    t = time.perf_counter()
    ours, _ = oadev(y, tau0, m)
    t_ours = time.perf_counter() - t

    t = time.perf_counter()
    ref = np.empty_like(ours)
    for axis in range(args.axes):
        taus, dev, _, _ = allantools.oadev(
            y[:, axis], rate=1.0 / tau0, data_type="freq", taus=m * tau0
        )
        if taus.size != m.size:
            raise RuntimeError("allantools returned a different tau grid")
        ref[:, axis] = dev
    t_ref = time.perf_counter() - t

    print(f"samples {args.samples} x {args.axes} axes, {m.size} taus (m = 1..{m[-1]})")
    print(f"allantools.oadev {t_ref:.2f} s, ours {t_ours:.2f} s")
    print(f"speed ratio {t_ref / t_ours:.1f}x")
    print(f"max relative difference {np.max(np.abs(ours / ref - 1.0)):.2e}")


if __name__ == "__main__":
    main()
