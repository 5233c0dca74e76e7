"""The virtual ADIS16364 and its noise generators: determinism, noise statistics, effects."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from imupipe.device.adis16364 import (
    DIAG_OVER_RANGE,
    DIAG_SUPPLY_HIGH,
    DIAG_SUPPLY_LOW,
    EA_BIT,
    ND_BIT,
    REGISTERS,
    DeviceConfig,
    burst_counts,
    config_for_rate,
)
from imupipe.errors import ConfigError
from imupipe.recording.noise import (
    FLICKER_PLATEAU,
    FlickerNoise,
    GaussMarkov,
    NormalStream,
    RateRandomWalk,
)
from imupipe.recording.scenario import BiasStep, Scenario, Sinusoid, Spikes, Supply, Temperature
from imupipe.recording.simulator import VirtualADIS16364, bartlett_response, white_gain
from imupipe.vocab import AXES

PAPER_N = {"gyro_x": 0.05, "gyro_y": 0.05, "gyro_z": 0.05,
           "accel_x": 0.29, "accel_y": 0.27, "accel_z": 0.28}  # fmt: skip
PAPER_MEAN = {"gyro_x": 0.331, "gyro_y": -0.104, "gyro_z": -0.099,
              "accel_x": 27.3, "accel_y": -21.1, "accel_z": -998.6}  # fmt: skip
PAPER_RMS = {"gyro_x": 0.52, "gyro_y": 0.51, "gyro_z": 0.52,
             "accel_x": 3.0, "accel_y": 2.8, "accel_z": 2.9}  # fmt: skip


def oadev(y: np.ndarray, tau0: float, m: int) -> np.ndarray:
    """Overlapping Allan deviation of rate samples ``y`` (columns) at tau = m·tau0."""
    x = np.concatenate([np.zeros((1, *y.shape[1:])), np.cumsum(y, axis=0)]) * tau0
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    return np.sqrt(np.mean(d**2, axis=0) / (2 * (m * tau0) ** 2))


def physical(block, config: DeviceConfig) -> np.ndarray:
    """(n, 6) gyro °/s and accel mg from burst words."""
    counts = burst_counts(block.burst)[:, 1:7].astype(float)
    counts[:, :3] *= config.gyro_scale_dps
    return counts


def white_only(**overrides) -> Scenario:
    base = Scenario()
    noise = {
        a: replace(t, bias_instability=0.0, rate_random_walk=0.0, **overrides)
        for a, t in base.noise.items()
    }
    return replace(base, noise=noise)


# ---- determinism ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("config", "scenario"),
    [
        (DeviceConfig(), Scenario()),
        (DeviceConfig(sens_avg=0x0404), replace(Scenario(), jitter_s=0.002)),
        (config_for_rate(819.2), Scenario()),
    ],
    ids=["default", "overlapping-windows+jitter", "smpl_prd-divider"],
)
def test_block_size_independent_and_seeded(config, scenario):
    scenario = replace(scenario, spikes=(Spikes("accel_z", 3600.0, 50.0),))
    whole = VirtualADIS16364(config, scenario, seed=7).frames(1500)
    dev = VirtualADIS16364(config, scenario, seed=7)
    parts = [dev.frames(n) for n in (10, 5, 1, 484, 1000)]
    for field in ("burst", "stamp_ns", "counter", "diag_stat"):
        assert np.array_equal(
            whole.__dict__[field], np.concatenate([p.__dict__[field] for p in parts])
        )
    other = VirtualADIS16364(config, scenario, seed=8).frames(1500)
    assert not np.array_equal(whole.burst, other.burst)


# ---- noise statistics ----------------------------------------------------------------------


def test_white_gain_formula_for_disjoint_windows():
    h = bartlett_response(0x0402)
    assert list(h * 16) == [1, 2, 3, 4, 3, 2, 1]
    assert white_gain(DeviceConfig()) == pytest.approx(np.sum(h**2) / 100.0, rel=1e-12)
    # the divider keeps every sample: the filter then preserves the low-frequency level
    assert white_gain(config_for_rate(819.2)) == pytest.approx(1 / 819.202, rel=1e-3)


@pytest.mark.parametrize(
    "config",
    [DeviceConfig(), DeviceConfig(sens_avg=0x0404), config_for_rate(819.2)],
    ids=["host-poll-100Hz", "host-poll-M4", "divider-819Hz"],
)
def test_adev_at_1s_matches_configured_random_walk(config):
    """White part only: ADEV(τ = 1 s) of the output = configured N (1 h, or 30 min at 819.2
    Hz: ~1-1.4 % scatter per axis): each axis within 4 %, the six axes' mean within 2 %."""
    duration_s = 1800 if config.rate_method == "smpl_prd" else 3600
    n = round(duration_s * config.output_rate_hz)
    dev = VirtualADIS16364(config, white_only(), seed=3)
    y = physical(dev.frames(n), config)
    adev = oadev(y, 1.0 / config.output_rate_hz, round(config.output_rate_hz))
    ratio = adev / np.array([PAPER_N[a] for a in AXES])
    assert np.all(np.abs(ratio - 1) < 0.04), ratio
    assert abs(ratio.mean() - 1) < 0.02, ratio


def test_default_device_reproduces_paper_table():
    """Defaults: ADEV(1 s) ≈ √(N² + (0.664 B)²), rms ≈ 10·N ≈ paper's rms, means = paper's."""
    config = DeviceConfig()
    dev = VirtualADIS16364(config, seed=11)
    y = physical(dev.frames(360_000), config)
    adev1 = oadev(y, 0.01, 100)
    for i, axis in enumerate(AXES):
        terms = dev.scenario.noise[axis]
        expected = math.hypot(terms.random_walk, FLICKER_PLATEAU * terms.bias_instability)
        assert adev1[i] == pytest.approx(expected, rel=0.03), axis
        assert y[:, i].std() == pytest.approx(PAPER_RMS[axis], rel=0.08), axis
        tol = 0.02 if axis.startswith("gyro") else 0.4
        assert y[:, i].mean() == pytest.approx(PAPER_MEAN[axis], abs=tol), axis


def test_flicker_plateau_is_0664_b():
    """Flicker generator alone: ADEV flat at 0.664·B over 2.5 decades of τ (4 seeds)."""
    taus = [10, 30, 100, 300]
    adevs = []
    for seed in range(4):
        y = FlickerNoise(1.0, 1.0, NormalStream(seed, 1)).take(300_000)
        adevs.append([oadev(y[:, None], 1.0, m)[0] for m in taus])
    ratio = np.mean(adevs, axis=0) / FLICKER_PLATEAU
    assert np.all(np.abs(ratio - 1.0) < 0.08), ratio


def test_flicker_plateau_at_simulator_output():
    """accel_y with a large B: output ADEV at τ = 10..100 s ≈ √(N²/τ + (0.664 B)²)."""
    base = white_only()
    noise = dict(base.noise, accel_y=replace(base.noise["accel_y"], bias_instability=1.0))
    config = DeviceConfig()
    y = physical(
        VirtualADIS16364(config, replace(base, noise=noise), seed=5).frames(720_000), config
    )
    for tau in (10, 30, 100):
        expected = math.hypot(0.27 / math.sqrt(tau), FLICKER_PLATEAU)
        assert oadev(y[:, 4:5], 0.01, tau * 100)[0] == pytest.approx(expected, rel=0.15), tau


def test_rate_random_walk_and_gauss_markov():
    y = np.stack([RateRandomWalk(0.1, 1.0, NormalStream(s, 2)).take(20_000) for s in range(8)], 1)
    for tau in (10, 100):
        assert np.mean(oadev(y, 1.0, tau)) == pytest.approx(0.1 * math.sqrt(tau / 3), rel=0.1)
    gm = GaussMarkov(2.0, 50.0, 1.0, NormalStream(1, 3)).take(400_000)
    assert gm.std() == pytest.approx(2.0, rel=0.05)
    lag = np.corrcoef(gm[:-50], gm[50:])[0, 1]
    assert lag == pytest.approx(math.exp(-1.0), abs=0.05)


@pytest.mark.parametrize(
    "make",
    [
        lambda: FlickerNoise(1.0, 0.01, NormalStream(4, 1)),
        lambda: GaussMarkov(2.0, 5.0, 0.01, NormalStream(4, 3)),
        lambda: RateRandomWalk(0.1, 0.01, NormalStream(4, 2)),
    ],
    ids=["flicker", "gauss_markov", "rate_random_walk"],
)
def test_generators_block_independent(make):
    """Each generator's output depends on the sample index only: its state carried from one
    block to the next is the last sample's (the module's contract)."""
    a, b = make(), make()
    whole = a.take(100_000)
    parts = [b.take(70_001), b.take(0), b.take(1), b.take(29_998)]
    if isinstance(a, RateRandomWalk):  # a running sum restarted from its state: to rounding
        np.testing.assert_allclose(np.concatenate(parts), whole, rtol=1e-13, atol=0)
    else:
        assert np.array_equal(whole, np.concatenate(parts))


def test_flicker_poles_two_per_decade_with_zeros_between():
    """Keshner's cascade as the docstring states it: poles log-spaced at two per decade from
    f_lo up to the Nyquist frequency, each zero half a spacing (10^¼) above its pole."""
    dt = 0.01
    flicker = FlickerNoise(1.0, dt, NormalStream(0, 1), f_lo_hz=1e-6)
    f_pole = -np.log(-flicker.sos[:, 4]) / (2 * np.pi * dt)
    f_zero = -np.log(-flicker.sos[:, 1] / flicker.sos[:, 0]) / (2 * np.pi * dt)
    # read back to 1e-8: the lowest pole's coefficient is 1 - 6.3e-8, so its float64 rounding
    # (1.1e-16) moves the frequency by ~2e-9 of itself (numpy 2.4.6's log: 2.0e-9, past 1e-9)
    np.testing.assert_allclose(f_pole[1:] / f_pole[:-1], 10**0.5, rtol=1e-8)
    np.testing.assert_allclose(f_zero / f_pole, 10**0.25, rtol=1e-8)
    assert f_pole[0] == pytest.approx(1e-6, rel=1e-8)
    assert f_pole[-1] * 10**0.5 <= 0.5 / dt < f_pole[-1] * 10  # the last a spacing below


# ---- registers, flags, effects -------------------------------------------------------------


def test_temperature_supply_flags_and_stamps():
    dev = VirtualADIS16364(DeviceConfig(), seed=1, start_time_ns=10**18)
    block = dev.frames(100)
    counts = burst_counts(block.burst)
    assert np.all(counts[:, 7:10] == -29)  # 21 °C: (21 - 25)/0.136 = -29.4 LSB
    assert np.all(counts[:, 0] == 2068)  # 5.0 V / 2.418 mV
    assert np.all(block.burst & ND_BIT) and not np.any(block.burst & EA_BIT)
    assert np.all(np.diff(block.stamp_ns) == 10_000_000)
    assert block.stamp_ns[0] == 10**18 + 10_000_000
    assert list(block.counter[:3]) == [0, 1, 2] and np.all(block.diag_valid)


def test_saturation_sets_over_range_and_ea():
    scenario = replace(Scenario(), bias_step=(BiasStep("gyro_x", 0.5, 500.0),))
    dev = VirtualADIS16364(DeviceConfig(), scenario, seed=2)
    block = dev.frames(100)
    counts = burst_counts(block.burst)
    late = np.arange(100) >= 50  # frames at t >= 0.51 s
    assert np.all(counts[late, 1] == 8191) and np.all(counts[~late, 1] < 100)
    assert np.all(block.diag_stat[late] & DIAG_OVER_RANGE)
    assert not np.any(block.diag_stat[~late])
    assert np.all(block.burst[late] & EA_BIT) and not np.any(block.burst[~late] & EA_BIT)
    # register path: EA stays latched until DIAG_STAT is read, which clears it
    dev.burst_read()
    assert dev.read_register(REGISTERS["DIAG_STAT"]) & DIAG_OVER_RANGE
    assert dev.read_register(REGISTERS["DIAG_STAT"]) & DIAG_OVER_RANGE == 0


def test_effects_appear_in_output():
    scenario = replace(
        Scenario(),
        sinusoid=(Sinusoid("gyro_z", 2.0, 0.5), Sinusoid("accel_x", 20.0, 90.0)),
        bias_step=(BiasStep("accel_y", 60.0, 5.0),),
        temperature=Temperature(points=((0.0, 21.0), (120.0, 31.0)), coefficients={"gyro_y": 0.1}),
        supply=Supply(
            ripple_amplitude_v=0.2, ripple_frequency_hz=0.05, sensitivity={"accel_z": 10.0}
        ),
        spikes=(Spikes("gyro_x", 360.0, 100.0, duration_s=0.05),),
    )
    config = DeviceConfig()
    dev = VirtualADIS16364(config, scenario, seed=9)
    block = dev.frames(12_000)
    y = physical(block, config)
    t = (block.stamp_ns - dev.start_time_ns) / 1e9
    # 0.5 Hz sinusoid on gyro_z: least-squares amplitude (filter gain ≈ 1 at 0.5 Hz)
    basis = np.stack([np.sin(np.pi * t), np.cos(np.pi * t), np.ones_like(t)], 1)
    coef = np.linalg.lstsq(basis, y[:, 2], rcond=None)[0]
    assert math.hypot(*coef[:2]) == pytest.approx(2.0, rel=0.03)
    # 90 Hz on accel_x aliases to 10 Hz, attenuated by the Bartlett filter |H(90 Hz)|
    h = bartlett_response(config.sens_avg)
    gain = abs(
        np.sum(h * np.exp(-2j * np.pi * 90.0 / config.internal_rate_sps * np.arange(len(h))))
    )
    spectrum = np.abs(np.fft.rfft(y[:, 3] - y[:, 3].mean())) * 2 / len(t)
    freqs = np.fft.rfftfreq(len(t), 0.01)
    alias = spectrum[np.argmin(np.abs(freqs - 10.0)) - 3 :][:7].max()
    assert alias == pytest.approx(20.0 * gain, rel=0.1)
    # bias step of 5 mg at 60 s
    assert y[t >= 60, 4].mean() - y[t < 60, 4].mean() == pytest.approx(5.0, abs=0.3)
    # temperature ramp 21 -> 31 °C: TEMP registers follow, gyro_y moves 0.1 °/s/°C
    temp_c = burst_counts(block.burst)[:, 7] * 0.136 + 25.0
    assert temp_c[-1] == pytest.approx(31.0, abs=0.14) and temp_c[0] == pytest.approx(
        21.0, abs=0.14
    )
    assert y[-1000:, 1].mean() - y[:1000, 1].mean() == pytest.approx(0.1 * 9.2, abs=0.1)
    # supply ripple: SUPPLY_OUT follows, accel_z sensitivity 10 mg/V
    volts = burst_counts(block.burst)[:, 0] * 2.418e-3
    assert volts.max() - volts.min() == pytest.approx(0.4, abs=0.01)
    slope = np.polyfit(volts - 5.0, y[:, 5], 1)[0]
    assert slope == pytest.approx(10.0, abs=1.0)
    # spikes of 100 °/s at 360/h for 120 s: ~12 expected, each 5 frames long
    n_spikes = np.sum(np.diff((y[:, 0] > 50).astype(int)) == 1)
    assert 3 <= n_spikes <= 25
    truth = dev.truth()
    json.dumps(truth)
    assert truth["effects"]["sinusoid"][1]["frequency_hz"] == 90.0


def test_truth_records_internal_and_output_levels():
    dev = VirtualADIS16364(DeviceConfig(), seed=0)
    truth = json.loads(json.dumps(dev.truth()))
    gx = truth["noise"]["gyro_x"]
    assert gx["paper_units"]["random_walk"] == 0.05
    assert gx["si"]["random_walk"] == pytest.approx(0.05 * math.pi / 180)
    sigma = gx["internal_white"]["sigma_per_sample"]
    h2 = float(np.sum(bartlett_response(0x0402) ** 2))
    # N² = σ²·Σh²/f_out + q²/(12 f_out)
    assert sigma**2 * h2 / 100 + 0.05**2 / 1200 == pytest.approx(0.05**2, rel=1e-9)
    assert truth["device"]["rate_method"] == "host_poll" and truth["seed"] == 0


def test_register_writes_reconfigure():
    dev = VirtualADIS16364(DeviceConfig(), seed=0)
    assert dev.read_register(REGISTERS["PROD_ID"]) == 16364
    dev.write_register(REGISTERS["SENS_AVG"], 0x0203)
    assert dev.read_register(REGISTERS["SENS_AVG"]) == 0x0203
    assert (
        dev.config.gyro_scale_dps == 0.025
        and len(dev.truth()["device"]["filter_impulse_response"]) == 15
    )
    word = dev.read_register(REGISTERS["XGYRO_OUT"])
    assert word & ND_BIT and not dev.read_register(REGISTERS["XGYRO_OUT"]) & ND_BIT
    with pytest.raises(ConfigError, match="smpl_prd"):
        VirtualADIS16364(DeviceConfig(rate_method="smpl_prd", output_rate_hz=100.0))


@pytest.mark.parametrize(
    ("volts", "diag"), [(5.3, DIAG_SUPPLY_HIGH), (5.2, 0), (4.8, 0), (4.7, DIAG_SUPPLY_LOW)]
)
def test_supply_out_of_range_sets_its_diag_bit_and_ea_beside_nd(volts: float, diag: int):
    """The datasheet's supply limits (4.75–5.25 V) flag DIAG_STAT bit 1 (high) or 0 (low);
    a flag sets EA (bit 14) in every word of the frame beside ND (bit 15: new data)."""
    scenario = replace(Scenario(), supply=Supply(nominal_v=volts))
    block = VirtualADIS16364(DeviceConfig(), scenario, seed=3).frames(20)
    assert np.all(block.diag_stat == diag)
    top = block.burst & (ND_BIT | EA_BIT)
    assert np.all(top == (ND_BIT | EA_BIT if diag else ND_BIT))


def test_every_frame_of_the_divider_is_a_new_internal_sample_at_its_time():
    """rate_method "smpl_prd": frame k is internal sample k + 1, stamped (k + 1)/f_int after the
    start, each with ND set (the first one too)."""
    config = config_for_rate(819.2)
    block = VirtualADIS16364(config, seed=4, start_time_ns=0).frames(50)
    expected = np.rint(np.arange(1, 51) / config.internal_rate_sps * 1e9).astype(np.int64)
    np.testing.assert_array_equal(block.stamp_ns, expected)
    assert np.all(block.burst & ND_BIT)


def test_frames_of_no_or_negative_count_are_refused():
    dev = VirtualADIS16364(DeviceConfig(), seed=0)
    for n in (0, -1):
        with pytest.raises(ValueError, match="n >= 1"):
            dev.frames(n)


def test_register_reads_walk_the_same_frames_as_bulk_reads():
    """The first output-register read of a fresh part is frame 0's word (ND set), the next
    burst read frame 1's: the register path and the bulk path give one sequence."""
    bulk = VirtualADIS16364(DeviceConfig(), seed=5).frames(2).burst
    dev = VirtualADIS16364(DeviceConfig(), seed=5)
    outputs = ("XGYRO_OUT", "YGYRO_OUT", "ZGYRO_OUT", "XACCL_OUT", "YACCL_OUT", "ZACCL_OUT")
    first = [dev.read_register(REGISTERS[name]) for name in outputs]
    assert first == [int(w) for w in bulk[0, 1:7]]
    assert dev.burst_read() == [int(w) for w in bulk[1]]


def test_fresh_registers_serial_number_and_byte_writes():
    """Writable registers start at 0 (MSC_CTRL at 0x0006), the serial number reads back whole
    (odd too), and a register written twice holds the second value: each byte write replaces
    its byte."""
    dev = VirtualADIS16364(DeviceConfig(serial_number=0x1235), seed=0)
    assert dev.read_register(REGISTERS["XGYRO_OFF"]) == 0
    assert dev.read_register(REGISTERS["GPIO_CTRL"]) == 0
    assert dev.read_register(REGISTERS["MSC_CTRL"]) == 0x0006
    assert dev.read_register(REGISTERS["SERIAL_NUM"]) == 0x1235
    dev.write_register(REGISTERS["XGYRO_OFF"], 0x0F0F)
    dev.write_register(REGISTERS["XGYRO_OFF"], 0x1020)
    assert dev.read_register(REGISTERS["XGYRO_OFF"]) == 0x1020


def test_the_75_dps_range_reconfigures_and_the_stamps_run_on():
    """SENS_AVG written mid-run to the ±75 °/s range (code 1): the scale becomes 0.0125 °/s
    per LSB and the next frame follows the last one by one period (no repeated stamp)."""
    dev = VirtualADIS16364(DeviceConfig(), seed=6)
    before = dev.frames(5).stamp_ns
    dev.write_register(REGISTERS["SENS_AVG"], 0x0104)
    assert dev.config.sens_avg == 0x0104 and dev.config.gyro_scale_dps == 0.0125
    after = dev.frames(5).stamp_ns
    assert np.all(np.diff(np.r_[before, after]) == 10_000_000)
