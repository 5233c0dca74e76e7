"""Stops asked for by SIGINT, SIGTERM or SIGHUP, remembered as well as raised.

The command's signal handler raises :class:`Stopped` wherever the main thread is.  Python
swallows an exception raised inside a weak-reference callback or a ``__del__`` (it prints
"Exception ignored in …" and goes on), and a signal can arrive there, e.g. in importlib's
module-lock callback while a module is being imported: the stop would be lost and the run would
finish and replace the output.  So the handler also records the signal, and
:func:`raise_if_requested` raises it again at the point that must not be passed after a stop
(an analysis' output being put in place, :mod:`imupipe.report.staging`).
"""

from __future__ import annotations

import signal

_requested: int | None = None


class Stopped(BaseException):
    """SIGINT, SIGTERM or SIGHUP arrived: unwinds like Ctrl-C (a staged output is removed), but
    past typer, which turns a KeyboardInterrupt into a silent exit 130."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def request(signum: int, frame: object) -> None:
    """Signal handler: remember the stop, then raise it."""
    global _requested
    _requested = signum
    raise Stopped(signum)


def install(signals: tuple[int, ...]) -> dict[int, object]:
    """Forget any earlier stop (a command run in the same process) and make :func:`request` the
    handler of ``signals``; returns the previous handlers, for ``signal.signal`` to restore."""
    global _requested
    _requested = None
    return {s: signal.signal(s, request) for s in signals}


def raise_if_requested() -> None:
    """Raise :class:`Stopped` if a stop was asked for (also one whose exception was lost)."""
    if _requested is not None:
        raise Stopped(_requested)
