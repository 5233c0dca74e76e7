"""Turn the real static ADIS16405 recording into a ROS 2 bag, so imupipe analyses it as a user's.

The reference recording (not shipped: CC BY-NC-SA 4.0, University of Calgary, via
SMAC-Group/imudata) is 1,000,000 samples at 100 Hz of counts × LSB (0.05 °/s, 3.33 mg).  This
script writes it as ``sensor_msgs/msg/Imu`` (rad/s, m/s²) with rosbags' own rosbag2 MCAP writer
— an independent producer — with header stamps at exactly 10 ms.  Then:

    python benchmarks/adis16405_bag.py ../shared/reference/adis16405 /tmp/adis16405_bag
    imupipe analyze /tmp/adis16405_bag --out /tmp/adis16405.imupipe

The reference holds two units; a third argument picks one (``imu1``, the default, or ``imu2``):

    python benchmarks/adis16405_bag.py ../shared/reference/adis16405 /tmp/adis16405_imu2 imu2

The README's "Measured data" section reports what that analysis found.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from imupipe.units import RAD_PER_DEG, STANDARD_GRAVITY

T0_NS = 1_500_000_000_000_000_000


def main() -> None:
    if len(sys.argv) not in (3, 4):
        sys.exit("usage: adis16405_bag.py REFERENCE_DIR OUTPUT_BAG_DIR [imu1|imu2]")
    ref_dir, out = Path(sys.argv[1]), Path(sys.argv[2])
    unit = sys.argv[3] if len(sys.argv) == 4 else "imu1"
    data = np.load(ref_dir / f"adis16405_{unit}_lsb.npz")
    values = data["counts"].astype(np.float64) * data["lsb"]
    gyro = values[:, :3] * RAD_PER_DEG
    accel = values[:, 3:] * STANDARD_GRAVITY
    # imu2's file stores no rate; the reference README gives 100 Hz for both units
    rate_hz = float(data["rate_hz"]) if "rate_hz" in data.files else 100.0
    step = round(1e9 / rate_hz)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    imu_t, header_t, time_t = (
        ts.types[n]
        for n in ("sensor_msgs/msg/Imu", "std_msgs/msg/Header", "builtin_interfaces/msg/Time")
    )
    quat_t, vec_t = ts.types["geometry_msgs/msg/Quaternion"], ts.types["geometry_msgs/msg/Vector3"]
    cov = np.zeros(9)
    unknown = np.array([-1.0, 0, 0, 0, 0, 0, 0, 0, 0])  # REP 145: orientation not provided
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/imu/data_raw", "sensor_msgs/msg/Imu", typestore=ts)
        for i in range(len(values)):
            stamp = T0_NS + i * step
            msg = imu_t(
                header=header_t(
                    stamp=time_t(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id="adis16405"
                ),
                orientation=quat_t(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=unknown,
                angular_velocity=vec_t(x=gyro[i, 0], y=gyro[i, 1], z=gyro[i, 2]),
                angular_velocity_covariance=cov,
                linear_acceleration=vec_t(x=accel[i, 0], y=accel[i, 1], z=accel[i, 2]),
                linear_acceleration_covariance=cov,
            )
            writer.write(conn, stamp, ts.serialize_cdr(msg, conn.msgtype))
    print(f"wrote {len(values)} messages to {out}")


if __name__ == "__main__":
    main()
