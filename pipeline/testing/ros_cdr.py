"""Bulk CDR encoders for ``sensor_msgs/msg/Imu`` and ``sensor_msgs/msg/Temperature`` (tests and
benchmarks: many messages at once with numpy, for :class:`imupipe.io.mcap_bulk.BulkWriter`).

Layout (little-endian CDR, ROS 2 ``rosidl`` message definitions): 4-byte encapsulation, header
stamp (sec i32, nanosec u32), frame_id (u32 length incl. NUL, "imu\\0"), then the float64
fields, 8-aligned relative to the end of the encapsulation (payload byte 20).
"""

from __future__ import annotations

import numpy as np

_HEADER = 20  # encapsulation + stamp + frame_id "imu\0"


def _headers(stamp_ns: np.ndarray, size: int) -> np.ndarray:
    n = len(stamp_ns)
    out = np.zeros((n, size), np.uint8)
    out[:, 1] = 1  # little-endian CDR
    out[:, 4:8] = (stamp_ns // 10**9).astype("<i4").view(np.uint8).reshape(n, 4)
    out[:, 8:12] = (stamp_ns % 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    out[:, 12:16] = np.frombuffer(np.uint32(4).tobytes(), np.uint8)
    out[:, 16:20] = np.frombuffer(b"imu\0", np.uint8)
    return out


def imu_payloads(
    stamp_ns: np.ndarray, gyro: np.ndarray, accel: np.ndarray, covariance: float = 0.01
) -> np.ndarray:
    """Imu messages (n, 316) bytes: identity orientation, covariances all ``covariance``,
    ``gyro`` (n, 3) rad/s and ``accel`` (n, 3) m/s² as the 37 float64 from byte 20."""
    n = len(stamp_ns)
    out = _headers(stamp_ns, _HEADER + 37 * 8)
    f64 = np.full((n, 37), covariance)
    f64[:, 0:4] = [0.0, 0.0, 0.0, 1.0]
    f64[:, 13:16] = gyro
    f64[:, 25:28] = accel
    out[:, _HEADER:] = f64.astype("<f8").view(np.uint8).reshape(n, 37 * 8)
    return out


def temperature_payloads(stamp_ns: np.ndarray, temp_c: np.ndarray) -> np.ndarray:
    """Temperature messages (n, 36) bytes: ``temp_c`` °C and variance 0."""
    n = len(stamp_ns)
    out = _headers(stamp_ns, _HEADER + 16)
    f64 = np.column_stack([temp_c, np.zeros(n)])
    out[:, _HEADER:] = f64.astype("<f8").view(np.uint8).reshape(n, 16)
    return out
