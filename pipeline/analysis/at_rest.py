"""Is the analysed recording one of an IMU at rest whose accelerations are in m/s²?

An Allan analysis assumes a static sensor, and every noise term an export hands a filter is in
the units of the data.  ``sensor_msgs/msg/Imu`` carries accelerations in m/s² (its message
definition and ROS REP 103, "Standard Units of Measure and Coordinate Conventions"), but some
drivers publish them in g: the accelerometer terms would then be 9.81 times too small, with
nothing in the numbers to say so.  At rest, the accelerometers measure the specific force of
gravity, whatever the orientation: the magnitude of the mean acceleration vector is local
gravity, 9.78-9.83 m/s² on the Earth's surface, give or take the bias and scale error of the
sensor (the two real ADIS16405 units of ../shared/reference: 9.965 and 9.982 m/s²).  A
magnitude far from that says the units are not m/s², or the sensor was not at rest; one
near 0, that the driver removed gravity (a "linear acceleration" output).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from imupipe.analysis.results import AxisResult
from imupipe.units import STANDARD_GRAVITY

ACCEL_AXES = ("accel_x", "accel_y", "accel_z")
GRAVITY_TOLERANCE = 0.1
"""Relative departure of the mean specific force from standard gravity that is warned about:
local gravity spans ±0.3 %, a MEMS accelerometer's bias and scale error a few per cent."""
GRAVITY_REMOVED = 0.5
"""Mean specific force (m/s²) below which the accelerations read as gravity removed by the
driver: a MEMS bias is tens of mg at most, and g published as m/s² reads 0.9-1.1."""


def specific_force_warning(axes: Mapping[str, AxisResult]) -> str | None:
    """A warning when the magnitude of the mean acceleration vector (m/s²) of the analysed
    axes ``axes`` is not within :data:`GRAVITY_TOLERANCE` of standard gravity, naming g as the
    likely unit when it is within that of 1; None when it is, or when an accelerometer axis
    was not analysed (a gravity vector needs all three)."""
    if not all(a in axes for a in ACCEL_AXES):
        return None
    magnitude = float(np.linalg.norm([axes[a].mean for a in ACCEL_AXES]))
    if abs(magnitude / STANDARD_GRAVITY - 1) <= GRAVITY_TOLERANCE:
        return None
    said = f"the accelerometers' mean specific force is {magnitude:.4g} m/s², not about 9.81"
    if abs(magnitude - 1) <= GRAVITY_TOLERANCE:
        return (
            f"{said}: the accelerations look like g, not the m/s² that sensor_msgs/Imu and "
            "REP 103 require; every accelerometer term is then 9.81 times too small"
        )
    if magnitude < GRAVITY_REMOVED:
        return (
            f"{said}: about 0, as if the driver removed gravity (from its orientation "
            "estimate, whose errors then add to the accelerometers' noise: analyse the raw "
            "accelerations if the driver publishes them), or a sensor in free fall"
        )
    return (
        f"{said}: accelerations in another unit than m/s² (REP 103), or a sensor that was not "
        "at rest; the noise terms assume a static recording"
    )
