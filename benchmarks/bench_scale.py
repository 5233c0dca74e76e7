"""Scale benchmark: a long, fast ROS 2 Imu recording through ``imupipe analyze``.

Writes ``--hours`` h at ``--rate`` Hz (default 24 h at 1 kHz: 86.4 M ``sensor_msgs/msg/Imu``
messages, plus ``sensor_msgs/msg/Temperature`` at 1 Hz) with :class:`imupipe.io.mcap_bulk.
BulkWriter` in blocks of ``--block-s`` seconds, so the generator never holds more than one
block.  Each axis is white noise (gyro 1e-3 rad/s, accel 3e-3 m/s² per sample) plus a sum of
three first-order Gauss-Markov processes (time constants 10, 100, 1000 s: a flicker-like
plateau), their state carried across blocks.  Then ``python -m imupipe analyze FILE`` runs in
a child process; prints its wall time, CPU time and peak RSS (``getrusage(RUSAGE_CHILDREN)``:
user + system time, ``ru_maxrss``) and the load average.

    python benchmarks/bench_scale.py --hours 2 --rate 1000 --file /tmp/scale_2h.mcap
    python benchmarks/bench_scale.py --file /tmp/scale_24h.mcap      # 24 h / 1 kHz
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from imupipe.io.decode import IMU_SCHEMA, TEMPERATURE_SCHEMA
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.testing.ros_cdr import imu_payloads, temperature_payloads

WHITE = np.array([1e-3] * 3 + [3e-3] * 3)  # per-sample sigma: gyro rad/s, accel m/s²
GM_TC_S = np.array([10.0, 100.0, 1000.0])  # Gauss-Markov time constants, s
GM_SIGMA = np.array([2e-5] * 3 + [5e-5] * 3)  # steady-state sigma of each GM process
GRAVITY = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 9.81])
T0_NS = 1_700_000_000_000_000_000


class _GaussMarkov:
    """Sum of first-order GM processes x[k+1] = a x[k] + w, state kept between blocks."""

    def __init__(self, rate_hz: float, rng: np.random.Generator) -> None:
        self.a = np.exp(-1.0 / (GM_TC_S * rate_hz))  # (3,)
        self.drive = np.sqrt(1 - self.a**2)[:, None] * GM_SIGMA[None, :]  # (3, 6)
        self.state = rng.normal(size=(3, 6)) * GM_SIGMA
        self.rng = rng

    def block(self, n: int) -> np.ndarray:
        """(n, 6): the summed processes over the next ``n`` samples (closed form per lag)."""
        out = np.zeros((n, 6))
        k = np.arange(1, n + 1)
        for j, a in enumerate(self.a):
            w = self.rng.normal(size=(n, 6)) * self.drive[j]
            # x[k] = a^k x0 + sum_i a^(k-i) w[i]: a scaled cumulative sum keeps this O(n);
            # blocks are short enough (a^-n stays finite) for a >= exp(-1/(10 s * rate)).
            scale = a ** -k.astype(float)
            x = a ** k[:, None] * (self.state[j] + np.cumsum(w * scale[:, None], axis=0))
            self.state[j] = x[-1]
            out += x
        return out


def write_recording(path: Path, hours: float, rate_hz: float, block_s: float, seed: int) -> int:
    """Write the recording; returns the number of Imu messages."""
    rng = np.random.default_rng(seed)
    gm = _GaussMarkov(rate_hz, rng)
    n_total = round(hours * 3600 * rate_hz)
    per_block = round(block_s * rate_hz)
    period_ns = round(1e9 / rate_hz)
    with open(path, "wb") as f:
        w = BulkWriter(f, profile="ros2")
        imu = w.register_channel("/imu/data", "cdr", w.register_schema(IMU_SCHEMA, "ros2msg", b""))
        tmp = w.register_channel(
            "/imu/temperature", "cdr", w.register_schema(TEMPERATURE_SCHEMA, "ros2msg", b"")
        )
        for start in range(0, n_total, per_block):
            n = min(per_block, n_total - start)
            stamps = T0_NS + (start + np.arange(n, dtype=np.int64)) * period_ns
            y = rng.normal(size=(n, 6)) * WHITE + gm.block(n) + GRAVITY
            w.write_chunk(imu, stamps, imu_payloads(stamps, y[:, :3], y[:, 3:]))
            t_stamps = stamps[:: round(rate_hz)]
            t_s = (t_stamps - T0_NS) / 1e9
            temp = 25.0 + 2.0 * np.sin(2 * np.pi * t_s / 86_400)
            w.write_chunk(tmp, t_stamps, temperature_payloads(t_stamps, temp))
            print(f"\rwrote {start + n:,} / {n_total:,} messages", end="", file=sys.stderr)
        w.finish()
    print(file=sys.stderr)
    return n_total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--block-s", type=float, default=60.0, help="generator block, seconds")
    ap.add_argument("--file", type=Path, default=Path("/tmp/imupipe_scale.mcap"))
    ap.add_argument("--out", type=Path, default=None, help="analyze output folder")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--reuse", action="store_true", help="analyse an existing --file")
    ap.add_argument("analyze_args", nargs="*", help="extra arguments for imupipe analyze")
    args = ap.parse_args()
    if not (args.reuse and args.file.is_file()):
        t = time.perf_counter()
        n = write_recording(args.file, args.hours, args.rate, args.block_s, args.seed)
        print(
            f"generated {n:,} messages, {args.file.stat().st_size / 1e9:.2f} GB "
            f"in {time.perf_counter() - t:.1f} s"
        )
    out = args.out or args.file.with_suffix(".imupipe")
    cmd = [sys.executable, "-m", "imupipe", "analyze", str(args.file), "--out", str(out), "-q"]
    load = os.getloadavg()[0]
    t = time.perf_counter()
    subprocess.run([*cmd, *args.analyze_args], check=True)
    wall = time.perf_counter() - t
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    peak_gb = usage.ru_maxrss * 1024 / 1e9
    print(
        f"analyze: wall {wall:.1f} s, CPU {usage.ru_utime + usage.ru_stime:.1f} s, peak RSS "
        f"{peak_gb:.2f} GB, load average {load:.1f} -> {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} cores ({' '.join([*cmd[3:], *args.analyze_args])})"
    )


if __name__ == "__main__":
    main()
