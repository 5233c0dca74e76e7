"""ADIS16364 register map, burst-read layout and output-word encoding.

Everything here is a fact of the part, read from the ADIS1636x datasheets (burst layout, ND/EA
flag bits, 14-/12-bit two's complement formats, scale factors) and cross-checked against the
Linux ``adis16400`` driver (register addresses, DIAG_STAT bits, SMPL_PRD formula).  Conversion
between raw 16-bit output words and physical values is vectorised over numpy arrays so that a
whole chunk of frames is encoded or decoded at once.

Units: gyro words are °/s per LSB, accelerometer words mg per LSB, temperature °C per LSB (0 LSB
= 25 °C), supply volts per LSB.  SI conversion (rad/s, m/s²) happens in :mod:`imupipe.io.decode`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numba
import numpy as np

from imupipe.errors import ConfigError

PROD_ID_VALUE = 16364
"""What PROD_ID (0x56) reads on an ADIS16364."""

REGISTERS: dict[str, int] = {
    "FLASH_CNT": 0x00,
    "SUPPLY_OUT": 0x02,
    "XGYRO_OUT": 0x04,
    "YGYRO_OUT": 0x06,
    "ZGYRO_OUT": 0x08,
    "XACCL_OUT": 0x0A,
    "YACCL_OUT": 0x0C,
    "ZACCL_OUT": 0x0E,
    "XTEMP_OUT": 0x10,
    "YTEMP_OUT": 0x12,
    "ZTEMP_OUT": 0x14,
    "AUX_ADC": 0x16,
    "XGYRO_OFF": 0x1A,
    "YGYRO_OFF": 0x1C,
    "ZGYRO_OFF": 0x1E,
    "XACCL_OFF": 0x20,
    "YACCL_OFF": 0x22,
    "ZACCL_OFF": 0x24,
    "ALM_MAG1": 0x26,
    "ALM_MAG2": 0x28,
    "ALM_SMPL1": 0x2A,
    "ALM_SMPL2": 0x2C,
    "ALM_CTRL": 0x2E,
    "AUX_DAC": 0x30,
    "GPIO_CTRL": 0x32,
    "MSC_CTRL": 0x34,
    "SMPL_PRD": 0x36,
    "SENS_AVG": 0x38,
    "SLP_CNT": 0x3A,
    "DIAG_STAT": 0x3C,
    "GLOB_CMD": 0x3E,
    "LOT_ID1": 0x52,
    "LOT_ID2": 0x54,
    "PROD_ID": 0x56,
    "SERIAL_NUM": 0x58,
}
"""Register addresses (lower byte of each 16-bit register).  ALM_MAG1..AUX_DAC sit at 0x26-0x30
on the ADIS1636x (Analog Devices' ADIS16364 example code and ADIS1636x headers); the 0x40-0x4A
that the Linux ``adis16400.c`` defines are the ADIS16400's addresses."""

BURST_COMMAND = 0x3E00
"""DIN word that starts a burst read (GLOB_CMD address); 11 output words follow."""

BURST_WORDS: tuple[str, ...] = (
    "SUPPLY_OUT",
    "XGYRO_OUT",
    "YGYRO_OUT",
    "ZGYRO_OUT",
    "XACCL_OUT",
    "YACCL_OUT",
    "ZACCL_OUT",
    "XTEMP_OUT",
    "YTEMP_OUT",
    "ZTEMP_OUT",
    "AUX_ADC",
)
"""Order of the words a burst read clocks out (datasheet burst-mode table)."""

BURST_BITS: tuple[int, ...] = (12, 14, 14, 14, 14, 14, 14, 12, 12, 12, 12)
BURST_SIGNED: tuple[bool, ...] = (
    False,
    True,
    True,
    True,
    True,
    True,
    True,
    True,
    True,
    True,
    False,
)

ND_BIT = 1 << 15
"""New data: set when the output registers hold a sample not read yet."""
EA_BIT = 1 << 14
"""Error/alarm: set when any DIAG_STAT flag is set."""

DIAG_OVER_RANGE = 1 << 4
"""DIAG_STAT bit 4: sensor over-range."""
DIAG_SUPPLY_HIGH = 1 << 1
DIAG_SUPPLY_LOW = 1 << 0

DIAG_MESSAGES: dict[int, str] = {
    15: "Z-axis accelerometer self-test failure",
    14: "Y-axis accelerometer self-test failure",
    13: "X-axis accelerometer self-test failure",
    12: "X-axis gyroscope self-test failure",
    11: "Y-axis gyroscope self-test failure",
    10: "Z-axis gyroscope self-test failure",
    9: "alarm 2 active",
    8: "alarm 1 active",
    6: "flash checksum error",
    5: "self-test error",
    4: "sensor over-range",
    3: "SPI communication failure",
    2: "flash update failed",
    1: "supply above 5.25 V",
    0: "supply below 4.75 V",
}
"""DIAG_STAT bit -> meaning (Linux ``adis16400_status_error_msgs``; bit 7 is undefined).  Every
one of these flags fails the start-up check, as the kernel's ``status_error_mask`` does."""


def diag_flags(diag_stat: int) -> list[str]:
    """The meanings of the DIAG_STAT flags set in ``diag_stat``, highest bit first."""
    return [text for bit, text in DIAG_MESSAGES.items() if diag_stat >> bit & 1]


MSC_DATA_RDY_DIO2 = 1 << 0
"""MSC_CTRL bit 0: data-ready on DIO2 (clear: DIO1)."""
MSC_DATA_RDY_POL_HIGH = 1 << 1
"""MSC_CTRL bit 1: data-ready active high (its rising edge marks a new sample)."""
MSC_DATA_RDY_EN = 1 << 2
"""MSC_CTRL bit 2: data-ready output enabled."""
MSC_SELF_TESTS = 0x0F00
"""MSC_CTRL bits 8-11: positive/negative manual self-test, internal self-test, memory test."""
MSC_INT_SELF_TEST = 1 << 10
"""MSC_CTRL bit 10: run the internal self-test; the part clears it when the test is done."""
GLOB_CMD_SW_RESET = 1 << 7
"""GLOB_CMD bit 7: software reset."""

RESET_S = 0.130
"""Wait after a software reset before the part answers (Linux ``adis16362_timeouts.sw_reset_ms``,
the timeouts the kernel uses for the ADIS16364)."""
SELF_TEST_S = 0.012
"""Wait after starting the self-test before polling for its end (Linux ``self_test_ms``)."""

SENS_AVG_MIN_TAPS_LOG2: dict[int, int] = {4: 0, 2: 2, 1: 4}
"""Gyro range code SENS_AVG[10:8] -> least M = SENS_AVG[2:0] it allows: ±150 °/s needs M >= 2
(N >= 4 taps), ±75 °/s needs M >= 4 (N >= 16); the NTUA ADIS16364 driver enforces the same
(DRngFIRCtrl raises the taps to this minimum)."""


def check_sens_avg(sens_avg: int) -> None:
    """Raise :class:`ConfigError` unless ``sens_avg`` is a gyro range and Bartlett filter length
    the part accepts together (see :data:`SENS_AVG_MIN_TAPS_LOG2`)."""
    code, m = (sens_avg >> 8) & 0x7, sens_avg & 0x7
    if code not in SENS_AVG_MIN_TAPS_LOG2:
        raise ConfigError(f"SENS_AVG 0x{sens_avg:04X} selects no valid gyro range")
    if m < SENS_AVG_MIN_TAPS_LOG2[code]:
        raise ConfigError(
            f"SENS_AVG 0x{sens_avg:04X}: the ±{GYRO_RANGES_DPS[code][0]:g} °/s range needs "
            f"SENS_AVG[2:0] >= {SENS_AVG_MIN_TAPS_LOG2[code]} "
            f"(>= {1 << SENS_AVG_MIN_TAPS_LOG2[code]} filter taps), got {m}"
        )


@dataclass(frozen=True)
class SpiTiming:
    """SCLK and stall the part allows in one operating mode.

    ``sclk_hz`` clocks register reads and writes, ``burst_hz`` burst reads; ``stall_us`` is the
    idle time after every 16-bit frame (and after a burst) before the next frame starts.
    """

    sclk_hz: int
    burst_hz: int
    stall_us: int


LINUX_FRAME_DELAY_US = 50
"""The Linux adis driver waits 50 µs after every 16-bit frame (``read_delay``/``write_delay``)."""
DATASHEET_STALL_US = {"fast": 9, "low_power": 75}
"""tDATASTALL, least time between 16-bit frames (ADIS1636x/ADIS16400 timing table)."""
DATASHEET_PERIOD_US = {"fast": 40, "low_power": 100}
"""tDATARATE, least chip-select period from one frame's start to the next (same table)."""


def _timing(mode: str, sclk_hz: int, burst_hz: int) -> SpiTiming:
    """Stall = the longest of the kernel's proven delay, tDATASTALL and what tDATARATE leaves
    after a 16-bit frame at ``sclk_hz``."""
    frame_us = 16e6 / sclk_hz
    need = max(LINUX_FRAME_DELAY_US, DATASHEET_STALL_US[mode], DATASHEET_PERIOD_US[mode] - frame_us)
    return SpiTiming(sclk_hz, burst_hz, math.ceil(need))


FAST_TIMING = _timing("fast", 2_000_000, 1_000_000)
"""SMPL_PRD[7:0] <= 0x09: SCLK <= 2 MHz, bursts <= 1 MHz (datasheets; Linux SPI_FAST/BURST)."""
LOW_POWER_TIMING = _timing("low_power", 300_000, 300_000)
"""Low-power mode (Ns >= 0x0A or the slow time base): SCLK <= 300 kHz for everything, bursts
included (datasheets; Linux SPI_SLOW).  Also the safe timing while SMPL_PRD is unknown."""


def low_power_mode(smpl_prd: int) -> bool:
    """Whether SMPL_PRD puts the part in low-power mode: Ns >= 0x0A or the 52.851 SPS base."""
    return bool(smpl_prd & 0x80) or (smpl_prd & 0x7F) >= 0x0A


def spi_timing(smpl_prd: int) -> SpiTiming:
    """The SPI timing the part accepts with SMPL_PRD = ``smpl_prd``."""
    return LOW_POWER_TIMING if low_power_mode(smpl_prd) else FAST_TIMING


INTERNAL_BASE_SPS = 1638.404
"""SMPL_PRD time base (bit 7 = 0), samples per second (Linux adis16400_get_freq)."""

SUPPLY_V_PER_LSB = 2.418e-3
TEMP_C_PER_LSB = 0.136
TEMP_ZERO_C = 25.0
AUX_ADC_V_PER_LSB = 805.8e-6
ACCEL_MG_PER_LSB = 1.0
GYRO_RANGES_DPS: dict[int, tuple[float, float]] = {
    4: (300.0, 0.05),
    2: (150.0, 0.025),
    1: (75.0, 0.0125),
}
"""SENS_AVG[10:8] code -> (range °/s, scale °/s/LSB)."""


def sample_rate_sps(smpl_prd: int) -> float:
    """Internal sample rate set by SMPL_PRD: base/(Ns+1), base 1638.404 or 52.851 SPS."""
    base = 52.851 if smpl_prd & 0x80 else INTERNAL_BASE_SPS
    return base / ((smpl_prd & 0x7F) + 1)


def gyro_scale_dps(sens_avg: int) -> float:
    """Gyro scale factor (°/s per LSB) selected by SENS_AVG[10:8]."""
    code = (sens_avg >> 8) & 0x7
    if code not in GYRO_RANGES_DPS:
        raise ConfigError(f"SENS_AVG 0x{sens_avg:04X} selects no valid gyro range")
    return GYRO_RANGES_DPS[code][1]


def bartlett_taps(sens_avg: int) -> int:
    """Number of taps N = 2^M of the Bartlett FIR filter, M = SENS_AVG[2:0]."""
    return 1 << (sens_avg & 0x7)


def encode_words(values: np.ndarray, bits: int, signed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Quantised integer counts -> output words (flag bits clear) and a saturation mask.

    ``values`` are integer counts (any integer or float dtype, rounded already).  Signed words
    are two's complement in ``bits`` bits, unsigned words offset binary; values outside the
    representable range saturate at the rail and are reported in the mask.
    """
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    counts = np.asarray(values, dtype=np.int64)
    saturated = (counts < lo) | (counts > hi)
    clipped = np.clip(counts, lo, hi)
    words = (clipped & ((1 << bits) - 1)).astype(np.uint16)
    return words, saturated


def decode_words(words: np.ndarray, bits: int, signed: bool) -> np.ndarray:
    """Output words -> integer counts (int32): mask the flag bits, sign-extend signed words."""
    raw = (np.asarray(words, dtype=np.uint16) & ((1 << bits) - 1)).astype(np.int32)
    if signed:
        sign = 1 << (bits - 1)
        raw = (raw ^ sign) - sign
    return raw


_BURST_MASKS = np.array([(1 << b) - 1 for b in BURST_BITS], dtype=np.int32)
_BURST_SIGNS = np.array(
    [1 << (b - 1) if s else 0 for b, s in zip(BURST_BITS, BURST_SIGNED, strict=True)],
    dtype=np.int32,
)


@numba.njit(cache=True, nogil=True)
def _decode_burst(
    burst: np.ndarray, masks: np.ndarray, signs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover (JIT)
    n, words = burst.shape
    counts = np.empty((words, n), dtype=np.int16)
    new_data = np.empty(n, dtype=np.bool_)
    alarm = np.empty(n, dtype=np.bool_)
    for i in range(n):  # serial: called per MCAP chunk, where a parallel launch costs more
        nd = True
        ea = False
        for w in range(words):
            word = np.int32(burst[i, w])
            counts[w, i] = np.int16(((word & masks[w]) ^ signs[w]) - signs[w])
            nd = nd and (word & ND_BIT) != 0
            ea = ea or (word & EA_BIT) != 0
        new_data[i] = nd
        alarm[i] = ea
    return counts, new_data, alarm


def decode_burst(burst: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decode ``(n, 11)`` burst words in one pass: :func:`decode_words` for every word.

    Returns counts axis-major ``(11, n)`` int16 (word order :data:`BURST_WORDS`), whether every
    word of a frame had ND set (bool ``(n,)``), and whether any word had EA set (bool ``(n,)``).
    Sign extension is ``((v & mask) ^ s) - s`` with ``s`` the sign bit (0 for unsigned words).
    """
    burst = np.ascontiguousarray(burst, dtype=np.uint16)
    return _decode_burst(burst, _BURST_MASKS, _BURST_SIGNS)


def burst_counts(burst: np.ndarray) -> np.ndarray:
    """Decode an ``(n, 11)`` array of burst words into an ``(n, 11)`` int16 array of counts."""
    return decode_burst(burst)[0].T


@dataclass(frozen=True)
class DeviceConfig:
    """What the analyser needs to turn raw words into physical units; stored as MCAP metadata.

    ``output_rate_hz`` is the rate frames are recorded at; ``rate_method`` says whether the
    sensor's SMPL_PRD divider produced it (``"smpl_prd"``) or a host timer polled the filtered
    internal stream with sample-and-hold (``"host_poll"``, the paper's set-up, aliasing noise
    above the Nyquist frequency of the output rate).  ``pacing`` says how a real sensor's reads
    were timed: ``"data_ready"`` (each read on the part's DIO1 data-ready edge) or
    ``"host_timer"``; it is empty for the simulator and then left out of the metadata.
    """

    product_id: int = PROD_ID_VALUE
    serial_number: int = 0
    smpl_prd: int = 0x0001
    sens_avg: int = 0x0402
    output_rate_hz: float = 100.0
    rate_method: str = "host_poll"
    source: str = "sim"
    frame_id: str = "adis16364"
    pacing: str = ""

    @property
    def internal_rate_sps(self) -> float:
        return sample_rate_sps(self.smpl_prd)

    @property
    def gyro_scale_dps(self) -> float:
        return gyro_scale_dps(self.sens_avg)

    def to_metadata(self) -> dict[str, str]:
        """Flat string map for an MCAP Metadata record named ``adis16364``."""
        meta = {k: str(v) for k, v in asdict(self).items() if k != "pacing" or v}
        meta.update(
            {
                "internal_rate_sps": repr(self.internal_rate_sps),
                "gyro_scale_dps_per_lsb": repr(self.gyro_scale_dps),
                "gyro_range_dps": repr(GYRO_RANGES_DPS[(self.sens_avg >> 8) & 0x7][0]),
                "accel_scale_mg_per_lsb": repr(ACCEL_MG_PER_LSB),
                "temp_scale_c_per_lsb": repr(TEMP_C_PER_LSB),
                "temp_zero_c": repr(TEMP_ZERO_C),
                "supply_scale_v_per_lsb": repr(SUPPLY_V_PER_LSB),
                "aux_adc_scale_v_per_lsb": repr(AUX_ADC_V_PER_LSB),
                "bartlett_taps": str(bartlett_taps(self.sens_avg)),
            }
        )
        return meta

    @classmethod
    def from_metadata(cls, meta: dict[str, str]) -> DeviceConfig:
        """Inverse of :meth:`to_metadata` (extra keys ignored).

        Raises:
            KeyError: a key is missing.
            ValueError: a value does not parse, or the output rate is not positive and finite.
        """
        rate_hz = float(meta["output_rate_hz"])
        if not math.isfinite(rate_hz) or rate_hz <= 0:
            raise ValueError(f"output_rate_hz {meta['output_rate_hz']} is not a positive rate")
        return cls(
            product_id=int(meta["product_id"]),
            serial_number=int(meta["serial_number"]),
            smpl_prd=int(meta["smpl_prd"]),
            sens_avg=int(meta["sens_avg"]),
            output_rate_hz=rate_hz,
            rate_method=meta["rate_method"],
            source=meta["source"],
            frame_id=meta.get("frame_id", "adis16364"),
            pacing=meta.get("pacing", ""),
        )


@dataclass
class FrameBlock:
    """A run of consecutive sensor frames, as a source delivers them to the recorder.

    Attributes:
        stamp_ns: host time of each burst read, ns since the Unix epoch (int64, shape ``(n,)``).
        counter: frame counter, incremented per frame by the host (uint32, ``(n,)``); a jump
            means frames were missed.
        burst: raw burst words exactly as the sensor returns them, flags included
            (uint16, ``(n, 11)``, order :data:`BURST_WORDS`).
        diag_stat: DIAG_STAT word when it was read, else 0 (uint16, ``(n,)``).
        diag_valid: whether DIAG_STAT was read for that frame (bool, ``(n,)``).
    """

    stamp_ns: np.ndarray
    counter: np.ndarray
    burst: np.ndarray
    diag_stat: np.ndarray
    diag_valid: np.ndarray

    def __len__(self) -> int:
        return len(self.stamp_ns)

    def __getitem__(self, rows: slice | np.ndarray) -> FrameBlock:
        """The frames selected by a slice, an index array or a boolean mask."""
        return FrameBlock(*(getattr(self, f.name)[rows] for f in fields(self)))


def config_for_rate(
    output_rate_hz: float, source: str = "sim", serial_number: int = 0
) -> DeviceConfig:
    """Device configuration producing ``output_rate_hz``.

    A rate the SMPL_PRD divider makes (1638.404/(Ns+1) SPS, to 100 ppm) is produced by the
    sensor itself; any other rate (100 Hz, the paper's) by a host timer polling the default
    819.2 SPS stream with sample-and-hold.
    """
    if not math.isfinite(output_rate_hz) or output_rate_hz <= 0:
        raise ConfigError(f"output rate must be positive and finite, got {output_rate_hz}")
    for ns in range(128):
        if abs(sample_rate_sps(ns) / output_rate_hz - 1) < 1e-4:
            return DeviceConfig(
                serial_number=serial_number,
                smpl_prd=ns,
                output_rate_hz=sample_rate_sps(ns),
                rate_method="smpl_prd",
                source=source,
            )
    if output_rate_hz > sample_rate_sps(0x0001):
        raise ConfigError(
            f"{output_rate_hz} Hz is faster than the sensor's {sample_rate_sps(1):.1f} SPS output"
        )
    return DeviceConfig(
        serial_number=serial_number,
        output_rate_hz=output_rate_hz,
        rate_method="host_poll",
        source=source,
    )
