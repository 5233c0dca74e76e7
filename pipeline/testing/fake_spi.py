"""A fake ADIS16364 on Linux SPI and GPIO, for tests: stand-ins for the ``spidev`` and ``gpiod``
(v2) modules that enforce the part's rules.

The rules are written here from the datasheet facts, independently of the driver
(:mod:`imupipe.recording.spi` and the timing in :mod:`imupipe.device.adis16364` are not used), so
a timing mistake in the driver is not mirrored by its test double.  Sample values come from a
:class:`~imupipe.recording.simulator.VirtualADIS16364` behind the fake.

Time is virtual, in integer ns (:attr:`FakeAdis16364.now_ns`): a transfer takes its clock time
(8 bits per byte at its speed) plus its spidev ``delay_usecs``; :meth:`FakeAdis16364.sleep` and
waiting for a data-ready edge advance it too.  Host time between calls is taken as zero, the
worst case for the stall: the delay the driver asks of spidev must carry all of it.

Rules (a broken one raises :class:`SpiProtocolViolation`):

* SPI mode 3, 8-bit words, MSB first; whole 16-bit frames.
* SCLK between 10 kHz and 2 MHz (bursts 1 MHz) while SMPL_PRD[7:0] <= 0x09; at most 300 kHz
  for everything in low-power mode (Ns >= 0x0A or the 52.851 SPS time base).
* Between frames, from the last clock edge to the next transfer, at least tDATASTALL (9 µs
  fast, 75 µs low-power), and chip-select falls at least tDATARATE apart (40 / 100 µs).  One
  chip-select period holds one frame, or a burst (0x3E00 and up to 11 more frames).
* No transfer within 130 ms of a software reset (GLOB_CMD bit 7); DIAG_STAT not read while
  the internal self-test (MSC_CTRL bit 10, cleared by the part when done) runs.

Samples are made at base/(Ns+1) from the last SMPL_PRD write (or reset).  A burst returns the
newest sample; a sample already read comes back with ND (bit 15) clear.  With MSC_CTRL
DATA_RDY_EN and DIO1 selected, each sample drives an edge on the data-ready line (rising when
active high, falling when active low; the pulse's trailing edge is not modelled).
"""

from __future__ import annotations

import enum
import math
import types
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from datetime import timedelta

from imupipe.device.adis16364 import config_for_rate, sample_rate_sps
from imupipe.recording.simulator import VirtualADIS16364

# ---- the part's rules (datasheet facts; see the module docstring) ----------------------------
_SCLK_MIN_HZ = 10_000
_SCLK_MAX_HZ = {"fast": 2_000_000, "low_power": 300_000}
_BURST_MAX_HZ = {"fast": 1_000_000, "low_power": 300_000}
_STALL_MIN_NS = {"fast": 9_000, "low_power": 75_000}
_PERIOD_MIN_NS = {"fast": 40_000, "low_power": 100_000}
_RESET_NS = 130_000_000
_BURST_DIN = 0x3E00
_BURST_FRAMES = 12
_ND = 0x8000
_MSC_CTRL, _SMPL_PRD, _DIAG_STAT, _GLOB_CMD = 0x34, 0x36, 0x3C, 0x3E
_DR_DIO2, _DR_POL_HIGH, _DR_EN = 0x0001, 0x0002, 0x0004
_SELF_TEST_RUNNING = 0x0400
_SELF_CLEARING = 0x0C00
"""MSC_CTRL internal self-test and memory test: the part clears them when done."""
_SAMPLE_BLOCK = 64
_KERNEL_EVENT_BUFFER = 16
"""Edge events the kernel keeps per requested line (gpiolib-cdev default 16 x lines)."""


class SpiProtocolViolation(AssertionError):
    """The driver did something the real part would not accept."""


@dataclass(frozen=True)
class Transfer:
    """One chip-select period as the part saw it: CS falls at ``start_ns``, ``words`` (DIN) are
    clocked at ``speed_hz``, the clock idles ``delay_us`` µs, CS rises.  ``mode`` is the part's
    mode (``"fast"`` / ``"low_power"``) at that time."""

    start_ns: int
    words: tuple[int, ...]
    speed_hz: int
    delay_us: int
    mode: str


@dataclass(frozen=True)
class _Edge:
    time_ns: int
    serial: int
    rising: bool


def _mode(smpl_prd: int) -> str:
    return "low_power" if smpl_prd & 0x80 or (smpl_prd & 0x7F) >= 0x0A else "fast"


class FakeAdis16364:
    """An ADIS16364 wired to ``/dev/spidev{bus}.{cs}`` with DIO1 on ``gpio_chip``:``gpio_line``.

    Args:
        device: the virtual part whose registers and samples the fake serves (default: 819.2
            SPS, serial number 0x1234).
        flash: register values a reset restores (default: the factory SMPL_PRD 0x0001,
            SENS_AVG 0x0402, MSC_CTRL 0x0006); also applied at power-on.
        self_test_fail: DIAG_STAT bits the internal self-test latches (0 = it passes).
        self_test_s: how long the internal self-test runs.

    Attributes:
        transfers: every :class:`Transfer`, in order.
        burst_serials: serial number of the sample each burst returned (samples are numbered
            from power-on, across SMPL_PRD changes).
        burst_fresh: whether that sample was unread (ND set) when the burst returned it.
    """

    def __init__(
        self,
        device: VirtualADIS16364 | None = None,
        *,
        flash: dict[int, int] | None = None,
        self_test_fail: int = 0,
        self_test_s: float = 0.012,
        bus: int = 0,
        cs: int = 0,
        gpio_chip: str = "/dev/gpiochip0",
        gpio_line: int = 17,
        epoch_ns: int = 1_700_000_000_000_000_000,
    ) -> None:
        self.device = device or VirtualADIS16364(
            config_for_rate(sample_rate_sps(0x0001), serial_number=0x1234), seed=3
        )
        self.flash = {_SMPL_PRD: 0x0001, 0x38: 0x0402, _MSC_CTRL: 0x0006, **(flash or {})}
        self.self_test_fail = self_test_fail
        self.self_test_ns = round(self_test_s * 1e9)
        self.spi_address = (bus, cs)
        self.gpio_chip, self.gpio_line = gpio_chip, gpio_line
        self.epoch_ns = epoch_ns
        self.now_ns = 0
        self.transfers: list[Transfer] = []
        self.burst_serials: list[int] = []
        self.burst_fresh: list[bool] = []
        self.edges: list[_Edge] = []
        self._pending: int | None = None
        self._last_clock_end_ns: int | None = None
        self._last_cs_fall_ns: int | None = None
        self._busy_until_ns = 0
        self._self_test_until_ns = 0
        self._diag_latch = 0
        self._t0_ns, self._serial0 = 0, 0
        self._read_serial = -1
        self._last_words: list[int] = []
        self._samples: deque[list[int]] = deque()
        self._edges_done = 0
        self._load_flash()

    # ---- time --------------------------------------------------------------------------------
    def sleep(self, seconds: float) -> None:
        """The host waits ``seconds`` (virtual)."""
        self.now_ns += round(seconds * 1e9)

    def clock_ns(self) -> int:
        """Monotonic host clock (ns)."""
        return self.now_ns

    def wall_clock_ns(self) -> int:
        """Wall clock (ns since the Unix epoch)."""
        return self.epoch_ns + self.now_ns

    # ---- the sample timeline -----------------------------------------------------------------
    def _smpl_prd(self) -> int:
        return self.device.read_register(_SMPL_PRD) & 0xFF

    @property
    def mode(self) -> str:
        """``"fast"`` or ``"low_power"``, from SMPL_PRD."""
        return _mode(self._smpl_prd())

    def _edge_ns(self, j: int) -> int:
        return self._t0_ns + round(j * 1e9 / sample_rate_sps(self._smpl_prd()))

    def _serial_at(self, t_ns: int) -> int:
        """Serial number of the newest sample made by ``t_ns``."""
        j = max(0, math.floor((t_ns - self._t0_ns) * sample_rate_sps(self._smpl_prd()) / 1e9))
        while self._edge_ns(j + 1) <= t_ns:
            j += 1
        while j > 0 and self._edge_ns(j) > t_ns:
            j -= 1
        return self._serial0 + j

    def _retime(self, change: Callable[[], None], t0_ns: int) -> None:
        """Apply ``change`` (to SMPL_PRD) and restart the sample clock at ``t0_ns``."""
        self._advance_edges()
        serial = self._serial_at(self.now_ns)
        change()
        self._serial0, self._t0_ns, self._edges_done = serial, t0_ns, serial

    def _data_ready(self) -> tuple[bool, bool]:
        """(data-ready drives DIO1, asserting edge is rising)."""
        msc = self.device.read_register(_MSC_CTRL)
        return bool(msc & _DR_EN) and not msc & _DR_DIO2, bool(msc & _DR_POL_HIGH)

    def _advance_edges(self) -> None:
        """Log the data-ready edges of the samples made up to now (state unchanged since)."""
        serial = self._serial_at(self.now_ns)
        enabled, rising = self._data_ready()
        if enabled:
            self.edges.extend(
                _Edge(self._edge_ns(s - self._serial0), s, rising)
                for s in range(self._edges_done + 1, serial + 1)
            )
        self._edges_done = max(self._edges_done, serial)

    def next_edge_ns(self, wanted: frozenset[bool]) -> int | None:
        """When the next data-ready edge comes whose direction (rising?) is ``wanted``, if ever."""
        enabled, rising = self._data_ready()
        if not enabled or rising not in wanted:
            return None
        return self._edge_ns(self._serial_at(self.now_ns) - self._serial0 + 1)

    # ---- registers ---------------------------------------------------------------------------
    def _load_flash(self) -> None:
        for addr, value in self.flash.items():
            self._write_device(addr, value & 0xFF)
            self._write_device(addr + 1, value >> 8)

    def _read(self, addr: int) -> int:
        addr &= 0x7E
        if addr == _DIAG_STAT:
            if self.now_ns < self._self_test_until_ns:
                raise SpiProtocolViolation("DIAG_STAT read while the self-test still runs")
            value = self.device.read_register(addr) | self._diag_latch
            self._diag_latch = 0
            return value
        if addr == _MSC_CTRL and self.now_ns < self._self_test_until_ns:
            return self.device.read_register(addr) | _SELF_TEST_RUNNING
        return self.device.read_register(addr)

    def _write_byte(self, addr: int, byte: int, end_ns: int) -> None:
        if addr == _GLOB_CMD and byte & 0x80:
            self._busy_until_ns = end_ns + _RESET_NS
            self._self_test_until_ns = 0
            self._retime(self._load_flash, self._busy_until_ns)
        elif addr == _SMPL_PRD:
            self._retime(lambda: self._write_device(addr, byte), end_ns)
        else:
            if addr == _MSC_CTRL + 1 and byte & (_SELF_TEST_RUNNING >> 8):
                self._self_test_until_ns = end_ns + self.self_test_ns
                self._diag_latch |= self.self_test_fail
            if addr == _MSC_CTRL + 1:
                byte &= ~(_SELF_CLEARING >> 8)
            self._write_device(addr, byte)

    def _next_sample(self) -> list[int]:
        """The virtual part's next output words, generated in blocks (its bulk API)."""
        if not self._samples:
            self._samples.extend(self.device.frames(_SAMPLE_BLOCK).burst.tolist())
        return self._samples.popleft()

    def _write_device(self, addr: int, byte: int) -> None:
        self.device.write_byte(addr, byte)
        self._samples.clear()  # made under the old settings

    def _burst_words(self) -> list[int]:
        serial = self._serial_at(self.now_ns)
        fresh = serial > self._read_serial
        if fresh:
            unread = serial - self._read_serial - 1 if self._read_serial >= 0 else 0
            for _ in range(unread + 1):  # samples made and overwritten before anyone read them
                self._last_words = self._next_sample()
            self._read_serial = serial
        self.burst_serials.append(serial)
        self.burst_fresh.append(fresh)
        return [w if fresh else w & ~_ND for w in self._last_words]

    # ---- SPI ---------------------------------------------------------------------------------
    def transfer(
        self, data: list[int], speed_hz: int, delay_us: int, spi_mode: int, bits: int, lsb: bool
    ) -> list[int]:
        """One spidev transfer (one chip-select period) of bytes ``data``."""
        if spi_mode != 3 or bits != 8 or lsb:
            raise SpiProtocolViolation(
                f"SPI mode {spi_mode}, {bits}-bit words, lsbfirst={lsb}: the part needs mode 3 "
                "(CPOL=1, CPHA=1), MSB first"
            )
        if not data or len(data) % 2:
            raise SpiProtocolViolation(f"{len(data)} bytes: frames are 16 bits")
        words = [(data[i] << 8) | data[i + 1] for i in range(0, len(data), 2)]
        self._advance_edges()
        t, mode = self.now_ns, self.mode
        if t < self._busy_until_ns:
            raise SpiProtocolViolation(
                f"transfer {(t - self._busy_until_ns + _RESET_NS) / 1e6:.1f} ms after a reset: "
                f"the part starts up for {_RESET_NS / 1e6:g} ms"
            )
        burst = words[0] == _BURST_DIN
        if len(words) > (_BURST_FRAMES if burst else 1):
            raise SpiProtocolViolation(
                f"{len(words)} frames in one chip-select period: frames need a stall between"
            )
        limit = (_BURST_MAX_HZ if burst else _SCLK_MAX_HZ)[mode]
        if not _SCLK_MIN_HZ <= speed_hz <= limit:
            raise SpiProtocolViolation(
                f"{'burst' if burst else 'frame'} at {speed_hz} Hz SCLK in {mode} mode "
                f"(SMPL_PRD 0x{self._smpl_prd():02X}): the part takes {_SCLK_MIN_HZ}..{limit} Hz"
            )
        if self._last_clock_end_ns is not None and self._last_cs_fall_ns is not None:
            stall = t - self._last_clock_end_ns
            if stall < _STALL_MIN_NS[mode]:
                raise SpiProtocolViolation(
                    f"{stall / 1e3:g} µs stall before this frame in {mode} mode: tDATASTALL "
                    f"is {_STALL_MIN_NS[mode] / 1e3:g} µs"
                )
            period = t - self._last_cs_fall_ns
            if period < _PERIOD_MIN_NS[mode]:
                raise SpiProtocolViolation(
                    f"frames {period / 1e3:g} µs apart in {mode} mode: tDATARATE is "
                    f"{_PERIOD_MIN_NS[mode] / 1e3:g} µs"
                )
        self.transfers.append(Transfer(t, tuple(words), speed_hz, delay_us, mode))
        clock_end = t + round(len(data) * 8 * 1e9 / speed_hz)
        out = self._clock(words, clock_end)
        self._last_cs_fall_ns, self._last_clock_end_ns = t, clock_end
        self.now_ns = clock_end + delay_us * 1000
        return [b for w in out for b in ((w >> 8) & 0xFF, w & 0xFF)]

    def _clock(self, words: list[int], end_ns: int) -> list[int]:
        """The part's answers to ``words``: a read's value goes out on the next frame (also in
        the next chip-select period); a burst clocks out the output registers."""
        out: list[int] = []
        burst: list[int] = []
        for din in words:
            if burst:
                out.append(burst.pop(0))
                continue
            out.append(self._read(self._pending) if self._pending is not None else 0)
            self._pending = None
            if din & 0x8000:
                self._write_byte((din >> 8) & 0x7F, din & 0xFF, end_ns)
            elif din == _BURST_DIN:
                burst = self._burst_words()
            else:
                self._pending = (din >> 8) & 0x7F
        return out

    # ---- stand-in modules --------------------------------------------------------------------
    def spidev_module(self) -> types.ModuleType:
        """A ``spidev`` module whose ``SpiDev`` talks to this part (py-spidev's API)."""
        chip = self

        class SpiDev:
            def __init__(self) -> None:
                self.mode = 0
                self.bits_per_word = 8
                self.lsbfirst = False
                self.max_speed_hz = 125_000_000
                self.opened = False

            def open(self, bus: int, device: int) -> None:
                if (bus, device) != chip.spi_address:
                    raise FileNotFoundError(2, f"No such file: /dev/spidev{bus}.{device}")
                self.opened = True

            def xfer2(
                self, values: list[int], speed_hz: int = 0, delay_usecs: int = 0, bits: int = 0, /
            ) -> list[int]:
                if not self.opened:
                    raise OSError(9, "Bad file descriptor")
                speed = speed_hz or self.max_speed_hz
                return chip.transfer(
                    list(values), speed, delay_usecs, self.mode, bits or self.bits_per_word,
                    self.lsbfirst,
                )  # fmt: skip

            def close(self) -> None:
                self.opened = False

        module = types.ModuleType("spidev")
        module.SpiDev = SpiDev  # type: ignore[attr-defined]
        return module

    def gpiod_modules(self) -> dict[str, types.ModuleType]:
        """``gpiod`` and ``gpiod.line`` modules (libgpiod v2 API) whose line requests see this
        part's data-ready edges on :attr:`gpio_chip`:``gpio_line``."""
        chip = self

        class Edge(enum.Enum):
            NONE, RISING, FALLING, BOTH = range(4)

        class Direction(enum.Enum):
            AS_IS, INPUT, OUTPUT = range(3)

        @dataclass
        class LineSettings:
            direction: Direction = Direction.AS_IS
            edge_detection: Edge = Edge.NONE

        @dataclass(frozen=True)
        class EdgeEvent:
            class Type(enum.Enum):
                RISING_EDGE, FALLING_EDGE = 1, 2

            event_type: EdgeEvent.Type
            timestamp_ns: int
            line_offset: int
            global_seqno: int
            line_seqno: int

        class LineRequest:
            def __init__(self, offset: int, settings: LineSettings, buffer: int) -> None:
                self.offset, self.settings = offset, settings
                wanted = {Edge.RISING: {True}, Edge.FALLING: {False}, Edge.BOTH: {True, False}}
                wired = offset == chip.gpio_line
                self._wanted = frozenset(wanted.get(settings.edge_detection, ()) if wired else ())
                chip._advance_edges()
                self._cursor = len(chip.edges)
                self._seqno = 0
                self._events: deque[EdgeEvent] = deque(maxlen=buffer)
                self.released = False

            def _collect(self) -> None:
                chip._advance_edges()
                for edge in chip.edges[self._cursor :]:
                    if edge.rising in self._wanted:
                        self._seqno += 1
                        kind = EdgeEvent.Type["RISING_EDGE" if edge.rising else "FALLING_EDGE"]
                        self._events.append(
                            EdgeEvent(kind, edge.time_ns, self.offset, self._seqno, self._seqno)
                        )
                self._cursor = len(chip.edges)

            def wait_edge_events(self, timeout: timedelta | float | None = None) -> bool:
                self._collect()
                if self._events:
                    return True
                if isinstance(timeout, timedelta):
                    timeout = timeout.total_seconds()
                nxt = chip.next_edge_ns(self._wanted)
                limit = None if timeout is None else chip.now_ns + round(timeout * 1e9)
                if nxt is None or (limit is not None and nxt > limit):
                    if limit is None:
                        raise SpiProtocolViolation("waiting forever for an edge that never comes")
                    chip.now_ns = limit
                    return False
                chip.now_ns = nxt
                self._collect()
                return True

            def read_edge_events(self, max_events: int | None = None) -> list[EdgeEvent]:
                if not self.wait_edge_events(None):
                    return []
                n = len(self._events) if max_events is None else max_events
                return [self._events.popleft() for _ in range(min(n, len(self._events)))]

            def release(self) -> None:
                self.released = True

            def __enter__(self) -> LineRequest:
                return self

            def __exit__(self, *exc: object) -> None:
                self.release()

        def request_lines(
            path: str,
            config: dict[int, LineSettings | None],
            consumer: str | None = None,
            output_values: object = None,
            event_buffer_size: int | None = None,
        ) -> LineRequest:  # gpiod.request_lines(path, ...) -> Chip.request_lines(config, ...)
            if path != chip.gpio_chip:
                raise FileNotFoundError(2, f"No such file or directory: {path!r}")
            ((offset, settings),) = config.items()
            size = event_buffer_size or _KERNEL_EVENT_BUFFER
            return LineRequest(offset, settings or LineSettings(), size)

        line = types.ModuleType("gpiod.line")
        line.Edge, line.Direction = Edge, Direction  # type: ignore[attr-defined]
        gpiod = types.ModuleType("gpiod")
        gpiod.line = line  # type: ignore[attr-defined]
        gpiod.LineSettings = LineSettings  # type: ignore[attr-defined]
        gpiod.EdgeEvent = EdgeEvent  # type: ignore[attr-defined]
        gpiod.request_lines = request_lines  # type: ignore[attr-defined]
        return {"gpiod": gpiod, "gpiod.line": line}
