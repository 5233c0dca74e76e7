"""The analysis' result objects as the report stage reads them: a sensor's axes, the outlier
block of report.json, and results that cannot be changed once made."""

from __future__ import annotations

import dataclasses

import pytest


def test_a_sensors_axes_are_its_own_in_report_order(synthetic_result) -> None:
    result = synthetic_result()
    assert [a.name for a in result.by_sensor("accel")] == ["accel_x", "accel_y", "accel_z"]
    assert [a.name for a in result.by_sensor("gyro")] == ["gyro_x", "gyro_y", "gyro_z"]


def test_the_outlier_search_reaches_report_json_only_when_it_ran(synthetic_result) -> None:
    result = synthetic_result(with_loop=False)
    searched = {"count": 2, "threshold_sigma": 7.5, "unit": "rad/s"}
    axes = dict(result.axes)
    axes["gyro_y"] = dataclasses.replace(axes["gyro_y"], outliers=searched)
    document = dataclasses.replace(result, axes=axes).to_dict()
    assert document["axes"]["gyro_y"]["outliers"] == searched
    assert "outliers" not in document["axes"]["gyro_x"]  # not searched: no block, not null


def test_results_cannot_be_changed_once_made(synthetic_result) -> None:
    result = synthetic_result(with_loop=False)
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.axes["gyro_x"].mean = 0.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.device = {}  # type: ignore[misc]
