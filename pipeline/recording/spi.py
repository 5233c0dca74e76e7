"""ADIS16364 SPI driver: the real bus (Linux spidev), a fake bus backed by the virtual device,
and the protocol code both share.

Protocol (ADIS1636x datasheets; Linux ``adis16400`` driver): 16-bit frames, SPI mode 3
(CPOL = 1, CPHA = 1), MSB first.  A register read sends DIN = addr << 8 and the value comes back
on the NEXT 16-bit frame; a write sends DIN = 0x8000 | addr << 8 | byte, one byte per frame, low
address first; a burst read sends DIN = 0x3E00 and 11 more frames clock out SUPPLY_OUT..AUX_ADC
(:data:`imupipe.device.adis16364.BURST_WORDS`).  Register reads toggle chip select between frames
(the driver issues one :meth:`SpiBus.xfer16` per frame); a burst keeps it low for all 12.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from imupipe.device.adis16364 import (
    BURST_COMMAND,
    BURST_WORDS,
    PROD_ID_VALUE,
    REGISTERS,
    DeviceConfig,
    FrameBlock,
)
from imupipe.errors import DeviceError
from imupipe.recording.simulator import VirtualADIS16364

WRITE_BIT = 0x8000
BURST_SPEED_HZ = 1_000_000
"""SCLK for burst reads (datasheet/Linux: bursts at <= 1 MHz)."""


class SpiBus(Protocol):
    """Full-duplex 16-bit SPI transfer with chip select held low for all ``words``."""

    def xfer16(self, words: list[int]) -> list[int]: ...


class SpidevBus:
    """A Linux spidev device (``pip install imupipe[spi]``), mode 3, 16-bit words MSB first."""

    def __init__(self, device: str = "/dev/spidev0.0", speed_hz: int = BURST_SPEED_HZ) -> None:
        try:
            import spidev  # type: ignore[import-not-found]  # optional extra
        except ImportError as exc:
            raise DeviceError(
                "reading a real ADIS16364 needs the 'spidev' package: pip install 'imupipe[spi]'"
            ) from exc
        try:
            bus, cs = (int(x) for x in device.removeprefix("/dev/spidev").split("."))
        except ValueError as exc:
            raise DeviceError(f"{device!r} is not a /dev/spidevB.C path") from exc
        self._spi = spidev.SpiDev()
        try:
            self._spi.open(bus, cs)
        except OSError as exc:
            raise DeviceError(f"cannot open {device}: {exc}") from exc
        self._spi.mode = 3
        self._spi.max_speed_hz = speed_hz
        self._spi.bits_per_word = 8

    def xfer16(self, words: list[int]) -> list[int]:
        tx = [b for w in words for b in ((w >> 8) & 0xFF, w & 0xFF)]
        rx = self._spi.xfer2(tx)
        return [(rx[i] << 8) | rx[i + 1] for i in range(0, len(rx), 2)]

    def close(self) -> None:
        self._spi.close()


class FakeSpiBus:
    """Answers the words an ADIS16364 would, from a :class:`VirtualADIS16364` behind it.

    Keeps the chip's pipeline: a read command's answer goes out on the next frame, also across
    transfers (chip-select toggles); DIN = 0x3E00 starts a burst that ends with the transfer.
    """

    def __init__(self, device: VirtualADIS16364) -> None:
        self.device = device
        self.log: list[int] = []
        """Every DIN word received, in order (for tests)."""
        self._pending: int | None = None

    def xfer16(self, words: list[int]) -> list[int]:
        out: list[int] = []
        burst: list[int] = []
        for din in words:
            self.log.append(din)
            if burst:
                out.append(burst.pop(0))
                continue
            out.append(self.device.read_register(self._pending) if self._pending is not None else 0)
            self._pending = None
            if din & WRITE_BIT:
                self.device.write_byte((din >> 8) & 0x7F, din & 0xFF)
            elif din == BURST_COMMAND:
                burst = self.device.burst_read()
            else:
                self._pending = (din >> 8) & 0x7F
        return out


class Pacer(Protocol):
    """Waits for the next frame; returns how many frame periods passed (1 = none missed)."""

    def wait(self) -> int: ...


@dataclass
class TimerPacer:
    """Host-timer pacing at ``rate_hz``: sleeps to the next deadline; if the host woke up late
    past later deadlines, skips them and reports them (the frames they would have read).
    ``clock`` (ns) and ``sleep`` (s) are injectable so tests need not sleep."""

    rate_hz: float
    clock: Callable[[], int] = time.monotonic_ns
    sleep: Callable[[float], None] = time.sleep
    _next_ns: float | None = field(default=None, init=False)

    def wait(self) -> int:
        period_ns = 1e9 / self.rate_hz
        now = self.clock()
        if self._next_ns is None:
            self._next_ns = now + period_ns
            return 1
        if now < self._next_ns:
            self.sleep((self._next_ns - now) / 1e9)
            self._next_ns += period_ns
            return 1
        late = int((now - self._next_ns) // period_ns)
        self._next_ns += (late + 1) * period_ns
        return late + 1


class Adis16364Driver:
    """Protocol code for an ADIS16364 on any :class:`SpiBus`."""

    def __init__(self, bus: SpiBus, wall_clock_ns: Callable[[], int] = time.time_ns) -> None:
        self.bus = bus
        self.wall_clock_ns = wall_clock_ns
        self.counter = 0
        """Frame counter of the next frame: it advances by the periods the pacer reports."""
        self.missed_frames = 0

    # ---- registers ---------------------------------------------------------------------------
    def read_register(self, addr: int) -> int:
        """Read a 16-bit register: command frame, then the answer on the next frame."""
        self.bus.xfer16([(addr & 0x7F) << 8])
        return self.bus.xfer16([0x0000])[0]

    def write_register(self, addr: int, value: int) -> None:
        """Write a 16-bit register as two byte writes, low address first."""
        for offset, byte in ((0, value & 0xFF), (1, (value >> 8) & 0xFF)):
            self.bus.xfer16([WRITE_BIT | (((addr + offset) & 0x7F) << 8) | byte])

    def check_product_id(self) -> int:
        """Read PROD_ID; raise :class:`DeviceError` unless it is 16364."""
        prod_id = self.read_register(REGISTERS["PROD_ID"])
        if prod_id != PROD_ID_VALUE:
            raise DeviceError(
                f"PROD_ID reads {prod_id} (0x{prod_id:04X}), expected {PROD_ID_VALUE}: "
                "not an ADIS16364, or wiring/SPI mode wrong"
            )
        return prod_id

    def configure(self, smpl_prd: int, sens_avg: int) -> None:
        """Write SMPL_PRD and SENS_AVG and read them back."""
        for name, value in (("SMPL_PRD", smpl_prd), ("SENS_AVG", sens_avg)):
            self.write_register(REGISTERS[name], value)
            readback = self.read_register(REGISTERS[name])
            if readback != value:
                raise DeviceError(f"{name} reads 0x{readback:04X} after writing 0x{value:04X}")

    def read_diag_stat(self) -> int:
        """DIAG_STAT (reading it clears the latched flags)."""
        return self.read_register(REGISTERS["DIAG_STAT"])

    def burst_read(self) -> list[int]:
        """One burst: DIN 0x3E00 then 11 frames; the 11 output words, flags included."""
        return self.bus.xfer16([BURST_COMMAND] + [0] * len(BURST_WORDS))[1:]

    def start(self, config: DeviceConfig) -> DeviceConfig:
        """Check PROD_ID, write ``config``'s SMPL_PRD and SENS_AVG, and return ``config`` with
        the serial number the part reports."""
        self.check_product_id()
        self.configure(config.smpl_prd, config.sens_avg)
        return replace(config, serial_number=self.read_register(REGISTERS["SERIAL_NUM"]))

    # ---- frames ------------------------------------------------------------------------------
    def frames(self, n: int, pacer: Pacer, diag_every: int = 1) -> FrameBlock:
        """Read ``n`` frames paced by ``pacer``; DIAG_STAT is read after every ``diag_every``-th
        burst.  The counter advances by the periods the pacer reports, so a jump > 1 marks
        frames missed (also counted in :attr:`missed_frames`)."""
        stamps = np.empty(n, dtype=np.int64)
        counters = np.empty(n, dtype=np.uint32)
        burst = np.empty((n, len(BURST_WORDS)), dtype=np.uint16)
        diag = np.zeros(n, dtype=np.uint16)
        valid = np.zeros(n, dtype=bool)
        for i in range(n):
            periods = pacer.wait()
            self.missed_frames += periods - 1
            self.counter += periods - 1
            stamps[i] = self.wall_clock_ns()
            burst[i] = self.burst_read()
            counters[i] = self.counter & 0xFFFFFFFF
            self.counter += 1
            if diag_every and (i + 1) % diag_every == 0:
                diag[i], valid[i] = self.read_diag_stat(), True
        return FrameBlock(stamps, counters, burst, diag, valid)

    def stream(self, block: int, pacer: Pacer, diag_every: int = 1) -> Iterator[FrameBlock]:
        """Endless blocks of ``block`` frames (see :meth:`frames`)."""
        while True:
            yield self.frames(block, pacer, diag_every)


class SpiSource:
    """A started ADIS16364 as a frame source for the recorder: ``config`` and ``frames(n)``.

    Frames are paced by ``pacer`` (default: a host timer at ``config.output_rate_hz``; with
    ``rate_method="smpl_prd"`` pass a data-ready pacer for exact device timing)."""

    def __init__(self, driver: Adis16364Driver, config: DeviceConfig, pacer: Pacer | None = None):
        self.driver = driver
        self.config = driver.start(config)
        self.pacer = pacer if pacer is not None else TimerPacer(config.output_rate_hz)

    def frames(self, n: int) -> FrameBlock:
        return self.driver.frames(n, self.pacer)


def open_spi_source(device: str, config: DeviceConfig) -> SpiSource:
    """Open ``device`` (/dev/spidevB.C), check it is an ADIS16364 and configure it."""
    return SpiSource(Adis16364Driver(SpidevBus(device)), config)
