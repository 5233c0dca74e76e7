"""Which files a recording is (imupipe.io.rosbag2): metadata.yaml's list read as ROS 2 writes it,
rosbag2's compression settings, an empty file, and the bound on a whole-file inflation."""

from __future__ import annotations

from collections import namedtuple
from pathlib import Path

import pytest
import zstandard

from imupipe.errors import InputError
from imupipe.io import rosbag2


def test_metadata_lists_its_files_once_whatever_other_lists_it_holds(tmp_path: Path) -> None:
    """ROS 2's writer puts ``files:`` (``- path: …``) after ``relative_file_paths``; rosbags'
    writer before it: only the relative paths are the bag's files, with no warning."""
    bag = tmp_path / "bag"
    bag.mkdir()
    for name in ("b_0.mcap", "b_1.mcap"):
        (bag / name).write_bytes(b"x")
    (bag / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n"
        "  files:\n  - path: b_9.mcap\n    message_count: 1\n"
        "  relative_file_paths:\n  - b_0.mcap\n\n  - 'b_1.mcap'\n"  # a blank line: still the list
        "  files:\n    - path: b_8.mcap\n      message_count: 1\n"
    )
    assert rosbag2.bag_files(bag) == ([bag / "b_0.mcap", bag / "b_1.mcap"], [])
    assert rosbag2.storage_files(bag) == [bag / "b_0.mcap", bag / "b_1.mcap"]


def test_compression_other_than_zstd_is_one_clear_error(tmp_path: Path) -> None:
    (tmp_path / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  compression_format: lz4\n  compression_mode: message\n"
    )
    with pytest.raises(InputError, match="compressed with 'lz4'; imupipe reads zstd"):
        rosbag2.message_compression(tmp_path)


def test_an_empty_file_is_named_empty(tmp_path: Path) -> None:
    (tmp_path / "e.mcap").write_bytes(b"")
    with pytest.raises(InputError, match=r"e\.mcap: empty file"):
        rosbag2.bag_files(tmp_path / "e.mcap")
    (tmp_path / "one.mcap").write_bytes(b"x")  # a one-byte file is a file, not "empty"
    assert rosbag2.bag_files(tmp_path / "one.mcap") == ([tmp_path / "one.mcap"], [])


def test_a_whole_file_inflating_beyond_half_the_free_space_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    packed = tmp_path / "bag_0.mcap.zstd"
    packed.write_bytes(zstandard.ZstdCompressor().compress(b"\x00" * 600))
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(rosbag2.shutil, "disk_usage", lambda p: usage(10_000, 9_000, 1_000))
    with pytest.raises(InputError, match="inflates beyond 50% of the free space"):
        with rosbag2._inflated(packed):
            pass
    monkeypatch.setattr(rosbag2.shutil, "disk_usage", lambda p: usage(10_000, 8_000, 2_000))
    with rosbag2._inflated(packed) as plain:  # 600 bytes of a 1 000-byte half: inflated
        assert plain.name == "bag_0.mcap" and plain.read_bytes() == b"\x00" * 600
