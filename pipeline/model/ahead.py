"""The IEEE 952 fit's and the closed loop's numba kernels compiled ahead on a first run after
installing: the fit's in a child process, the loop's in this one while it waits for the child.

With an empty numba disk cache every kernel compiles on its first call (docs/performance.md,
"First run after installing").  The fit's and the loop's kernels (:data:`FIT_KERNELS`,
:data:`LOOP_KERNELS`) are first called only after the recording is decoded and the first
axis' Allan curve and outliers are computed.  When the fit's cache is cold, :func:`compile_ahead`
starts a child process that compiles them into numba's disk cache
(:func:`compile_late_kernels`, on synthetic inputs of the types the analysis passes) while
this process decodes and computes, compiling the earlier kernels itself; :meth:`Ahead.wait`,
before the first fit, waits for the child, and numba then loads the kernels from the cache.
The loop's kernels go to whichever process is free first: a short record reaches the wait
while the child still compiles the fit's chain (the 5-min sample: ~1.7 s early), and compiles
them there, meanwhile, after leaving a note that the child reads when its chain is done; a
long one arrives after the child, which has compiled them too.  A warm cache costs a look at
the kernels' cache indices and no child.  If the child fails (e.g. it cannot write the cache)
or takes longer than :data:`WAIT_S`, the kernels compile in this process on first use, as they
would without it.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import threading
import uuid
from pathlib import Path
from types import TracebackType

import numpy as np

from imupipe.jit import disk_cached
from imupipe.model import effects, ieee952
from imupipe.stats.allan import AllanCurve

FIT_KERNELS = (ieee952._fit_gamma, ieee952._nnls, ieee952._passive_lstsq)
"""The IEEE 952 fit's kernels (~7 s of CPU to compile, the longest chain)."""
LOOP_KERNELS = (effects._innovations, effects._hann_windowed)
"""Kernels first called by the closed loop: its whitener and its periodogram.  (The R(n) noise
identification, ``edf._mvar_over_avar``, is not one: the fit's Allan curve reaches T/2, whose
last factors the first Allan curve already identifies with it.)"""
WAIT_S = 300.0
"""Longest wait for the child before compiling in this process instead."""


def compile_late_kernels(loop: bool, taken: str | None = None) -> None:
    """Compile :data:`FIT_KERNELS` (and then :data:`LOOP_KERNELS` with ``loop``, unless the file
    ``taken`` exists by then: the analysing process compiles them itself) into numba's disk
    cache by calling them on synthetic inputs: a white-noise Allan curve and white noise."""
    tau = np.geomspace(0.01, 100.0, 41)
    adev = 1e-3 / np.sqrt(tau)
    n_terms = np.round(1e4 / tau).astype(np.int64)
    alpha = np.zeros(tau.size, np.int64)
    curve = AllanCurve(tau, adev, 0.9 * adev, 1.1 * adev, n_terms / 2.0, n_terms, alpha, 0.683)
    ieee952.fit_noise_terms(curve, "gyro", 0.01)
    if loop and not (taken and Path(taken).exists()):
        compile_loop_kernels()


def compile_loop_kernels() -> None:
    """Compile :data:`LOOP_KERNELS` (or load them from numba's disk cache): a whitener of white
    noise and its periodogram's line."""
    white = np.random.default_rng(0).standard_normal(4096)
    effects.Whitener(effects.NoisePsd(1.0, 0.0, np.inf, 0.0), white.size, 0.01)
    effects.psd_line(white, 0.01, 10.0, 20.0)


class Ahead:
    """The child compiling the late kernels (or none); a context manager that stops it if the
    analysis ends before :meth:`wait`.  ``taken``: the note a :meth:`wait` that finds the child
    still running leaves before compiling the loop's kernels itself (``None``: no loop)."""

    def __init__(self, child: subprocess.Popen | None, taken: Path | None = None) -> None:
        self.child = child
        self.taken = taken
        self._waiting = threading.Lock()

    def wait(self, take_loop: bool = True) -> None:
        """Wait for the child (at most :data:`WAIT_S`, then stop it), compiling the loop's
        kernels here meanwhile if it still runs (and ``take_loop``: not where another child
        compiles everything, the spilled path); idempotent, and safe to call from the threads
        that analyse the axes at once."""
        with self._waiting:
            if self.child is None:
                return
            if take_loop and self.taken is not None and self.child.poll() is None:
                try:
                    self.taken.touch()  # read by the child once the fit's chain is compiled
                except OSError:  # no note (a read-only temporary folder): the child takes them
                    pass
                else:
                    compile_loop_kernels()
            try:
                self.child.wait(WAIT_S)
            except subprocess.TimeoutExpired:
                self.child.kill()
                self.child.wait()
            self._forget()

    def _forget(self) -> None:
        self.child = None
        if self.taken is not None:
            self.taken.unlink(missing_ok=True)
            self.taken = None

    def __enter__(self) -> Ahead:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self.child is not None:
            self.child.kill()
            self.child.wait()
            self._forget()


def child_command(loop: bool, taken: Path | None = None) -> list[str]:
    """The child's command line: this Python running :func:`compile_late_kernels`."""
    code = (
        "from imupipe.model.ahead import compile_late_kernels; "
        f"compile_late_kernels({loop}, {None if taken is None else str(taken)!r})"
    )
    return [sys.executable, "-c", code]


def compile_ahead(loop: bool, enabled: bool = True) -> Ahead:
    """Start the child compiling the late kernels if ``enabled`` and any of the fit's is not in
    numba's disk cache; else an :class:`Ahead` without a child."""
    if not enabled or all(disk_cached(k) for k in FIT_KERNELS):
        return Ahead(None)
    taken = (
        Path(tempfile.gettempdir()) / f"imupipe-loop-kernels-{uuid.uuid4().hex}" if loop else None
    )
    try:
        child = subprocess.Popen(
            child_command(loop, taken),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except OSError:  # no process to spare: compile here, as without a child
        return Ahead(None)
    return Ahead(child, taken)
