"""Bulk CDR encoders for ``sensor_msgs/msg/Imu`` and ``sensor_msgs/msg/Temperature`` (tests and
benchmarks: many messages at once with numpy, for :class:`imupipe.io.mcap_bulk.BulkWriter`).

Layout (little-endian CDR, ROS 2 ``rosidl`` message definitions): 4-byte encapsulation, header
stamp (sec i32, nanosec u32), frame_id (u32 length incl. NUL, the bytes, NUL), then the float64
fields, 8-aligned relative to the end of the encapsulation (payload byte 20 for ``"imu"``).
"""

from __future__ import annotations

import numpy as np


def _field_start(frame_id: bytes) -> int:
    """Payload byte of the first float64 after a header with ``frame_id`` (CDR alignment is
    counted from the end of the 4-byte encapsulation)."""
    return 4 + (12 + len(frame_id) + 1 + 7) // 8 * 8


def _headers(stamp_ns: np.ndarray, size: int, frame_id: bytes) -> np.ndarray:
    n = len(stamp_ns)
    out = np.zeros((n, size), np.uint8)
    out[:, 1] = 1  # little-endian CDR
    out[:, 4:8] = (stamp_ns // 10**9).astype("<i4").view(np.uint8).reshape(n, 4)
    out[:, 8:12] = (stamp_ns % 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    out[:, 12:16] = np.frombuffer(np.uint32(len(frame_id) + 1).tobytes(), np.uint8)
    out[:, 16 : 16 + len(frame_id)] = np.frombuffer(frame_id, np.uint8)
    return out


def imu_payloads(
    stamp_ns: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    covariance: float = 0.01,
    frame_id: str = "imu",
    no_estimate: tuple[np.ndarray | bool, np.ndarray | bool] = (False, False),
) -> np.ndarray:
    """Imu messages (n, size) bytes: identity orientation, covariances all ``covariance``,
    ``gyro`` (n, 3) rad/s and ``accel`` (n, 3) m/s² among the 37 float64 after the header
    (size 316 for the frame_id ``"imu"``).  ``no_estimate``: per message (or for all), whether
    its angular velocity, its linear acceleration is marked as no estimate (element 0 of its
    covariance -1, as ``sensor_msgs/msg/Imu.msg`` asks)."""
    n, fid = len(stamp_ns), frame_id.encode()
    start = _field_start(fid)
    out = _headers(stamp_ns, start + 37 * 8, fid)
    f64 = np.full((n, 37), covariance)
    f64[:, 0:4] = [0.0, 0.0, 0.0, 1.0]
    f64[:, 13:16] = gyro
    f64[:, 25:28] = accel
    f64[:, 16] = np.where(no_estimate[0], -1.0, covariance)
    f64[:, 28] = np.where(no_estimate[1], -1.0, covariance)
    out[:, start:] = f64.astype("<f8").view(np.uint8).reshape(n, 37 * 8)
    return out


def temperature_payloads(
    stamp_ns: np.ndarray, temp_c: np.ndarray, frame_id: str = "imu"
) -> np.ndarray:
    """Temperature messages (n, size) bytes: ``temp_c`` °C and variance 0 (size 36 for the
    frame_id ``"imu"``)."""
    n, fid = len(stamp_ns), frame_id.encode()
    start = _field_start(fid)
    out = _headers(stamp_ns, start + 16, fid)
    f64 = np.column_stack([temp_c, np.zeros(n)])
    out[:, start:] = f64.astype("<f8").view(np.uint8).reshape(n, 16)
    return out
