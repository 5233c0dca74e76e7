"""The SPI driver, through the real ``SpidevBus`` and ``DataReadyPacer``, against a fake part
(:mod:`imupipe.testing.fake_spi`) that enforces the ADIS16364's clock, stall, reset and self-test
rules on its own, behind stand-in ``spidev`` and ``gpiod`` modules."""

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from imupipe.device.adis16364 import (
    FAST_TIMING,
    ND_BIT,
    REGISTERS,
    burst_counts,
    check_sens_avg,
    config_for_rate,
    sample_rate_sps,
)
from imupipe.errors import ConfigError, DeviceError, SelfTestError
from imupipe.recording import spi
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.recording.spi import (
    Adis16364Driver,
    DataReadyPacer,
    SpidevBus,
    SpiSource,
    TimerPacer,
    open_spi_source,
    parse_gpio_line,
    split_device,
)
from imupipe.testing.fake_spi import FakeAdis16364, SpiProtocolViolation

DATA = Path(__file__).resolve().parents[1] / "data"
RATE_819 = config_for_rate(sample_rate_sps(0x01), source="spi")  # SMPL_PRD 0x01: fast mode
RATE_102 = config_for_rate(102.4, source="spi")  # SMPL_PRD 0x0F: low-power mode
LINE = "/dev/gpiochip0:17"


def install(monkeypatch, part: FakeAdis16364) -> FakeAdis16364:
    """Put ``part`` behind the ``spidev`` and ``gpiod`` modules, and give the drivers that
    :func:`open_spi_source` makes the part's virtual clock."""
    monkeypatch.setitem(sys.modules, "spidev", part.spidev_module())
    for name, module in part.gpiod_modules().items():
        monkeypatch.setitem(sys.modules, name, module)
    virtual = {"wall_clock_ns": part.wall_clock_ns, "sleep": part.sleep}
    monkeypatch.setattr(spi, "Adis16364Driver", lambda bus: Adis16364Driver(bus, **virtual))
    return part


@pytest.fixture
def part(monkeypatch) -> FakeAdis16364:
    return install(monkeypatch, FakeAdis16364())


def driver_for(part: FakeAdis16364) -> Adis16364Driver:
    return Adis16364Driver(SpidevBus("/dev/spidev0.0"), part.wall_clock_ns, part.sleep)


class FixedPacer:
    method = "host_timer"

    def __init__(self, periods):
        self._periods = iter(periods)

    def wait(self) -> int:
        return next(self._periods)


class LateHost:
    """Data-ready pacing by a host that, before every ``every``-th wait, is busy ``late_s``."""

    method = "data_ready"

    def __init__(self, pacer, part: FakeAdis16364, every: int, late_s: float) -> None:
        self.pacer, self.part, self.every, self.late_s, self.n = pacer, part, every, late_s, 0

    def wait(self) -> int:
        self.n += 1
        if self.n % self.every == 0:
            self.part.sleep(self.late_s)
        return self.pacer.wait()


# ---- facts ---------------------------------------------------------------------------------
def test_register_map_is_the_corrected_adis1636x_map():
    facts = json.loads((DATA / "adis16364_registers.json").read_text())["registers"]
    assert REGISTERS == {name: int(addr, 16) for name, addr in facts.items()}
    assert (REGISTERS["ALM_MAG1"], REGISTERS["AUX_DAC"]) == (0x26, 0x30)


@pytest.mark.parametrize(
    ("sens_avg", "error"),
    [(0x0402, None), (0x0400, None), (0x0202, None), (0x0201, ">= 2"), (0x0104, None),
     (0x0103, ">= 4"), (0x0302, "no valid gyro range")],
)  # fmt: skip
def test_gyro_range_needs_enough_filter_taps(sens_avg, error):
    if error is None:
        check_sens_avg(sens_avg)
    else:
        with pytest.raises(ConfigError, match=error):
            check_sens_avg(sens_avg)


# ---- SpidevBus against the stand-in spidev module ------------------------------------------
def test_spidev_bus_sets_mode_and_per_transfer_speed_and_delay(part):
    driver = driver_for(part)
    dev = driver.bus._spi
    assert (dev.mode, dev.bits_per_word, dev.max_speed_hz) == (3, 8, 300_000)
    config = driver.start(replace(RATE_819, sens_avg=0x0403))
    first = part.transfers[0]
    assert first.words == (0xBE80,) and (first.speed_hz, first.delay_us) == (300_000, 75)
    assert part.transfers[1].start_ns - first.start_ns >= 130_000_000  # start-up wait
    smpl = [i for i, t in enumerate(part.transfers) if t.words == (0xB601,)]
    assert len(smpl) == 1 and part.transfers[smpl[0]].speed_hz == 300_000
    after = part.transfers[smpl[0] + 1 :]
    assert {(t.speed_hz, t.delay_us) for t in after} == {(2_000_000, 50)}
    assert [t.words[0] for t in after if t.words[0] & 0x8000] == [0xB803, 0xB904, 0xB406, 0xB500]
    driver.burst_read()
    burst = part.transfers[-1]
    assert len(burst.words) == 12 and (burst.speed_hz, burst.delay_us) == (1_000_000, 50)
    assert config.serial_number == 0x1234


def test_low_power_rate_is_clocked_at_300_khz_with_the_longer_stall(part):
    driver = driver_for(part)
    driver.start(RATE_102)
    assert part.mode == "low_power" and driver.timing.sclk_hz == 300_000
    mark = len(part.transfers)
    driver.frames(3, FixedPacer([1, 1, 1]))
    assert {(t.speed_hz, t.delay_us) for t in part.transfers[mark:]} == {(300_000, 75)}


@pytest.mark.parametrize(
    ("smpl_prd", "sclk_hz", "burst_hz", "stall_us"),
    [(0x09, 2_000_000, 1_000_000, 50), (0x0A, 300_000, 300_000, 75), (0x81, 300_000, 300_000, 75)],
)
def test_sclk_and_stall_follow_the_mode_at_its_boundaries(
    part, smpl_prd, sclk_hz, burst_hz, stall_us
):
    driver = driver_for(part)
    driver.start(RATE_819)
    driver.configure(smpl_prd, 0x0402)
    driver.read_diag_stat()
    driver.burst_read()
    *_, read, answer, burst = part.transfers
    assert {(t.speed_hz, t.delay_us) for t in (read, answer)} == {(sclk_hz, stall_us)}
    assert (burst.speed_hz, burst.delay_us) == (burst_hz, stall_us)


def test_switching_into_low_power_mode_writes_smpl_prd_slowly(part):
    driver = driver_for(part)
    driver.start(RATE_819)
    driver.configure(0x8F, 0x0402)  # slow time base
    write = next(t for t in reversed(part.transfers) if t.words == (0xB68F,))
    assert (write.speed_hz, write.delay_us, write.mode) == (300_000, 75, "fast")
    driver.configure(0x01, 0x0402)  # and back
    assert driver.timing == FAST_TIMING and part.mode == "fast"


# ---- the fake part rejects what the real one would not -------------------------------------
def test_the_part_rejects_one_sclk_for_every_mode(part):
    driver = driver_for(part)
    driver.start(RATE_102)
    driver.timing = replace(FAST_TIMING, burst_hz=1_000_000, stall_us=100)  # the old 1 MHz
    with pytest.raises(SpiProtocolViolation, match=r"burst at 1000000 Hz SCLK in low_power"):
        driver.burst_read()


def test_the_part_rejects_frames_without_stall(part):
    bus = SpidevBus("/dev/spidev0.0")
    bus.transfer([0x5600], 2_000_000, 0)
    with pytest.raises(SpiProtocolViolation, match="tDATASTALL is 9 µs"):
        bus.transfer([0x0000], 2_000_000, 0)
    with pytest.raises(SpiProtocolViolation, match="3 frames in one chip-select period"):
        bus.transfer([0x5600, 0x5800, 0x0000], 300_000, 100)


def test_the_part_rejects_a_short_chip_select_period_mode_0_and_an_early_diag_read(part):
    bus = SpidevBus("/dev/spidev0.0")
    bus.transfer([0x5600], 2_000_000, 20)  # 8 µs frame + 20 µs: stall ok, period 28 µs
    with pytest.raises(SpiProtocolViolation, match="tDATARATE is 40 µs"):
        bus.transfer([0x0000], 2_000_000, 20)
    bus._spi.mode = 0
    with pytest.raises(SpiProtocolViolation, match="SPI mode 0"):
        bus.transfer([0x0000], 300_000, 100)
    bus._spi.mode = 3
    part.sleep(0.001)  # a rejected frame takes no time
    bus.transfer([0xB504], 300_000, 100)  # MSC_CTRL[15:8]: start the internal self-test
    bus.transfer([0x3C00], 300_000, 100)  # DIAG_STAT comes out on the next frame
    with pytest.raises(SpiProtocolViolation, match="DIAG_STAT read while the self-test"):
        bus.transfer([0x0000], 300_000, 100)


def test_the_part_rejects_transfers_during_start_up(part):
    driver = Adis16364Driver(SpidevBus("/dev/spidev0.0"), sleep=lambda s: None)
    with pytest.raises(
        SpiProtocolViolation, match="ms after a reset: the part starts up for 130 ms"
    ):
        driver.start(RATE_819)


def test_read_answers_on_next_frame_across_chip_select(part):
    bus = SpidevBus("/dev/spidev0.0")
    assert [bus.transfer([w], 300_000, 100)[0] for w in (0x5600, 0x5800, 0x0000)] == [
        0,
        16364,
        0x1234,
    ]


# ---- start-up --------------------------------------------------------------------------------
def test_restart_when_the_flash_holds_a_low_power_rate(monkeypatch):
    part = install(monkeypatch, FakeAdis16364(flash={0x36: 0x0F}))
    driver = driver_for(part)
    driver.start(RATE_819)  # the reset brings SMPL_PRD 0x0F back: slow until it is rewritten
    driver.start(RATE_819)
    reset = [t for t in part.transfers if t.words == (0xBE80,)]
    assert [(t.speed_hz, t.delay_us, t.mode) for t in reset] == [
        (300_000, 75, "low_power"),
        (300_000, 75, "fast"),
    ]


def test_failed_self_test_is_one_clear_error(monkeypatch):
    install(monkeypatch, part := FakeAdis16364(self_test_fail=0x0420))
    with pytest.raises(SelfTestError) as err:
        driver_for(part).start(RATE_819)
    assert str(err.value) == (
        "ADIS16364 start-up check failed: DIAG_STAT 0x0420 "
        "(Z-axis gyroscope self-test failure; self-test error)"
    )


def test_self_test_is_awaited_until_the_part_clears_it(monkeypatch):
    install(monkeypatch, part := FakeAdis16364(self_test_s=0.05))  # longer than 12 ms
    driver_for(part).start(RATE_819)
    install(monkeypatch, part := FakeAdis16364(self_test_s=1.0))
    with pytest.raises(SelfTestError, match=r"did not finish within 0\.12 s"):
        driver_for(part).start(RATE_819)


def test_wrong_prod_id_raises():
    class OtherChip:
        def transfer(self, words, speed_hz, stall_us):
            return [16405] * len(words)

    with pytest.raises(DeviceError, match="16405"):
        Adis16364Driver(OtherChip(), sleep=lambda s: None).check_product_id()


def test_config_readback_mismatch_raises(part):
    driver = driver_for(part)
    driver.start(RATE_819)
    part.device.write_byte = lambda addr, byte: None  # the part ignores writes
    with pytest.raises(DeviceError, match="SENS_AVG reads 0x0402 after writing 0x0403"):
        driver.configure(0x01, 0x0403)


def test_filter_constraint_is_checked_before_writing(part):
    driver = driver_for(part)
    mark = len(part.transfers)
    with pytest.raises(ConfigError, match="±75 °/s range needs"):
        driver.configure(0x01, 0x0102)
    assert part.transfers[mark:] == []


# ---- data-ready pacing ----------------------------------------------------------------------
def test_data_ready_pacing_has_no_duplicates_and_no_silent_skips(monkeypatch):
    # data-ready off, on DIO2, active low in the part's flash; bits 7:6 (bias/alignment) set
    part = install(monkeypatch, FakeAdis16364(flash={0x34: 0x00C1}))
    driver = driver_for(part)
    pacer = LateHost(DataReadyPacer(LINE, RATE_819.output_rate_hz), part, 37, 3.4 / 819.2)
    source = SpiSource(driver, RATE_819, pacer)
    assert source.config.pacing == "data_ready"
    assert source.config.to_metadata()["pacing"] == "data_ready"
    block = source.frames(400)
    serials = np.array(part.burst_serials)
    assert all(part.burst_fresh)  # every burst read a sample nobody had read: no duplicate
    assert np.all(block.burst & ND_BIT)
    assert np.array_equal(np.diff(block.counter.astype(np.int64)), np.diff(serials))
    # 10 late waits, each after 3 new samples of which the newest is read: 2 missed each
    assert driver.missed_frames == serials[-1] - serials[0] - 399 == 20
    msc = part.device.read_register(REGISTERS["MSC_CTRL"])
    assert msc & 0x0007 == 0x0006 and msc & 0x00C0 == 0x00C0  # DIO1, active high; 7:6 kept


def test_fake_data_ready_line_fires_at_the_sensors_own_rate(part):
    driver = driver_for(part)
    driver.start(RATE_102)
    gpiod = sys.modules["gpiod"]
    rising = gpiod.LineSettings(edge_detection=gpiod.line.Edge.RISING)
    request = gpiod.request_lines("/dev/gpiochip0", consumer="test", config={17: rising})
    part.sleep(0.5)
    events = request.read_edge_events()
    assert len(events) == 16  # the kernel's buffer keeps the newest 16 of the 51 edges
    assert (events[0].line_seqno, events[-1].line_seqno) == (36, 51)
    assert np.allclose(np.diff([e.timestamp_ns for e in events]), 1e9 / 102.4, atol=1)


def test_host_late_beyond_the_kernel_event_buffer_still_counts_every_sample(part):
    driver = driver_for(part)
    source = SpiSource(driver, RATE_819, LateHost(DataReadyPacer(LINE, 819.2), part, 3, 0.05))
    block = source.frames(6)
    assert np.array_equal(np.diff(block.counter.astype(np.int64)), np.diff(part.burst_serials))
    assert driver.missed_frames == 80  # 2 waits 50 ms late: 41 samples each, 40 missed


def test_host_timer_at_the_sensor_rate_reads_stale_and_skips_silently(part):
    driver = driver_for(part)
    driver.start(RATE_819)
    rng = np.random.default_rng(5)
    overshoot = lambda s: part.sleep(s + rng.uniform(0.0, 0.5e-3))  # noqa: E731  # OS wake-up
    pacer = TimerPacer(RATE_819.output_rate_hz, clock=part.clock_ns, sleep=overshoot)
    block = driver.frames(300, pacer)
    steps = np.diff(part.burst_serials)
    assert np.all(np.diff(block.counter.astype(np.int64)) == 1)  # the counter sees nothing
    assert np.any(steps == 0) and np.any(steps == 2)  # duplicates and skips happened
    assert not all(part.burst_fresh)
    with pytest.raises(DeviceError, match="read on its data-ready edge: wire DIO1"):
        SpiSource(driver, RATE_819, pacer)


def test_data_ready_line_not_wired_is_a_clear_error(part):
    driver = driver_for(part)
    source = SpiSource(driver, RATE_819, DataReadyPacer("gpiochip0:18", 819.2))
    with pytest.raises(DeviceError, match=r"no data-ready edge on gpiochip0:18 within 0\.5 s"):
        source.frames(1)


def test_host_poll_rate_keeps_the_timer(part):
    source = SpiSource(driver_for(part), config_for_rate(100.0, source="spi"), FixedPacer([1]))
    assert source.config.pacing == "host_timer" and source.config.rate_method == "host_poll"
    with pytest.raises(DeviceError, match="not a rate the sensor makes"):
        SpiSource(driver_for(part), config_for_rate(100.0), DataReadyPacer(LINE, 100.0))


def test_burst_decode_matches_device(part):
    driver = driver_for(part)
    source = SpiSource(driver, RATE_819, DataReadyPacer(LINE, 819.2))
    block = source.frames(20)
    reference = VirtualADIS16364(config_for_rate(819.202, serial_number=0x1234), seed=3)
    assert np.array_equal(block.burst, reference.frames(20).burst)
    counts = burst_counts(block.burst)
    assert np.all(counts[:, 0] == 2068) and np.all(counts[:, 6] < -990)
    assert np.all(block.diag_valid) and not np.any(block.diag_stat)
    assert np.all(np.diff(block.stamp_ns) > 0)


def test_missed_frames_from_timer_pacer(part):
    clock = {"ns": 0}
    sleeps = []

    def sleep(s):
        sleeps.append(s)
        clock["ns"] += round(s * 1e9)

    pacer = TimerPacer(100.0, clock=lambda: clock["ns"], sleep=sleep)
    driver = driver_for(part)
    assert driver.frames(2, pacer).counter.tolist() == [0, 1]
    clock["ns"] += 35_000_000  # host stalls 35 ms: deadlines at 20, 30, 40 ms passed
    block = driver.frames(3, pacer)
    assert block.counter.tolist() == [4, 5, 6]
    assert driver.missed_frames == 2
    assert sleeps and all(0 < s <= 0.01 for s in sleeps)


def test_diag_stat_read_every_n_frames(part):
    driver = driver_for(part)
    block = driver.frames(6, FixedPacer([1] * 6), diag_every=3)
    assert block.diag_valid.tolist() == [False, False, True, False, False, True]
    assert sum(t.words == (0x3C00,) for t in part.transfers) == 2


# ---- opening a source ------------------------------------------------------------------------
def test_device_string_and_gpio_line_parsing():
    assert split_device("/dev/spidev0.1") == ("/dev/spidev0.1", None)
    assert split_device("/dev/spidev0.0,data_ready=gpiochip1:5") == (
        "/dev/spidev0.0",
        "gpiochip1:5",
    )
    assert parse_gpio_line("gpiochip1:5") == ("/dev/gpiochip1", 5)
    with pytest.raises(DeviceError, match="unknown device option 'drdy=4'"):
        split_device("/dev/spidev0.0,drdy=4")
    with pytest.raises(DeviceError, match="not CHIP:LINE"):
        parse_gpio_line("gpiochip0")


def test_sensor_rate_without_data_ready_line_is_refused(part):
    with pytest.raises(DeviceError, match=r"819\.202 Hz is the sensor's own rate"):
        open_spi_source("/dev/spidev0.0", RATE_819)
    assert part.transfers == []  # refused before touching the part


def test_host_rate_is_timer_paced_even_with_a_data_ready_line(part):
    source = open_spi_source(f"/dev/spidev0.0,data_ready={LINE}", config_for_rate(100.0))
    assert isinstance(source.pacer, TimerPacer) and source.config.pacing == "host_timer"


def test_missing_packages_give_clear_errors(monkeypatch):
    monkeypatch.setitem(sys.modules, "spidev", None)
    monkeypatch.setitem(sys.modules, "gpiod", None)
    with pytest.raises(DeviceError, match=r"'spidev' package: pip install 'imupipe\[spi\]'"):
        SpidevBus("/dev/spidev0.0")
    with pytest.raises(DeviceError, match=r"'gpiod' package"):
        DataReadyPacer(LINE, 819.2)


def test_cli_records_a_sensor_rate_paced_by_data_ready(monkeypatch, tmp_path, capsys):
    from mcap.reader import make_reader

    from imupipe.cli import main

    def run(*args):
        monkeypatch.setattr(sys, "argv", ["imupipe", "record", "--quiet", *args])
        with pytest.raises(SystemExit) as exit_info:
            main()
        return exit_info.value.code, capsys.readouterr().err

    part = install(monkeypatch, FakeAdis16364())
    out = tmp_path / "spi.mcap"
    device = f"/dev/spidev0.0,data_ready={LINE}"
    code, _ = run("-o", str(out), "--source", "spi", "--device", "/dev/spidev0.0",
                  "--data-ready", LINE, "--rate", "819.2", "--duration", "0.5s")  # fmt: skip
    assert code == 0
    with out.open("rb") as f:
        reader = make_reader(f)
        meta = next(m.metadata for m in reader.iter_metadata() if m.name == "adis16364")
        n = sum(1 for _ in reader.iter_messages())
    assert (meta["pacing"], meta["rate_method"], meta["smpl_prd"]) == (
        "data_ready",
        "smpl_prd",
        "1",
    )
    assert n == 410 and all(part.burst_fresh) and np.all(np.diff(part.burst_serials) == 1)

    install(monkeypatch, FakeAdis16364(self_test_fail=1 << 13))
    code, err = run("-o", str(tmp_path / "bad.mcap"), "--source", "spi", "--device", device,
                    "--rate", "819.2", "--duration", "1s")  # fmt: skip
    assert code == 2
    assert err == (
        "imupipe: error: ADIS16364 start-up check failed: DIAG_STAT 0x2000 "
        "(X-axis accelerometer self-test failure)\n"
    )
