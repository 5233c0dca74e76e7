"""Benchmark: the first ``imupipe analyze`` after installing (numba's disk cache empty) against a
warm run, each in a fresh interpreter, on the 5-min sample log.

Three runs per repeat, each the ``imupipe analyze SAMPLE --out OUT`` command with everything a
user gets by default (figures, recording.rrd, the loop), its exit included, in a new process:

* cold: ``NUMBA_CACHE_DIR`` an empty folder; the fit's and the loop's kernels compile in a child
  meanwhile (imupipe.model.ahead);
* cold, in process: the same with ``compile_ahead=False`` (every kernel compiles in the
  analysing process, as before the child);
* warm: the cache the cold run filled.

Wall clock, CPU time of the process and its children (``resource.getrusage(RUSAGE_CHILDREN)``:
the compiling child included) and of the analysing process alone (its ``RUSAGE_SELF``: the
critical path on idle cores, which the compiling child runs beside); the machine may be shared,
so the load average is printed with each run.

    python benchmarks/bench_first_run.py [--sample sample_logs/adis16364_default_5min.mcap]
                                         [--repeat 1]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUN = """import atexit, resource, sys
import imupipe.analysis.analyze as analysis
from imupipe.cli import console
if not {}:  # every kernel compiles in the analysing process
    start_child = analysis.compile_ahead
    analysis.compile_ahead = lambda loop, enabled=True: start_child(loop, False)
own = lambda: resource.getrusage(resource.RUSAGE_SELF)
atexit.register(lambda: print(own().ru_utime + own().ru_stime))
sys.argv = ["imupipe", "analyze", sys.argv[1], "--out", sys.argv[2], "--quiet"]
console()"""


def run(sample: Path, out: Path, cache: Path, ahead: bool) -> tuple[float, float, float]:
    """(wall s, CPU s of the process and its children, CPU s of the analysing process alone)
    of one analysis in a new interpreter."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", RUN.format(ahead), str(sample), str(out)],
        env=env, check=True, capture_output=True, text=True,
    )  # fmt: skip
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, float(done.stdout.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", type=Path, default=Path("sample_logs/adis16364_default_5min.mcap"))
    ap.add_argument("--repeat", type=int, default=1, help="runs of each; the best is kept")
    args = ap.parse_args()
    best: dict[str, tuple[float, float, float]] = {}
    with tempfile.TemporaryDirectory(prefix="imupipe-first-run-") as tmp:
        for i in range(args.repeat):
            for name, ahead, fresh in (
                ("cold", True, True),
                ("cold, in process", False, True),
                ("warm", True, False),
            ):
                cache = Path(tmp) / f"numba-{i}-{ahead}" if fresh else Path(tmp) / f"numba-{i}-True"
                load = os.getloadavg()[0]
                wall, cpu, own = run(args.sample, Path(tmp) / f"out-{i}", cache, ahead)
                print(
                    f"run {i + 1} {name:16s}: wall {wall:6.2f} s, CPU {cpu:6.2f} s (analysing "
                    f"process {own:6.2f} s); load average {load:.1f} -> "
                    f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores",
                    flush=True,
                )
                best[name] = min(best.get(name, (wall, cpu, own)), (wall, cpu, own))
    warm_wall, warm_cpu, _ = best["warm"]
    for name, (wall, cpu, own) in best.items():
        print(
            f"best {name:16s}: wall {wall:6.2f} s ({wall / warm_wall:.2f}x warm), "
            f"CPU {cpu:6.2f} s ({cpu / warm_cpu:.2f}x warm), analysing process {own:6.2f} s"
        )


if __name__ == "__main__":
    main()
