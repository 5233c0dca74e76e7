"""The axes of one analysis on several cores: a pool of threads, each analysing one axis.

The heavy parts of an axis release the GIL (numba kernels compiled ``nogil=True``, numpy's
array passes), so threads share the cores without copying the columns, and an exception in a
worker is the very exception object the serial path would raise.  Every worker runs the same
functions on the same inputs as the serial path, so the results are bit-identical; they are
collected in submission order (:data:`imupipe.vocab.AXES`).

While ``n`` axes run at once, each worker's kernels spread their jobs over ``cores // n``
threads (:func:`imupipe.jit.set_cores_here`), so the workers and the kernels' threads together
never ask for more than the usable cores.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

from imupipe.jit import set_cores_here, usable_cores

T = TypeVar("T")
R = TypeVar("R")


def axes_at_once(workers: int | None, axes: int, axis_bytes: int, spare_bytes: int) -> int:
    """How many axes to analyse at once: ``workers`` (default: the usable cores), no more than
    ``axes``, and no more than fit the memory: the first axis is in the estimate already, each
    further one needs ``axis_bytes`` of the ``spare_bytes`` left under the budget.  At least 1.
    """
    wanted = usable_cores() if workers is None else workers
    fit = 1 + max(spare_bytes, 0) // max(axis_bytes, 1)
    return max(1, min(wanted, axes, fit))


@contextlib.contextmanager
def axis_pool(n: int) -> Iterator[Callable[[Callable[[T], R], Iterable[T]], Iterator[R]]]:
    """A ``map(fn, items)`` that runs ``fn`` on ``n`` threads (in the caller's thread when
    ``n`` is 1) and yields the results in the items' order as they become available.

    A failing item re-raises its exception when its result is reached; the items not yet
    started are then cancelled and the running ones finished before the block is left (also
    on Ctrl-C), so no worker outlives the block."""
    if n <= 1:
        yield lambda fn, items: map(fn, items)
        return
    pool = ThreadPoolExecutor(
        n,
        thread_name_prefix="imupipe-axis",
        initializer=set_cores_here,
        initargs=(usable_cores() // n,),
    )

    def ordered(fn: Callable[[T], R], items: Iterable[T]) -> Iterator[R]:
        futures: list[Future[R]] = [pool.submit(fn, item) for item in items]
        for future in futures:
            yield future.result()

    try:
        yield ordered
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
