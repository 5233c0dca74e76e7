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
"""

from __future__ import annotations

import sys

import numpy as np
import numpy.typing as npt
from numba.core.dispatcher import Dispatcher


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
