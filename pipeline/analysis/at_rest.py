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

A level change of several axes at one instant says the same of a moment of the record: the
closed loop finds a bias step on each axis alone (the joint event search sees transients, not
lasting level changes: docs/events.md), and steps whose 95 % time intervals overlap on several
axes are one shift of the whole unit — a tilt moving gravity's projection, a bump, a supply
change — which :func:`coincident_step_warnings` names (the real ADIS16405 unit 2: one step at
2020 s on all three accelerometers).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from imupipe.analysis.events import overlapping_groups
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


STEP_KIND = "bias_step"
"""The loop's effect kind of a lasting level change (:mod:`imupipe.model.loop`)."""


def coincident_step_warnings(
    axes: Mapping[str, AxisResult], duration_s: float, t0_s: float
) -> list[str]:
    """One warning per instant at which the loops of two or more axes each accepted a bias
    step, their 95 % time intervals (``time_s``, s from the analysed start) overlapping
    (chained: a step overlapping one of the group joins it); the sizes in each axis' SI unit.
    The steps stay corrected per axis: the warning says they are one event of the unit.  Then
    one line naming the longest part of the analysed ``duration_s`` between those instants'
    intervals, with the ``--start``/``--end`` that analyse it alone (s from the recording's
    first frame: ``t0_s`` is the analysed start's)."""
    steps = [
        (*effect.intervals["time_s"], name, effect)
        for name, axis in axes.items()
        if axis.loop is not None
        for effect in axis.loop.accepted
        if effect.kind == STEP_KIND
    ]
    groups = [
        [steps[i] for i in members]
        for members in overlapping_groups([s[0] for s in steps], [s[1] for s in steps])
    ]
    warnings, shifts = [], []
    for group in groups:
        if len({name for _, _, name, _ in group}) < 2:
            continue
        shifts.append((min(s[0] for s in group), max(s[1] for s in group)))
        times = sorted(effect.params["time_s"] for *_, effect in group)
        sizes = ", ".join(
            f"{name} {effect.params['size']:.3g} {axes[name].unit}"
            for _, _, name, effect in sorted(group, key=lambda s: list(axes).index(s[2]))
        )
        warnings.append(
            f"bias steps at the same instant on several axes, {times[0]:.0f}"
            + (f"-{times[-1]:.0f}" if times[-1] > times[0] else "")
            + f" s [{min(s[0] for s in group):.0f}, {max(s[1] for s in group):.0f}] ({sizes}): "
            "one shift of the whole unit (a tilt, a bump or a supply change), found by each "
            "axis' loop and corrected on each; the recording was not static there"
        )
    return warnings + ([_longest_part(shifts, duration_s, t0_s)] if shifts else [])


def _longest_part(shifts: list[tuple[float, float]], duration_s: float, t0_s: float) -> str:
    """The longest part of [0, ``duration_s``] outside every shift's interval ``shifts``
    (sorted, disjoint), and the options that analyse it alone."""
    edges = [0.0, *(x for lo_hi in shifts for x in lo_hi), duration_s]
    ends = zip(edges[::2], edges[1::2], strict=True)
    parts = [(max(a, 0.0), min(b, duration_s)) for a, b in ends]
    a, b = max(parts, key=lambda p: p[1] - p[0])
    options = " ".join(
        [f"--start {t0_s + a:.0f}"] * (a > 0) + [f"--end {t0_s + b:.0f}"] * (b < duration_s)
    )
    return (
        f"the longest part between the unit's shifts: {a:.0f}-{b:.0f} s of the analysed "
        f"{duration_s:.0f} s ({(b - a) / duration_s:.0%}); to analyse it alone: {options}"
    )
