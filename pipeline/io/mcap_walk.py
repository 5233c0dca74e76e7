"""Compiled walks over MCAP record bytes: index the Message records, gather fields by offset.

A robot's bag interleaves topics message by message, so the messages of one channel are not
contiguous in a chunk and cutting a chunk into runs of equal-size messages (one numpy view
each) degenerates into one Python step per message.  Instead, :func:`index_messages` walks a
decompressed chunk (or a stretch of top-level records of an unchunked file) once, compiled, and
returns where every Message record's payload starts, its size, channel and log time (MCAP spec,
"Message": ``opcode 0x05, length u64, channel_id u16, sequence u32, log_time u64,
publish_time u64, data``); :func:`gather` then copies fixed-width fields at per-message offsets
into one contiguous array.  Both release the GIL, so the walk runs on the scanner's unpack thread
beside the decompression.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

RECORD_HEAD = 9  # opcode u8 + length u64
MESSAGE_FIXED = 2 + 4 + 8 + 8  # channel_id, sequence, log_time, publish_time
MESSAGE_HEAD = RECORD_HEAD + MESSAGE_FIXED  # bytes of a Message record before its data
_OPCODE_MESSAGE = 0x05


@numba.njit(cache=True, nogil=True)
def _walk(buf, pos, end, offset, size, channel, log_time):  # pragma: no cover - compiled
    """Index consecutive well-formed Message records of ``buf[pos:end]``; stop at the first
    record that is not one (another opcode, a Message shorter than its fixed fields, a record
    running past ``end``) or when fewer than a record head's bytes remain.
    Returns (messages indexed, byte where the walk stopped)."""
    n = 0
    while end - pos >= RECORD_HEAD and buf[pos] == _OPCODE_MESSAGE:
        length = 0  # u64 little endian; a length beyond 2**63 ends the walk as it wraps < 0
        for k in range(8):
            length |= np.int64(buf[pos + 1 + k]) << (8 * k)
        if length < MESSAGE_FIXED or length > end - pos - RECORD_HEAD:
            break
        at = pos + RECORD_HEAD
        channel[n] = buf[at] | (np.uint16(buf[at + 1]) << 8)
        time = np.uint64(0)
        for k in range(8):
            time |= np.uint64(buf[at + 6 + k]) << np.uint64(8 * k)
        log_time[n] = time
        offset[n] = pos + MESSAGE_HEAD
        size[n] = length - MESSAGE_FIXED
        n += 1
        pos = at + length
    return n, pos


@numba.njit(cache=True, nogil=True)
def _gather(buf, start, out):  # pragma: no cover - compiled
    width = out.shape[1]
    for i in range(start.size):
        s = start[i]
        for j in range(width):
            out[i, j] = buf[s + j]


@dataclass(frozen=True)
class MessageIndex:
    """The Message records found by :func:`index_messages`, in byte order.

    Attributes:
        offset: int64, byte of ``buf`` where each payload (the message's ``data``) starts.
        size: int64, payload bytes.
        channel: uint16 channel ids.
        log_time: uint64 log times, ns since the epoch.
        stop: byte of ``buf`` where the walk stopped (see :func:`index_messages`).
    """

    offset: np.ndarray
    size: np.ndarray
    channel: np.ndarray
    log_time: np.ndarray
    stop: int

    def __len__(self) -> int:
        return len(self.offset)


def index_messages(buf: np.ndarray, pos: int = 0, end: int | None = None) -> MessageIndex:
    """Index the consecutive Message records of the uint8 array ``buf`` from byte ``pos``.

    The walk stops at ``end`` (default: the end of ``buf``), at a record that is not a Message,
    at a Message too short for its fixed fields or at a record that runs past ``end``; ``stop``
    is that record's first byte, for the caller to parse, skip or report."""
    end = len(buf) if end is None else end
    capacity = max(end - pos, 0) // MESSAGE_HEAD + 1
    offset = np.empty(capacity, np.int64)
    size = np.empty(capacity, np.int64)
    channel = np.empty(capacity, np.uint16)
    log_time = np.empty(capacity, np.uint64)
    n, stop = _walk(buf, pos, end, offset, size, channel, log_time)
    return MessageIndex(offset[:n], size[:n], channel[:n], log_time[:n], int(stop))


def gather(buf: np.ndarray, start: np.ndarray, width: int, dtype: str = "u1") -> np.ndarray:
    """``out[i] = buf[start[i] : start[i] + width]`` viewed as ``dtype`` (``width`` a multiple
    of its size): an ``(n, width // itemsize)`` array, the bytes copied exactly.

    Raises:
        IndexError: a field would reach past the end of ``buf``.
    """
    out = np.empty((len(start), width // np.dtype(dtype).itemsize), dtype)
    if len(start):
        if int(start.min()) < 0 or int(start.max()) + width > len(buf):
            raise IndexError("gathered field outside the buffer")
        _gather(buf, start, out.view(np.uint8).reshape(len(start), width))
    return out
