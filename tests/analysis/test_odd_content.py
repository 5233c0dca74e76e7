"""Valid bags of odd content: the whole analysis, loop included, returns or refuses in one line.

Each example is a well-formed ROS 2 Imu bag (the mcap library's writer) whose values and stamps
are what careless hardware and software produce: 30 to 5000 samples at 10 Hz to 2 kHz, scales
from 1e-12 to 1e6 with large offsets, a quiet sensor under a strong tone, coarse quantisation,
a constant axis or block, NaN bursts, repeated or frozen stamps, stamps running backwards,
jitter, gaps.  Whatever the mix, :func:`imupipe.analyze` returns (every analysed N finite or a
bound) or raises our one-line :class:`~imupipe.errors.ImupipeError`, and no numpy warning
reaches the user.  Before session 29 a scratch fuzz of 120 such bags crashed on 15 (division by
zero in the loop's whitener and in the rate-change warning, a singular covariance, a step
searched in constant block means, NaN read from the wrong rows of a masked grid).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import imupipe
from imupipe.errors import ImupipeError
from imupipe.testing.busy_bag import Stream, write_bag
from imupipe.testing.ros_cdr import imu_payloads

EDITS = ("quant", "const_axis", "nan_burst", "step", "dup_stamps", "reverse", "gap", "jitter",
         "spike", "const_block", "ramp", "tone", "frozen_clock", "two_streams")  # fmt: skip


def odd_bag(path: Path, n: int, rate: float, scale: float, offset: float, edits, seed: int):
    """Write the bag: white noise of ``scale`` plus ``offset`` on six axes, then ``edits``
    ((name, where 0-1, length 0-1, axis), ...) applied in order."""
    rng = np.random.default_rng(seed)
    t = 1_700_000_000_000_000_000 + np.round(np.arange(n) * 1e9 / rate).astype(np.int64)
    y = rng.standard_normal((n, 6)) * scale + offset
    for name, where, length, axis in edits:
        a = int(where * (n - 1))
        b = min(n, a + 1 + int(length * n / 3))
        if name == "quant":
            y = np.round(y / (10 * scale))
        elif name == "const_axis":
            y[:, axis] = 0.5
        elif name == "nan_burst":
            y[a:b, axis] = np.nan
        elif name == "step":
            y[a:, axis] += 10 * scale
        elif name == "dup_stamps":
            t[a:b] = t[a]
        elif name == "reverse":
            t[a:b] = t[a:b][::-1].copy()
        elif name == "gap":
            t[a:] += 10**9
        elif name == "jitter":
            t = t + rng.integers(0, int(0.5e9 / rate), n)
        elif name == "spike":
            y[a, axis] = 1e9
        elif name == "const_block":
            y[a:b] = y[a]
        elif name == "ramp":
            y[:, axis] += np.linspace(0, 1e3 * scale, n)
        elif name == "tone":
            y[:, axis] += 5e3 * scale * np.sin(0.3 * np.arange(n))
        elif name == "two_streams":  # a second IMU on the topic, ``where`` of a period later
            t[1::2] = t[0 : n - 1 : 2] + int(where * 1e9 / rate)
        else:  # frozen_clock: stamps advance a thousand times too slowly
            t[a:b] = t[a] + (t[a:b] - t[a]) // 1000
    payloads = [row.tobytes() for row in imu_payloads(t, y[:, :3], y[:, 3:])]
    write_bag(path, [Stream("/imu/data", "sensor_msgs/msg/Imu", payloads, np.sort(t))], "")


edit = st.tuples(st.sampled_from(EDITS), st.floats(0, 1), st.floats(0, 1), st.integers(0, 5))


@settings(
    max_examples=15,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    st.sampled_from([30, 1000, 5000]),
    st.sampled_from([10.0, 100.0, 2000.0]),
    st.sampled_from([1e-12, 1e-3, 1.0, 1e6]),
    st.sampled_from([0.0, -5.0, 1e6]),
    st.lists(edit, max_size=3),
)
def test_an_odd_bag_is_analysed_or_refused_in_one_line(
    tmp_path: Path, n: int, rate: float, scale: float, offset: float, edits
) -> None:
    path = tmp_path / "odd.mcap"
    odd_bag(path, n, rate, scale, offset, edits, seed=n)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # what the command would print
        try:
            result = imupipe.analyze(path, tmp_path / "out", rrd=False, figures=False)
        except ImupipeError as exc:
            assert "\n" not in str(exc)
            return
    for axis in result.axes.values():
        n_value = axis.terms.random_walk.value
        assert n_value is None or np.isfinite(n_value)


@pytest.mark.parametrize("edits", [[], [("tone", 0, 0, 0)]], ids=["30_samples", "tone"])
def test_the_cases_that_crashed_are_analysed(tmp_path: Path, edits) -> None:
    """A 30-sample record at 400 Hz, and 5000 samples of a 1e-12 rad/s sensor under a tone:
    both ended in a ZeroDivisionError in the loop's whitener (every noise term fitted 0)."""
    path = tmp_path / "odd.mcap"
    odd_bag(path, 30 if not edits else 5000, 400.0, 1e-12 if edits else 1.0, 0.0, edits, 1)
    result = imupipe.analyze(path, tmp_path / "out", rrd=False, figures=False)
    assert list(result.axes) == ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]


@pytest.mark.parametrize(("n", "rate"), [(1000, 100.0), (5000, 10.0)])
def test_a_constant_record_with_one_spike_and_two_streams_is_analysed(
    tmp_path: Path, n: int, rate: float
) -> None:
    """1e-12 of noise on an offset of 1e6 is a constant record to float64; with one spike and
    a second stream on the topic, its spike-corrected halves do not vary at all.  Until
    session 47 the loop's hold-out divided by zero there (the noise identification's ACF and
    B1, the gamma fit of a zero curve) and a warm-up's profile read 0/0 (found by the fuzz
    above, outside its fixed examples)."""
    path = tmp_path / "odd.mcap"
    edits = [("spike", 0.0, 0.0, 0), ("two_streams", 0.0, 0.0, 0)]
    odd_bag(path, n, rate, 1e-12, 1e6, edits, seed=n)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        result = imupipe.analyze(path, tmp_path / "out", rrd=False, figures=False)
    assert list(result.axes) == ["gyro_x"]  # the other five are constant: not analysed
    loop = result.axes["gyro_x"].loop
    assert loop.accepted == []
    notes = [c.evidence["holdout"].get("note") for c in loop.rejected if "holdout" in c.evidence]
    assert "a half of the record has no Allan variance to fit" in notes


FUZZED = {
    # a NaN burst over 82 % of accel_z from its start: the second half of that axis is all
    # excluded (the hold-out's Allan curve of it raised "every sample is excluded"); a band of
    # zero spectrum under a constant block (a line's 0/0 frequency interval)
    "nan_half": (100.0, 1e-3, -5.0, [("tone", 0.9002, 0.9180, 0), ("const_axis", 0.2511, 0.1675, 1),
                 ("const_block", 0.5325, 0.6602, 1), ("nan_burst", 0.0127, 0.8201, 5)]),
    # stamps repeated, frozen and reversed over most of the record: the envelope's period
    # correction reached 0 (a division by zero placing the frames)
    "frozen": (10.0, 1e-12, 1e6, [("dup_stamps", 0.6777, 0.6924, 2), ("frozen_clock", 0.1148,
               0.0267, 1), ("tone", 0.5422, 0.1875, 4), ("reverse", 0.2156, 0.8778, 0)]),
}  # fmt: skip


@pytest.mark.parametrize("case", list(FUZZED))
def test_the_bags_a_wider_fuzz_crashed_on_are_analysed(tmp_path: Path, case: str) -> None:
    """Two of 300 bags of a wider scratch fuzz (session 47: up to five edits) ended in a
    traceback; each is now analysed with no warning, the axes it can."""
    rate, scale, offset, edits = FUZZED[case]
    path = tmp_path / "odd.mcap"
    odd_bag(path, 5000, rate, scale, offset, edits, seed=5000)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        result = imupipe.analyze(path, tmp_path / "out", rrd=False, figures=False)
    expected = {"nan_half": ["gyro_x", "gyro_z", "accel_x", "accel_y", "accel_z"],
                "frozen": ["accel_y"]}  # fmt: skip
    assert list(result.axes) == expected[case]


def test_stamps_that_stand_still_in_most_blocks_are_refused_in_one_line_not_placed_forever(
    tmp_path: Path,
) -> None:
    """Stamps repeated and reversed over most of a 2 kHz record (and every axis quantised to
    0): the stamp envelope's period correction came out 3e-16, its period 1e-19 s, and the
    lost-frame placement iterated over ~3e8 levels (a scratch fuzz hung on it for 40 min in
    session 47).  The correction now applies within a factor 2 only: the bag is read in
    seconds and refused, its axes all zero."""
    edits = [("quant", 0.8535, 0.5669, 3), ("dup_stamps", 0.3688, 0.8120, 4),
             ("reverse", 0.7280, 0.9307, 4), ("quant", 0.6574, 0.1546, 3),
             ("quant", 0.4998, 0.2883, 5)]  # fmt: skip
    path = tmp_path / "odd.mcap"
    odd_bag(path, 5000, 2000.0, 1e-3, 0.0, edits, seed=5000)
    with pytest.raises(ImupipeError) as err:
        imupipe.analyze(path, tmp_path / "out", rrd=False, figures=False)
    message = str(err.value)
    assert "\n" not in message
    assert "no axis can be analysed: gyro_x is 0 in every sample over the segment" in message
