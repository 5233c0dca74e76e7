"""Stamps as host drivers write them: no frame counter, receive times with latency, samples
stamped together in bursts (two or three a USB frame), frames lost among them.

Rounding each stamp step to periods put a host's receive times (30 % of a period of latency)
on a grid 3 % too long with 10 000 places masked, and stamps in pairs on no grid at all ("the
longest clean segment has 2 frames"): frames keep their order now, and only the stamps' lower
envelope says where frames were lost (:func:`imupipe.analysis.condition._envelope_places`).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import polars as pl
import pytest

import imupipe
from imupipe.analysis.condition import condition
from imupipe.io.decode import ImuRecording
from imupipe.testing.busy_bag import T0_NS, Stream, write_bag
from imupipe.testing.ros_cdr import imu_payloads
from imupipe.vocab import AXES

PERIOD_NS = 5_000_000  # 200 Hz
LOST = ((30_011, 1), (60_500, 3), (80_000, 1000))
"""(first true frame lost, frames lost): one frame, three, and 5 s."""


def received(n: int, lost=LOST) -> np.ndarray:
    """The true frame index of each of ``n`` frames received when the ``lost`` ones are not."""
    keep = np.ones(n + sum(m for _, m in lost), dtype=bool)
    for first, m in lost:
        keep[first : first + m] = False
    return np.flatnonzero(keep)[:n]


def stamped(kind: str, frame: np.ndarray, seed: int = 0) -> np.ndarray:
    """Stamps (ns) of the true frames ``frame`` as a host writes them, its clock 30 ppm off."""
    rng = np.random.default_rng(seed)
    t = frame * PERIOD_NS * (1 + 30e-6)
    if kind == "latency":  # receive times: half-normal latency of 30 % of a period, then
        t = np.maximum.accumulate(t + np.abs(rng.normal(0, 0.3 * PERIOD_NS, len(t))))
    elif kind == "gauss":  # a time filter's symmetric error, 30 % of a period
        t = t + rng.normal(0, 0.3 * PERIOD_NS, len(t))
    elif kind.startswith("burst"):  # every `size` samples arrive together, stamped on arrival
        size = int(kind.removeprefix("burst"))
        bursts = frame // size
        arrival = (bursts + 1) * size * PERIOD_NS * (1 + 30e-6)
        t = arrival + rng.uniform(0, 0.3 * PERIOD_NS, bursts[-1] + 1)[bursts]
        t += (frame % size) * 50_000  # 50 µs apart within the burst
    return t.astype(np.int64)


def imu_recording(stamp_ns: np.ndarray, seed: int = 0) -> ImuRecording:
    """A ``sensor_msgs/msg/Imu`` recording (no frame counter, no configured rate)."""
    n = len(stamp_ns)
    rng = np.random.default_rng(seed)
    frame = pl.DataFrame(
        {
            "stamp_ns": stamp_ns,
            "log_time_ns": stamp_ns,
            **{a: rng.normal(0, 1, n) for a in AXES},
            "temp_c": np.full(n, 21.0),
            "supply_v": np.full(n, 5.0),
            "counter": pl.Series([None] * n, dtype=pl.UInt32),
            "flag_nd": np.ones(n, bool),
            "flag_ea": np.zeros(n, bool),
            "saturated": np.zeros(n, bool),
            "diag_stat": np.zeros(n, np.uint16),
            "t_s": (stamp_ns - stamp_ns[0]) / 1e9,
        }
    )
    return ImuRecording(frame, Path("x.mcap"), "/imu", "sensor_msgs/msg/Imu", "header.stamp", {})


def test_receive_times_keep_every_frame_in_order() -> None:
    """Latency of 30 % of a period and stamps clamped to never go back (55 repeat their
    predecessor's): one stream, nothing masked, the mean period measured (before: a grid of
    370 204 places for 360 000 frames, 10 259 masked, the rate 205.67 Hz)."""
    frame = np.arange(100_000)
    s = condition(imu_recording(stamped("latency", frame)))
    assert s.excluded is None and s.segment.frames == 100_000
    assert s.counts["gaps"] == 0 and s.counts["missed_frames"] == 0
    assert s.rate_hz == pytest.approx(200 / (1 + 30e-6), rel=2e-6)
    assert s.counts["duplicate_stamps"] > 0  # counted, not cut at
    said = [w for w in s.warnings if w.startswith("stamps scatter by ")]
    assert len(said) == 1 and "(a host's receive times, or samples stamped in bursts;" in said[0]
    assert not any("duplicate stamp(s)" in w for w in s.warnings)


@pytest.mark.parametrize(
    "kind", ["burst2", "burst3", "burst7", "burst10", "burst16", "latency", "gauss"]
)
def test_lost_frames_are_found_and_placed_among_jittery_stamps(kind: str) -> None:
    """One frame, three and a thousand lost: each gap counted with its frames and the rows on
    the true grid, but for the few rows at a gap's edge whose place their stamps cannot tell
    (the last samples of a burst before a lost frame). Bursts of 2 to 16 (a USB serial
    adapter's 16 ms latency timer at 1 kHz): before session 41, bursts of 7 counted the 5 s
    gap as 1008 frames (the spans' median period 0.8 % off) and bursts of 10 found 2 gaps
    that were not there (the blocks' level jumped with their count of bursts' ends)."""
    frame = received(100_000)
    s = condition(imu_recording(stamped(kind, frame)), gaps="mask")
    assert (s.counts["gaps"], s.counts["missed_frames"]) == (3, 1004)
    assert s.samples == frame[-1] - frame[0] + 1
    wrong = np.flatnonzero(s.grid_index != frame - frame[0])
    edge = max(int(kind.removeprefix("burst")) - 1, 3) if kind.startswith("burst") else 3
    assert wrong.size <= len(LOST) * edge, wrong  # at most a burst's rows but one, a gap
    # only frames received before a gap, in the burst before it, are placed late
    assert all(any(first - 16 <= frame[w] < first for first, _ in LOST) for w in wrong)
    assert np.all(s.grid_index[wrong] > frame[wrong] - frame[0])
    assert s.tau0_s == pytest.approx(PERIOD_NS * 1e-9 * (1 + 30e-6), rel=1e-3)


def test_frames_lost_in_the_first_block_are_found() -> None:
    """Receive times with latency, one frame lost at frame 6 and two at 40 (both in the first
    64-row block), one at 10 000: all four found and every row placed. Before session 41 the
    clock's drift, a running median whose window repeats the first change beyond the start,
    took the first block's step of 3 periods for drift: 1 of 4 found, the first 40 rows placed
    3 early. (Stamped in bursts, a loss that close to the start can still be undercounted: the
    block holds too few samples before it to read its level.)"""
    frame = received(20_000, lost=((6, 1), (40, 2), (10_000, 1)))
    s = condition(imu_recording(stamped("latency", frame)), gaps="mask")
    assert (s.counts["gaps"], s.counts["missed_frames"]) == (3, 4)
    assert np.array_equal(s.grid_index, frame - frame[0])


def test_a_window_or_a_short_record_of_jittery_stamps_keeps_its_rate() -> None:
    """The rate read from the placed stamps of a window that starts 10 s in (stamps not from 0),
    and of a record too short for three 240-row spans (the mean step then)."""
    frame = received(20_000, lost=((12_000, 2),))
    s = condition(imu_recording(stamped("latency", frame)), gaps="mask", start_s=10.0)
    assert s.counts["missed_frames"] == 2
    assert s.rate_hz == pytest.approx(200 / (1 + 30e-6), rel=1e-4)
    assert s.nominal_rate_hz == pytest.approx(s.rate_hz, rel=1e-9)  # no rate but the stamps'
    assert not any("differs from the nominal" in w for w in s.warnings)
    short = condition(imu_recording(stamped("burst2", np.arange(500))))
    assert any(w.startswith("stamps scatter by ") for w in short.warnings)
    assert short.rate_hz == pytest.approx(200, rel=5e-3)  # a burst at either end: ~1 / n


def test_frames_lost_often_under_a_drifting_clock_are_each_counted() -> None:
    """A host timer whose rate drifts by 4 % over the record, latency, and 0.2 % of the frames
    lost at random (403 of them, some next to each other): every lost frame counted."""
    rng = np.random.default_rng(7)
    keep = rng.random(201_000) > 0.002
    frame = np.flatnonzero(keep)[:200_000]
    period = PERIOD_NS * (1 + 0.04 * np.linspace(0, 1, frame[-1] + 1))
    clock = np.concatenate(([0.0], np.cumsum(period[1:])))
    t = clock[frame] + np.abs(rng.normal(0, 0.3 * PERIOD_NS, len(frame)))
    s = condition(imu_recording(t.astype(np.int64)), gaps="mask")
    assert s.counts["missed_frames"] == frame[-1] - frame[0] + 1 - len(frame)
    assert np.count_nonzero(s.grid_index != frame - frame[0]) < 0.002 * len(frame)


@pytest.mark.parametrize(("apart", "gaps"), [(16, 1), (17, 2)])
def test_frames_lost_a_burst_apart_are_one_gap(apart: int, gaps: int) -> None:
    """Every other stamp 0.3 periods late, frames 1000 and 1001 + ``apart`` lost: the second
    loss lies ``apart`` rows after the first.  Losses up to BURST_ROWS (16) rows apart are one
    gap (stamped in bursts, the floor passes one gap's levels up to a burst apart): 2 frames
    missing, both places at the first; further apart, two gaps, each at its own place."""
    lost = (1000, 1001 + apart)
    frame = np.setdiff1d(np.arange(2002), lost)
    late = np.where(np.arange(2000) % 2, 0.3, 0.0)  # scatter 44 %: jittery, placed by envelope
    s = condition(imu_recording(((frame + late) * PERIOD_NS).astype(np.int64)))
    assert f"{gaps} gap(s) in time or frame counter (2 frames missing)" in s.warnings
    assert s.samples == 2002
    places = [1000, 1001] if gaps == 1 else list(lost)
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), places)


def test_two_frames_stamped_alike_are_not_a_burst() -> None:
    """Messages of two frame_ids stamped in pairs are two IMUs on one topic, not one IMU's
    bursts: the steps are cut as before (no scatter warning)."""
    t = stamped("burst2", np.arange(2_000))
    rec = imu_recording(t)
    rec = ImuRecording(
        rec.frames, rec.path, rec.topic, rec.source, rec.time_source, rec.device,
        frame_ids=("imu_left", "imu_right"),
    )  # fmt: skip
    s = condition(rec, gaps="longest")
    assert not any(w.startswith("stamps scatter by") for w in s.warnings)
    assert s.segment.frames <= 2


def write_imu_bag(path: Path, stamp_ns: np.ndarray, seed: int = 0) -> tuple[float, float]:
    """An Imu bag (the mcap library's writer) of white noise, logged at the stamps; returns
    the true (gyro, accel) random walk N, /√Hz."""
    rng = np.random.default_rng(seed)
    gyro = rng.normal(0, 0.01, (len(stamp_ns), 3))
    accel = rng.normal(0, 0.03, (len(stamp_ns), 3)) + np.array([0.0, 0.0, 9.81])
    payloads = [row.tobytes() for row in imu_payloads(T0_NS + stamp_ns, gyro, accel)]
    write_bag(path, [Stream("/imu/data", "sensor_msgs/msg/Imu", payloads, T0_NS + stamp_ns)])
    return 0.01 * np.sqrt(PERIOD_NS * 1e-9), 0.03 * np.sqrt(PERIOD_NS * 1e-9)


def test_a_bag_stamped_in_pairs_is_analysed_whole(tmp_path: Path) -> None:
    """10 min at 200 Hz stamped in pairs with one frame lost: before, "the longest clean
    segment has 2 frames" (exit 2); now the whole recording on its grid, the lost place
    masked, the rate and N right and the curve to T/4 (the report's)."""
    frame = received(120_000, lost=((50_000, 1),))
    n_gyro, _ = write_imu_bag(tmp_path / "pairs.mcap", stamped("burst2", frame))
    result = imupipe.analyze(tmp_path / "pairs.mcap", tmp_path / "out", rrd=False, loop=False)
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["input"]["counts"]["missed_frames"] == 1
    assert report["input"]["rate_hz"] == pytest.approx(200 / (1 + 30e-6), rel=1e-5)
    for name in ("gyro_x", "gyro_y", "gyro_z"):
        n = result.axes[name].terms.random_walk
        assert n.lo <= n_gyro <= n.hi, (name, n)
        assert 600 / 4 / 10**0.1 < max(result.axes[name].curve.tau_s) <= 600 / 4


def test_a_bag_losing_three_percent_of_its_frames_is_analysed_and_says_where_it_stops(
    tmp_path: Path,
) -> None:
    """3 % of the messages lost at random: every Allan term longer than a few hundred samples
    touches a masked place.  The closed loop crashed on it ("internal error: averaging factors
    must lie in 1..N": no τ of the curve reached a block of its time-domain tests); now the
    analysis completes and a warning says how far the curve goes and why."""
    rng = np.random.default_rng(3)
    frame = np.flatnonzero(rng.random(113_000) > 0.03)  # 565 s: the loop's blocks are 1 s
    write_imu_bag(tmp_path / "lossy.mcap", frame * PERIOD_NS)
    result = imupipe.analyze(tmp_path / "lossy.mcap", tmp_path / "out", rrd=False, figures=False)
    stops = [w for w in result.input.warnings if "the Allan variance stops at τ = " in w]
    assert len(stops) == 1 and "cannot be told from this recording" in stops[0]
    said = float(re.search(r"stops at τ = ([0-9.]+) s", stops[0]).group(1))
    for axis in result.axes.values():  # the curve's last τ of its grid (10 a decade) below it
        assert said / 10**0.1 < max(axis.curve.tau_s) <= said


def test_a_bag_losing_one_percent_of_its_frames_keeps_its_long_taus(tmp_path: Path) -> None:
    """1 % of the messages lost at random, one or two at a time: skipped, no Allan term longer
    than a few seconds would be free of them (the curve stopped at 1.6 s of 30 min).  At the τ
    where skipping leaves fewer than half the terms they are read as their fill: the curve
    reaches T/4 and N, fitted where they are skipped, keeps its interval around the truth."""
    rng = np.random.default_rng(5)
    frame = np.flatnonzero(rng.random(113_000) > 0.01)
    n_gyro, n_accel = write_imu_bag(tmp_path / "lossy.mcap", frame * PERIOD_NS)
    result = imupipe.analyze(tmp_path / "lossy.mcap", tmp_path / "out", rrd=False, figures=False)
    said = [w for w in result.input.warnings if "are read by the Allan variance as their fill" in w]
    lost = 113_000 - len(frame)
    assert len(said) == 1 and said[0].startswith(f"{lost} masked samples in ")
    assert f"({100 * lost / 113_000:.3g} % of the grid)" in said[0]
    assert said[0].endswith(
        f"now {113_000} ({113_000 * PERIOD_NS * 1e-9:.4g} s); the fill carries no noise, so "
        f"there a white noise' Allan variance reads low by about {100 * lost / 113_000:.2g} %"
    )
    assert not any("the Allan variance stops at" in w for w in result.input.warnings)
    (masked,) = [w for w in result.input.warnings if w.startswith("analysing the whole")]
    assert masked.endswith(
        "Allan variance terms touching them are skipped (the short runs only where that "
        "leaves half the terms: below)"
    )
    seconds = 113_000 * PERIOD_NS * 1e-9
    covered = 0
    for name, axis in result.axes.items():
        assert seconds / 4 / 10**0.1 < max(axis.curve.tau_s) <= seconds / 4, name
        n, truth = axis.terms.random_walk, n_gyro if name.startswith("gyro") else n_accel
        assert n.value == pytest.approx(truth, rel=0.015), name
        covered += n.lo <= truth <= n.hi
        assert not axis.loop.accepted, name  # white noise: nothing to add
    # 95 % intervals (36 axes of six such bags: 33 held the truth, N 0.9985 × it on average)
    assert covered >= 5
