"""The ADIS16364 frame message: its ROS 2 definition and its CDR bytes, encoded in bulk.

The message (``imupipe_msgs/msg/Adis16364Frame``, text in ``schemas/imupipe_msgs/msg/``) is stored
in MCAP as a ``ros2msg`` schema with ``cdr`` message encoding, so any ROS 2 tool (rosbags,
mcap-ros2-support, Foxglove) decodes it without our code.  With a constant ``frame_id`` every
message has the same size, so a whole run of frames is one numpy structured array: encoding is a
single ``tobytes()`` and decoding a single ``frombuffer`` (no per-message Python).

CDR layout (OMG XCDR1, little endian; alignment counted from the end of the 4-byte encapsulation
header): ``stamp.sec`` i32 @0, ``stamp.nanosec`` u32 @4, ``frame_id`` u32 length (incl. NUL) @8 +
bytes, then ``frame_counter`` u32 aligned to 4, 12 × u16 words, ``diag_stat_valid`` u8.
"""

from __future__ import annotations

import importlib.resources
from importlib.resources.abc import Traversable

import numpy as np

from imupipe.device.adis16364 import FrameBlock

SCHEMA_NAME = "imupipe_msgs/msg/Adis16364Frame"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
PROFILE = "ros2"
DEFAULT_TOPIC = "/imu/adis16364/frame"
METADATA_NAME = "adis16364"
"""Name of the MCAP metadata record holding :class:`imupipe.device.adis16364.DeviceConfig`."""

CDR_LE_HEADER = b"\x00\x01\x00\x00"

_HEADER_DEFS = """
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""

TAIL_SIZE = 4 + 12 * 2 + 1
"""Bytes after the header: frame_counter, 11 burst words + DIAG_STAT, diag_stat_valid."""


def schema_file(name: str) -> Traversable:
    """A file of the repository's ``schemas/``, installed (editable or not) as the package
    ``imupipe.schemas`` (``imupipe`` itself is only importable once installed)."""
    return importlib.resources.files("imupipe.schemas").joinpath(name)


def message_definition() -> str:
    """The ``ros2msg`` schema text: our ``.msg`` followed by the definitions it depends on."""
    msg = schema_file("imupipe_msgs/msg/Adis16364Frame.msg")
    return msg.read_text(encoding="utf-8").rstrip("\n") + "\n" + _HEADER_DEFS


def _align(offset: int, n: int) -> int:
    return (offset + n - 1) // n * n


def frame_dtype(frame_id: str) -> np.dtype:
    """Structured dtype of one whole CDR payload (encapsulation header included)."""
    fid = len(frame_id.encode()) + 1
    tail = 4 + _align(12 + fid, 4)  # payload offset of frame_counter
    return np.dtype(
        {
            "names": ["encap", "sec", "nanosec", "fid_len", "frame_counter", "words", "valid"],
            "formats": ["<u4", "<i4", "<u4", "<u4", "<u4", ("<u2", 12), "u1"],
            "offsets": [0, 4, 8, 12, tail, tail + 4, tail + 28],
            "itemsize": tail + TAIL_SIZE,
        }
    )


def encode_frames(block: FrameBlock, frame_id: str) -> np.ndarray:
    """Encode a :class:`FrameBlock` as an ``(n, size)`` uint8 array, one CDR payload per row."""
    dtype = frame_dtype(frame_id)
    fid = frame_id.encode() + b"\x00"
    rec = np.zeros(len(block), dtype=dtype)
    rec["encap"] = np.frombuffer(CDR_LE_HEADER, "<u4")[0]
    sec, nsec = np.divmod(block.stamp_ns.astype(np.int64), 1_000_000_000)
    rec["sec"] = sec
    rec["nanosec"] = nsec
    rec["fid_len"] = len(fid)
    rec["frame_counter"] = block.counter
    rec["words"][:, :11] = block.burst
    rec["words"][:, 11] = block.diag_stat
    rec["valid"] = block.diag_valid
    raw = rec.view(np.uint8).reshape(len(block), dtype.itemsize)
    raw[:, 16 : 16 + len(fid)] = np.frombuffer(fid, np.uint8)
    return raw


def decode_frames(payloads: np.ndarray) -> FrameBlock:
    """Decode an ``(n, size)`` uint8 array of equal-size CDR payloads into a :class:`FrameBlock`.

    The fields after ``frame_id`` are read at fixed offsets from the END of each payload, so the
    frame_id's length (constant within a run of equal-size messages) need not be known.
    """
    size = payloads.shape[1]
    tail = size - TAIL_SIZE
    head = np.ascontiguousarray(payloads[:, 4:12]).view("<u4")
    counter = np.ascontiguousarray(payloads[:, tail : tail + 4]).view("<u4")[:, 0]
    words = np.ascontiguousarray(payloads[:, tail + 4 : tail + 28]).view("<u2")
    stamp = head[:, 0].astype(np.int64) * 1_000_000_000 + head[:, 1]
    return FrameBlock(
        stamp_ns=stamp,
        counter=counter.copy(),
        burst=words[:, :11].copy(),
        diag_stat=words[:, 11].copy(),
        diag_valid=payloads[:, tail + 28].astype(bool),
    )
