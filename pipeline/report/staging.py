"""The output folder of ``imupipe analyze``, replaced all at once or not at all.

An analysis writes into a fresh temporary folder beside ``--out`` (same file system) and only
when every file is written is that folder put in place of ``--out``, by an atomic exchange
(Linux ``renameat2(RENAME_EXCHANGE)``; elsewhere two renames).  Interrupted by SIGINT, SIGTERM
or SIGKILL, a run therefore leaves either the previous complete output or the new complete one,
never a mix of the two, and never a file this run did not produce (a ``--no-rrd`` rerun leaves
no old ``recording.rrd`` behind).  After SIGKILL, the unfinished temporary folder
(``.NAME.partial-…``) stays beside ``--out``; the next run into the same ``--out`` removes it.

``--out`` is refused (one line, exit 2) when it is an existing file, a dangling link, a folder
holding anything an analysis does not write (it would be replaced), or in a folder that
cannot be created or written.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import glob
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from imupipe import stopping
from imupipe.errors import OutputError

OUTPUT_SUFFIXES = frozenset({".json", ".md", ".png", ".parquet", ".yaml", ".rrd"})
"""Suffixes of the files an analysis writes; a folder holding only such files (with a
report.json), or nothing, may be replaced by a new analysis."""
_PARTIAL = ".partial-"
_RENAME_EXCHANGE = 2  # linux/fs.h
_AT_FDCWD = -100


def _is_previous_output(folder: Path) -> bool:
    """Whether ``folder`` is empty or holds only what an earlier analysis wrote."""
    entries = list(folder.iterdir())
    if not entries:
        return True
    return (folder / "report.json").is_file() and all(
        e.is_file() and not e.is_symlink() and e.suffix in OUTPUT_SUFFIXES for e in entries
    )


def check_out(out: Path) -> None:
    """Refuse an ``--out`` that an analysis must not replace (see the module docstring).

    Raises:
        OutputError: stated in one line.
    """
    if out.is_symlink() and not out.exists():
        raise OutputError(f"--out {out} is a dangling symbolic link")
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} exists and is not a folder")
    if out.is_dir() and not _is_previous_output(out):
        raise OutputError(
            f"--out {out} holds files an analysis does not write; "
            "choose a new or empty folder (it would be replaced)"
        )
    parent = out.absolute().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"--out {out}: cannot create {parent} ({exc.strerror})") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"--out {out}: cannot write in {parent}")


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux renameat2); False where that is not supported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    rc = renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _remove_stale(out: Path) -> None:
    """Remove the unfinished folders of earlier runs into ``out`` whose process is gone."""
    for folder in out.absolute().parent.glob(f".{glob.escape(out.name)}{_PARTIAL}*"):
        pid = folder.name.rsplit("-", 2)[-2]
        alive = pid.isdigit() and Path(f"/proc/{pid}").exists() and int(pid) != os.getpid()
        if not alive:
            shutil.rmtree(folder, ignore_errors=True)


def _put_in_place(new: Path, out: Path) -> None:
    """Make the finished folder ``new`` the output ``out``; the old output is removed."""
    if not out.exists():
        new.rename(out)
        return
    if _exchange(new, out):
        shutil.rmtree(new)  # now the old output
        return
    old = new.with_name(new.name + "-old")
    out.rename(old)
    new.rename(out)
    shutil.rmtree(old)


@contextlib.contextmanager
def staged_output(out: Path) -> Iterator[Path]:
    """A fresh folder to write an analysis into; it replaces ``out`` when the block ends
    without an exception and is removed when it raises (also on KeyboardInterrupt).

    Raises:
        OutputError: ``out`` cannot receive an analysis (:func:`check_out`).
    """
    out = Path(out)
    check_out(out)
    _remove_stale(out)
    try:
        prefix = f".{out.name}{_PARTIAL}{os.getpid()}-"
        tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=out.absolute().parent))
    except OSError as exc:
        raise OutputError(f"--out {out}: cannot write beside it ({exc.strerror})") from None
    try:
        yield tmp
        stopping.raise_if_requested()  # a stop whose exception was lost
        tmp.chmod(0o777 & ~_umask())
        _put_in_place(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
