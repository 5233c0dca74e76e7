"""The Dask cluster a fleet runs on: an embedded ``LocalCluster`` started and stopped around the
run, or an existing scheduler (``--scheduler`` / ``DASK_SCHEDULER_ADDRESS``) such as one that
dask-jobqueue (SLURM, PBS...) or dask-kubernetes started."""

from __future__ import annotations

import contextlib
import gc
import logging
import multiprocessing
from collections.abc import Iterator

import dask.config
from dask.system import CPU_COUNT
from distributed import Client, LocalCluster

from imupipe.errors import FleetError

CONNECT_TIMEOUT_S = 10.0
"""How long to try reaching an existing scheduler before giving up (s)."""

WORKER_CONFIG = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}
"""Dask settings of the embedded cluster (its scheduler and workers): glibc's own malloc trim
threshold (Dask sets 64 KiB, so each analysis' large temporaries are returned to the OS and
faulted in again) and no statistical profiler sampling the task's stack every 10 ms: measured
on 1 h / 100 Hz units, one worker, 5.0 s per unit with Dask's defaults, 3.6 s with these two.
The event loops' health check every 1 s instead of 20 ms and the host's CPU and memory read
every 2 s instead of 0.5 s: with two workers on two cores these callbacks run on the cores the
analyses need (12 units on 2 workers, four rounds alternated: 20.4–21.4 s against 21.2–22.2 s,
with work stealing off as well; stealing on or off alone, three rounds each, made no difference,
and it stays on: it is what moves a long recording queued behind another to an idle worker).
A user's own cluster keeps its deployment's settings (docs/fleets.md says which to set)."""

SINGLE_THREAD_ENV = {"NUMBA_NUM_THREADS": "1", "POLARS_MAX_THREADS": "1"}
"""Set in every embedded worker process (Dask's nanny already sets OMP/MKL/OpenBLAS to one
thread): the Allan and EDF kernels run on up to ``NUMBA_NUM_THREADS`` threads
(:func:`imupipe.jit.cores_here`) and polars has its own pool, so an unpinned worker takes
~1.2 cores and two of them oversubscribe two cores.  One single-threaded
worker per core is the fleet's unit of parallelism."""


def scheduler_address(scheduler: str | None) -> str | None:
    """``scheduler``, else Dask's ``scheduler-address`` setting (``DASK_SCHEDULER_ADDRESS``)."""
    return scheduler or dask.config.get("scheduler-address", None)


@contextlib.contextmanager
def fleet_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Client]:
    """A Dask client for the fleet.

    Without an address: a ``LocalCluster`` of ``workers`` processes (default one per core the
    process may use: ``dask.system.CPU_COUNT`` honours CPU affinity and cgroup quotas), one
    thread each and its numba and polars pools pinned to one thread (``SINGLE_THREAD_ENV``),
    every server bound to 127.0.0.1 (the scheduler's HTTP routes on a free port rather
    than 8787), stopped on exit.  With an address: a client of that
    scheduler; ``workers`` then means "wait until that many workers have joined".

    Raises:
        FleetError: the scheduler cannot be reached, or ``workers`` did not join in time.
    """
    if workers is not None and workers < 1:
        raise FleetError(f"--workers must be at least 1, not {workers}")
    address = scheduler_address(scheduler)
    if address is None:
        n = workers or CPU_COUNT
        with (
            _started(n) as cluster,
            Client(cluster) as client,
        ):
            yield client
            _freeze_worker_heaps(client)
        return
    try:
        client = Client(address, timeout=f"{CONNECT_TIMEOUT_S}s")
    except (OSError, TimeoutError) as exc:
        raise FleetError(f"cannot reach the Dask scheduler at {address}: {exc}") from exc
    with client:
        if workers is not None:
            try:
                client.wait_for_workers(workers, timeout=f"{CONNECT_TIMEOUT_S * 6}s")
            except TimeoutError as exc:
                raise FleetError(
                    f"{address}: fewer than {workers} workers joined within "
                    f"{CONNECT_TIMEOUT_S * 6:.0f} s"
                ) from exc
        yield client


def _freeze_worker_heaps(client: Client) -> None:
    """Freeze the embedded workers' heaps (``gc.freeze``) before they are stopped.

    A worker process that has run analyses spends its exit in the interpreter's finalization,
    whose garbage collections traverse every object numba, polars, scipy, matplotlib and rerun
    left on its heap: measured after two units on two workers, the cluster took 0.74-1.03 s to
    close, 0.11-0.13 s with the heaps frozen (the objects are not collected at all, which at a
    process's exit costs nothing).  Only for the cluster this fleet started and is about to
    stop; a user's cluster outlives the fleet, and a frozen heap would never be collected."""
    with contextlib.suppress(Exception):  # a worker already gone: nothing to speed up
        client.run(gc.freeze)


@contextlib.contextmanager
def _started(n: int) -> Iterator[LocalCluster]:
    """The embedded ``LocalCluster`` of ``n`` single-threaded worker processes.

    Raises:
        FleetError: it did not start (Dask's start-up timeouts on an overloaded machine, a
            worker process that died starting), or this process is a worker being spawned and
            importing the caller's script (no ``if __name__ == "__main__":`` around the call).
    """
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        # a worker process being spawned runs the user's script again (as __mp_main__): a
        # cluster started there waits for workers of its own that can never start, and the
        # user's fleet waits for this one: both hung, silently (multiprocessing's own check,
        # spawn._check_not_importing_main, is the same)
        raise FleetError(
            "a fleet was started while a worker process was importing the calling script: "
            'call imupipe.analyze_fleet under `if __name__ == "__main__":`'
        )
    try:
        with dask.config.set(WORKER_CONFIG):  # read by the nannies as they spawn the workers
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address="127.0.0.1:0",
                # a worker's heartbeat racing the scheduler's shutdown logs an ERROR with a
                # traceback on the user's terminal; every unit's failure is in the fleet report
                silence_logs=logging.CRITICAL,
                env=SINGLE_THREAD_ENV,
            )
    except (TimeoutError, OSError, RuntimeError) as exc:  # RuntimeError: a worker died starting
        hint = (
            'from a script: is imupipe.analyze_fleet called under `if __name__ == "__main__":`?'
            if isinstance(exc, RuntimeError)
            else "is the machine overloaded? --workers fewer, or --scheduler an existing cluster"
        )
        raise FleetError(
            f"the local Dask cluster of {n} worker(s) did not start: "
            f"{str(exc) or type(exc).__name__} ({hint})"
        ) from exc
    with cluster:
        yield cluster
