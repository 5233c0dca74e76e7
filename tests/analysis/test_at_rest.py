"""The specific-force check: a static IMU's accelerometers measure gravity, so a mean vector far
from 9.81 m/s² says the accelerations are in g (or another unit), or the sensor moved."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from imupipe.analysis.at_rest import specific_force_warning


def axes(x: float, y: float, z: float) -> dict:
    return {f"accel_{a}": SimpleNamespace(mean=v) for a, v in zip("xyz", (x, y, z), strict=True)}


@pytest.mark.parametrize(
    "mean",
    [(0.0, 0.0, -9.80665), (0.27, -0.21, -9.79), (-0.043, -0.023, -9.965), (6.0, 0.0, 7.0)],
)
def test_gravity_in_any_orientation_is_no_warning(mean: tuple[float, float, float]) -> None:
    assert specific_force_warning(axes(*mean)) is None  # the last: |a| 9.22, tilted


@pytest.mark.parametrize(
    ("mean", "says"),
    [
        ((0.0, 0.0, 1.0), "look like g"),
        ((0.03, -0.02, -0.98), "look like g"),
        ((0.0, 0.0, 10.8), "or a sensor that was not at rest"),  # 10.1 % over
        ((0.0, 0.0, 8.82), "or a sensor that was not at rest"),  # 10.1 % under
        ((0.3, 0.0, -0.39), "as if the driver removed gravity"),  # |a| 0.492 m/s²
        ((0.0, 0.0, 0.0), "as if the driver removed gravity"),  # no gravity at all
        ((0.0, 0.0, 0.5), "or a sensor that was not at rest"),  # 0.5 m/s²: neither
    ],
)
def test_far_from_gravity_is_warned(mean: tuple[float, float, float], says: str) -> None:
    warning = specific_force_warning(axes(*mean))
    assert warning is not None and says in warning
    assert f"is {abs(mean[2]):.4g} m/s²" in warning or mean[0] != 0.0


def test_the_bounds_are_ten_per_cent_of_standard_gravity() -> None:
    assert specific_force_warning(axes(0.0, 0.0, 9.80665 * 1.0999)) is None
    assert specific_force_warning(axes(0.0, 0.0, 9.80665 * 1.1001)) is not None
    assert specific_force_warning(axes(0.0, 0.0, 9.80665 * 0.9001)) is None
    assert specific_force_warning(axes(0.0, 0.0, 9.80665 * 0.8999)) is not None


def test_without_all_three_accelerometers_nothing_is_said() -> None:
    two = axes(0.0, 0.0, 1.0)
    del two["accel_y"]  # not analysed (stuck, or not provided): no gravity vector
    assert specific_force_warning(two) is None
