"""Which recordings a fleet holds: MCAP files, rosbag2 directories, folders or globs holding
them, and fsspec URLs (``s3://bucket/prefix/``, ``gcs://``, ``file://``...).

Listing happens on the machine that runs ``imupipe fleet``; the bytes are read later by the
worker that analyses the recording (:mod:`imupipe.fleet.task`).  Local paths go through
fsspec's local file system too, so one set of rules covers both:

- a file named on the command line (or matched by a glob) is a recording, whatever its
  extension (a file that is not MCAP then fails as that unit, with its one-line error);
- a directory holding ``metadata.yaml`` is a rosbag2 recording;
- any other directory is searched recursively for ``*.mcap`` files and rosbag2 directories.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import fsspec
from fsspec.implementations.local import LocalFileSystem

from imupipe.errors import FleetError

ROSBAG2_METADATA = "metadata.yaml"
_GLOB_CHARS = re.compile(r"[*?\[]")
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


@dataclass(frozen=True)
class Recording:
    """One unit of the fleet.

    ``name`` is its folder under the fleet's output (unique, file-system safe); ``location`` an
    absolute local path when ``local``, else the fsspec URL the worker downloads.
    """

    name: str
    location: str
    local: bool
    is_dir: bool


def _url_to_fs(spec: str) -> tuple[fsspec.AbstractFileSystem, str]:
    try:
        return fsspec.core.url_to_fs(spec)
    except (ImportError, ValueError) as exc:  # unknown protocol or its package missing
        raise FleetError(f"{spec}: {exc}") from exc


def _is_bag(fs: fsspec.AbstractFileSystem, path: str) -> bool:
    return fs.isfile(f"{path.rstrip('/')}/{ROSBAG2_METADATA}")


def _walk(fs: fsspec.AbstractFileSystem, root: str) -> list[tuple[str, bool]]:
    """(path, is_dir) of the recordings under a directory that is not itself a bag."""
    found: list[tuple[str, bool]] = []
    files = sorted(fs.find(root))
    bags = sorted({f.rsplit("/", 1)[0] for f in files if f.rsplit("/", 1)[-1] == ROSBAG2_METADATA})
    found += [(b, True) for b in bags]
    for f in files:
        inside_bag = any(f.startswith(b + "/") for b in bags)
        if f.endswith(".mcap") and not inside_bag:
            found.append((f, False))
    return found


def _expand(spec: str) -> list[tuple[fsspec.AbstractFileSystem, str, bool]]:
    """(fs, path, is_dir) of the recordings one command-line argument names."""
    fs, root = _url_to_fs(spec)
    paths = sorted(fs.glob(root)) if _GLOB_CHARS.search(root) else [root]
    out = []
    for path in paths:
        if not fs.exists(path):
            continue
        if not fs.isdir(path):
            out.append((fs, path, False))
        elif _is_bag(fs, path):
            out.append((fs, path, True))
        else:
            out += [(fs, p, d) for p, d in _walk(fs, path)]
    if not out:
        raise FleetError(f"{spec}: no recording there (no such path, or no MCAP file or bag)")
    return out


def _unit_name(path: str) -> str:
    base = path.rstrip("/").rsplit("/", 1)[-1]
    if base.endswith(".mcap"):
        base = base[: -len(".mcap")]
    return _UNSAFE.sub("_", base).lstrip(".") or "unit"


def unique_names(paths: Iterable[str]) -> list[str]:
    """A folder name per recording: its file or directory name without ``.mcap``, characters
    outside ``[A-Za-z0-9._-]`` replaced by ``_``; repeated names get ``-2``, ``-3``..."""
    names: list[str] = []
    for path in paths:
        base = name = _unit_name(path)
        k = 1
        while name in names:
            k += 1
            name = f"{base}-{k}"
        names.append(name)
    return names


def discover(specs: Sequence[str]) -> list[Recording]:
    """The recordings that ``specs`` (paths, globs, fsspec URLs) name, each once, in order.

    Raises:
        FleetError: an argument that names no recording, or an unknown URL protocol.
    """
    found: list[tuple[fsspec.AbstractFileSystem, str, bool]] = []
    seen: set[tuple[str, str]] = set()
    for spec in specs:
        for fs, path, is_dir in _expand(str(spec)):
            key = (fs.protocol if isinstance(fs.protocol, str) else fs.protocol[0], path)
            if key not in seen:
                seen.add(key)
                found.append((fs, path, is_dir))
    names = unique_names(path for _, path, _ in found)
    return [
        Recording(
            name=name,
            location=path if isinstance(fs, LocalFileSystem) else fs.unstrip_protocol(path),
            local=isinstance(fs, LocalFileSystem),
            is_dir=is_dir,
        )
        for name, (fs, path, is_dir) in zip(names, found, strict=True)
    ]
