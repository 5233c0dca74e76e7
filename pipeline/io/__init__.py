"""Bytes in and out: the MCAP scanner (:mod:`.mcap_scan`, its compiled record walk
:mod:`.mcap_walk`) and bulk writer (:mod:`.mcap_bulk`), rosbag2's SQLite storage read through
the same interface (:mod:`.db3_scan`), the decoders of ADIS16364 frames and
ROS 2 ``sensor_msgs/msg/Imu`` into a polars frame (:mod:`.decode`), rosbag2 directories, the
column sources the analysis reads from (in memory, or spilled to a temporary on-disk store:
:mod:`.columns`), and ``imupipe info`` (:mod:`.info`)."""

from imupipe.io.columns import ColumnSource, open_columns
from imupipe.io.decode import IMU_SCHEMA, TEMPERATURE_SCHEMA, ImuRecording, mcap_files
from imupipe.io.info import describe, imu_topics
from imupipe.io.mcap_bulk import BulkWriter
from imupipe.io.mcap_scan import McapScanner, ScanReport

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
    "mcap_files",
    "open_columns",
]
