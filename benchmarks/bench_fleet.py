"""Fleet throughput: 2 Dask workers against 1, and the fleet against a plain loop of
``imupipe.api.analyze`` (issue 14's targets: ≥ 1.8× on 2 cores, ≤ 10 % overhead).

    python benchmarks/bench_fleet.py [--units 24] [--duration 1h] [--rounds 2] [--dir DIR]

Records ``--units`` simulated recordings at 100 Hz (seeds 0..units-1, kept in ``--dir`` for the
next run), warms the numba cache with one analysis, then times the sequential loop in this
process (numba's and polars' default thread pools), and then ``--rounds`` rounds of five runs: a
loop of the ``imupipe analyze`` command (one process per recording, ``--jobs 1``, one thread:
what a user runs without a fleet, each process paying its start, imports and numba cache
loading), the sequential loop in one child process pinned to one core as a fleet worker is
(``SINGLE_THREAD_ENV``, one axis at a time), two such loops side by side over half of the
recordings each (the machine's own 2-core ceiling, without Dask), ``run_fleet`` on a
LocalCluster of 1 worker, and of 2 workers (each including cluster start and stop and the fleet
report). Every other round runs the five in reverse order, so a machine whose speed drifts
(shared cores) biases no ratio; the ratios are printed per round. The fleet's overhead is
measured against the one-thread loop in one process — the same work on the same single core,
without Dask, the fleet report or any process start: the strict baseline; each fleet runs in a
fresh child process, as ``imupipe fleet`` does, its imports untimed like the loop's — and
against the loop of commands, the issue's literal baseline. All runs use imupipe analyze's
defaults (closed loop, figures, recording.rrd). The load average is printed with every timing:
on a shared machine the ratios are only as good as the load was steady. From the 1-worker runs
(median worker-seconds per unit) it derives what a 1,000-unit fleet of such recordings needs,
one single-threaded worker per core.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from imupipe.api import analyze, record
from imupipe.fleet.cluster import SINGLE_THREAD_ENV

ONE_THREAD_LOOP = """
import sys, time
from imupipe.api import analyze
out, paths = sys.argv[1], sys.argv[2:]
analyze(paths[0], out + "/warm", workers=1)  # imports and the numba cache, not timed
t0 = time.perf_counter()
for k, path in enumerate(paths):
    analyze(path, f"{out}/{k}", workers=1)  # one axis at a time, as in a fleet worker
print(time.perf_counter() - t0)
"""


def _load() -> str:
    return "load " + " ".join(f"{v:.1f}" for v in os.getloadavg())


def _recordings(folder: Path, units: int, duration: str) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for k in range(units):
        path = folder / f"unit{k:03d}_{duration}.mcap"
        if not path.exists():
            record(path, duration=duration, rate_hz=100.0, seed=k)
        paths.append(path)
    return paths


def _start_loop(work: Path, paths: list[Path]) -> subprocess.Popen:
    """A child running :data:`ONE_THREAD_LOOP` over ``paths``, pinned to one thread as a
    fleet worker is (``SINGLE_THREAD_ENV``)."""
    return subprocess.Popen(
        [sys.executable, "-c", ONE_THREAD_LOOP, str(work), *map(str, paths)],
        env=os.environ | SINGLE_THREAD_ENV, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip


def _loop_seconds(child: subprocess.Popen) -> float:
    """The timed seconds a :func:`_start_loop` child prints, once it has ended."""
    out, _ = child.communicate()
    if child.returncode:
        raise RuntimeError(f"a one-thread loop failed (exit {child.returncode})")
    return float(out.split()[-1])


def _one_core_loop(work: Path, paths: list[Path]) -> float:
    """Seconds of the sequential loop in a child pinned to one thread, as a fleet worker runs."""
    return _loop_seconds(_start_loop(work, paths))


def _two_loops(work: Path, paths: list[Path]) -> float:
    """Seconds of two one-thread loops side by side, each over half of the recordings (the
    longer of the two): what two cores of this machine do with the fleet's work and no Dask
    at all, the ceiling of the 2-worker fleet's speedup here.  Two analyses side by side slow
    each other down (shared cache and memory bandwidth; 1-11 % per unit in session 54's
    pairs), so on two cores the ceiling is under 2x."""
    children = [_start_loop(work / str(k), paths[k::2]) for k in (0, 1)]
    return max(_loop_seconds(child) for child in children)


def _command_loop(work: Path, paths: list[Path]) -> float:
    """Seconds of a shell-style loop of the ``imupipe analyze`` command, one process per
    recording pinned to one thread (``--jobs 1``, ``SINGLE_THREAD_ENV``): what a user runs
    without a fleet, each process paying its own start, imports and numba cache loading."""
    command = Path(sys.executable).with_name("imupipe")
    t0 = time.perf_counter()
    for k, path in enumerate(paths):
        subprocess.run(
            [str(command), "analyze", str(path), "--out", str(work / str(k)), "--jobs", "1",
             "--quiet"],
            env=os.environ | SINGLE_THREAD_ENV, capture_output=True, check=True,
        )  # fmt: skip
    return time.perf_counter() - t0


FLEET_RUN = """
import statistics, sys, time
from imupipe.fleet.run import run_fleet
if __name__ == "__main__":
    out, workers, paths = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
    t0 = time.perf_counter()
    result = run_fleet(paths, out, workers=workers)
    seconds = time.perf_counter() - t0
    assert not result.failed, [u.error for u in result.failed]
    print(seconds, statistics.median(u.seconds for u in result.units))
"""


def _fleet(work: Path, paths: list[Path], workers: int) -> float:
    """Seconds of ``run_fleet`` on a LocalCluster of ``workers`` (start, stop, report included)
    in a fresh child process, as ``imupipe fleet`` runs it (its imports not timed, as the
    loop's are not).  Run in this process instead, after its own loop of analyses, the
    1-worker fleet measured +40 % against the one-core loop where a fresh process measured
    +12 to +21 % (12 units; session 20)."""
    script = work.with_name(f"{work.name}_fleet.py")  # a file: Dask's spawned workers import it
    script.write_text(FLEET_RUN)
    child = subprocess.run(
        [sys.executable, str(script), str(work), str(workers), *map(str, paths)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    seconds, unit_s = map(float, child.stdout.split()[-2:])
    print(f"  fleet, LocalCluster of {workers} worker(s): {seconds:.1f} s "
          f"({unit_s:.2f} s per unit on its worker, median), {_load()}")  # fmt: skip
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--units", type=int, default=24)
    parser.add_argument("--duration", default="1h")
    parser.add_argument("--rounds", type=int, default=2, help="alternated rounds (see above)")
    parser.add_argument("--dir", type=Path, default=Path("/tmp/imupipe_bench_fleet"))
    args = parser.parse_args()
    print(f"cores {os.cpu_count()}, {_load()}")
    t0 = time.perf_counter()
    paths = _recordings(args.dir, args.units, args.duration)
    print(f"{len(paths)} recordings of {args.duration} at 100 Hz ready "
          f"({time.perf_counter() - t0:.0f} s)")  # fmt: skip
    work = Path(tempfile.mkdtemp(prefix="bench_fleet_"))
    try:
        analyze(paths[0], work / "warm")  # numba cache, imports: not timed

        t0 = time.perf_counter()
        per_unit = []
        for k, path in enumerate(paths):
            t = time.perf_counter()
            analyze(path, work / "seq" / f"{k}")
            per_unit.append(time.perf_counter() - t)
        t_seq = time.perf_counter() - t0
        peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
        print(f"sequential loop of analyze: {t_seq:.1f} s ({statistics.median(per_unit):.2f} s "
              f"per unit, median), peak RSS {peak_gb:.2f} GB, {_load()}")  # fmt: skip

        runs = {
            "command": lambda r: _command_loop(work / f"cmd_{r}", paths),
            "loop": lambda r: _one_core_loop(work / f"seq1_{r}", paths),
            "two loops": lambda r: _two_loops(work / f"seq2_{r}", paths),
            1: lambda r: _fleet(work / f"fleet1_{r}", paths, 1),
            2: lambda r: _fleet(work / f"fleet2_{r}", paths, 2),
        }
        timings: dict[object, list[float]] = {name: [] for name in runs}
        for r in range(args.rounds):
            print(f"round {r + 1}:")
            for name in list(runs) if r % 2 == 0 else list(runs)[::-1]:
                timings[name].append(runs[name](r))
                if name == "loop":
                    print(f"  sequential loop, one thread (as a fleet worker): "
                          f"{timings[name][-1]:.1f} s, {_load()}")  # fmt: skip
                if name == "two loops":
                    print(f"  two one-thread loops side by side, half of the units each: "
                          f"{timings[name][-1]:.1f} s, {_load()}")  # fmt: skip
                if name == "command":
                    print(f"  loop of the imupipe analyze command, one thread: "
                          f"{timings[name][-1]:.1f} s, {_load()}")  # fmt: skip
    finally:
        shutil.rmtree(work, ignore_errors=True)

    speedups = [one / two for one, two in zip(timings[1], timings[2], strict=True)]
    ceilings = [a / b for a, b in zip(timings["loop"], timings["two loops"], strict=True)]
    print("two one-thread loops side by side vs one, per round: "
          + ", ".join(f"{v:.2f}x" for v in ceilings) + " (this machine's ceiling)")  # fmt: skip
    overheads = [100 * (f / b - 1) for f, b in zip(timings[1], timings["loop"], strict=True)]
    print("speedup 2 vs 1 worker, per round: "
          + ", ".join(f"{v:.2f}x" for v in speedups) + " (target >= 1.8x on 2 cores)")  # fmt: skip
    print("fleet (1 worker) vs one-thread sequential loop, per round: "
          + ", ".join(f"{v:+.1f} %" for v in overheads) + " (target <= 10 %)")  # fmt: skip
    commands = [100 * (f / b - 1) for f, b in zip(timings[1], timings["command"], strict=True)]
    print("fleet (1 worker) vs the loop of imupipe analyze commands, per round: "
          + ", ".join(f"{v:+.1f} %" for v in commands))  # fmt: skip
    core_s = statistics.median(timings[1]) / len(paths)  # one worker, one unit after the other
    print(f"per unit: {core_s:.1f} worker-seconds ({args.duration} at 100 Hz, 1-worker runs)")
    for n in (16, 64, 256):
        print(f"1,000 units on {n} workers: {1000 * core_s / n / 60:.1f} min, "
              f"~{peak_gb:.1f} GB per worker")  # fmt: skip


if __name__ == "__main__":
    main()
