"""Bytes in and out: the MCAP scanner (:mod:`.mcap_scan`, its compiled record walk
:mod:`.mcap_walk`) and bulk writer (:mod:`.mcap_bulk`), the decoders of ADIS16364 frames and
ROS 2 ``sensor_msgs/msg/Imu`` into a polars frame (:mod:`.decode`), rosbag2 directories, and
``imupipe info`` (:mod:`.info`)."""
