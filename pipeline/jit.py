"""The numba kernels' argument types (one compiled specialisation per kernel) and whether
numba's disk cache holds them.

numba compiles a kernel once per distinct argument type, and an array's type includes whether
it is writable: a column polars hands out without copying is read-only, a computed array is
not, so the same kernel would compile twice on one analysis (each ~0.2-2 s of CPU on a first
run after installing, docs/performance.md).  Every kernel input array goes through
:func:`kernel_input` at the kernel's Python boundary instead.

Kernels copy arrays element by element rather than by slice assignment (``a[:k] = b``): the
first slice assignment a process compiles brings numba's shape-mismatch error message with
it, string formatting compiled for ~1-2 s of CPU.

No kernel is compiled ``parallel=True``: a ``prange`` kernel costs ~1.5 s more CPU to compile
than the same loop compiled serially (numba's parfor passes and gufunc), and it needs a
threading layer that takes launches from several threads at once (``workqueue`` aborts the
process).  A kernel whose jobs are independent takes ``(start, step)`` and handles the jobs
``start, start + step, ...``; :func:`spread` runs it on the cores the calling thread may use
(:func:`cores_here`), each thread its own ``start``, the GIL released.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
import numpy.typing as npt
from numba.core.dispatcher import Dispatcher

_share = threading.local()
"""The calling thread's share of the cores (:func:`set_cores_here`)."""


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity mask, else ``os.cpu_count()``)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def set_cores_here(cores: int) -> None:
    """Let kernels called from this thread use ``cores`` threads (the axis pool gives each of
    its n workers ``usable_cores() // n``)."""
    _share.cores = max(1, int(cores))


def cores_here() -> int:
    """Threads a kernel called from this thread may use: the share :func:`set_cores_here`
    gave it, else the usable cores; never more than ``NUMBA_NUM_THREADS`` (numba's setting,
    which a fleet's one-core Dask workers set to 1)."""
    share = getattr(_share, "cores", None)
    return max(1, min(usable_cores() if share is None else share, numba.config.NUMBA_NUM_THREADS))


def spread(kernel: Callable[[int, int], None], jobs: int) -> None:
    """Run ``kernel(start, step)`` for every ``start`` < ``step`` = min(:func:`cores_here`,
    ``jobs``), each on its own thread (the caller's among them), so that job j runs in thread
    j mod step: interleaved, so that jobs whose cost falls with j (short τ first) spread
    evenly.  The kernel releases the GIL (``nogil=True``) and writes its jobs' results into
    arrays it closes over; an exception in any thread is raised here."""
    step = max(1, min(cores_here(), jobs))
    if step == 1:
        kernel(0, 1)
        return
    with ThreadPoolExecutor(step - 1, thread_name_prefix="imupipe-kernel") as pool:
        others = [pool.submit(kernel, start, step) for start in range(1, step)]
        kernel(0, step)
        for done in others:
            done.result()


PART_MIN = 1 << 20
"""Values a thread of a pass over a long series reads at least: a shorter series is read by one
thread (a thread's start would cost more than its share)."""


def parts(size: int) -> int:
    """Contiguous parts of a pass over ``size`` values, one a thread (:func:`on_parts`): as
    many as :func:`cores_here`, fewer when a part would hold under :data:`PART_MIN` values."""
    return max(1, min(cores_here(), size // PART_MIN))


@numba.njit(cache=True, nogil=True, inline="always")
def part_bounds(size: int, parts: int, p: int) -> tuple[int, int]:
    """Values [start, stop) of part ``p`` of ``parts`` contiguous parts of ``size`` values."""
    return p * size // parts, (p + 1) * size // parts


def on_parts(kernel: Callable[..., None], parts: int, *args: object) -> None:
    """``kernel(*args, start, step)`` for the ``parts`` parts of a pass (:func:`spread`): the
    kernel handles parts ``start, start + step, …``, each bounded by :func:`part_bounds`."""
    spread(lambda start, step: kernel(*args, start, step), parts)


def kernel_input(x: npt.ArrayLike, dtype: npt.DTypeLike = None) -> np.ndarray:
    """``x`` as a C-contiguous, read-only array of ``dtype`` (default: its own): a read-only
    view when it already is one, copied only when it is not contiguous or of another dtype."""
    out = np.ascontiguousarray(x, dtype=dtype)
    if out.flags.writeable:
        out = out.view()
        out.flags.writeable = False
    return out


def disk_cached(kernel: object) -> bool:
    """Whether numba's disk cache holds a compiled version of ``kernel`` (a ``cache=True``
    dispatcher) for its current source: the cache index numba itself reads before compiling
    (stale after an edit of the kernel's file).  True when that cannot be told (no disk cache,
    another numba's layout): then nothing is done ahead and numba compiles as it always does."""
    index = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    load = getattr(index, "_load_index", None)
    if load is None:
        return True
    try:
        return bool(load())
    except Exception:  # an unreadable index: numba recompiles; so would we
        return False


def imported_kernels() -> list[Dispatcher]:
    """The numba kernels defined in every imupipe module imported so far that numba compiles
    on their own (not those inlined into their callers: ``inline="always"``)."""
    return [
        value
        for name, module in list(sys.modules.items())
        if name == "imupipe" or name.startswith("imupipe.")
        for value in vars(module).values()
        if isinstance(value, Dispatcher)
        and value.__module__ == name
        and value.targetoptions.get("inline") != "always"
    ]
