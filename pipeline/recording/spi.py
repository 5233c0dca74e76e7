"""ADIS16364 SPI driver: the Linux spidev bus, the protocol, its timing, start-up and pacing.

Protocol (ADIS1636x datasheets; Linux ``adis16400``/``adis`` drivers): 16-bit frames, SPI mode 3
(CPOL = 1, CPHA = 1), MSB first.  A register read sends DIN = addr << 8 and the value comes back
on the NEXT 16-bit frame; a write sends DIN = 0x8000 | addr << 8 | byte, one byte per frame, low
address first; a burst read sends DIN = 0x3E00 and 11 more frames clock out SUPPLY_OUT..AUX_ADC
(:data:`imupipe.device.adis16364.BURST_WORDS`) in one chip-select period.

Timing (:func:`imupipe.device.adis16364.spi_timing`): SCLK follows the mode SMPL_PRD selects,
<= 2 MHz (bursts <= 1 MHz) while SMPL_PRD[7:0] <= 0x09, <= 300 kHz for everything in low-power
mode (Ns >= 0x0A or the slow time base) and while SMPL_PRD is unknown (after a reset).  Every
16-bit frame and every burst is its own spidev transfer whose ``delay_usecs`` is the stall: the
kernel idles the clock that long after the last bit, before chip select is released, so the
stall does not depend on Python's timing.

Start-up (as the Linux adis library's ``__adis_initial_startup``): software reset through
GLOB_CMD, 130 ms wait, PROD_ID check, internal self-test (MSC_CTRL bit 10, polled until the part
clears it) and DIAG_STAT check, any flag being one :class:`~imupipe.errors.SelfTestError`; then
SMPL_PRD and SENS_AVG (gyro range vs filter checked) written and read back, and data-ready
enabled on DIO1, active high (MSC_CTRL, as the kernel's ``adis_enable_irq``).

Pacing: a rate the sensor makes itself (``rate_method="smpl_prd"``) is read on each rising edge
of DIO1 through the Linux GPIO character device (:class:`DataReadyPacer`, ``gpiod`` v2), whose
per-line sequence numbers count the samples the host was too late for; a host timer
(:class:`TimerPacer`) only polls rates the sensor cannot make (the paper's 100 Hz).  The method
used is stored in the recording's metadata (``pacing``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import ClassVar, Protocol

import numpy as np

from imupipe.device.adis16364 import (
    BURST_COMMAND,
    BURST_WORDS,
    GLOB_CMD_SW_RESET,
    LOW_POWER_TIMING,
    MSC_DATA_RDY_DIO2,
    MSC_DATA_RDY_EN,
    MSC_DATA_RDY_POL_HIGH,
    MSC_INT_SELF_TEST,
    MSC_SELF_TESTS,
    PROD_ID_VALUE,
    REGISTERS,
    RESET_S,
    SELF_TEST_S,
    DeviceConfig,
    FrameBlock,
    check_sens_avg,
    diag_flags,
    low_power_mode,
    spi_timing,
)
from imupipe.errors import DeviceError, SelfTestError

WRITE_BIT = 0x8000
SPI_MODE = 3
"""CPOL = 1, CPHA = 1."""
SELF_TEST_POLLS = 10
"""MSC_CTRL reads (SELF_TEST_S apart) before a self-test that never ends is an error."""
PACING_FOR_RATE_METHOD = {"smpl_prd": "data_ready", "host_poll": "host_timer"}
"""The only pacing each rate method may use: the sensor's own rate on its data-ready edge, a
rate it cannot make by a host timer."""


class SpiBus(Protocol):
    """Full-duplex 16-bit SPI transfers."""

    def transfer(self, words: list[int], speed_hz: int, stall_us: int) -> list[int]:
        """Clock ``words`` out (and as many in) in one chip-select period at ``speed_hz``, then
        keep the clock idle ``stall_us`` µs before the next transfer may start."""
        ...


class SpidevBus:
    """A Linux spidev device (``pip install imupipe[spi]``): mode 3, 8-bit words, MSB first.

    Each :meth:`transfer` is one ``SpiDev.xfer2`` call with its own speed and ``delay_usecs``
    (py-spidev takes them positionally: ``xfer2(values, speed_hz, delay_usecs)``).  The default
    ``max_speed_hz`` is the slowest SCLK the part takes in any mode.
    """

    def __init__(self, device: str = "/dev/spidev0.0") -> None:
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
        self.device = device
        self._spi = spidev.SpiDev()
        try:
            self._spi.open(bus, cs)
        except OSError as exc:
            raise DeviceError(f"cannot open {device}: {exc}") from exc
        self._spi.mode = SPI_MODE
        self._spi.bits_per_word = 8
        self._spi.max_speed_hz = LOW_POWER_TIMING.sclk_hz

    def transfer(self, words: list[int], speed_hz: int, stall_us: int) -> list[int]:
        tx = [b for w in words for b in ((w >> 8) & 0xFF, w & 0xFF)]
        try:
            rx = self._spi.xfer2(tx, speed_hz, stall_us)
        except OSError as exc:
            raise DeviceError(f"SPI transfer on {self.device} failed: {exc}") from exc
        return [(rx[i] << 8) | rx[i + 1] for i in range(0, len(rx), 2)]

    def close(self) -> None:
        self._spi.close()


class Pacer(Protocol):
    """Waits for the next frame; returns how many frame periods passed (1 = none missed)."""

    method: ClassVar[str]
    """How reads are paced, as stored in the metadata (``pacing``)."""

    def wait(self) -> int: ...


@dataclass
class TimerPacer:
    """Host-timer pacing at ``rate_hz``: sleeps to the next deadline; if the host woke up late
    past later deadlines, skips them and reports them (the frames they would have read).
    ``clock`` (ns) and ``sleep`` (s) are injectable so tests need not sleep."""

    method: ClassVar[str] = "host_timer"
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


def parse_gpio_line(text: str) -> tuple[str, int]:
    """``"/dev/gpiochip0:17"`` or ``"gpiochip0:17"`` -> (chip path, line offset)."""
    chip, _, offset = text.rpartition(":")
    if not chip or not offset.isdigit():
        raise DeviceError(f"data-ready line {text!r} is not CHIP:LINE (e.g. /dev/gpiochip0:17)")
    return (chip if "/" in chip else f"/dev/{chip}"), int(offset)


class DataReadyPacer:
    """Pacing by the part's data-ready output (DIO1, active high) on a GPIO line ``line``
    (``CHIP:OFFSET``), through the Linux GPIO character device (``gpiod`` >= 2).

    Each :meth:`wait` blocks for a rising edge; the edges' per-line sequence numbers count the
    samples made since the previous wait, so a host that came late reports the samples it
    missed instead of skipping them silently.  No edge within four sample periods (at least
    0.5 s) is a :class:`DeviceError` (DIO1 not wired to that line, or data-ready off).
    """

    method: ClassVar[str] = "data_ready"

    def __init__(self, line: str, rate_hz: float) -> None:
        chip_path, offset = parse_gpio_line(line)
        try:
            import gpiod  # type: ignore[import-not-found]  # optional extra
            from gpiod.line import Direction, Edge  # type: ignore[import-not-found]
        except ImportError as exc:
            raise DeviceError(
                "pacing by data-ready needs the 'gpiod' package (libgpiod >= 2 bindings): "
                "pip install 'imupipe[spi]'"
            ) from exc
        settings = gpiod.LineSettings(direction=Direction.INPUT, edge_detection=Edge.RISING)
        try:
            self._request = gpiod.request_lines(
                chip_path, consumer="imupipe", config={offset: settings}
            )
        except (OSError, ValueError) as exc:
            raise DeviceError(f"cannot watch GPIO line {line}: {exc}") from exc
        self.line = line
        self.timeout_s = max(0.5, 4.0 / rate_hz)
        self._last_seqno: int | None = None

    def wait(self) -> int:
        if not self._request.wait_edge_events(self.timeout_s):
            raise DeviceError(
                f"no data-ready edge on {self.line} within {self.timeout_s:g} s: "
                "is the ADIS16364's DIO1 wired to that GPIO line?"
            )
        seqno = self._request.read_edge_events()[-1].line_seqno
        periods = 1 if self._last_seqno is None else seqno - self._last_seqno
        self._last_seqno = seqno
        return periods

    def close(self) -> None:
        self._request.release()


class Adis16364Driver:
    """Protocol code for an ADIS16364 on any :class:`SpiBus`; the SPI timing follows the mode
    of the SMPL_PRD last written (:attr:`timing`).  ``sleep`` (s) waits for the part (reset,
    self-test) and is injectable so tests need not sleep."""

    def __init__(
        self,
        bus: SpiBus,
        wall_clock_ns: Callable[[], int] = time.time_ns,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.bus = bus
        self.wall_clock_ns = wall_clock_ns
        self.sleep = sleep
        self.timing = LOW_POWER_TIMING
        """SPI timing in force: the low-power one until SMPL_PRD is known."""
        self.counter = 0
        """Frame counter of the next frame: it advances by the periods the pacer reports."""
        self.missed_frames = 0

    # ---- registers ---------------------------------------------------------------------------
    def _frame(self, din: int) -> int:
        """One 16-bit frame in its own chip-select period, followed by the stall."""
        return self.bus.transfer([din], self.timing.sclk_hz, self.timing.stall_us)[0]

    def read_register(self, addr: int) -> int:
        """Read a 16-bit register: command frame, then the answer on the next frame."""
        self._frame((addr & 0x7F) << 8)
        return self._frame(0x0000)

    def write_byte(self, addr: int, byte: int) -> None:
        """One write frame: ``byte`` into the register byte at ``addr``."""
        self._frame(WRITE_BIT | ((addr & 0x7F) << 8) | (byte & 0xFF))

    def write_register(self, addr: int, value: int) -> None:
        """Write a 16-bit register as two byte writes, low address first."""
        self.write_byte(addr, value & 0xFF)
        self.write_byte(addr + 1, (value >> 8) & 0xFF)

    def _write_checked(self, name: str, value: int) -> None:
        """Write a 16-bit register and read it back."""
        self.write_register(REGISTERS[name], value)
        readback = self.read_register(REGISTERS[name])
        if readback != value:
            raise DeviceError(f"{name} reads 0x{readback:04X} after writing 0x{value:04X}")

    # ---- start-up ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Software reset (GLOB_CMD bit 7) and the start-up wait; SMPL_PRD comes back from the
        part's flash, so the low-power timing holds until it is written."""
        self.timing = LOW_POWER_TIMING
        self.write_byte(REGISTERS["GLOB_CMD"], GLOB_CMD_SW_RESET)
        self.sleep(RESET_S)

    def check_product_id(self) -> int:
        """Read PROD_ID; raise :class:`DeviceError` unless it is 16364."""
        prod_id = self.read_register(REGISTERS["PROD_ID"])
        if prod_id != PROD_ID_VALUE:
            raise DeviceError(
                f"PROD_ID reads {prod_id} (0x{prod_id:04X}), expected {PROD_ID_VALUE}: "
                "not an ADIS16364, or wiring/SPI mode wrong"
            )
        return prod_id

    def self_test(self) -> None:
        """Run the internal self-test (MSC_CTRL bit 10), wait until the part clears the bit and
        check DIAG_STAT: any flag set raises one :class:`SelfTestError` naming them all."""
        msc_addr = REGISTERS["MSC_CTRL"]
        msc = self.read_register(msc_addr) & ~MSC_SELF_TESTS
        self.write_register(msc_addr, msc | MSC_INT_SELF_TEST)
        for _ in range(SELF_TEST_POLLS):
            self.sleep(SELF_TEST_S)
            if not self.read_register(msc_addr) & MSC_INT_SELF_TEST:
                break
        else:
            raise SelfTestError(
                f"the ADIS16364 self-test did not finish within {SELF_TEST_POLLS * SELF_TEST_S:g}"
                " s (MSC_CTRL bit 10 stays set)"
            )
        diag = self.read_diag_stat()
        if diag_flags(diag):
            raise SelfTestError(
                f"ADIS16364 start-up check failed: DIAG_STAT 0x{diag:04X} "
                f"({'; '.join(diag_flags(diag))})"
            )

    def configure(self, smpl_prd: int, sens_avg: int) -> None:
        """Write SMPL_PRD (its byte [7:0], as the kernel) and SENS_AVG, read both back.

        The SMPL_PRD write frame uses the low-power timing if either the old or the new mode is
        low-power (its stall must suit the frames that follow); after it, :attr:`timing` is the
        new mode's.  A gyro range the filter length does not allow is a ConfigError."""
        check_sens_avg(sens_avg)
        if low_power_mode(smpl_prd):
            self.timing = LOW_POWER_TIMING
        self.write_byte(REGISTERS["SMPL_PRD"], smpl_prd)
        self.timing = spi_timing(smpl_prd)
        readback = self.read_register(REGISTERS["SMPL_PRD"]) & 0xFF
        if readback != smpl_prd & 0xFF:
            raise DeviceError(f"SMPL_PRD reads 0x{readback:02X} after writing 0x{smpl_prd:02X}")
        self._write_checked("SENS_AVG", sens_avg)

    def enable_data_ready(self) -> None:
        """Data-ready on DIO1, active high (MSC_CTRL bits 2, 1 set, bit 0 clear); the other
        MSC_CTRL bits are kept, the self-test bits cleared."""
        msc = self.read_register(REGISTERS["MSC_CTRL"])
        msc = (msc & ~(MSC_SELF_TESTS | MSC_DATA_RDY_DIO2)) | MSC_DATA_RDY_EN
        self._write_checked("MSC_CTRL", msc | MSC_DATA_RDY_POL_HIGH)

    def read_diag_stat(self) -> int:
        """DIAG_STAT (reading it clears the latched flags)."""
        return self.read_register(REGISTERS["DIAG_STAT"])

    def burst_read(self) -> list[int]:
        """One burst: DIN 0x3E00 then 11 frames; the 11 output words, flags included."""
        words = [BURST_COMMAND] + [0] * len(BURST_WORDS)
        return self.bus.transfer(words, self.timing.burst_hz, self.timing.stall_us)[1:]

    def start(self, config: DeviceConfig) -> DeviceConfig:
        """Reset, check PROD_ID, self-test, write ``config``'s SMPL_PRD and SENS_AVG, enable
        data-ready; return ``config`` with the serial number the part reports."""
        self.reset()
        self.check_product_id()
        self.self_test()
        self.configure(config.smpl_prd, config.sens_avg)
        self.enable_data_ready()
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

    ``pacer`` must be the one :data:`PACING_FOR_RATE_METHOD` names for ``config.rate_method``
    (checked before the part is touched); ``config`` records it as ``pacing``."""

    def __init__(self, driver: Adis16364Driver, config: DeviceConfig, pacer: Pacer) -> None:
        if pacer.method != PACING_FOR_RATE_METHOD[config.rate_method]:
            if config.rate_method == "smpl_prd":
                raise DeviceError(
                    f"{config.output_rate_hz:g} Hz is the sensor's own rate (SMPL_PRD "
                    f"0x{config.smpl_prd:02X}) and is read on its data-ready edge: wire DIO1 "
                    "to a GPIO line and name it (--device /dev/spidevB.C,data_ready="
                    "/dev/gpiochipN:LINE), or record at a rate the host polls (e.g. 100 Hz)"
                )
            raise DeviceError(
                f"{config.output_rate_hz:g} Hz is not a rate the sensor makes: it is polled by "
                "a host timer, not paced by data-ready"
            )
        self.driver = driver
        self.pacer = pacer
        self.config = replace(driver.start(config), pacing=pacer.method)

    def frames(self, n: int) -> FrameBlock:
        return self.driver.frames(n, self.pacer)


def split_device(device: str) -> tuple[str, str | None]:
    """``"/dev/spidev0.0"`` or ``"/dev/spidev0.0,data_ready=/dev/gpiochip0:17"`` -> (spidev
    path, data-ready line or None)."""
    spi_path, *options = device.split(",")
    line = None
    for option in options:
        key, _, value = option.partition("=")
        if key.strip() != "data_ready" or not value:
            raise DeviceError(
                f"unknown device option {option!r} (only data_ready=/dev/gpiochipN:LINE)"
            )
        line = value.strip()
    return spi_path.strip(), line


def open_spi_source(device: str, config: DeviceConfig, data_ready: str | None = None) -> SpiSource:
    """Open ``device`` (``/dev/spidevB.C``, optionally ``,data_ready=CHIP:LINE``), start the
    part and pace it: by the data-ready line (``data_ready`` or the device option) at a rate
    the sensor makes, by a host timer at any other rate."""
    spi_path, line = split_device(device)
    line = data_ready or line
    if config.rate_method == "smpl_prd" and line:
        pacer: Pacer = DataReadyPacer(line, config.output_rate_hz)
    else:
        pacer = TimerPacer(config.output_rate_hz)
    return SpiSource(Adis16364Driver(SpidevBus(spi_path)), config, pacer)
