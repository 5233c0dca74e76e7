"""imupipe.jit: kernel inputs of one type (read-only, C-contiguous), and reading numba's cache
state."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import threading
from pathlib import Path
from types import SimpleNamespace

import numba
import numpy as np
import pytest

from imupipe import jit
from imupipe.jit import disk_cached, kernel_input


def test_kernel_input_is_a_read_only_view_of_a_contiguous_array() -> None:
    x = np.arange(5.0)
    out = kernel_input(x)
    assert not out.flags.writeable and out.flags.c_contiguous
    assert np.shares_memory(out, x)  # no copy
    assert x.flags.writeable  # the caller's array is left writable
    x[0] = 7.0
    assert out[0] == 7.0


def test_kernel_input_copies_only_a_strided_or_other_dtype_array() -> None:
    x = np.arange(10.0)
    strided = kernel_input(x[::2])
    assert strided.flags.c_contiguous and not strided.flags.writeable
    assert strided.tolist() == [0.0, 2.0, 4.0, 6.0, 8.0]
    as_float = kernel_input(np.arange(3, dtype=np.int32), np.float64)
    assert as_float.dtype == np.float64 and as_float.tolist() == [0.0, 1.0, 2.0]
    already = np.arange(3.0)
    already.flags.writeable = False
    assert kernel_input(already) is already  # already read-only: returned as it is


def _kernel(index: object) -> SimpleNamespace:
    """A stand-in dispatcher whose disk cache index loads as ``index()``."""
    return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_load_index=index)))


def test_disk_cached_reads_the_index_numba_reads() -> None:
    assert disk_cached(_kernel(lambda: {("sig", "cpu"): "data-1"}))
    assert not disk_cached(_kernel(dict))  # empty or stale index: numba will compile


def test_disk_cached_unreadable_index_is_cold() -> None:
    def broken() -> dict:
        raise EOFError("truncated index")

    assert not disk_cached(_kernel(broken))


@pytest.mark.parametrize("kernel", [object(), SimpleNamespace(_cache=SimpleNamespace())])
def test_disk_cached_without_a_disk_cache_claims_nothing_to_do(kernel: object) -> None:
    """No disk cache to fill (or another numba's layout): nothing is compiled ahead."""
    assert disk_cached(kernel)


def test_imported_kernels_are_the_packages_own_compiled_kernels() -> None:
    import imupipe.model.effects as effects
    import imupipe.stats.robust as robust
    from imupipe.jit import imported_kernels

    kernels = imported_kernels()
    assert robust._histogram_parts in kernels and effects._hann_windowed in kernels
    assert (
        robust._value not in kernels and jit.part_bounds not in kernels
    )  # inlined into its callers: never compiled alone
    assert all(k.__module__.startswith("imupipe.") for k in kernels)
    assert len(kernels) == len(set(map(id, kernels)))  # a re-exported kernel counted once


def test_every_kernel_of_the_package_is_kept_in_numbas_disk_cache() -> None:
    """A kernel declared without ``cache=True`` is compiled again in every process that calls
    it (0.1-3 s each, every run, every fleet worker) and :func:`disk_cached` cannot tell: it
    claims that a kernel without a disk cache has nothing to compile ahead."""
    import importlib
    import pkgutil

    import imupipe
    from imupipe.jit import imported_kernels

    for module in pkgutil.walk_packages(imupipe.__path__, "imupipe."):
        if not module.name.endswith("__main__"):  # the command line itself
            importlib.import_module(module.name)
    kernels = imported_kernels()
    assert len(kernels) >= 30  # every stage's kernels were imported
    uncached = [
        f"{k.py_func.__module__}.{k.py_func.__qualname__}"
        for k in kernels
        if isinstance(k._cache, numba.core.caching.NullCache)
    ]
    assert uncached == []


@pytest.mark.parametrize("cached", [True, False])
def test_the_spilled_paths_compile_child_runs_only_on_a_cold_cache(
    cached: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    from imupipe.analysis import analyze as orchestrator

    children: list[list[str]] = []
    monkeypatch.setattr(orchestrator, "disk_cached", lambda kernel: cached)
    monkeypatch.setattr(orchestrator.subprocess, "run", lambda cmd, **kw: children.append(cmd))
    monkeypatch.setattr(orchestrator, "compile_kernels", lambda loop: None)
    orchestrator.load_kernels(True)
    assert len(children) == (0 if cached else 1)


def test_an_uncached_decoder_kernel_starts_no_compile_child(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A ROS 2 Imu bag never compiles the ADIS16364 burst decoder or the ADIS frame gather: with
    only those out of numba's cache, the spilled path starts no compile child (it started one on
    every 24 h run, ~2 s); with one analysis kernel out of it, it does."""
    import imupipe.device.adis16364 as adis
    import imupipe.io.mcap_walk as walk
    import imupipe.stats.allan as allan
    from imupipe.analysis import analyze as orchestrator

    decoders = [walk._gather, adis._decode_burst]
    assert all(orchestrator.decoding_kernel(k) for k in decoders)
    assert not orchestrator.decoding_kernel(allan._block_sums)
    for uncached, children_expected in [(decoders, 0), ([allan._block_sums], 1)]:
        children: list[list[str]] = []
        monkeypatch.setattr(orchestrator, "disk_cached", lambda k, out=uncached: k not in out)
        monkeypatch.setattr(
            orchestrator.subprocess, "run", lambda cmd, c=children, **kw: c.append(cmd)
        )
        monkeypatch.setattr(orchestrator, "compile_kernels", lambda loop: None)
        orchestrator.load_kernels(True)
        assert len(children) == children_expected


def test_cores_here_is_the_threads_share_capped_by_numba_num_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(jit, "usable_cores", lambda: 4)
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 8)
    seen: list[int] = []
    worker = threading.Thread(target=lambda: seen.append(jit.cores_here()))
    worker.start()
    worker.join()
    assert seen == [4]  # a thread without a share: every usable core
    shared = threading.Thread(target=lambda: (jit.set_cores_here(3), seen.append(jit.cores_here())))
    shared.start()
    shared.join()
    assert seen == [4, 3]

    def no_share() -> None:  # more axis workers than cores: usable_cores() // n is 0
        jit.set_cores_here(0)
        seen.append(jit.cores_here())

    starved = threading.Thread(target=no_share)
    starved.start()
    starved.join()
    assert seen == [4, 3, 1]
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 1)  # a fleet's one-core worker
    assert jit.cores_here() == 1


@pytest.mark.parametrize(("cores", "jobs", "threads"), [(3, 10, 3), (3, 2, 2), (1, 5, 1)])
def test_spread_runs_every_job_once_interleaved_over_the_cores(
    monkeypatch: pytest.MonkeyPatch, cores: int, jobs: int, threads: int
) -> None:
    monkeypatch.setattr(jit, "cores_here", lambda: cores)
    calls: list[tuple[int, int, str]] = []
    together = threading.Barrier(threads, timeout=10)  # all starts run at once

    def kernel(start: int, step: int) -> None:
        calls.append((start, step, threading.current_thread().name))
        together.wait()

    jit.spread(kernel, jobs)
    assert sorted(c[:2] for c in calls) == [(s, threads) for s in range(threads)]
    assert len({c[2] for c in calls}) == threads  # each start on its own thread
    (mine,) = [c for c in calls if c[0] == 0]
    assert mine[2] == threading.current_thread().name  # the caller works too


def test_spread_raises_a_threads_exception(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(jit, "cores_here", lambda: 2)

    def kernel(start: int, step: int) -> None:
        if start == 1:
            raise ValueError("job 1 failed")

    with pytest.raises(ValueError, match="job 1 failed"):
        jit.spread(kernel, 4)


def test_a_long_series_is_read_in_parts_of_at_least_part_min_values(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(jit, "cores_here", lambda: 4)
    assert jit.parts(jit.PART_MIN * 2 - 1) == 1
    assert jit.parts(jit.PART_MIN * 2) == 2
    assert jit.parts(jit.PART_MIN * 100) == 4
    assert jit.parts(0) == 1
    assert jit.PART_MIN == 1 << 20  # a million values a thread (a thread's start costs more)
    assert jit.parts(3 << 20) == 3


def test_spread_of_no_jobs_calls_the_kernel_once_on_the_caller() -> None:
    calls: list[tuple[int, int]] = []
    jit.spread(lambda start, step: calls.append((start, step)), 0)
    assert calls == [(0, 1)]  # its range of jobs is empty; no thread is started


def test_without_an_affinity_mask_the_cpu_count_or_one(monkeypatch: pytest.MonkeyPatch) -> None:
    """Not Linux: os.cpu_count(), which may not know (None): then one core."""
    monkeypatch.delattr(os, "sched_getaffinity")
    monkeypatch.setattr(os, "cpu_count", lambda: None)
    assert jit.usable_cores() == 1
    monkeypatch.setattr(os, "cpu_count", lambda: 6)
    assert jit.usable_cores() == 6


def test_kernels_of_modules_outside_the_package_are_not_the_packages(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A module named after ``imupipe`` in sort order (``zz_other``) with a kernel of its own is
    not scanned: only ``imupipe`` and its submodules are."""
    import types

    other = types.ModuleType("zz_other")
    other.kernel = numba.njit(lambda x: x + 1)
    other.kernel.__module__ = "zz_other"
    monkeypatch.setitem(sys.modules, "zz_other", other)
    assert all(k.__module__.startswith("imupipe") for k in jit.imported_kernels())


@pytest.mark.parametrize(("size", "n_parts"), [(10, 3), (7, 7), (1_000_003, 4)])
def test_part_bounds_cover_every_value_once_in_order(size: int, n_parts: int) -> None:
    bounds = [jit.part_bounds(size, n_parts, p) for p in range(n_parts)]
    assert bounds[0][0] == 0 and bounds[-1][1] == size
    assert all(a[1] == b[0] for a, b in itertools.pairwise(bounds))
    assert max(b - a for a, b in bounds) - min(b - a for a, b in bounds) <= 1


COLD_COMPILE = """
from imupipe.analysis.analyze import compile_kernels, decoding_kernel
from imupipe.jit import disk_cached, imported_kernels
compile_kernels(True)
print([
    f"{k.py_func.__module__}.{k.py_func.__qualname__}"
    for k in imported_kernels() if not decoding_kernel(k) and not disk_cached(k)
])
"""


def test_compile_kernels_leaves_no_analysis_kernel_out_of_the_cache(tmp_path: Path) -> None:
    """The spilled path's :func:`load_kernels` starts a compile child whenever an analysis
    kernel is out of numba's cache (2-6 s of a 24 h run): a kernel that ``compile_kernels``
    never reaches — one only a record with gaps calls, such as the masked whitener's
    ``effects._rectangle_sums`` — would start it on every later run."""
    done = subprocess.run(
        [sys.executable, "-c", COLD_COMPILE],
        env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)},
        capture_output=True, text=True, timeout=900, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.splitlines()[-1] == "[]"
