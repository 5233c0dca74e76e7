"""Bytes in and out: the MCAP scanner (:mod:`.mcap_scan`) and bulk writer (:mod:`.mcap_bulk`),
the decoders of ADIS16364 frames and ROS 2 ``sensor_msgs/msg/Imu`` into a polars frame
(:mod:`.decode`), rosbag2 directories, the column sources the analysis reads from (in memory,
or spilled to a temporary on-disk store: :mod:`.columns`), and ``imupipe info`` (:mod:`.info`)."""
