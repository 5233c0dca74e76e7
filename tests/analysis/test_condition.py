"""Conditioning: every break in uniform sampling is found, cut around and reported."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from imupipe.analysis.condition import (
    condition,
    fill_runs,
    two_sensors,
    unanalysable,
    window_rows,
)
from imupipe.errors import ImupipeError
from imupipe.io.decode import ImuRecording
from imupipe.vocab import AXES


def recording(n: int = 1000, rate: float = 100.0, seed: int = 0, **edits) -> ImuRecording:
    """A clean synthetic recording; ``edits`` mutate numpy columns before the frame is built."""
    rng = np.random.default_rng(seed)
    cols = {
        "stamp_ns": (np.arange(n) * (1e9 / rate)).astype(np.int64),
        "counter": np.arange(n, dtype=np.int64),
        **{a: rng.normal(0, 1, n) for a in AXES},
        "saturated": np.zeros(n, bool),
        "flag_ea": np.zeros(n, bool),
        "flag_nd": np.ones(n, bool),
    }
    for key, fn in edits.items():
        fn(cols[key])
    frame = pl.DataFrame(
        {
            "stamp_ns": cols["stamp_ns"],
            "log_time_ns": cols["stamp_ns"],
            **{a: cols[a] for a in AXES},
            "temp_c": np.full(n, 21.0),
            "supply_v": np.full(n, 5.0),
            "counter": (cols["counter"] % (1 << 32)).astype(np.uint32),
            "flag_nd": cols["flag_nd"],
            "flag_ea": cols["flag_ea"],
            "saturated": cols["saturated"],
            "diag_stat": np.zeros(n, np.uint16),
            "t_s": (cols["stamp_ns"] - cols["stamp_ns"][0]) / 1e9,
        }
    )
    return ImuRecording(
        frame, Path("x.mcap"), "/imu", "test", "header.stamp", {"output_rate_hz": str(rate)}
    )


def test_an_axis_beyond_the_float_range_names_its_largest_magnitude() -> None:
    y = np.random.default_rng(0).normal(0, 1, 1000)
    y[5] = -3e101  # the negative extreme is the largest in magnitude
    assert unanalysable(y) == "reaches 3e+101, beyond what float64 Allan sums hold (1e100)"


def test_a_constant_axis_with_a_few_glitches_names_how_many() -> None:
    """0.25 in every sample but one above it and one below (of 5000: fewer than 1 in 1000): no
    noise, said with the count of glitches (both directions: a value differs from the usual
    one whether it is higher or lower)."""
    y = np.full(5000, 0.25)
    y[1000], y[3000] = 0.5, -1.0
    assert unanalysable(y) == "is constant but for 2 sample(s) (glitches?)"


def test_clean_recording_is_one_segment() -> None:
    s = condition(recording())
    assert len(s.segments) == 1 and s.segment.frames == 1000
    assert s.tau0_s == pytest.approx(0.01)
    assert s.warnings == ()


def test_one_missing_frame_splits_and_longest_is_chosen() -> None:
    def missing(i):
        def fn(a):
            a[i:] += 10_000_000 if a.dtype == np.int64 and a.max() > 1e6 else 1

        return fn

    rec = recording(stamp_ns=missing(300), counter=missing(300))
    s = condition(rec, gaps="longest")
    assert [seg.frames for seg in s.segments] == [300, 700]
    # each segment's first and last stamp (s from the first frame): the lost frame's 10 ms
    ends = [t for g in s.segments for t in (g.t_start_s, g.t_stop_s)]
    assert ends == pytest.approx([0.0, 2.99, 3.01, 10.0], abs=1e-9)
    assert s.segment.frames == 700 and s.chosen == 1 and s.rows == slice(300, 1000)
    assert s.counts["missed_frames"] == 1
    assert any("gap" in w for w in s.warnings)
    assert any("longest clean segment" in w for w in s.warnings)
    with pytest.raises(ImupipeError, match="segments"):
        condition(rec, gaps="fail")
    # the default masks a gap this short: the whole recording, the lost frame's place excluded
    auto = condition(rec)
    assert auto.rows == slice(0, 1000) and np.flatnonzero(auto.excluded).tolist() == [300]
    assert not any("longest clean segment" in w for w in auto.warnings)


def test_auto_policy_masks_gaps_up_to_an_hour_and_the_longest_segment_beyond() -> None:
    """``"auto"`` (the default) masks when no gap exceeds AUTO_MAX_GAP_S (1 h = 3600 frames at
    1 Hz here) and analyses the longest segment, saying why, across a longer one."""

    def gap(frames):
        def fn(a):
            a[4000:] += frames * (10**9 if a.max() > 1e6 else 1)

        return fn

    n = 10_000
    short = condition(recording(n, rate=1.0, stamp_ns=gap(3600), counter=gap(3600)))
    assert short.excluded is not None and int(short.excluded.sum()) == 3600
    long = condition(recording(n, rate=1.0, stamp_ns=gap(3601), counter=gap(3601)))
    assert long.excluded is None and long.rows == slice(4000, n)
    assert any("a gap of 3601 s, longer than the 3600 s" in w for w in long.warnings)
    assert any("longest clean segment" in w for w in long.warnings)


def test_hour_long_gap_in_time_only() -> None:
    def gap(a):
        a[600:] += 3600 * 10**9

    s = condition(recording(stamp_ns=gap))
    assert [seg.frames for seg in s.segments] == [600, 400]
    assert s.counts["gaps"] == 1


def test_duplicate_and_backwards_stamps() -> None:
    def dup(a):
        a[100] = a[99]
        a[500] = a[498]

    s = condition(recording(stamp_ns=dup))
    assert s.counts["duplicate_stamps"] == 1
    assert s.counts["non_monotonic_stamps"] == 1
    assert len(s.segments) >= 3


def test_nonfinite_and_saturated_rows_are_cut_out() -> None:
    def nan(a):
        a[200] = np.nan
        a[201] = np.inf

    def sat(a):
        a[800] = True

    rec = recording(gyro_y=nan, saturated=sat)
    s = condition(rec, gaps="longest")
    assert s.counts["nonfinite_frames"] == 2
    assert s.counts["saturated_frames"] == 1
    assert [seg.frames for seg in s.segments] == [200, 598, 199]
    assert np.isfinite(rec.frames[s.rows].select(AXES).to_numpy()).all()


def test_counter_wrap_is_not_a_gap() -> None:
    def wrap(a):
        a += (1 << 32) - 500

    s = condition(recording(counter=wrap))
    assert len(s.segments) == 1
    assert s.counts["counter_wraps"] == 1


def test_stuck_channel_and_flags_are_reported() -> None:
    def stuck(a):
        a[:] = 0.25

    def ea(a):
        a[10:20] = True

    def nd(a):
        a[5] = False

    rec = recording(accel_z=stuck, flag_ea=ea, flag_nd=nd)
    before = rec.frames.clone()
    s = condition(rec)
    assert rec.frames.equals(before)  # read, never changed
    y = {a: rec.frames[a][s.rows].to_numpy() for a in AXES}
    assert [a for a in AXES if unanalysable(y[a])] == ["accel_z"]  # the orchestrator's test
    assert s.counts["flagged_frames"] == 10 and s.counts["stale_frames"] == 1
    assert len(s.segments) == 1


def test_drifting_rate_uses_measured_mean_period() -> None:
    n = 2000
    t = np.cumsum(np.full(n, 0.0102)) * 1e9  # host timer 2 % slow

    def slow(a):
        a[:] = t.astype(np.int64)

    s = condition(recording(n=n, stamp_ns=slow))
    assert s.tau0_s == pytest.approx(0.0102, rel=1e-6)
    assert (
        "measured mean rate 98.0392 Hz differs from the nominal 100 Hz; the measured rate is used"
        in s.warnings
    )


def test_jittery_stamps_warn() -> None:
    rng = np.random.default_rng(1)

    def jitter(a):
        a += (rng.uniform(-3e6, 3e6, len(a))).astype(np.int64)

    def late_start(a):
        jitter(a)
        a[10:] += 3_600 * 10**9  # an hour's gap: the analysed segment starts at row 10

    rec = recording(stamp_ns=late_start)
    s = condition(rec)
    assert [(g.start, g.stop) for g in s.segments] == [(0, 10), (10, 1000)]
    # the rms jitter of the steps over their mean, written out with numpy's std (ddof 0)
    steps = np.diff(rec.frames["t_s"].to_numpy()[10:])
    expected = np.std(steps) / np.mean(steps)
    assert s.counts["jitter_ppm"] == round(expected * 1e6)
    assert f"stamp jitter is {100 * expected:.0f} % of the sample period" in s.warnings[-1]


def test_single_frame_is_an_error() -> None:
    with pytest.raises(ImupipeError, match="too few"):
        condition(recording(n=1))


@pytest.mark.parametrize("chunk", [1, 2, 7, 64])
def test_chunked_step_scan_equals_one_pass(monkeypatch, chunk) -> None:
    """Steps are examined a chunk at a time (no full-length step array): every break, count
    and warning must equal the one-pass result, also for bad stamps on chunk boundaries."""
    import imupipe.analysis.condition as cond

    def anomalies(a):
        a[7] = a[6]  # duplicate at a boundary of chunks of 7
        a[14] = a[12]  # backwards, then the long step that makes up for it
        a[64:] += 37_000_000  # gap on a boundary of chunks of 64
        a[300:] += 3_600 * 10**9  # an hour

    def counter(a):
        a += (1 << 32) - 100  # wraps at row 100
        a[500:] += 3  # three frames missed

    rng = np.random.default_rng(3)

    def jitter(a):
        a += rng.integers(-200_000, 200_000, len(a))

    def both(a):
        jitter(a)
        anomalies(a)

    rec = recording(n=1000, stamp_ns=both, counter=counter)
    reference = condition(rec)
    monkeypatch.setattr(cond, "_CHUNK", chunk)
    chunked = condition(rec)
    assert chunked.segments == reference.segments
    assert chunked.counts == reference.counts
    assert chunked.warnings == reference.warnings
    assert chunked.tau0_s == reference.tau0_s
    assert reference.counts["counter_wraps"] == 1
    assert reference.counts["duplicate_stamps"] == 1
    assert reference.counts["non_monotonic_stamps"] == 1
    assert reference.counts["gaps"] == 3 and reference.counts["missed_frames"] == 3
    assert [(s.start, s.stop) for s in reference.segments] == [
        (0, 7), (7, 14), (14, 64), (64, 300), (300, 500), (500, 1000)
    ]  # fmt: skip


@pytest.mark.parametrize("missing", [1, 3])
def test_dropped_messages_without_a_frame_counter_are_a_gap(missing: int) -> None:
    # a ROS Imu stream has no frame counter: the stamps alone must reveal the dropped messages
    def drop(a):
        a[500:] += missing * 10_000_000

    rec = recording(stamp_ns=drop)
    rec = ImuRecording(
        rec.frames.with_columns(pl.lit(None, dtype=pl.UInt32).alias("counter")),
        rec.path,
        rec.topic,
        "sensor_msgs/msg/Imu",
        rec.time_source,
        rec.device,
    )
    s = condition(rec)
    assert [seg.frames for seg in s.segments] == [500, 500]
    assert (s.counts["gaps"], s.counts["missed_frames"]) == (1, missing)
    assert f"1 gap(s) in time or frame counter ({missing} frames missing)" in " ".join(s.warnings)


def test_mask_policy_keeps_the_whole_recording_around_a_missing_frame() -> None:
    """One lost frame (stamp and counter skip) and a NaN row: with ``gaps="mask"`` nothing is
    thrown away; the grid has a place for the lost frame, and both places are excluded."""

    def missing(a):
        a[300:] += 10_000_000 if a.max() > 1e6 else 1

    def nan(a):
        a[700] = np.nan

    rec = recording(stamp_ns=missing, counter=missing, gyro_x=nan)
    s = condition(rec, gaps="mask")
    assert s.rows == slice(0, 1000) and s.samples == 1001 and s.usable_samples == 999
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), [300, 701])
    assert s.grid_index[299:302].tolist() == [299, 301, 302]
    assert s.counts["masked_samples"] == 2 and s.counts["missed_frames"] == 1
    assert s.tau0_s == pytest.approx(0.01)
    assert any("2 masked (0.2 %" in w for w in s.warnings)
    assert not any("longest clean segment" in w for w in s.warnings)
    assert not any("measured mean rate" in w for w in s.warnings)
    x = rec.frames["gyro_x"][s.rows].to_numpy()
    y = s.on_grid(x)
    # each hole: the mean of the 0.5 s (50 samples) of usable data either side, not of the
    # two neighbouring samples (a whole sample-noise sigma off: an event at every gap)
    assert y[300] == pytest.approx((x[250:300].mean() + x[300:350].mean()) / 2, rel=1e-12)
    assert y[701] == pytest.approx((x[650:700].mean() + x[701:751].mean()) / 2, rel=1e-12)
    assert y[702] == x[701] and np.isfinite(y).all()


def test_mask_policy_uses_the_measured_mean_period_of_a_slow_host_timer() -> None:
    """A host timer 2 % slow (stamps every 10.2 ms, the device's 100 Hz in the metadata) with
    one lost frame: the grid's sample interval is the measured mean period, the nominal rate is
    still reported, and a warning names both."""
    n = 2000
    t = (np.arange(n) * 0.0102 * 1e9).astype(np.int64)
    t += np.random.default_rng(2).integers(-100_000, 100_000, n)  # 0.1 ms of jitter
    t[900:] += 10_200_000  # the lost frame

    def stamps(a):
        a[:] = t

    def missing(a):
        a[900:] += 1

    s = condition(recording(n=n, stamp_ns=stamps, counter=missing), gaps="mask")
    assert s.samples == n + 1 and np.flatnonzero(s.excluded).tolist() == [900]
    assert s.tau0_s == pytest.approx((t[-1] - t[0]) / n / 1e9, rel=1e-12)  # first to last
    assert s.nominal_rate_hz == 100.0
    rate = n * 1e9 / (t[-1] - t[0])  # 98.039 Hz
    assert (
        f"measured mean rate {rate:.4f} Hz differs from the nominal 100 Hz; the measured rate is "
        "used" in s.warnings
    )


def test_fill_runs_draws_a_line_between_the_means_either_side() -> None:
    y = np.arange(20.0)
    holes = np.zeros(20, dtype=bool)
    holes[[0, 1, 5, 6, 7, 12, 19]] = True
    holes[9] = True  # a hole inside the right span of 5..7: left out of its mean
    fill_runs(y, holes, 3)
    # 0-1: the record starts there, so the mean after, of 2, 3, 4; 5-7: from mean(2, 3, 4) = 3
    # to mean(8, 10) = 9 (9 is a hole); 9: from 8 (6, 7 are holes) to mean(10, 11) = 10.5
    # (12 is a hole); 12: from 10.5 to mean(13, 14, 15) = 14; 19: the record ends, 17 alone
    np.testing.assert_allclose(
        y, [3, 3, 2, 3, 4, 4.5, 6, 7.5, 8, 9.25, 10, 11, 12.25, 13, 14, 15, 16, 17, 18, 17]
    )


def test_mask_policy_falls_back_when_most_of_the_grid_is_a_gap() -> None:
    def gap(a):
        a[600:] += 3600 * 10**9

    s = condition(recording(stamp_ns=gap), gaps="mask")
    assert s.excluded is None and s.segment.frames == 600
    assert any("more than 50 % of the sample grid" in w for w in s.warnings)


@pytest.mark.parametrize("policy", ["mask", "auto"])
def test_a_stamp_damaged_into_the_far_future_allocates_no_grid_for_it(policy, monkeypatch):
    """A flipped high bit in one stamp (found fuzzing a SQLite bag: a grid of 6.7e9 samples,
    6.25 GiB, and `internal error: MemoryError`): the grid would be almost all gap, so the
    longest segment is analysed, and no array of the grid's size is ever made."""

    def damaged(a):
        a[-1] += 1 << 62  # ns: 146 years late

    ones = np.ones

    def small_only(shape, *args, **kwargs):
        assert np.prod(shape) < 10**6, shape
        return ones(shape, *args, **kwargs)

    monkeypatch.setattr(np, "ones", small_only)
    s = condition(recording(stamp_ns=damaged), gaps=policy)
    assert s.excluded is None and s.segment.frames == 999
    assert any("more than 50 % of the sample grid" in w for w in s.warnings)


def test_mask_policy_duplicate_stamp_row_is_excluded_not_shifted() -> None:
    def dup(a):
        a[100] = a[99]

    s = condition(recording(stamp_ns=dup), gaps="mask")
    assert s.samples == 1000  # the counter keeps every row in its place
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), [100])


def test_rate_without_a_configured_one_is_the_median_stamp_step() -> None:
    """A stream that does not state its rate (a plain ROS bag): 1 / median step, here the
    ADIS16364's 819.2 Hz."""
    rec = recording(rate=819.2)
    rec = ImuRecording(rec.frames, rec.path, rec.topic, rec.source, rec.time_source, {})
    s = condition(rec)
    assert s.nominal_rate_hz == pytest.approx(819.2, rel=1e-6)
    assert s.tau0_s == pytest.approx(1 / 819.2, rel=1e-6, abs=0)
    assert len(s.segments) == 1 and s.segment.frames == 1000 and s.warnings == ()


def test_rate_cannot_be_told_from_stamps_that_never_increase() -> None:
    rec = recording(stamp_ns=lambda a: a.fill(5))
    rec = ImuRecording(rec.frames, rec.path, rec.topic, rec.source, rec.time_source, {})
    with pytest.raises(ImupipeError, match="cannot tell the sample rate"):
        condition(rec)


def test_repeated_counter_is_a_break_not_a_wrap() -> None:
    """The same frame read twice (counter does not advance): cut there, no wrap counted."""

    def repeat(a):
        a[400:] -= 1

    s = condition(recording(counter=repeat))
    assert s.counts["counter_wraps"] == 0 and s.counts["missed_frames"] == 0
    assert [(g.start, g.stop) for g in s.segments] == [(0, 400), (400, 1000)]


def test_gap_at_the_last_step_of_two_frames() -> None:
    def late(a):
        a[1] = 1_000_000_000  # 1 s after the first frame at 100 Hz

    s = condition(recording(n=2, stamp_ns=late))
    assert s.counts["gaps"] == 1
    assert [(g.start, g.stop) for g in s.segments] == [(0, 1), (1, 2)]


def test_mask_policy_backwards_stamp_row_is_excluded() -> None:
    """A stamp going backwards: its row's time is wrong, so its grid place is masked."""

    def backwards(a):
        a[100] = a[99] - 1_000_000  # 1 ms before its predecessor

    s = condition(recording(stamp_ns=backwards), gaps="mask")
    assert s.samples == 1000 and s.counts["non_monotonic_stamps"] == 1
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), [100])


def test_mask_policy_stamp_two_periods_back_does_not_shift_the_grid() -> None:
    """One stamp 2 periods back (counter right): only its row is masked; the row after it is
    placed by the counter (the span from the row before agrees), not by its 3-period stamp
    step."""

    def backwards(a):
        a[100] = a[98]

    s = condition(recording(stamp_ns=backwards), gaps="mask")
    assert s.samples == 1000 and s.tau0_s == pytest.approx(0.01, rel=1e-9)
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), [100])


def test_mask_policy_one_stamp_ahead_does_not_shift_the_grid() -> None:
    """One stamp 7 periods ahead, the next ones right (counter right): the row is placed by
    the counter (no 6-sample hole); it and the row after it (stamp step backwards) are
    masked."""

    def ahead(a):
        a[200] += 60_000_000

    s = condition(recording(stamp_ns=ahead), gaps="mask")
    assert s.samples == 1000
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), [200, 201])


def test_mask_policy_stamp_gap_wins_over_a_counter_that_disagrees() -> None:
    """Stamps jump 7 periods where the counter steps by 1: the stamps place the row (6 grid
    samples masked) and the row itself is uncertain, masked too."""

    def jump(a):
        a[300:] += 60_000_000

    s = condition(recording(stamp_ns=jump), gaps="mask")
    assert s.samples == 1006
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), np.arange(300, 307))


def test_mask_policy_two_stamps_wrong_in_a_row_are_bridged_only_if_their_span_agrees() -> None:
    """Row 200 stamped 6 periods late and every row after it 12 (counter steps of 1): the two
    steps around row 200 disagree with the counter and so does their span (14 periods against
    2), so nothing is bridged: the stamps place the rows, 12 grid places are missing and rows
    200 and 201 are uncertain.  (A span read wrong, as about 1 period, would agree with the
    counter's 2 within one sample and pull the rows back onto 1000 places.)"""

    def two(a):
        a[200] += 60_000_000
        a[201:] += 120_000_000

    s = condition(recording(stamp_ns=two), gaps="mask")
    assert s.samples == 1012
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), np.arange(200, 214))


def test_mask_policy_repeated_counter_row_is_masked_not_stacked() -> None:
    """A counter that does not advance (stamps fine): the row is uncertain and masked; the rows
    after it keep their places."""

    def repeat(a):
        a[400:] -= 1

    s = condition(recording(counter=repeat), gaps="mask")
    assert s.samples == 1000
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), [400])


def test_mask_policy_long_gap_counter_must_agree_within_one_percent() -> None:
    """Stamps jump 198 periods, the counter 196: off by 2 > 1 % of 198, so the stamps place the
    row (197 grid samples masked) and the row itself is uncertain."""

    def stamps(a):
        a[300:] += 197 * 10_000_000

    def counter(a):
        a[300:] += 195

    s = condition(recording(stamp_ns=stamps, counter=counter), gaps="mask")
    assert s.samples == 1197
    np.testing.assert_array_equal(np.flatnonzero(s.excluded), np.arange(300, 498))


def test_a_block_of_stamps_that_do_not_advance_is_no_rate() -> None:
    """5000 stamps frozen inside a 100 Hz recording (a clock that stopped): whole blocks of 256
    steps with a median step of 0.  They were taken for a part at a rate of its own, and the
    rate-change warning divided by that step (ZeroDivisionError, found by fuzzing); they are
    counted as duplicate stamps, with no rate of their own."""

    def freeze(a):
        a[3000:8000] = a[3000]

    s = condition(recording(n=20_000, stamp_ns=freeze))
    assert s.nominal_rate_hz == 100.0
    assert not any("sample rate changes" in w for w in s.warnings)
    assert s.counts["duplicate_stamps"] == 4999


def test_a_rate_switch_early_in_a_block_is_found_to_the_row() -> None:
    """200 Hz for 3100 frames, then 100 Hz: the switch lies 28 steps into a block of 256 (steps
    3072..3327), whose median step is already the new rate's.  The 100 Hz part starts at frame
    3100 exactly, so no 200 Hz row is read as if it were at 100 Hz (which the measured mean
    rate would show)."""

    def stamps(a):
        a[:3100] = np.arange(3100) * 5_000_000
        a[3100:] = a[3099] + np.arange(1, len(a) - 3099) * 10_000_000

    rec = recording(n=10_000, stamp_ns=stamps)
    s = condition(replace(rec, device={}))
    assert s.warnings == (
        "the sample rate changes 1 time(s) (200 Hz from frame 0, 100 Hz from frame 3100): "
        "analysing the longest part at one rate, frames 3100..9999 (100 Hz)",
    )
    assert s.rows == slice(3100, 10_000) and s.tau0_s == pytest.approx(0.01, rel=1e-9)


def test_the_masked_grid_of_the_part_at_one_rate_reads_that_parts_rows() -> None:
    """3000 frames at 200 Hz, then 12000 at 100 Hz that lost one frame: the 100 Hz part is kept
    and, for its missing frame, analysed on its sample grid.  The grid's rows are that part's;
    they were rows 0… of the recording (the 200 Hz part's, here 1000 rad/s on gyro_x, read as
    if they were the 100 Hz part's: found by fuzzing, as NaN of the wrong rows)."""

    def stamps(a):
        a[:3000] = np.arange(3000) * 5_000_000
        a[3000:] = a[2999] + 5_000_000 + np.arange(12_000) * 10_000_000
        a[9000:] += 10_000_000  # one frame lost

    def counter(a):
        a[9000:] += 1

    def first_part(a):
        a[:3000] = 1000.0

    rec = recording(n=15_000, stamp_ns=stamps, counter=counter, gyro_x=first_part)
    rec = ImuRecording(rec.frames, rec.path, rec.topic, rec.source, rec.time_source, {})
    s = condition(rec)
    assert s.excluded is not None and s.excluded.sum() == 1  # the lost frame, masked
    start = s.rows.start
    assert 3000 <= start <= 3000 + 256 and s.rows.stop == 15_000
    assert s.tau0_s == pytest.approx(0.01)
    y = rec.frames["gyro_x"].to_numpy()
    on_grid = s.on_grid(y[s.rows])
    assert np.abs(on_grid).max() < 10  # no row of the 200 Hz part
    np.testing.assert_array_equal(on_grid[:5], y[start : start + 5])


def test_window_rows_from_start_to_end_or_before_the_last_frame() -> None:
    t = np.arange(1000) * 0.01  # 0 .. 9.99 s
    assert window_rows(t, 2.0, 5.0) == slice(200, 501)  # both ends stamped in
    assert window_rows(t, 2.005, 5.005) == slice(201, 501)
    assert window_rows(t, 0.0, -1.0) == slice(0, 900)  # up to 8.99 s: 1 s before 9.99 s
    assert window_rows(t, 9.5) == slice(950, 1000)  # to the last frame
    assert window_rows(t, 10.5) == slice(1000, 1000)  # past the end: empty
    back = t.copy()
    back[300] = 1.0  # a stamp going backwards inside the window stays in it (a break to find)
    assert window_rows(back, 2.0, 5.0) == slice(200, 501)


def test_a_window_is_conditioned_like_the_same_frames_alone() -> None:
    """--start 2 --end 6 on 10 s with a lost frame at 4 s: the same segments as conditioning
    rows 200..600 alone, at the recording's row numbers and times; the rate regime's and the
    mask's offsets add to the window's."""

    def lost(a):
        a[400:] += 10_000_000 if a.dtype == np.int64 and a.max() > 1e6 else 1

    rec = recording(stamp_ns=lost, counter=lost)
    windowed = condition(rec, "longest", 2.0, 6.0)
    alone = condition(replace(rec, frames=rec.frames.slice(200, 400)), "longest")
    assert windowed.window_s == (2.0, 6.0) and alone.window_s == (0.0, None)
    shift = [(s.start - 200, s.stop - 200, s.t_start_s, s.t_stop_s) for s in windowed.segments]
    assert shift == [(s.start, s.stop, s.t_start_s, s.t_stop_s) for s in alone.segments]
    assert [(s.start, s.stop) for s in windowed.segments] == [(200, 400), (400, 600)]
    masked = condition(rec, "mask", 2.0, 6.0)
    assert masked.rows == slice(200, 600) and masked.excluded.sum() == 1


@pytest.mark.parametrize(
    ("start", "end", "says"),
    [
        (20.0, None, "the window --start 20 --end (last frame) s holds 0 frame(s)"),
        (5.0, 5.001, "holds 1 frame(s) of a recording stamped 0..9.99 s"),
        (float("nan"), None, "needs a finite --start >= 0 and --end (s): --start nan"),
        (-1.0, None, "needs a finite --start >= 0"),
        (0.0, float("inf"), "--start 0 --end inf"),
    ],
)
def test_a_window_without_two_frames_or_not_finite_is_an_error(start, end, says) -> None:
    with pytest.raises(ImupipeError, match=re.escape(says)):
        condition(recording(), "auto", start, end)


def test_two_sensors_are_told_by_the_bias_or_the_noise_of_alternate_rows() -> None:
    """Rows alternating between two sensors: biases 0.05 apart on noise of 1 (means 1.6
    standard errors apart in a block of 4096: one sensor), 1 apart (32: two), or noise 1.6×
    apart; one sensor's white and random-walk rows read alike; under a block of rows, or no
    noise in any block, nothing is said."""
    rng = np.random.default_rng(8)
    n = 16 * 4096

    def interleaved(bias: float, noise: float) -> np.ndarray:
        y = rng.standard_normal(n)
        y[1::2] = bias + noise * y[1::2]
        return y

    assert two_sensors(interleaved(0.05, 1.0)) is None
    assert (
        two_sensors(interleaved(1.0, 1.0)) == "means 31.7 standard errors apart, noise 1.01× apart"
    )
    assert (
        two_sensors(interleaved(0.0, 1.6)) == "means 0.51 standard errors apart, noise 1.61× apart"
    )
    assert two_sensors(rng.standard_normal(n)) is None
    assert two_sensors(np.cumsum(rng.standard_normal(n))) is None  # slow parts cancel
    assert two_sensors(interleaved(1.0, 1.0)[:4095]) is None
    assert two_sensors(np.repeat([0.0, 1.0], n // 2)) is None  # no noise: no block to compare


@pytest.mark.parametrize("latency_ms", [0, 3, 15])
def test_a_clock_reset_left_in_the_stamps_keeps_the_sample_period(latency_ms: int) -> None:
    """Stamps of a clock reset after row 600 (back by 5000 s) and left as they are (more
    resets than the decoder places): the sample period is that of the steps within the runs,
    not of the end points (before session 40: negative, and an internal error in the fit),
    and the step jitter that of every step but the reset's (a host's 0-3 ms latency; 0-15 ms,
    whose steps also go back, by less than a period)."""
    rng = np.random.default_rng(4)

    def reset(a):
        a += rng.integers(0, latency_ms * 1_000_000 + 1, len(a))
        a[600:] -= 5_000 * 10**9

    rec = recording(2000, stamp_ns=reset)
    frames = rec.frames.with_columns(counter=pl.lit(None, dtype=pl.UInt32))  # an Imu topic's
    s = condition(replace(rec, frames=frames, device={}))
    assert s.tau0_s == pytest.approx(0.01, rel=2e-3 if latency_ms else 1e-12)
    if latency_ms:  # frames kept in order (the envelope's grid), the reset's step not a step
        steps = np.delete(np.diff(rec.frames["t_s"].to_numpy()), 599)
        expected = np.sqrt(np.mean((steps - s.tau0_s) ** 2)) / s.tau0_s
        assert s.counts["jitter_ppm"] == round(expected * 1e6)
        assert expected == pytest.approx(latency_ms / np.sqrt(6) / 10, rel=0.1)
    else:  # the row after the reset masked, the runs joined on the grid
        assert s.counts["non_monotonic_stamps"] == s.counts["masked_samples"] == 1
        assert s.counts["grid_samples"] == 2000
