"""Benchmark: the whole ``imupipe analyze`` of a recording (12 h / 100 Hz ADIS16364) against
allantools' bare overlapping ADEV of the same six axes at the same taus, in one process.

The recording is ``imupipe record --duration 12h`` (4.32 M frames; written to ``--file`` unless
it exists).  Ours: :func:`imupipe.analyze` with everything a user gets by default (decode,
conditioning, Allan curves with intervals, IEEE 952 fit, closed loop, report.json/.md,
figures, imu.yaml, allan.parquet and recording.rrd).  The numba kernels are loaded from their
disk cache once before timing (a first run after install compiles them: see
``docs/performance.md``).  Baseline: ``allantools.oadev`` of each of the six decoded axes at
the analysis' own taus.  Both are timed by wall clock and by CPU time of the whole process
(``time.process_time``, all threads); on a machine shared with other jobs the CPU ratio is the
steadier figure, so the load average is printed too.

    python benchmarks/bench_analysis.py [--file /tmp/imupipe_12h.mcap] [--repeat 1]

``--file`` may also name a recording made elsewhere, e.g. the real ADIS16405 unit as a ROS 2
bag (``benchmarks/adis16405_bag.py``), whose loop has events excised and many more candidates
to weigh than a simulated night:

    python benchmarks/adis16405_bag.py ../shared/reference/adis16405 /tmp/adis16405_bag
    python benchmarks/bench_analysis.py --file /tmp/adis16405_bag --repeat 3
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import allantools
import numpy as np

import imupipe
from imupipe.analysis.analyze import compile_kernels
from imupipe.io.decode import decode
from imupipe.vocab import AXES


def cpu_s() -> float:
    """CPU seconds of this process (all threads) and of the children it waited for."""
    t = os.times()
    return time.process_time() + t.children_user + t.children_system


def timed(run) -> tuple[object, float, float]:
    """(result, wall s, CPU s of the process and its children) of ``run()``."""
    cpu, wall = cpu_s(), time.perf_counter()
    out = run()
    return out, time.perf_counter() - wall, cpu_s() - cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", type=Path, default=Path(tempfile.gettempdir()) / "imupipe_12h.mcap")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each; the best is kept")
    args = ap.parse_args()
    if not args.file.exists():
        imupipe.record(args.file, duration="12h")
    compile_kernels()  # load (or compile) the numba kernels: not what is measured
    ours: list[tuple[float, float]] = []
    serial: list[tuple[float, float]] = []
    base: list[tuple[float, float]] = []
    with tempfile.TemporaryDirectory(prefix="imupipe-bench-") as tmp:
        for i in range(args.repeat):
            load = os.getloadavg()[0]
            result, wall, cpu = timed(lambda i=i: imupipe.analyze(args.file, out=f"{tmp}/{i}"))
            ours.append((wall, cpu))
            _, s_wall, s_cpu = timed(
                lambda i=i: imupipe.analyze(args.file, out=f"{tmp}/serial{i}", workers=1)
            )
            serial.append((s_wall, s_cpu))
            frames = decode(args.file).frames
            tau0 = 1.0 / result.input.rate_hz

            def bare_oadev(frames=frames, result=result, tau0=tau0) -> None:
                for name in AXES:
                    y = frames[name].to_numpy()
                    taus = np.asarray(result.axes[name].curve.tau_s)
                    allantools.oadev(y, rate=1.0 / tau0, data_type="freq", taus=taus)

            _, b_wall, b_cpu = timed(bare_oadev)
            base.append((b_wall, b_cpu))
            print(
                f"run {i + 1}: imupipe analyze wall {wall:.2f} s, CPU {cpu:.2f} s; one axis at "
                f"a time wall {s_wall:.2f} s, CPU {s_cpu:.2f} s; allantools "
                f"oadev x6 wall {b_wall:.2f} s, CPU {b_cpu:.2f} s; load average {load:.1f} "
                f"-> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
            )
    (wall, cpu), (s_wall, s_cpu), (b_wall, b_cpu) = min(ours), min(serial), min(base)
    print(f"{result.input.frames:,} frames at {result.input.rate_hz:g} Hz, "
          f"{len(result.axes['gyro_x'].curve.tau_s)} taus per axis")  # fmt: skip
    print(f"best: imupipe analyze wall {wall:.2f} s, CPU {cpu:.2f} s")
    print(f"best: one axis at a time (workers=1) wall {s_wall:.2f} s, CPU {s_cpu:.2f} s")
    print(f"best: allantools oadev x6 wall {b_wall:.2f} s, CPU {b_cpu:.2f} s")
    print(f"ratio one at a time / default: wall {s_wall / wall:.2f}x, CPU {s_cpu / cpu:.2f}x")
    print(f"ratio allantools / imupipe: wall {b_wall / wall:.2f}x, CPU {b_cpu / cpu:.2f}x")


if __name__ == "__main__":
    main()
