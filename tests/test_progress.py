"""The progress bars (:class:`imupipe.progress.StageProgress`): shown on stderr when it is a
terminal, never on stdout, and not at all with ``--quiet`` or when stderr is a pipe or a file
(a log then holds no bar redraws).  Each case runs in a child process whose stderr is a real
pseudo-terminal (or a pipe), as a user's shell gives it."""

from __future__ import annotations

import os
import pty
import re
import subprocess
import sys

import pytest

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")  # colours, cursor moves
# one stage of 10 bytes, advanced to 4 and left: the bar ends full (10/10)
SCRIPT = """
import sys
from imupipe.progress import StageProgress
bars = StageProgress() if sys.argv[1] == "default" else StageProgress(quiet=sys.argv[1] == "quiet")
with bars, bars.stage("decode", 10, "bytes") as advance:
    advance(4)
print("done")
"""


def _run(mode: str, terminal: bool) -> tuple[str, str]:
    """(stdout, stderr) of the script, its stderr a pseudo-terminal when ``terminal``."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("FORCE_COLOR", "NO_COLOR", "TTY_COMPATIBLE")
    }
    env |= {"TERM": "xterm", "COLUMNS": "100"}
    if not terminal:
        done = subprocess.run(
            [sys.executable, "-c", SCRIPT, mode],
            capture_output=True,
            text=True,
            env=env,
            timeout=60,
        )
        return done.stdout, done.stderr
    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, mode],
        stdout=subprocess.PIPE,
        stderr=slave,
        text=True,
        env=env,
    )
    os.close(slave)
    err = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        err += chunk
    os.close(master)
    out = proc.stdout.read()
    proc.wait(timeout=60)
    return out, err.decode()


@pytest.mark.parametrize("mode", ["default", "not quiet"])
def test_a_terminal_shows_the_stage_its_count_and_unit_on_stderr_only(
    mode: str,
) -> None:
    """Without ``--quiet`` (``StageProgress()``'s default too) a terminal gets the bar on stderr:
    the stage's name and ``done/total unit``, full when the stage ends; stdout holds only the
    command's own output, so ``imupipe ... > file`` is not mixed with bar redraws."""
    out, err = _run(mode, terminal=True)
    assert out == "done\n"
    drawn = [x for x in re.split(r"[\r\n]+", ANSI.sub("", err)) if x.strip()]
    assert re.fullmatch(r"decode +━+ 10/10 bytes \d:\d\d:\d\d \d:\d\d:\d\d", drawn[-1])


def test_quiet_shows_no_bar_even_on_a_terminal() -> None:
    out, err = _run("quiet", terminal=True)
    assert (out, err) == ("done\n", "")


def test_stderr_that_is_no_terminal_gets_no_bar() -> None:
    """stderr into a pipe or a log file (CI, ``2> log``): no bar, even without ``--quiet``."""
    assert _run("not quiet", terminal=False) == ("done\n", "")
