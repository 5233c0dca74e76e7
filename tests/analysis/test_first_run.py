"""A first run after installing, numba's disk cache empty: the IEEE 952 fit's kernels are
compiled ahead by a child process (imupipe.model.ahead) and the loop's by the analysing process
while it waits for the child, every kernel compiles once, a short record's statistics compile
none of the long-record kernels, and report.json is the same as from a run that compiles in
process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import imupipe
from imupipe.analysis.analyze import AXIS_BYTES_PER_SAMPLE
from imupipe.model import ahead

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "adis16364_default_5min.mcap"

PROBE = r"""
import json, sys
import numba.core.event as ev
from numba.core.registry import CPUDispatcher

compiled = []  # every kernel this process compiles itself (not loaded from the cache)


class Listener(ev.Listener):
    def on_start(self, event):
        func = event.data["dispatcher"].py_func
        compiled.append(f"{func.__module__}.{func.__qualname__}")

    def on_end(self, event):
        pass


ev.register("numba:compile", Listener())
import imupipe
from imupipe.jit import disk_cached
import imupipe.model.ahead as ahead_module
from imupipe.model.ahead import FIT_KERNELS, LOOP_KERNELS

ahead_module.WAIT_S = 3600.0  # a loaded machine may take minutes: this test is not timed
_child = ahead_module.child_command
# the child starts late: a late kernel called before the wait then compiles here, every time,
# and the wait always finds it running
ahead_module.child_command = lambda loop, taken=None: [
    _child(loop, taken)[0], "-c", "import time; time.sleep(3); " + _child(loop, taken)[-1]
]

cold = [not disk_cached(k) for k in FIT_KERNELS + LOOP_KERNELS]
imupipe.analyze(sys.argv[1], out=sys.argv[2], rrd=False, figures=False)
kernels = {
    f"{d.py_func.__module__}.{d.py_func.__qualname__}": len(d.signatures)
    for m in list(sys.modules.values()) if m.__name__.startswith("imupipe")
    for d in vars(m).values() if isinstance(d, CPUDispatcher)
}
print(json.dumps({
    "cold_before": cold,
    "cached_after": [disk_cached(k) for k in FIT_KERNELS + LOOP_KERNELS],
    "compiled_here": compiled,
    "signatures": kernels,
}))
"""


def names(kernels) -> set[str]:
    return {f"{k.py_func.__module__}.{k.py_func.__qualname__}" for k in kernels}


FIT, LOOP = names(ahead.FIT_KERNELS), names(ahead.LOOP_KERNELS)
LONG_RECORD = {
    "imupipe.stats.robust._extent_parts",
    "imupipe.stats.robust._histogram_parts",
    "imupipe.stats.robust._gather_parts",
    "imupipe.stats.robust._rank_bin",
    "imupipe.stats.robust._running_median",
}
"""The robust statistics' kernels, for records of over ``robust.NUMPY_MAX`` values."""
LITERAL_FLAG = {"imupipe.stats.edf._value"}
"""Called with the literal ``phase=True`` by the gather in edf._acf_ids (inlined by LLVM) and
with a runtime flag by _acf_power: a tiny function, two specialisations."""


@pytest.fixture(scope="module")
def cold_run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The sample analysed in a fresh interpreter with an empty NUMBA_CACHE_DIR."""
    tmp = tmp_path_factory.mktemp("cold")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp / "numba")}
    done = subprocess.run(
        [sys.executable, "-c", PROBE, str(SAMPLE), str(tmp / "out")],
        env=env, capture_output=True, text=True, timeout=900, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    probe = json.loads(done.stdout.splitlines()[-1])
    probe["report"] = json.loads((tmp / "out" / "report.json").read_text())
    return probe


@pytest.fixture(scope="module")
def child_failed_report(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """report.json of the sample analysed here with the cache taken for cold and a child that
    fails at once, leaving the cache as it was (a read-only cache, a crash): the kernels
    compile (or load) in this process."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ahead, "disk_cached", lambda kernel: False)
        mp.setattr(
            ahead, "child_command", lambda loop, taken=None: [sys.executable, "-c", "exit(3)"]
        )
        out = tmp_path_factory.mktemp("failed-child")
        imupipe.analyze(SAMPLE, out, rrd=False, figures=False)
    return json.loads((out / "report.json").read_text())


def test_cold_cache_child_compiles_the_fit_and_the_waiting_analysis_the_loop(
    cold_run: dict,
) -> None:
    assert all(cold_run["cold_before"])
    assert all(cold_run["cached_after"])
    here = cold_run["compiled_here"]
    # the analysis loaded the child's compiled kernels: same types, nothing compiled twice
    assert FIT.isdisjoint(here)
    assert all(here.count(name) == 1 for name in LOOP)  # while the child compiled the fit's
    assert "imupipe.stats.allan._block_sums" in here
    assert LONG_RECORD.isdisjoint(here)  # 30,000 samples: numpy's order statistics


def test_each_kernel_compiles_once_on_the_sample(cold_run: dict) -> None:
    """A second specialisation (a read-only column, int32 for int64, a literal argument) costs
    a whole compile of the kernel on every first run."""
    counts = cold_run["signatures"]
    assert counts["imupipe.model.ieee952._fit_gamma"] == 1
    assert counts["imupipe.stats.edf._acf_pass"] == 1
    several = {name: n for name, n in counts.items() if n > 1}
    assert several == dict.fromkeys(LITERAL_FLAG, 2)


def test_cold_cache_report_equals_the_in_process_report(
    cold_run: dict, child_failed_report: dict
) -> None:
    cold = cold_run["report"]
    assert cold["input"]["path"] == child_failed_report["input"]["path"] == str(SAMPLE)
    for axis in ("gyro_x", "accel_z"):
        terms = cold["axes"][axis]["ieee952"]
        assert terms["random_walk"] == child_failed_report["axes"][axis]["ieee952"]["random_walk"]
        assert terms["random_walk"]["value"] > 0
        assert cold["axes"][axis]["allan"] == child_failed_report["axes"][axis]["allan"]
    assert cold == child_failed_report


def test_failed_child_is_waited_for_and_forgotten(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ahead, "disk_cached", lambda kernel: False)
    monkeypatch.setattr(
        ahead, "child_command", lambda loop, taken=None: [sys.executable, "-c", "exit(3)"]
    )
    with ahead.compile_ahead(loop=True) as started:
        assert started.child is not None
        child = started.child
        started.wait()
        started.wait()  # idempotent
    assert started.child is None and child.returncode == 3


def test_warm_cache_or_fleet_worker_starts_no_child(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(
        ahead, "child_command", lambda loop, taken=None: pytest.fail("a child was started")
    )
    monkeypatch.setattr(ahead, "disk_cached", lambda kernel: True)
    assert ahead.compile_ahead(loop=True).child is None
    monkeypatch.setattr(ahead, "disk_cached", lambda kernel: False)
    assert ahead.compile_ahead(loop=True, enabled=False).child is None


def test_without_the_loop_its_kernels_are_not_compiled_ahead(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No loop: the child compiles the fit's kernels only, and no note is kept.  The fit's
    kernels alone decide whether a child starts (a cold loop kernel compiles where it is
    called)."""
    compiled: list[int] = []
    monkeypatch.setattr(ahead, "compile_loop_kernels", lambda: compiled.append(1))
    ahead.compile_late_kernels(False)
    assert compiled == []
    monkeypatch.setattr(ahead, "disk_cached", lambda kernel: kernel in ahead.FIT_KERNELS)
    assert ahead.compile_ahead(loop=True).child is None


def test_an_analysis_ending_early_stops_the_child(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ahead, "disk_cached", lambda kernel: False)
    sleeper = [sys.executable, "-c", "import time; time.sleep(60)"]
    monkeypatch.setattr(ahead, "child_command", lambda loop, taken=None: sleeper)
    with pytest.raises(imupipe.ImupipeError), ahead.compile_ahead(loop=True) as started:
        child = started.child
        raise imupipe.ImupipeError("bad input")
    assert child.poll() is not None  # killed, not left running


def noting_child(monkeypatch: pytest.MonkeyPatch, after_s: float = 1.0) -> list[int]:
    """A cold cache and a child that exits, after ``after_s``, 0 if it finds the note and 5 if
    not; returns the list a call of ``compile_loop_kernels`` here appends to."""
    monkeypatch.setattr(ahead, "disk_cached", lambda kernel: False)
    reads = (
        f"import sys, time, pathlib; time.sleep({after_s}); "
        "sys.exit(0 if pathlib.Path({!r}).exists() else 5)"
    )
    monkeypatch.setattr(
        ahead, "child_command", lambda loop, taken: [sys.executable, "-c", reads.format(str(taken))]
    )
    compiled: list[int] = []
    monkeypatch.setattr(ahead, "compile_loop_kernels", lambda: compiled.append(1))
    return compiled


def test_a_wait_that_finds_the_child_compiling_takes_the_loops_kernels(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The child still runs: the waiting process leaves the note, compiles the loop's kernels
    itself and then waits; the child, reading the note, leaves them (exit 0 here only if it
    saw the note); the note is removed."""
    compiled = noting_child(monkeypatch)
    with ahead.compile_ahead(loop=True) as started:
        child, note = started.child, started.taken
        assert not note.exists()
        started.wait()
    assert child.returncode == 0 and compiled == [1]
    assert not note.exists() and started.taken is None


@pytest.mark.parametrize("case", ["spilled", "no_note"])
def test_a_wait_that_cannot_or_must_not_take_the_loops_kernels_leaves_them_to_the_child(
    case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The spilled path's wait (its own child compiles every kernel next, and this process
    should not hold LLVM's memory), or a note that cannot be written (a read-only temporary
    folder): nothing compiled here, the child not noted (it exits 5 here)."""
    compiled = noting_child(monkeypatch)
    with ahead.compile_ahead(loop=True) as started:
        child = started.child
        if case == "no_note":
            started.taken = tmp_path / "missing-folder" / "note"
        started.wait(take_loop=case != "spilled")
    assert child.returncode == 5 and compiled == []


def test_the_spilled_analysis_leaves_the_loops_kernels_to_its_compiling_child(
    tmp_path: Path, small_recordings, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A recording over the memory budget (the spilled column source) whose wait finds the
    child still compiling: the loop's kernels are left to the child, not compiled in the
    process that holds the data (the unit case above, through :func:`imupipe.analyze`)."""
    compiled = noting_child(monkeypatch, after_s=3.0)  # still compiling when waited for
    path = small_recordings.make("adis", tmp_path / "in.mcap")
    budget = 2 * AXIS_BYTES_PER_SAMPLE * small_recordings.frames  # 1.9 MB: spilled
    report, _ = small_recordings.run(path, tmp_path / "out", budget, workers=1)
    assert any(w.startswith("low-memory path") for w in report["input"]["warnings"])
    assert compiled == []


def test_a_wait_after_the_child_ended_compiles_nothing_here(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A long record reaches the wait after the child has compiled everything: nothing to do."""
    monkeypatch.setattr(ahead, "disk_cached", lambda kernel: False)
    monkeypatch.setattr(ahead, "child_command", lambda loop, taken: [sys.executable, "-c", ""])
    compiled: list[int] = []
    monkeypatch.setattr(ahead, "compile_loop_kernels", lambda: compiled.append(1))
    with ahead.compile_ahead(loop=True) as started:
        started.child.wait()
        started.wait()
    assert compiled == []
    with ahead.compile_ahead(loop=False) as started:  # no loop: no note, nothing taken
        assert started.taken is None
        started.wait()
    assert compiled == []


@pytest.mark.parametrize("noted", [True, False])
def test_the_child_leaves_the_loops_kernels_when_noted(
    noted: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    compiled: list[int] = []
    monkeypatch.setattr(ahead, "compile_loop_kernels", lambda: compiled.append(1))
    note = tmp_path / "taken"
    if noted:
        note.touch()
    ahead.compile_late_kernels(True, str(note))
    assert compiled == ([] if noted else [1])
    ahead.compile_late_kernels(False, None)
    assert compiled == ([] if noted else [1])


def test_the_child_is_told_where_the_note_would_be(tmp_path: Path) -> None:
    note = tmp_path / "it's a note"
    assert ahead.child_command(True, note)[-1].endswith(
        f"compile_late_kernels(True, {str(note)!r})"
    )
    assert ahead.child_command(False)[-1].endswith("compile_late_kernels(False, None)")
    assert ahead.child_command(True)[-1].endswith("compile_late_kernels(True, None)")


COMPLETE = r"""
import json, sys
import numpy as np
from numba.core.registry import CPUDispatcher
import imupipe
from imupipe.analysis.analyze import compile_kernels, decoding_kernel

def signatures():  # the decoders' kernels run before: compile_kernels is for the stages after
    return {
        f"{d.py_func.__module__}.{d.py_func.__qualname__}": sorted(map(str, d.signatures))
        for m in list(sys.modules.values()) if m.__name__.startswith("imupipe")
        for d in vars(m).values() if isinstance(d, CPUDispatcher) and not decoding_kernel(d)
    }

compile_kernels()
before = signatures()
imupipe.analyze(sys.argv[1], out=sys.argv[2], rrd=False, figures=False)
after = signatures()
print(json.dumps({k: v for k, v in after.items() if v != before.get(k, [])}))
"""


def test_compile_kernels_leaves_nothing_for_a_long_gapped_analysis_to_compile(
    tmp_path: Path, imu_mcap
) -> None:
    """What the low-memory path and the benchmarks load before analysing
    (:func:`imupipe.analysis.analyze.compile_kernels`) is every kernel, with every type, that
    an analysis calls from Python: here of 6 min at 1 kHz (the noise identification's window of
    averages, the long-record statistics) with a masked gap (the gap-tolerant sums)."""
    n = 360_000
    rng = np.random.default_rng(3)
    stamps = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 1_000_000
    keep = np.ones(n, dtype=bool)
    keep[200_000:200_050] = False
    sizes = [int(keep[a : a + (1 << 16)].sum()) for a in range(0, n, 1 << 16)]  # a chunk each
    gyro, accel = [], []
    for size in sizes:  # drawn chunk by chunk
        gyro.append(rng.normal(0, 1e-3, (size, 3)))
        accel.append(rng.normal(0, 1e-2, (size, 3)) + np.array([0.0, 0.0, 9.81]))
    imu = (stamps[keep], np.concatenate(gyro), np.concatenate(accel))
    path = imu_mcap(tmp_path / "f.mcap", {"/imu": imu}, chunk=sizes)
    done = subprocess.run(
        [sys.executable, "-c", COMPLETE, str(path), str(tmp_path / "out")],
        capture_output=True, text=True, timeout=900, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.splitlines()[-1]) == {}
