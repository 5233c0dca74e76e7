"""Benchmark: bulk decode vs a loop over the mcap library's ``iter_messages`` on the same file.

The baseline only iterates the messages (no CDR decoding at all), so the ratio understates our
advantage.  Also reports the whole ``imupipe analyze`` wall time (all stages, rrd included) and
its peak memory, run as a user runs it (``python -m imupipe analyze``, a child process).

Usage: ``python benchmarks/bench_decode.py [--hours 12] [--rate 100] [--file FILE]``
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mcap.reader import make_reader

from imupipe.device.adis16364 import config_for_rate
from imupipe.io.decode import decode
from imupipe.recording.recorder import record
from imupipe.recording.simulator import VirtualADIS16364


def iter_messages(path: Path) -> int:
    count = 0
    with open(path, "rb") as f:
        for _ in make_reader(f).iter_messages():
            count += 1
    return count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=12.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--file", type=Path, help="benchmark this file instead of a simulation")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.file
        if path is None:
            path = Path(tmp) / "run.mcap"
            n = round(args.hours * 3600 * args.rate)
            record(path, VirtualADIS16364(config_for_rate(args.rate), seed=2), n)
        start = time.perf_counter()
        frames = decode(path).frames.height
        ours = time.perf_counter() - start
        start = time.perf_counter()
        count = iter_messages(path)
        base = time.perf_counter() - start
        assert count == frames, (count, frames)
        start = time.perf_counter()
        cmd = [sys.executable, "-m", "imupipe", "analyze", str(path), "-q", "--out"]
        subprocess.run([*cmd, str(Path(tmp) / "out")], check=True)
        whole = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"frames: {frames}")
    print(f"imupipe decode:              {ours:.2f} s = {frames / ours / 1e6:.2f} M frames/s")
    print(f"mcap iter_messages loop:     {base:.2f} s = {frames / base / 1e6:.2f} M frames/s")
    print(f"ratio (iter_messages / decode): {base / ours:.1f}x")
    print(f"whole imupipe analyze (decode..rrd): {whole:.2f} s")
    print(f"peak memory of imupipe analyze (max RSS): {peak_mb:.0f} MB")


if __name__ == "__main__":
    main()
