"""Disturbance events found jointly on all axes and excised (issue 13 item 1).

The pipeline cases write a ROS 2 Imu MCAP (white + flicker noise of known N and B on six
axes), analyse it with ``imupipe.analyze`` and read report.json; the threshold cases call the
detector on fine block means of unit white noise, where the z of an injected box is known.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import special

import imupipe
from imupipe.analysis import events as ev
from imupipe.vocab import AXES

SCHEMA = Path(__file__).resolve().parents[2] / "schemas" / "report.schema.json"
RATE_HZ = 100.0
MINUTES = 40
N_TRUE = np.array([3e-4, 3e-4, 3e-4, 2e-3, 2e-3, 2e-3])  # unit/sqrt(Hz)
B_TRUE = np.array([2e-4, 2e-4, 2e-4, 1e-3, 1e-3, 1e-3])  # unit (flicker S = B^2 / (2 pi f))
BUMP = {"start_s": 1200.0, "duration_s": 20.0, "axes": ("gyro_y", "accel_x", "accel_z")}


def noise(seed: int) -> np.ndarray:
    """(n, 6) white + flicker rate noise with N_TRUE, B_TRUE (IEEE 952 Annex C PSDs)."""
    n = int(MINUTES * 60 * RATE_HZ)
    rng = np.random.default_rng(seed)
    tau0 = 1 / RATE_HZ
    f = np.fft.rfftfreq(2 * n, tau0)
    shape = np.zeros_like(f)
    shape[1:] = np.sqrt(2 * n / tau0 / (2 * np.pi * f[1:]))
    out = np.empty((n, 6))
    for j in range(6):
        bins = shape * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
        flicker = np.fft.irfft(bins / np.sqrt(2), 2 * n)[:n] * B_TRUE[j]
        out[:, j] = N_TRUE[j] / np.sqrt(tau0) * rng.standard_normal(n) + flicker
    out[:, 5] += 9.80665
    return out


def bump_size(j: int) -> float:
    """12 x the Allan deviation of axis j at the bump's duration (N^2/tau + 0.44 B^2)."""
    tau = BUMP["duration_s"]
    return float(12 * np.sqrt(N_TRUE[j] ** 2 / tau + 2 * np.log(2) / np.pi * B_TRUE[j] ** 2))


def with_bump(y: np.ndarray) -> np.ndarray:
    """The bump: +-:func:`bump_size` (alternating signs) on three axes."""
    y = y.copy()
    t = np.arange(len(y)) / RATE_HZ
    inside = (t >= BUMP["start_s"]) & (t < BUMP["start_s"] + BUMP["duration_s"])
    for k, name in enumerate(BUMP["axes"]):
        j = AXES.index(name)
        y[inside, j] += (-1) ** k * bump_size(j)
    return y


def write_mcap(imu_mcap, path: Path, y: np.ndarray, lost: slice = slice(0, 0)) -> Path:
    """An Imu MCAP of ``y`` at 100 Hz without the frames ``lost`` (a gap)."""
    stamps = 1_700_000_000_000_000_000 + np.arange(len(y), dtype=np.int64) * 10_000_000
    keep = np.ones(len(y), dtype=bool)
    keep[lost] = False
    stamps, y = stamps[keep], y[keep]
    return imu_mcap(path, {"/imu": (stamps, y[:, :3], y[:, 3:])}, chunk=1 << 16)


def analysed(imu_mcap, tmp: Path, y: np.ndarray, events: bool = True) -> dict:
    path = write_mcap(imu_mcap, tmp / "imu.mcap", y)
    out = tmp / f"out_{events}"
    imupipe.analyze(path, out, rrd=False, figures=False, loop=False, events=events)
    return json.loads((out / "report.json").read_text())


@pytest.fixture(scope="module")
def reports(tmp_path_factory: pytest.TempPathFactory, imu_mcap) -> dict[str, dict]:
    """report.json of the same noise: clean, with the bump, with the bump and no event search."""
    y = noise(7)
    bumped = with_bump(y)
    return {
        "clean": analysed(imu_mcap, tmp_path_factory.mktemp("clean"), y),
        "bump": analysed(imu_mcap, tmp_path_factory.mktemp("bump"), bumped),
        "bump_kept": analysed(imu_mcap, tmp_path_factory.mktemp("kept"), bumped, events=False),
    }


def test_three_axis_bump_is_found_once_with_its_start_duration_axes_and_size(
    reports, schema_errors
) -> None:
    doc = reports["bump"]
    schema = json.loads(SCHEMA.read_text())
    assert schema_errors(doc, schema, schema) == []
    (found,) = doc["events"]["found"]
    assert found["kind"] == "transient"
    assert tuple(found["axes"]) == BUMP["axes"]
    assert found["start_s"] == pytest.approx(BUMP["start_s"], abs=1.0)  # one fine block (0.5 s)
    assert found["duration_s"] == pytest.approx(BUMP["duration_s"], abs=1.5)
    assert found["size"]["accel_x"]["value"] == pytest.approx(-bump_size(3), rel=0.25)
    assert found["size"]["accel_x"]["unit"] == "m/s^2"
    assert found["size"]["gyro_y"]["unit"] == "rad/s"
    assert found["size"]["accel_x"]["value"] * found["size"]["gyro_y"]["value"] < 0  # signs
    assert any("disturbance event (transient) at 1200" in w for w in doc["input"]["warnings"])


def test_the_bump_is_excised_on_every_axis_and_the_terms_return_to_the_clean_ones(
    reports,
) -> None:
    doc, clean = reports["bump"], reports["clean"]
    (found,) = doc["events"]["found"]
    cut = found["excised"]
    k = cut["samples"]
    assert cut["start_s"] <= BUMP["start_s"] and cut["stop_s"] >= sum(
        BUMP[x] for x in ("start_s", "duration_s")
    )
    assert doc["events"]["excised_samples"] == k
    for name in AXES:  # every axis, touched or not: runs of n - k samples, k + 2m - 1 terms lost
        allan = doc["axes"][name]["allan"]
        m = np.round(np.asarray(allan["tau_s"]) * RATE_HZ).astype(int)
        lost = np.asarray(clean["axes"][name]["allan"]["n_terms"])[: len(m)] - allan["n_terms"]
        np.testing.assert_array_equal(lost[m < 1000], (k + 2 * m - 1)[m < 1000])
    for name in BUMP["axes"]:
        j = AXES.index(name)
        terms = {c: reports[c]["axes"][name]["ieee952"] for c in ("bump", "clean")}
        n_hat = {c: t["random_walk"]["value"] for c, t in terms.items()}
        b_hat = {c: t["bias_instability"]["value"] for c, t in terms.items()}
        assert n_hat["bump"] == pytest.approx(N_TRUE[j], rel=0.02)
        assert n_hat["bump"] == pytest.approx(n_hat["clean"], rel=0.005)
        assert b_hat["bump"] == pytest.approx(b_hat["clean"], rel=0.10)
        assert b_hat["bump"] == pytest.approx(B_TRUE[j], rel=0.30)
        # what the excision undoes: the bump raises the deviation near its duration
        adev = {c: np.asarray(r["axes"][name]["allan"]["adev"]) for c, r in reports.items()}
        k = int(np.argmin(np.abs(np.asarray(clean["axes"][name]["allan"]["tau_s"]) - 20.0)))
        assert adev["bump_kept"][k] > 1.15 * adev["clean"][k]
        assert adev["bump"][k] == pytest.approx(adev["clean"][k], rel=0.03)


def test_a_gap_and_an_event_are_both_left_out_of_the_allan_sums(
    reports, tmp_path, imu_mcap
) -> None:
    """The bumped recording without 1 s of frames at 600 s (masked by the default gap
    policy): the same bump is found and excised, and every axis' Allan sums lose the terms
    that touch either the event or the gap."""
    path = write_mcap(
        imu_mcap, tmp_path / "imu.mcap", with_bump(noise(7)), lost=slice(60_000, 60_100)
    )
    imupipe.analyze(path, tmp_path / "out", rrd=False, figures=False, loop=False)
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    clean = reports["clean"]
    (found,) = doc["events"]["found"]
    assert tuple(found["axes"]) == BUMP["axes"]
    assert doc["input"]["counts"]["masked_samples"] == 100
    k = found["excised"]["samples"]
    for name in AXES:
        allan = doc["axes"][name]["allan"]
        m = np.round(np.asarray(allan["tau_s"]) * RATE_HZ).astype(int)
        lost = np.asarray(clean["axes"][name]["allan"]["n_terms"])[: len(m)] - allan["n_terms"]
        small = m < 1000  # the two runs' term windows do not overlap
        np.testing.assert_array_equal(lost[small], (k + 2 * m - 1 + 100 + 2 * m - 1)[small])


def test_clean_recording_yields_no_event_and_unchanged_numbers(reports, tmp_path, imu_mcap) -> None:
    clean = reports["clean"]
    assert clean["events"]["found"] == [] and clean["events"]["excised_samples"] == 0
    assert clean["events"]["detector"]["tests"] > 10_000
    common = clean["events"]["common_mode"]  # independent axes: no pair moves together
    assert common["pairs"] == []
    assert common["tests"] == 15 * len(clean["events"]["detector"]["scales"])
    off = analysed(imu_mcap, tmp_path, noise(7), events=False)
    assert "events" not in off
    for name in AXES:
        assert clean["axes"][name]["allan"] == off["axes"][name]["allan"]


def test_accelerometers_sharing_a_wander_are_reported_as_moving_together(
    tmp_path, imu_mcap
) -> None:
    """The three accelerometers share a white + flicker series as large as their own noise
    (pair correlation ~0.5 at every window): report.json names their three pairs and no other,
    report.md tabulates them, and the warning says so."""
    y = noise(7)
    y[:, 3:] += noise(8)[:, :1] * (N_TRUE[3] / N_TRUE[0])
    path = write_mcap(imu_mcap, tmp_path / "imu.mcap", y)
    out = tmp_path / "out"
    imupipe.analyze(path, out, rrd=False, figures=False, loop=False)
    doc = json.loads((out / "report.json").read_text())
    pairs = doc["events"]["common_mode"]["pairs"]
    assert sorted(tuple(p["axes"]) for p in pairs) == [
        ("accel_x", "accel_y"), ("accel_x", "accel_z"), ("accel_y", "accel_z")
    ]  # fmt: skip
    for p in pairs:
        shortest = p["correlation"][0]  # 0.5 s windows
        assert shortest["window_s"] == pytest.approx(0.5)
        assert 0.45 < shortest["value"] < 0.6 and p["p_value"] < 1e-16
    assert doc["events"]["found"] == []
    (warning,) = [w for w in doc["input"]["warnings"] if w.startswith("axes that move together")]
    assert "more pair" not in warning
    md = (out / "report.md").read_text()
    assert md.count("\n| accel_") == 3
    # a subsection after the events' own lines, inside their section
    together = md.index("### Axes that move together")
    assert md.index("None found.") < together < md.index("\n## ", together)


# --- the acceptance thresholds, on unit white noise of fine block means ---------------------

DT = ev.FINE_BLOCK_S
BLOCKS = 28_800  # 4 h of 0.5 s blocks
BOX = 16  # blocks: one window at the 8 s scale covers it exactly
AT = 9_600  # a multiple of the 8 s scale's stride


def unit_means(seed: int, axes: int = 6) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {AXES[j]: rng.standard_normal(BLOCKS) for j in range(axes)}


def limits(means: dict[str, np.ndarray]) -> tuple[float, float, np.ndarray]:
    """(z1, z2, residual scale of each axis) of the 8 s scale, whose windows cover the box."""
    x = np.column_stack(list(means.values()))
    (scale,) = [s for s in ev._scales(x, DT) if s.length == BOX]
    _, det = ev.find_events(means, DT, 50, BLOCKS * 50)
    k = det.scales_s.index(BOX * DT)
    return det.z_single[k], det.z_joint[k], scale.sigma


def with_box(
    means: dict[str, np.ndarray], heights: dict[str, float], sigma: np.ndarray
) -> dict[str, np.ndarray]:
    """A noise-free box of ``heights`` (z units of the 8 s scale) on the named axes: the
    window it fills has exactly that mean, and its local level (the median of the windows
    that share no block with it) is that of unit noise, ≈ 0."""
    out = {a: v.copy() for a, v in means.items()}
    for a, z in heights.items():
        out[a][AT : AT + BOX] = z * sigma[AXES.index(a)]
    return out


def found(means: dict[str, np.ndarray]) -> list[ev.DisturbanceEvent]:
    return ev.find_events(means, DT, 50, BLOCKS * 50)[0]


def test_z_scores_of_short_records_have_at_most_gaussian_tails() -> None:
    """Unit white block means, twelve 1 h records: |z| > 3 at most as often as a Gaussian's
    (0.66-0.88 of it at the first three scales).  Scaled by the spread of the residual against
    a median that contains the window, short records' z had heavier tails (1.2-1.3×)."""
    counts = np.zeros((3, 2))
    for seed in range(12):
        x = np.random.default_rng(seed).standard_normal((7_200, 6))
        for k, s in enumerate(ev._scales(x, DT)[:3]):
            counts[k] += [np.sum(np.abs(s.z) > 3.0), 2 * special.ndtr(-3.0) * s.z.size]
    ratio = counts[:, 0] / counts[:, 1]
    assert np.all(ratio < 0.95) and np.all(ratio > 0.6), ratio


@pytest.mark.parametrize("factor, expected", [(1.2, 1), (0.8, 0)])
def test_single_axis_threshold(factor: float, expected: int) -> None:
    means = unit_means(1)
    z1, _, sigma = limits(means)
    events = found(with_box(means, {"gyro_z": factor * z1}, sigma))
    assert len(events) == expected
    if expected:
        assert events[0].axes == ("gyro_z",) and events[0].start_s == AT * DT


@pytest.mark.parametrize("second, expected", [(1.2, 1), (0.8, 0)])
def test_two_axis_threshold(second: float, expected: int) -> None:
    """Both axes above z2 (each far below z1): an event; the second below z2: none."""
    means = unit_means(2)
    z1, z2, sigma = limits(means)
    assert 1.2 * z2 < 0.9 * z1
    events = found(with_box(means, {"gyro_x": 1.2 * z2, "accel_y": -second * z2}, sigma))
    assert len(events) == expected
    if expected:
        assert events[0].axes == ("gyro_x", "accel_y") and events[0].kind == "transient"
        assert events[0].duration_s == pytest.approx(BOX * DT, abs=DT)


def correlated_means(seed: int, rho: float) -> dict[str, np.ndarray]:
    """Unit white means whose six axes share a common part: correlation ``rho`` per pair."""
    rng = np.random.default_rng(seed)
    common = rng.standard_normal(BLOCKS)
    return {
        AXES[j]: np.sqrt(rho) * common + np.sqrt(1 - rho) * rng.standard_normal(BLOCKS)
        for j in range(6)
    }


def test_joint_tail_is_the_product_for_independent_axes_and_the_bivariate_normal_else() -> None:
    t = 4.5
    assert ev.joint_tail(t, np.array([0.0]))[0] == pytest.approx(4 * special.ndtr(-t) ** 2, 2e-3)
    # rho = 0.8 at t = 1.5: 2 [P(X > t, Y > t) + P(X > t, Y < -t)] by scipy's bivariate cdf
    assert ev.joint_tail(1.5, np.array([0.8, -0.8])) == pytest.approx([0.0697113] * 2, 1e-4)


@pytest.mark.parametrize("second, expected", [(1.05, 1), (0.85, 0)])
def test_correlated_axes_raise_the_two_axis_threshold(second: float, expected: int) -> None:
    """On axes that share noise (rho 0.7) two-axis coincidences are common: z2 rises above the
    independent-axes value, and a box between the two z2 is no event."""
    means = correlated_means(4, 0.7)
    z1, z2, sigma = limits(means)
    det = ev.find_events(means, DT, 50, BLOCKS * 50)[1]
    k = det.scales_s.index(BOX * DT)
    assert det.correlation[k] == pytest.approx(0.7, abs=0.05)
    dof = det.dof[k]
    independent = ev.thresholds(sum(det.windows), 6, dof)[1]
    assert z2 > independent + 0.4
    assert 1.05 * z2 < z1  # no single axis alone is an event
    boxed = {a: v.copy() for a, v in means.items()}
    for a, z in (("gyro_x", 1.05 * z2), ("accel_y", second * z2)):  # noise-free: z ~exact
        boxed[a][AT : AT + BOX] = z * sigma[AXES.index(a)]
    assert len(found(boxed)) == expected
    if expected == 0:  # the same box clears the independent-axes z2: a false alarm before
        assert second * z2 > independent


@pytest.mark.parametrize("after, kind", [(0.6, "step"), (0.0, "transient")])
def test_step_rule(after: float, kind: str) -> None:
    """An event that leaves the level changed by more than noise and than half its size is a
    step (kept), one whose level returns is a transient (excised)."""
    means = unit_means(3)
    height = 3.0  # per block: far beyond every threshold
    for a in ("accel_x", "accel_y"):
        means[a][AT : AT + 60] += height
        means[a][AT + 60 :] += after * height
    (event,) = found(means)
    assert event.kind == kind
    assert (event.excised is None) == (kind == "step")
    assert event.start_s == pytest.approx(AT * DT, abs=DT)
    assert set(event.axes) == {"accel_x", "accel_y"}
    assert event.level_change["accel_x"] == pytest.approx(after * height, abs=0.2)


def test_a_lasting_level_change_alone_is_no_event() -> None:
    """The local level is a running median, which keeps edges: a bias step without a
    transient leaves no residual and is left to the loop's bias_step candidate."""
    means = unit_means(3)
    means["accel_x"][AT:] += 3.0
    assert found(means) == []


def test_fill_excised_draws_a_line_between_the_levels_either_side() -> None:
    y = np.concatenate([np.full(100, 1.0), np.full(40, 50.0), np.full(100, 3.0)])
    event = ev.DisturbanceEvent(1.0, 0.4, ("gyro_x",), {}, {}, {}, "transient", (100, 140), 0.5)
    det = ev.EventDetector(DT, (), (), (), (), ("gyro_x",), ())
    filled = ev.fill_excised(y, ev.EventsFound(det, (event,), 0.01, 0.0))
    np.testing.assert_allclose(filled[100:140], np.linspace(1.0, 3.0, 42)[1:-1])
    assert filled[:100].tolist() == y[:100].tolist() and y[120] == 50.0
    mask = ev.event_mask([event], 240)
    assert mask.sum() == 40 and mask[100] and not mask[140]


def test_blocks_touching_a_gap_are_left_out_and_events_stay_on_the_record_grid() -> None:
    """Gap policy "mask": the blocks touching masked samples are left out and the blocks either
    side joined.  A gap whose fill sits 1.5 block sigmas off on every axis (what the fill from
    the two neighbouring samples did) is no event; a box after the gap is found where it is on
    the record's grid, and excised there."""
    means = unit_means(5)
    z1, _, sigma = limits(means)
    gap = slice(4_000, 4_704)  # blocks (352 s: the box stays aligned with the 8 s windows)
    for j, a in enumerate(AXES):
        means[a][gap] += 1.5 * sigma[j]
    means = with_box(means, {"gyro_z": 1.3 * z1}, sigma)
    excluded = np.zeros(BLOCKS * 50, dtype=bool)
    excluded[gap.start * 50 + 7 : gap.stop * 50 - 3] = True  # partial end blocks left out too
    units = dict.fromkeys(AXES, "rad/s")
    unmasked = ev.detect(means, DT / 50, BLOCKS * 50, units, 0.0).events
    assert any(e.start_s < gap.stop * DT and len(e.axes) == 6 for e in unmasked)
    (event,) = ev.detect(means, DT / 50, BLOCKS * 50, units, 0.0, excluded).events
    assert event.axes == ("gyro_z",) and event.start_s == pytest.approx(AT * DT, abs=2 * DT)
    assert event.duration_s == pytest.approx(BOX * DT, abs=2 * DT)
    a, b = event.excised
    assert a <= AT * 50 < (AT + BOX) * 50 <= b < (AT + BOX + 10) * 50


def test_residual_scale_is_sigma_on_gaussian_windows_and_the_tail_scale_on_heavy_ones() -> None:
    """The windows' residual scale: σ itself on Gaussian residuals (the winsorised SD; the tail
    quantile agrees), and on a heavy-tailed core (Student t, 3 dof) the (1 − p) quantile of
    |r| over the two-sided normal quantile Φ⁻¹(1 − p/2), so that core's tail is not read as
    events (p = TAIL_P = 1e-3: 3.29)."""
    rng = np.random.default_rng(7)
    assert ev._robust_scale(2.0 * rng.standard_normal(200_000)) == pytest.approx(2.0, rel=0.02)
    t = rng.standard_t(3, 200_000)
    tail = np.quantile(np.abs(t), 1 - 1e-3) / 3.2905267314918945
    assert ev._robust_scale(t) == pytest.approx(tail, rel=0.01)


def test_one_axis_recordings_are_searched_with_the_single_axis_threshold_alone() -> None:
    """A recording with one analysable axis (the MTi-G gyro; the others stuck): no pair rule
    (z2 = inf), and a box above z1 is found on it."""
    means = unit_means(1, axes=1)
    x = means["gyro_x"]
    (scale,) = [s for s in ev._scales(x[:, None], DT) if s.length == BOX]
    events, det = ev.find_events({"gyro_x": x + 0.0}, DT, 50, BLOCKS * 50)
    assert events == [] and set(det.z_joint) == {np.inf}
    k = det.scales_s.index(BOX * DT)
    x[AT : AT + BOX] += 1.2 * det.z_single[k] * scale.sigma[0]
    (event,) = ev.find_events({"gyro_x": x}, DT, 50, BLOCKS * 50)[0]
    assert event.axes == ("gyro_x",) and event.start_s == AT * DT


def test_the_longest_window_searched_is_512_s() -> None:
    """Scales double from one fine block up to MAX_SCALE_S = 512 s inclusive (a record long
    enough to hold more windows of 1024 s is not searched at 1024 s)."""
    x = np.random.default_rng(0).standard_normal((80_000, 2))  # 11 h of 0.5 s blocks
    lengths = [s.length * DT for s in ev._scales(x, DT)]
    assert lengths == [DT * 2**k for k in range(11)]  # 0.5 s ... 512 s


def test_the_box_search_of_a_day_long_event_stays_bounded() -> None:
    """An event of 172 800 fine blocks (24 h) is boxed on at most MAX_BOX_POINTS merged blocks
    (a (k + 1)² table of every [a, b): 0.24 TB unmerged), and the box is where the shift is,
    to one merged block (⌈172 800 / 1024⌉ = 169 fine blocks)."""
    e = np.zeros((172_800, 2))
    e[43_200:86_400] = 5.0  # the shift: 6 h to 12 h
    assert ev._best_box(e, np.ones(2)) == pytest.approx((43_200, 86_400), abs=169)


def test_winsorised_variance_constant_is_the_gaussian_expectation() -> None:
    """WINSOR_VAR = E[min(Z², c²)] for Z ~ N(0, 1), c = 3: by quadrature, independently of the
    closed form the module uses."""
    from scipy import integrate

    c = ev.WINSOR_C
    inside = integrate.quad(lambda z: z * z * np.exp(-z * z / 2) / np.sqrt(2 * np.pi), -c, c)[0]
    assert ev.WINSOR_VAR == pytest.approx(inside + c * c * 2 * special.ndtr(-c), rel=1e-12)


def test_a_perfectly_correlated_pair_exceeds_together_as_often_as_one_axis() -> None:
    """|ρ| = 1 (two axes carrying the same noise): P(|X| > t and |Y| > t) = P(|X| > t), to
    2 % (capped at 1 − 1e-9, the conditional law is a step that the quadrature's first node
    sits on: 1.8 % low at t = 3; a threshold moves by < 0.01 σ)."""
    t = 3.0
    single = 2 * special.ndtr(-t)
    assert ev.joint_tail(t, np.array([1.0, -1.0])) == pytest.approx([single] * 2, rel=0.02)


def test_the_event_box_weighs_each_axis_by_its_noise() -> None:
    """The box maximises Σ_axes (Σ e)² / (L v) with each axis' own block variance v: a 30 σ
    bump of 8 s on a quiet axis sets the event's extent over a 2 σ excursion of 32 s on a
    noisy one (read with equal weights, the noisy axis' 32 s would win)."""
    means = unit_means(6, axes=2)
    means["gyro_x"] *= 0.01
    means["gyro_x"][AT : AT + BOX] += 0.3
    means["gyro_y"][AT : AT + 4 * BOX] += 2.0
    (event,) = found(means)
    assert event.axes == ("gyro_x", "gyro_y")
    assert (event.start_s, event.duration_s) == (AT * DT, BOX * DT)


def test_the_levels_either_side_of_an_event_are_medians_over_60_s() -> None:
    """Size and level change read the level over LEVEL_SPAN_S = 60 s either side of the box:
    a baseline that moved by 10 σ only 20 s before a bump is mostly the old level in that
    minute, so the event carries a level change of about 10 σ (a transient still: less than
    half its size)."""
    means = unit_means(8, axes=2)
    for a in means:
        means[a][AT - 40 :] += 10.0
        means[a][AT : AT + BOX] += 30.0
    (event,) = found(means)
    assert (event.start_s, event.duration_s) == (AT * DT, BOX * DT)
    assert event.kind == "transient"
    for a in means:
        assert 8.5 < event.level_change[a] < 10.0


def swing(means: dict[str, np.ndarray], first: int, blocks: int, axes: tuple[str, ...]) -> dict:
    """A 0.7 Hz oscillation of 40 block sigmas over ``blocks`` fine blocks from ``first`` (a
    vibration burst, a robot carried about): zero mean, so no box of it stands out whole."""
    out = {a: v.copy() for a, v in means.items()}
    t = np.arange(blocks) * DT
    for k, a in enumerate(axes):
        out[a][first : first + blocks] += 40 * np.sin(2 * np.pi * 0.7 * t + k)
    return out


def test_an_oscillation_is_one_event_over_all_of_it_not_one_swing() -> None:
    """60 s of oscillation mid-record: one transient spanning the 60 s (the best box alone
    was one half-swing, 0.5 s, and the rest stayed in the data)."""
    (event,) = found(swing(unit_means(3), AT, 120, ("gyro_x", "accel_y", "accel_z")))
    assert event.kind == "transient" and {"gyro_x", "accel_y", "accel_z"} <= set(event.axes)
    assert event.start_s == pytest.approx(AT * DT, abs=DT)
    assert event.duration_s == pytest.approx(60.0, abs=2 * DT)


@pytest.mark.parametrize("at_end", [False, True])
def test_a_disturbance_from_the_first_tested_block_reaches_the_record_start(at_end) -> None:
    """A robot carried to its place for the first (or last) 60 s: the finest scale tests no
    window within 8 s of either end, so the event found from the first tested block on is
    taken to begin at the start (end at the end) of the record, and all of it is excised."""
    first = BLOCKS - 120 if at_end else 0
    (event,) = found(swing(unit_means(4), first, 120, AXES))
    a, b = event.excised
    assert event.kind == "transient"
    margin = round(max(ev.MARGIN_S, ev.MARGIN_FRACTION * 60.0) / DT)  # 3 s: 6 blocks
    if at_end:
        assert (a / 50, b) == (first - margin, BLOCKS * 50)
    else:
        assert (a, b / 50) == (0, 120 + margin)


def test_hull_spans_the_shortest_flagged_windows_and_reaches_an_end_from_its_untested_margin():
    n, tested = 1000, {1: (16, 984), 4: (32, 970), 16: (128, 880)}
    spans = np.array([(16, 17), (40, 41), (40, 44), (100, 116)])
    assert ev._hull(spans, np.array([1, 1, 4, 16]), tested, n) == (0, 41)  # from the start
    spans[0] = (17, 18)
    assert ev._hull(spans, np.array([1, 1, 4, 16]), tested, n) == (17, 41)  # 1 block: shortest
    assert ev._hull(spans[2:], np.array([4, 16]), tested, n) == (40, 44)  # 4 blocks: shortest
    assert ev._hull(np.array([(900, 966), (960, 970)]), np.array([4, 4]), tested, n) == (900, n)
    assert ev._hull(spans[3:], np.array([16]), tested, n) is None  # 8 s windows: the box only


def test_a_robot_carried_for_its_first_minute_gives_the_terms_of_the_rest(
    reports, tmp_path, imu_mcap
) -> None:
    """The first 60 s moved (0.4 rad/s, 1.5 m/s² swings), then 39 min at rest: the whole
    minute is excised and N is that of the clean record (it came out 100× too large)."""
    y = noise(7)
    t = np.arange(6000) / RATE_HZ
    for j in range(6):
        y[:6000, j] += (0.4 if j < 3 else 1.5) * np.sin(2 * np.pi * (0.3 + 0.1 * j) * t + j)
    doc = analysed(imu_mcap, tmp_path, y)
    (event,) = doc["events"]["found"]
    assert event["start_s"] == 0.0 and event["duration_s"] == pytest.approx(60.0, abs=1.0)
    assert event["excised"]["start_s"] == 0.0
    for name in AXES:
        n_hat = doc["axes"][name]["ieee952"]["random_walk"]["value"]
        clean = reports["clean"]["axes"][name]["ieee952"]["random_walk"]["value"]
        assert n_hat == pytest.approx(clean, rel=0.01)


def test_a_sustained_disturbance_does_not_set_the_tail_scale_that_would_hide_it() -> None:
    """30 000 Gaussian windows with 200 (0.7 %) swinging at ±40: the tail quantile leaves
    them out (the scale stays ~1; with them it was ~12 and hid them); scattered heavy tails
    (Student t, 3 dof) still set it, from every window."""
    rng = np.random.default_rng(11)
    r = rng.standard_normal(30_000)
    r[5_000:5_200] += 40 * np.sin(np.arange(200) * 2.2)
    marked = ev._sustained(r, 3.0)
    assert marked[5_000:5_200].mean() > 0.95 and marked[:4_980].sum() == 0
    assert marked[5_220:].sum() == 0
    assert ev._robust_scale(r) == pytest.approx(1.0, abs=0.1)
    heavy = rng.standard_t(3, 30_000)
    assert not ev._sustained(heavy, 3.0 * ev.robust.MAD_TO_SIGMA * np.median(np.abs(heavy))).any()
    tail = np.quantile(np.abs(heavy), 1 - ev.TAIL_P, method="higher") / -special.ndtri(
        ev.TAIL_P / 2
    )
    assert ev._robust_scale(heavy) == pytest.approx(tail, rel=1e-12)


def test_the_tail_scale_needs_ten_windows_beyond_its_quantile_once_sustained_ones_are_out():
    """Scattered heavy tails (Student t, 3 dof): 9 000 windows hold 9 beyond the 99.9 %
    quantile, too few, so the winsorised scale alone counts; 30 000 hold 30.  With 3 000 of
    12 000 in a sustained disturbance, the 9 000 left are too few as well."""
    rng = np.random.default_rng(12)
    few = rng.standard_t(3, 9_000)
    sigma0 = ev.robust.MAD_TO_SIGMA * np.median(np.abs(few))
    winsorised = np.sqrt(np.mean(np.clip(few, -3 * sigma0, 3 * sigma0) ** 2) / ev.WINSOR_VAR)
    assert ev._robust_scale(few) == pytest.approx(winsorised, rel=1e-12)
    many = rng.standard_t(3, 30_000)
    assert ev._robust_scale(many) > 1.2 * ev._robust_scale(many[:9_000])  # the tail floor
    mixed = np.concatenate([rng.standard_t(3, 9_000), 40 * np.sin(np.arange(3_000) * 2.2)])
    assert ev._sustained(mixed, 3.0).sum() >= 2_990
    sigma0 = ev.robust.MAD_TO_SIGMA * np.median(np.abs(mixed))
    clipped = np.clip(mixed, -3 * sigma0, 3 * sigma0)
    assert ev._robust_scale(mixed) == pytest.approx(
        np.sqrt(np.mean(clipped**2) / ev.WINSOR_VAR), rel=1e-12
    )


def test_overlapping_intervals_are_grouped_chained_and_touching() -> None:
    """[lo, hi] intervals given out of order: touching ends join (5's [5, 7] and 0's [7, 9]);
    an interval reaching any earlier member of a group joins it (4's [3, 4.5] starts after 3's
    [1, 2] ends, within 1's [0, 4]); ties in lo keep the order given; a gap of any size (2's
    [20, 21]) starts a group."""
    lo = [7.0, 0.0, 20.0, 1.0, 3.0, 5.0, 7.0 + 1e-9]
    hi = [9.0, 4.0, 21.0, 2.0, 4.5, 7.0, 8.0]
    groups = [g.tolist() for g in ev.overlapping_groups(lo, hi)]
    assert groups == [[1, 3, 4], [5, 0, 6], [2]]
    assert ev.overlapping_groups([], []) == []
    assert [g.tolist() for g in ev.overlapping_groups([3, 3, 3], [4, 4, 4])] == [[0, 1, 2]]


def test_without_the_event_search_a_stuck_axis_is_still_named_and_left_out(
    tmp_path, imu_mcap
) -> None:
    """``events=False``: no first pass finds the stuck axes, so the analysis' own pass does —
    the same warning and the same axes as with the search (2 min of white noise, accel_y
    constant)."""
    y = np.random.default_rng(3).normal(0.0, 1e-3, (12_000, 6))
    y[:, 4] = 0.25
    for events in (True, False):
        doc = analysed(imu_mcap, tmp_path, y, events=events)
        assert doc["input"]["warnings"] == [
            "accel_y is constant over the segment (stuck channel?): it is not analysed"
        ]
        assert sorted(doc["axes"]) == sorted(set(AXES) - {"accel_y"})


def test_a_spike_inside_an_excised_event_is_excised_with_it_not_as_an_outlier(
    tmp_path, imu_mcap
) -> None:
    """The bumped recording with a 30-sigma spike on gyro_y inside the bump: the event's fill
    replaces it, so no outlier is excised from the filled series (the first pass' outlier
    search, made on the series with the event in it, is not reused for it)."""
    y = with_bump(noise(7))
    at = int((BUMP["start_s"] + 5.0) * RATE_HZ)
    j = AXES.index("gyro_y")
    y[at, j] += 30 * N_TRUE[j] * np.sqrt(RATE_HZ)
    doc = analysed(imu_mcap, tmp_path, y)
    (found,) = doc["events"]["found"]
    assert found["excised"]["start_s"] < at / RATE_HZ < found["excised"]["stop_s"]
    assert "outliers" not in doc["axes"]["gyro_y"]
    assert not any("outlier" in w for w in doc["input"]["warnings"])


def test_the_warnings_say_which_events_were_excised_and_which_pairs_move_together() -> None:
    """One line an event (an excised transient, a step left to the loop), then the axes that
    move together; the detector's degrees of freedom are 0.95 × J / 2 (206 windows: 97.85)."""
    det = ev.EventDetector(
        0.5, (0.5,), (206,), (6.0,), (5.0,), ("accel_x", "accel_y"), ((0.9,),)
    )  # one test: r 0.9 at 97.85 dof is named
    assert det.dof == (pytest.approx(97.85, rel=1e-12),)
    transient = ev.DisturbanceEvent(
        1200.0, 30.0, ("gyro_y", "accel_x"), {}, {}, {}, "transient", (120_000, 123_000), 8.0
    )
    step = ev.DisturbanceEvent(3000.0, 4.5, ("accel_z",), {}, {}, {}, "step", None, 2.0)
    lines = ev.EventsFound(det, (transient, step), 0.01, 0.0).warnings()
    assert lines[:2] == [
        "disturbance event (transient) at 1200.0 s for 30.0 s on gyro_y, accel_x: excised on "
        "every axis",
        "disturbance event (step) at 3000.0 s for 4.5 s on accel_z: a lasting level change, left "
        "to the loop (bias step)",
    ]
    assert len(lines) == 3 and lines[2].startswith(
        "axes that move together: accel_x–accel_y r 0.90 at 0.5 s ("
    )
    assert ev.EventsFound(det, (), 0.01, 0.0).warnings() == lines[2:]
