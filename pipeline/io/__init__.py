"""Bytes in and out: the MCAP scanner (:mod:`.mcap_scan`, its compiled record walk
:mod:`.mcap_walk`) and bulk writer (:mod:`.mcap_bulk`), rosbag2's SQLite storage read through
the same interface (:mod:`.db3_scan`), rosbag2 directories and their compression
(:mod:`.rosbag2`), the decoders of ADIS16364 frames and ROS 2 ``sensor_msgs/msg/Imu`` into a
polars frame (:mod:`.decode`), the column sources the analysis reads from (in memory, or spilled
to a temporary on-disk store: :mod:`.columns`), and ``imupipe info`` (:mod:`.info`)."""

from imupipe.io.columns import ColumnSource, open_columns
from imupipe.io.decode import IMU_SCHEMA, TEMPERATURE_SCHEMA, ImuRecording
from imupipe.io.info import describe, imu_topics
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.io.mcap_scan import McapScanner, ScanReport
from imupipe.io.rosbag2 import storage_files

__all__ = [
    "IMU_SCHEMA",
    "TEMPERATURE_SCHEMA",
    "BulkWriter",
    "ColumnSource",
    "ImuRecording",
    "McapScanner",
    "ScanReport",
    "describe",
    "imu_topics",
    "open_columns",
    "storage_files",
]
