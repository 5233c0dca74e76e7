"""Peak RSS of ``imupipe analyze`` stage by stage (which stage holds the memory, and how much).

Runs the analysis in this process with a thread sampling the resident set size
(/proc/self/statm, every 10 ms, Linux) and labels the samples with the stage running: each
progress-bar stage ("decode" or "decode + spill", "analyse", "report") and, inside them, the
column source's hand-outs, the Allan curves, the IEEE 952 fit, the closed loop and its hold-out
and spike steps.  Prints one line per stage entry/exit (elapsed wall time, RSS: the per-stage
timings) and the peak of each label; the last line is the kernel's high-water mark.

    python benchmarks/memory_profile.py /tmp/imupipe_scale.mcap            # spilled source
    python benchmarks/memory_profile.py FILE --memory-budget-gb 2         # as the CLI decides
"""

from __future__ import annotations

import argparse
import contextlib
import resource
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import imupipe.analysis.analyze as analyze_module
import imupipe.model.loop as loop_module
from imupipe.analysis.analyze import AnalyzeOptions, analyze
from imupipe.io.columns import InMemoryColumns, SpilledColumns
from imupipe.progress import StageProgress
from imupipe.report.outputs import ReportOutputs

PAGE = resource.getpagesize()


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


class StageMemory:
    """Samples RSS in a daemon thread; ``with memory.label(name): ...`` marks a stage."""

    def __init__(self) -> None:
        self.current = "start"
        self.peaks: dict[str, int] = {}
        self.t0 = time.perf_counter()
        threading.Thread(target=self._sample, daemon=True).start()

    def _sample(self) -> None:
        while True:
            label = self.current
            self.peaks[label] = max(self.peaks.get(label, 0), rss_bytes())
            time.sleep(0.01)

    @contextlib.contextmanager
    def label(self, name: str) -> Iterator[None]:
        outer, self.current = self.current, name
        self._log("enter", name)
        try:
            yield
        finally:
            self.current = outer
            self._log("leave", name, f" (peak {self.peaks.get(name, 0) / 1e9:.2f} GB)")

    def _log(self, what: str, name: str, extra: str = "") -> None:
        elapsed, rss = time.perf_counter() - self.t0, rss_bytes() / 1e9
        print(f"{elapsed:7.1f} s  RSS {rss:5.2f} GB  {what} {name}{extra}", flush=True)

    def wrap(self, module: object, name: str) -> None:
        """Label every call of ``module.name``."""
        function: Callable = getattr(module, name)

        def labelled(*args, **kwargs):
            what = args[1] if len(args) > 1 and isinstance(args[1], str) else ""  # a column
            with self.label(f"{name} {what}".strip()):
                return function(*args, **kwargs)

        setattr(module, name, labelled)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", type=Path)
    ap.add_argument("--memory-budget-gb", type=float, default=0.0, help="0: spilled source")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    memory = StageMemory()
    stage = StageProgress.stage

    @contextlib.contextmanager
    def labelled_stage(self, name, total, unit=""):
        with memory.label(name), stage(self, name, total, unit) as advance:
            yield advance

    StageProgress.stage = labelled_stage
    for source in (InMemoryColumns, SpilledColumns):
        memory.wrap(source, "conditioning")
        memory.wrap(source, "column")
        memory.wrap(source, "signals")
    memory.wrap(analyze_module, "condition")
    memory.wrap(analyze_module, "allan_curves")
    memory.wrap(analyze_module, "fit_noise_terms")
    memory.wrap(analyze_module, "close_loop")
    memory.wrap(loop_module, "_holdout_column")
    memory.wrap(loop_module.effects, "spike_candidate")
    out = args.out or Path(tempfile.mkdtemp(prefix="imupipe-memory-"))
    options = AnalyzeOptions(memory_budget_bytes=round(args.memory_budget_gb * 1e9))
    with StageProgress(quiet=True) as progress:
        analyze(args.file, options, progress, ReportOutputs(out))
    print("peak RSS per label:")
    for name, peak in memory.peaks.items():
        print(f"  {name:28s} {peak / 1e9:.2f} GB")
    hwm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(f"max RSS (kernel high-water mark): {hwm / 1e9:.2f} GB; outputs in {out}")


if __name__ == "__main__":
    main()
