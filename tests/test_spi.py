"""The SPI driver against the fake bus (the virtual ADIS16364 behind the chip's protocol)."""

import numpy as np
import pytest

from imupipe.device.adis16364 import REGISTERS, DeviceConfig, burst_counts, config_for_rate
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.recording.spi import (
    Adis16364Driver,
    DeviceError,
    FakeSpiBus,
    SpidevBus,
    SpiSource,
    TimerPacer,
)


def make(seed: int = 4, **config):
    dev = VirtualADIS16364(DeviceConfig(serial_number=0x1234, **config), seed=seed)
    bus = FakeSpiBus(dev)
    return dev, bus, Adis16364Driver(bus, wall_clock_ns=lambda: 42)


class FixedPacer:
    def __init__(self, periods):
        self._periods = iter(periods)

    def wait(self) -> int:
        return next(self._periods)


def test_read_answers_on_next_frame():
    _, bus, driver = make()
    # a read command's answer comes one frame later, also within one transfer
    assert bus.xfer16([REGISTERS["PROD_ID"] << 8, REGISTERS["SERIAL_NUM"] << 8, 0]) == [
        0,
        16364,
        0x1234,
    ]
    assert driver.check_product_id() == 16364
    assert bus.log[-2:] == [0x5600, 0x0000]


def test_start_writes_config_bytes_low_first():
    dev, bus, driver = make()
    config = driver.start(DeviceConfig(sens_avg=0x0403, source="spi"))
    writes = [w for w in bus.log if w & 0x8000]
    assert writes == [0xB601, 0xB700, 0xB803, 0xB904]
    assert dev.config.sens_avg == 0x0403 and dev.config.smpl_prd == 0x0001
    assert config.rate_method == "host_poll" and config.serial_number == 0x1234
    # a rate the divider makes: SMPL_PRD written
    dev, bus, driver = make()
    config = driver.start(config_for_rate(409.6, source="spi"))
    assert config.smpl_prd == 0x0003 and config.rate_method == "smpl_prd"
    assert dev.read_register(REGISTERS["SMPL_PRD"]) == 0x0003


def test_spi_source_for_the_recorder():
    _, _, driver = make(seed=1)
    source = SpiSource(driver, DeviceConfig(source="spi"), pacer=FixedPacer([1, 2, 1]))
    block = source.frames(3)
    assert source.config.serial_number == 0x1234 and source.config.source == "spi"
    assert block.counter.tolist() == [0, 2, 3] and block.burst.shape == (3, 11)


def test_burst_decode_matches_device():
    _, bus, driver = make(seed=9)
    block = driver.frames(20, FixedPacer([1] * 20))
    reference = VirtualADIS16364(DeviceConfig(serial_number=0x1234), seed=9)
    expected = np.array([reference.burst_read() for _ in range(20)], dtype=np.uint16)
    assert np.array_equal(block.burst, expected)
    counts = burst_counts(block.burst)
    assert np.all(counts[:, 0] == 2068) and np.all(counts[:, 6] < -990)
    burst_cmds = [w for w in bus.log if w == 0x3E00]
    assert len(burst_cmds) == 20
    assert np.all(block.diag_valid) and not np.any(block.diag_stat)
    assert np.all(block.stamp_ns == 42)


def test_missed_frames_from_timer_pacer():
    clock = {"ns": 0}
    sleeps = []

    def sleep(s):
        sleeps.append(s)
        clock["ns"] += round(s * 1e9)

    pacer = TimerPacer(100.0, clock=lambda: clock["ns"], sleep=sleep)
    _, _, driver = make()
    assert driver.frames(2, pacer).counter.tolist() == [0, 1]
    clock["ns"] += 35_000_000  # host stalls 35 ms: deadlines at 20, 30, 40 ms passed
    block = driver.frames(3, pacer)
    assert block.counter.tolist() == [4, 5, 6]
    assert driver.missed_frames == 2
    assert sleeps and all(0 < s <= 0.01 for s in sleeps)


def test_wrong_prod_id_raises():
    class OtherChip:
        def xfer16(self, words):
            return [16405] * len(words)

    with pytest.raises(DeviceError, match="16405"):
        Adis16364Driver(OtherChip()).check_product_id()


def test_config_readback_mismatch_raises():
    class StuckBus(FakeSpiBus):
        def xfer16(self, words):
            return super().xfer16([w for w in words if not w & 0x8000] or [0])

    driver = Adis16364Driver(StuckBus(VirtualADIS16364(DeviceConfig())))
    with pytest.raises(DeviceError, match="SENS_AVG"):
        driver.configure(0x0001, 0x0403)


def test_diag_stat_read_every_n_frames():
    _, bus, driver = make()
    block = driver.frames(6, FixedPacer([1] * 6), diag_every=3)
    assert block.diag_valid.tolist() == [False, False, True, False, False, True]
    assert bus.log.count(REGISTERS["DIAG_STAT"] << 8) == 2


def test_spidev_missing_gives_clear_error():
    try:
        import spidev  # noqa: F401
    except ImportError:
        with pytest.raises(DeviceError, match=r"imupipe\[spi\]"):
            SpidevBus("/dev/spidev0.0")
    else:
        pytest.skip("spidev installed")
