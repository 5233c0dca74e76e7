"""Small pages for the analysis' large arrays.

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
"""

from __future__ import annotations

import contextlib
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
