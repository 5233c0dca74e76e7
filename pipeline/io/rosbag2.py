"""Which files hold a recording, and how to open each: an MCAP file or an SQLite database given
alone, or a rosbag2 directory (``metadata.yaml`` and its split files, MCAP or ``.db3``), with
rosbag2's own compression undone.

rosbag2 compresses in one of two modes (``metadata.yaml``: ``compression_mode``,
``compression_format``, rosbag2_compression): ``file`` compresses each split file whole
(``bag_0.db3.zstd``), which is decompressed here into a temporary file while it is read;
``message`` compresses each message's payload inside the storage, which the SQLite scan undoes
message by message (:class:`imupipe.io.db3_scan.Db3Scanner`).  MCAP files compressed per message
are refused with one line: the MCAP scan reads payloads inside chunks as they lie.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import zstandard

from imupipe.errors import InputError
from imupipe.io.db3_scan import Db3Scanner, is_db3
from imupipe.io.mcap_scan import McapScanner

STORAGE_SUFFIXES = (".mcap", ".db3")
"""The storage files of a rosbag2 directory: MCAP, or rosbag2's SQLite storage."""
COMPRESSED_SUFFIX = ".zstd"
"""A split file that rosbag2 compressed whole (``compression_mode: file``)."""
FREE_DISK_SHARE = 0.5
"""A whole-file-compressed split file may inflate to at most this share of the free space of
the temporary directory (a bomb stops there, with one line)."""


def _natural_key(file: Path) -> list[str | int]:
    """Sort key reading the digit runs of a name as numbers: bag_2 before bag_10."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", file.name)]


def _listed_files(meta: Path) -> list[str]:
    """The ``relative_file_paths`` entries of a rosbag2 ``metadata.yaml``, as written."""
    listed: list[str] = []
    in_list = False
    for line in meta.read_text(errors="replace").splitlines():
        stripped = line.strip()
        if stripped.startswith("relative_file_paths:"):
            in_list = True
        elif in_list and stripped.startswith("- "):
            listed.append(stripped[2:].strip().strip("'\""))
        elif in_list and stripped:
            in_list = False
    return listed


def message_compression(path: Path) -> str:
    """rosbag2's per-message compression of the recording at ``path`` from its
    ``metadata.yaml``: "zstd" where ``compression_mode`` is ``message``, else "" (a file given
    alone, a directory without the file, no compression, or whole files compressed: those are
    told by their ``.zstd`` suffix).

    Raises:
        InputError: a compression other than zstd (the only one rosbag2 ships).
    """
    meta = Path(path) / "metadata.yaml"
    found = {"compression_mode": "", "compression_format": ""}
    if meta.is_file():
        for line in meta.read_text(errors="replace").splitlines():
            key, _, value = line.strip().partition(":")
            if key in found:
                found[key] = value.strip().strip("'\"").lower()
    mode, fmt = found["compression_mode"], found["compression_format"]
    if mode in ("", "none"):
        return ""
    if fmt != "zstd":
        raise InputError(f"{meta}: compressed with {fmt!r}; imupipe reads zstd (rosbag2's own)")
    return fmt if mode == "message" else ""


def bag_files(path: Path) -> tuple[list[Path], list[str]]:
    """The storage files of a recording and warnings about them: the file itself, or a rosbag2
    directory's split files (MCAP or SQLite ``.db3``, each perhaps compressed whole:
    ``.zstd``).

    A rosbag2 directory lists its files in ``metadata.yaml`` (``relative_file_paths``) in
    recording order; a listed file that is missing is warned about.  Without the list (a killed
    recorder leaves none), the directory's ``*.mcap`` files, else its ``*.db3`` files (else
    the same compressed), are taken in natural name order (bag_2 before bag_10).

    Raises:
        InputError: not a file, empty, a directory without MCAP or .db3 files, a listed path
            that leaves the directory (absolute or with ``..``), or a split file that is not a
            regular file (a FIFO, a folder, a dangling link).
    """
    if path.is_file():
        if path.stat().st_size == 0:
            raise InputError(f"{path}: empty file")
        return [path], []
    if not path.is_dir():
        raise InputError(f"{path}: not a file")
    suffixes = (*STORAGE_SUFFIXES, *(s + COMPRESSED_SUFFIX for s in STORAGE_SUFFIXES))
    warnings: list[str] = []
    files: list[Path] = []
    meta = path / "metadata.yaml"
    if meta.is_file():
        for entry in _listed_files(meta):
            if Path(entry).is_absolute() or ".." in Path(entry).parts:
                raise InputError(
                    f"{meta}: lists {entry!r}, outside the bag directory; refusing to read it"
                )
            if not entry.endswith(suffixes):
                continue
            if os.path.lexists(path / entry):
                files.append(path / entry)
            else:
                warnings.append(f"{meta.name} lists {entry}, which is missing")
    for suffix in suffixes:
        files = files or sorted(path.glob(f"*{suffix}"), key=_natural_key)
    if not files:
        raise InputError(f"{path}: a directory without MCAP or .db3 files")
    for file in files:
        if not file.is_file():
            raise InputError(f"{file}: not a regular file (a FIFO, a folder or a broken link?)")
    return files, warnings


def storage_files(path: Path) -> list[Path]:
    """The storage files of a recording (:func:`bag_files` without its warnings)."""
    return bag_files(path)[0]


@contextlib.contextmanager
def _inflated(file: Path) -> Iterator[Path]:
    """``file`` itself, or for a whole-file-compressed one (``.zstd``) a temporary copy
    inflated (in the system's temporary directory; removed afterwards).

    Raises:
        InputError: it does not decompress, or would inflate beyond :data:`FREE_DISK_SHARE`
            of the free space of the temporary directory.
    """
    if not file.name.endswith(COMPRESSED_SUFFIX):
        yield file
        return
    with tempfile.TemporaryDirectory(prefix="imupipe-inflated-") as tmp:
        target = Path(tmp) / file.name[: -len(COMPRESSED_SUFFIX)]
        room = int(FREE_DISK_SHARE * shutil.disk_usage(tmp).free)
        try:
            with open(file, "rb") as src, open(target, "wb") as dst:
                reader = zstandard.ZstdDecompressor().stream_reader(src)
                while block := reader.read(1 << 24):
                    room -= len(block)
                    if room < 0:
                        raise InputError(
                            f"{file}: inflates beyond {FREE_DISK_SHARE:.0%} of the free space "
                            f"of {Path(tmp).parent}; refusing (a decompression bomb?)"
                        )
                    dst.write(block)
        except zstandard.ZstdError as exc:
            raise InputError(f"{file}: cannot decompress it (zstd: {exc})") from exc
        yield target


@contextlib.contextmanager
def opened(
    file: Path, message_compression: str = "", **options: Any
) -> Iterator[McapScanner | Db3Scanner]:
    """The scanner of one storage file (``options``: theirs, ``wanted``, ``progress``,
    ``max_chunk_bytes``): :class:`imupipe.io.db3_scan.Db3Scanner` for an SQLite database
    (told by its header, not its name), else :class:`imupipe.io.mcap_scan.McapScanner`; a
    whole-file-compressed file inflated while it is read (:func:`_inflated`).
    ``message_compression``: rosbag2's per-message compression ("zstd"), undone by the SQLite
    scan.

    Raises:
        InputError: per-message compression in an MCAP file; as :func:`_inflated`.
    """
    with _inflated(file) as plain:
        if is_db3(plain):
            yield Db3Scanner(plain, message_compression=message_compression, **options)
        elif message_compression:
            raise InputError(
                f"{file}: MCAP compressed message by message (rosbag2 compression_mode: "
                "message) is not read; convert the bag without it (ros2 bag convert)"
            )
        else:
            yield McapScanner(plain, **options)
