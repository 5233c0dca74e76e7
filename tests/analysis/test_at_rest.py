"""The specific-force check: a static IMU's accelerometers measure gravity, so a mean vector far
from 9.81 m/s² says the accelerations are in g (or another unit), or the sensor moved; and bias
steps the loop found at one instant on several axes are named as one shift of the unit."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from imupipe.analysis.at_rest import coincident_step_warnings, specific_force_warning
from imupipe.model.loop import AcceptedEffect


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


def _step(t: float, lo: float, hi: float, size: float) -> AcceptedEffect:
    return AcceptedEffect(
        "bias_step", {"time_s": t, "size": size}, {"time_s": [lo, hi]}, {}, 2.0, 1.0
    )


def _looped(**accepted: list[AcceptedEffect]) -> dict:
    unit = {"gyro": "rad/s", "accel": "m/s^2"}
    return {
        name: SimpleNamespace(loop=SimpleNamespace(accepted=effects), unit=unit[name[:-2]])
        for name, effects in accepted.items()
    }


def test_steps_whose_intervals_overlap_on_several_axes_are_one_warning() -> None:
    """The real ADIS16405 unit 2 (session 50): steps at 2020 s on its three accelerometers,
    one warning naming the instant, its span and each axis' size in the axis' order; its steps
    at 540 s and 740 s, on one axis each, and a sinusoid at any time say nothing.  Intervals
    that only chain (c overlaps a, not b; d touches c) are one instant."""
    sinusoid = AcceptedEffect("sinusoid", {"frequency_hz": 0.565}, {}, {}, 9.0, 1.0)
    axes = _looped(
        gyro_x=[sinusoid],
        accel_z=[_step(540.0, 530.0, 560.0, 0.0203), _step(2020.0, 2010.0, 2030.0, -0.0135)],
        accel_x=[_step(2020.0, 2010.0, 2030.0, -0.0209)],
        accel_y=[_step(740.0, 730.0, 750.0, 0.0171), _step(2020.0, 2011.0, 2025.0, -0.0126)],
    )
    assert coincident_step_warnings(axes, 10_000.0, 0.0) == [
        "bias steps at the same instant on several axes, 2020 s [2010, 2030] (accel_z "
        "-0.0135 m/s^2, accel_x -0.0209 m/s^2, accel_y -0.0126 m/s^2): one shift of the whole "
        "unit (a tilt, a bump or a supply change), found by each axis' loop and corrected on "
        "each; the recording was not static there",
        "the longest part between the unit's shifts: 2030-10000 s of the analysed 10000 s "
        "(80%); to analyse it alone: --start 2030",
    ]
    chained = _looped(
        gyro_x=[_step(100.0, 90.0, 130.0, 1e-4)],
        gyro_y=[_step(102.0, 100.0, 105.0, 2e-4)],  # inside gyro_x's
        gyro_z=[_step(125.0, 120.0, 140.0, 3e-4)],  # overlaps gyro_x's only
        accel_x=[_step(145.0, 140.0, 150.0, 0.01)],  # touches gyro_z's
    )
    (warning, _) = coincident_step_warnings(chained, 1000.0, 0.0)
    assert warning.startswith(
        "bias steps at the same instant on several axes, 100-145 s [90, 150] (gyro_x 0.0001 "
        "rad/s, gyro_y 0.0002 rad/s, gyro_z 0.0003 rad/s, accel_x 0.01 m/s^2)"
    )


def test_steps_apart_or_on_one_axis_are_no_warning() -> None:
    apart = _looped(
        accel_x=[_step(1000.0, 990.0, 1010.0, 0.02)],
        accel_y=[_step(1020.0, 1010.5, 1030.0, 0.02)],  # starts after accel_x's ends
    )
    assert coincident_step_warnings(apart, 3000.0, 0.0) == []
    pair = _looped(  # two steps a few seconds apart, inside each other's interval: one instant
        accel_x=[_step(1000.0, 990.0, 1010.0, 0.02)],
        accel_y=[_step(1004.0, 995.0, 1012.0, -0.01)],
    )
    (warning, _) = coincident_step_warnings(pair, 3000.0, 0.0)
    assert warning.startswith(
        "bias steps at the same instant on several axes, 1000-1004 s [990, 1012]"
    )
    three = _looped(  # the span from the first time to the last, not to the second
        gyro_x=[_step(1000.0, 990.0, 1010.0, 1e-4)],
        gyro_y=[_step(1000.0, 992.0, 1010.0, 1e-4)],
        gyro_z=[_step(1006.0, 996.0, 1016.0, 1e-4)],
    )
    (warning, _) = coincident_step_warnings(three, 3000.0, 0.0)
    assert warning.startswith(
        "bias steps at the same instant on several axes, 1000-1006 s [990, 1016]"
    )
    one_axis = _looped(accel_x=[_step(1000.0, 990.0, 1010.0, 0.02), _step(1005.0, 1000, 1010, 1)])
    assert coincident_step_warnings(one_axis, 3000.0, 0.0) == []
    no_loop = {"gyro_x": SimpleNamespace(loop=None, unit="rad/s")}
    assert coincident_step_warnings(no_loop, 3000.0, 0.0) == []


def test_the_longest_part_between_the_shifts_and_the_options_that_analyse_it() -> None:
    """Between two whole-unit shifts (and the record's ends) the longest part, its share and
    the --start/--end that cut it, on the recording's time base (the analysed start at 100 s);
    a part reaching an end of the analysed record needs no option there."""
    middle = _looped(
        accel_x=[_step(1000.0, 990.0, 1012.0, 0.02), _step(5004.0, 5000.0, 5010.0, 0.01)],
        accel_y=[_step(1001.0, 992.0, 1010.0, 0.02), _step(5005.0, 5001.0, 5009.0, 0.01)],
    )
    *_, part = coincident_step_warnings(middle, 8000.0, 100.0)
    assert part == (
        "the longest part between the unit's shifts: 1012-5000 s of the analysed 8000 s "
        "(50%); to analyse it alone: --start 1112 --end 5100"
    )
    *_, first = coincident_step_warnings(middle, 5500.0, 0.0)  # 0-990 vs 1012-5000 vs 5010-
    assert first.endswith("1012-5000 s of the analysed 5500 s (73%); to analyse it alone: "
                          "--start 1012 --end 5000")  # fmt: skip
    early = _looped(
        gyro_x=[_step(7000.0, 6990.0, 7010.0, 1e-4)], gyro_y=[_step(7000.0, 6995.0, 7005.0, 1e-4)]
    )
    *_, before = coincident_step_warnings(early, 8000.0, 0.0)
    assert before.endswith("0-6990 s of the analysed 8000 s (87%); to analyse it alone: --end 6990")


def test_a_simulated_tilt_at_one_instant_is_named_in_the_reports_warnings(tmp_path) -> None:
    """1 h of the simulated ADIS16364 whose accel_x and accel_y biases jump by ±1.5 mg at
    1800 s (a scenario file): each axis' loop finds its step, and the analysis' warnings (the
    command's stderr, report.json's input.warnings) name the one instant on both axes."""
    import imupipe

    scenario = tmp_path / "tilt.toml"
    scenario.write_text(
        'name = "tilt"\n'
        '[[bias_step]]\naxis = "accel_x"\ntime_s = 1800.0\nsize = 1.5\n'
        '[[bias_step]]\naxis = "accel_y"\ntime_s = 1800.0\nsize = -1.5\n'
    )
    imupipe.record(tmp_path / "tilt.mcap", duration="1h", seed=3, scenario=scenario)
    result = imupipe.analyze(tmp_path / "tilt.mcap", tmp_path / "out", rrd=False, figures=False)
    (warning,) = [w for w in result.input.warnings if w.startswith("bias steps")]
    assert warning.startswith("bias steps at the same instant on several axes, 1800 s [")
    assert "(accel_x 0.01" in warning and ", accel_y -0.01" in warning
