"""Small pages for the analysis' large arrays, and what glibc's malloc does with them once freed.

numpy asks the kernel for transparent huge pages (``madvise(MADV_HUGEPAGE)``) on every array of
4 MB or more (numpy's "madvise hugepage on Linux", numpy.org/doc/stable/reference/
global_state.html).  Where the kernel compacts memory on such a fault
(``/sys/kernel/mm/transparent_hugepage/defrag`` = ``madvise``, a common default) and free
memory is fragmented (a machine that has run for a while, its page cache full), each new
column stalls in the kernel: measured on a 2-core machine, one 35 MB float64 column took
0.25-0.44 s to fill with huge pages against 0.026 s with 4 KiB pages, and the whole analysis
of 12 h at 100 Hz spent 4.5 s in the kernel (12.5 s wall) against 1.3 s (8.5 s wall) with
small pages (``docs/performance.md``).  An analysis allocates dozens of such columns, each
once, so it never earns the huge pages' cheaper TLB back.

numpy reads ``NUMPY_MADVISE_HUGEPAGE`` only when it is imported; an analysis switches the
setting itself for its own duration (numpy's toggle, in ``numpy._core.multiarray`` since 2.0
and ``numpy.core.multiarray`` before) and restores it afterwards, so a program that imports
imupipe keeps numpy's behaviour everywhere else.

Freed arrays: glibc's malloc (``mallopt(3)``) maps each block of at least its mmap threshold
(dynamic, at most 32 MiB) on its own and unmaps it when freed, so every later array of that
size faults in and zeroes fresh pages again: the 12 h / 100 Hz analysis (4.32 M samples, 35 MB
per float64 column) took ~400,000 page faults and 1.0-1.3 s of kernel CPU.  The ``imupipe
analyze`` command, a process that analyses and ends, therefore has the C heap keep and reuse
them (:func:`reuse_freed_memory`).  A long-lived process does not: kept blocks fragment the
heap from one analysis to the next (12 analyses of 1 h in one process: RSS 0.53 → 1.17 GB,
against 0.45 → 0.62 GB with glibc's defaults; ``malloc_trim`` after each gave back less than
half of it), so the library itself never sets it.  A spilled analysis, sized to its memory
budget, has freed blocks returned at once (:func:`release_freed_memory`) wherever it runs.
These are the process' settings; glibc has no getter to restore them.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import threading
from collections.abc import Callable, Iterator


def _toggle() -> Callable[[bool], bool] | None:
    """numpy's ``_set_madvise_hugepage`` (returns the previous setting), or None where this
    numpy has none."""
    for module in ("numpy._core.multiarray", "numpy.core.multiarray"):
        with contextlib.suppress(ImportError):
            toggle = getattr(importlib.import_module(module), "_set_madvise_hugepage", None)
            if toggle is not None:
                return toggle
    return None


_lock = threading.Lock()
_active = 0  # analyses inside small_pages() (the setting is the process')
_saved = True  # numpy's setting before the first of them


@contextlib.contextmanager
def small_pages() -> Iterator[None]:
    """Within the block, numpy allocates its large arrays without asking for huge pages.

    The setting is the process': analyses running at the same time (threads) share one switch,
    set by the first to enter and restored by the last to leave."""
    global _active, _saved
    toggle = _toggle()
    if toggle is None:
        yield
        return
    with _lock:
        if _active == 0:
            _saved = toggle(False)
        _active += 1
    try:
        yield
    finally:
        with _lock:
            _active -= 1
            if _active == 0:
                toggle(_saved)


M_TRIM_THRESHOLD = -1
"""glibc ``mallopt`` parameter: free memory at the top of the heap beyond this is returned
to the system (malloc.h)."""
M_MMAP_THRESHOLD = -3
"""glibc ``mallopt`` parameter: allocations at least this large are mmapped (malloc.h)."""
REUSED_BLOCK_BYTES = 64 << 20
"""Largest block an in-memory analysis has the heap keep for reuse: a float64 column of
8.4 M samples (23 h at 100 Hz, 2.3 h at 1 kHz); larger ones are mapped and unmapped."""
KEPT_FREE_BYTES = 2 * REUSED_BLOCK_BYTES
"""Free memory the heap keeps at its top (two such blocks) instead of returning it; the
command keeps freed blocks only for a recording whose estimated peak leaves this much of the
memory budget (measured: the peak RSS grows by 30-70 MB)."""


def _mallopt(settings: dict[int, int], trim: bool = False) -> None:
    """glibc's ``mallopt`` of each (parameter, value), then ``malloc_trim(0)`` with ``trim``;
    nothing where the C library is not glibc."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        for parameter, value in settings.items():
            libc.mallopt(parameter, value)
        if trim:
            libc.malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def reuse_freed_memory() -> None:
    """Have freed blocks of up to :data:`REUSED_BLOCK_BYTES` reused from the C heap rather than
    unmapped (glibc only).

    Measured in fresh processes, the code before and after alternated, the same outputs to the
    byte: 12 h at 100 Hz, page faults 397,000-399,000 → 236,000-267,000 and kernel CPU
    1.01-1.20 → 0.65-0.85 s, peak RSS 1.02-1.03 → 1.02-1.05 GB."""
    _mallopt({M_MMAP_THRESHOLD: REUSED_BLOCK_BYTES, M_TRIM_THRESHOLD: KEPT_FREE_BYTES})


def release_freed_memory() -> None:
    """Make freed arrays leave the process (glibc only; elsewhere nothing is done).

    Per-chunk arrays (~0.5 MB) come from the C heap once glibc's dynamic mmap threshold has
    risen, and their free space stays resident (measured on 24 h / 1 kHz: a conditioning
    pass peaked at 3.5 GB with ~1.7 GB of live arrays).  A fixed 128 kB threshold mmaps them
    (returned on free), and ``malloc_trim`` hands back what the heap already holds."""
    _mallopt({M_MMAP_THRESHOLD: 128 * 1024, M_TRIM_THRESHOLD: 128 * 1024}, trim=True)
