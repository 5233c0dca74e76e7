"""Which recordings a fleet holds: MCAP files, rosbag2 directories, folders or globs holding
them, and fsspec URLs (``s3://bucket/prefix/``, ``gcs://``, ``file://``...).

Listing happens on the machine that runs ``imupipe fleet``; the bytes are read later by the
worker that analyses the recording (:mod:`imupipe.fleet.task`).  Local paths go through
fsspec's local file system too, so one set of rules covers both:

- a file named on the command line (or matched by a glob) is a recording, whatever its
  extension (a file that is not MCAP then fails as that unit, with its one-line error);
- a directory holding ``metadata.yaml`` is a rosbag2 recording;
- any other directory is searched recursively for ``*.mcap`` and ``*.db3`` files (rosbag2's
  SQLite storage) and rosbag2 directories; on the local file system, symbolic links to
  directories inside it are followed (each real directory searched once).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import fsspec
from fsspec.implementations.local import LocalFileSystem

from imupipe.errors import FleetError
from imupipe.io.mcap_scan import CONVERT_ROS1
from imupipe.io.rosbag2 import STORAGE_SUFFIXES

ROSBAG2_METADATA = "metadata.yaml"
ROS1_SUFFIX = ".bag"
"""A ROS 1 bag's file name: not read, but named when a folder holds nothing else."""
_GLOB_CHARS = re.compile(r"[*?\[]")
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
MAX_NAME = 120
"""Longest unit name made of a recording's folders (a file name may have 255 bytes, and the
unit's folder is also staged as ``<name>-<32 hex digits>``)."""


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


def _walk(
    fs: fsspec.AbstractFileSystem, root: str, walked: set[str] | None = None
) -> list[tuple[str, bool]]:
    """(path, is_dir) of the recordings under a directory that is not itself a bag.

    On the local file system a symbolic link to a directory (which fsspec's ``find`` lists as
    a leaf) is followed like a directory: a linked bag is a recording, a linked folder is
    searched.  ``walked``: the real paths of the directories searched so far (a link back up
    the tree, or a second link to a searched folder, adds nothing)."""
    walked = set() if walked is None else walked
    local = isinstance(fs, LocalFileSystem)
    if local:
        walked.add(os.path.realpath(root))
    found: list[tuple[str, bool]] = []
    files = sorted(fs.find(root))
    linked = {f for f in files if local and os.path.isdir(f)}  # links to directories
    bags = sorted({f.rsplit("/", 1)[0] for f in files if f.rsplit("/", 1)[-1] == ROSBAG2_METADATA})
    found += [(b, True) for b in bags]
    for f in files:
        inside_bag = any(f.startswith(b + "/") for b in bags)
        if inside_bag:
            continue
        if f in linked:
            if os.path.realpath(f) not in walked:
                found += [(f, True)] if _is_bag(fs, f) else _walk(fs, f, walked)
        elif f.endswith(STORAGE_SUFFIXES):
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
        ros1 = [f for p in paths if fs.isdir(p) for f in fs.find(p) if f.endswith(ROS1_SUFFIX)]
        hint = f"; it holds {len(ros1)} ROS 1 bag(s): {CONVERT_ROS1}" if ros1 else ""
        raise FleetError(f"{spec}: no recording there (no such path, or no MCAP file or bag){hint}")
    return out


def _name_parts(path: str) -> list[str]:
    """The path's components, innermost first (the file or directory name without ``.mcap`` or
    ``.db3``, then its folders outwards), each made safe for a folder name: characters outside
    ``[A-Za-z0-9._-]`` replaced by ``_``, no leading dot; empty ones dropped."""
    parts = path.rstrip("/").split("/")[::-1]
    for suffix in STORAGE_SUFFIXES:
        parts[0] = parts[0].removesuffix(suffix)
    safe = [_UNSAFE.sub("_", part).lstrip(".") for part in parts]
    return [part for part in safe if part] or ["unit"]


def unique_names(paths: Iterable[str]) -> list[str]:
    """A folder name per recording: its file or directory name without ``.mcap``
    (:func:`_name_parts`).  Recordings whose names collide are told apart by as many of their
    folders as it takes — one calibration bag per robot, ``robot-7/calib.mcap`` and
    ``robot-8/calib.mcap``, gives ``robot-7_calib`` and ``robot-8_calib`` — and names still
    alike after that (a path named twice over two file systems, or recordings whose folders
    differ only where the name would grow longer than :data:`MAX_NAME`) keep their own name,
    numbered ``-2``, ``-3``...

    Linear in the recordings: numbering every repeat by scanning the names so far was cubic in
    them (1,000 bags named alike took 1.8 s; 10,000 would have taken about half an hour)."""
    parts = [_name_parts(path) for path in paths]
    depth = [1] * len(parts)

    def joined(i: int, d: int) -> str:
        return "_".join(parts[i][:d][::-1])

    while True:
        names = [joined(i, d) for i, d in enumerate(depth)]
        holders: dict[str, list[int]] = {}
        for i, name in enumerate(names):
            holders.setdefault(name, []).append(i)
        longer = [i for held in holders.values() if len(held) > 1 for i in held]
        longer = [
            i
            for i in longer
            if depth[i] < len(parts[i]) and len(joined(i, depth[i] + 1)) <= MAX_NAME
        ]
        if not longer:
            break
        for i in longer:
            depth[i] += 1
    for held in holders.values():  # folders did not tell these apart: their own names, numbered
        if len(held) > 1:
            for i in held:
                names[i] = parts[i][0]
    taken: set[str] = set()
    repeats: dict[str, int] = {}
    out = []
    for name in names:
        unique, k = name, repeats.get(name, 1)
        while unique in taken:
            k += 1
            unique = f"{name}-{k}"
        repeats[name] = k
        taken.add(unique)
        out.append(unique)
    return out


def discover(specs: Sequence[str]) -> list[Recording]:
    """The recordings that ``specs`` (paths, globs, fsspec URLs) name, each once (a local one
    reached through several links too), in order.

    Raises:
        FleetError: an argument that names no recording, or an unknown URL protocol.
    """
    found: list[tuple[fsspec.AbstractFileSystem, str, bool]] = []
    seen: set[tuple[str, str]] = set()
    for spec in specs:
        for fs, path, is_dir in _expand(str(spec)):
            protocol = fs.protocol if isinstance(fs.protocol, str) else fs.protocol[0]
            key = (protocol, os.path.realpath(path) if isinstance(fs, LocalFileSystem) else path)
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
