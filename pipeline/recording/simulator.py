"""A register-level virtual ADIS16364.

Signal chain (per inertial axis), following the ADIS1636x datasheets' block diagram:

1. Internal samples at ``sample_rate_sps(SMPL_PRD)`` (819.2 SPS by default): white sensor noise of
   std ``sigma_internal`` plus the scenario's deterministic effects evaluated at each internal
   sample time (temperature, supply ripple, sinusoids, bias steps, drift, spikes).
2. The SENS_AVG Bartlett FIR: the datasheets describe it as two cascaded N-tap averaging stages,
   N = 2^SENS_AVG[2:0] (so the impulse response is a (2N-1)-tap triangle, |H| = |H_avg|²).
   :data:`adis16364_facts.json` only gives "N = 2^M taps"; we take N per stage.
3. The output: either every internal sample (``rate_method="smpl_prd"``: the SMPL_PRD divider
   makes the output rate) or a host timer reading the latest filtered sample every
   1/output_rate_hz s with sample and hold (``"host_poll"``, the paper's 100 Hz set-up: nothing
   averages between polls, so filtered noise above the output Nyquist frequency aliases in).
   Optional host-timer latency (``jitter_s``): each poll is late by |N(0, jitter_s)|, capped at
   half a period.
4. Bias, flicker (bias instability), rate random walk and Gauss–Markov terms are generated at
   the poll instants and added after the filter: their spectra lie far below the filter's
   corner (≈ 95 Hz at N = 4), where its gain is 1 to < 0.1 %.  Valid for Gauss–Markov
   correlation times ≫ the filter length (2N-1)/819.2 s.
5. 14-bit two's complement quantisation at the gyro range's scale (0.05 °/s/LSB at ±300 °/s)
   and 1 mg/LSB with saturation at the word limits, 12-bit temperature (0.136 °C/LSB, 0 = 25 °C)
   and supply (2.418 mV/LSB, offset binary); ND (bit 15: sample not read before) and EA
   (bit 14: any DIAG_STAT flag latched) in every burst word; DIAG_STAT bit 4 when an inertial
   word saturates, bits 1/0 for supply > 5.25 V / < 4.75 V.

Output-referred white noise.  The scenario's random walk N is what the recording shows (Allan
deviation at τ = 1 s of the output frames).  With polls that see disjoint filter windows the
output white noise has variance sigma_internal²·Σh² per frame, so N² = sigma_internal²·Σh²/f_out
+ q²/(12·f_out) (q = LSB, quantisation noise).  In general :func:`white_gain` computes the
variance of a long average of the actual poll pattern, and sigma_internal is solved from it; both
are in :meth:`VirtualADIS16364.truth`.  The sensor's sigma_internal stays fixed if SMPL_PRD or
SENS_AVG are rewritten over SPI, so the output noise then changes as it would on the part.

When every poll sees its own filter window (no jitter, ⌊f_int/f_out⌋ ≥ 2N-1: the default), the
filtered white noise at the polls is drawn directly as independent N(0, sigma_internal²·Σh²)
samples — the same distribution as filtering the full internal stream, at an eighth of the
cost; otherwise the full internal white stream is generated and filtered.
"""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from imupipe.device.adis16364 import (
    ACCEL_MG_PER_LSB,
    BURST_WORDS,
    DIAG_OVER_RANGE,
    DIAG_SUPPLY_HIGH,
    DIAG_SUPPLY_LOW,
    EA_BIT,
    ND_BIT,
    PROD_ID_VALUE,
    REGISTERS,
    SUPPLY_V_PER_LSB,
    TEMP_C_PER_LSB,
    TEMP_ZERO_C,
    DeviceConfig,
    FrameBlock,
    bartlett_taps,
    encode_words,
    sample_rate_sps,
)
from imupipe.errors import ConfigError
from imupipe.recording.noise import (
    FlickerNoise,
    GaussMarkov,
    NormalStream,
    RateRandomWalk,
    keyed_rng,
)
from imupipe.recording.scenario import Scenario
from imupipe.vocab import AXES

SUPPLY_HIGH_V = 5.25
SUPPLY_LOW_V = 4.75
SPIKE_SEGMENT_S = 3600.0
"""Spike times are drawn per segment of this length (Poisson count, uniform times)."""

_OUTPUT_REGS = {REGISTERS[name]: i for i, name in enumerate(BURST_WORDS)}
_WRITABLE = {
    "GPIO_CTRL", "MSC_CTRL", "SMPL_PRD", "SENS_AVG", "SLP_CNT", "ALM_MAG1", "ALM_MAG2",
    "ALM_SMPL1", "ALM_SMPL2", "ALM_CTRL", "AUX_DAC", "XGYRO_OFF", "YGYRO_OFF", "ZGYRO_OFF",
    "XACCL_OFF", "YACCL_OFF", "ZACCL_OFF",
}  # fmt: skip
_WRITABLE_ADDR = {REGISTERS[n] for n in _WRITABLE}


def bartlett_response(sens_avg: int) -> np.ndarray:
    """Impulse response of the SENS_AVG Bartlett filter: two cascaded N-tap averages."""
    n = bartlett_taps(sens_avg)
    box = np.full(n, 1.0 / n)
    return np.convolve(box, box)


def poll_indices(config: DeviceConfig, n: int, phase: float = 0.0) -> np.ndarray:
    """Internal sample index read by each of ``n`` un-jittered output frames."""
    f_int = config.internal_rate_sps
    if config.rate_method == "smpl_prd":
        return np.arange(1, n + 1)
    t = np.arange(1, n + 1) / config.output_rate_hz
    return np.floor(t * f_int - phase).astype(np.int64)


def white_gain(config: DeviceConfig, average_s: float = 100.0) -> float:
    """N² per sigma_internal²: the Allan variance at τ = 1 s (s·unit² per unit²) that unit-std
    internal white noise produces at the output, from τ·Var(mean of the frames over τ)
    with τ = ``average_s`` and the filter weights the real poll pattern puts on each sample."""
    h = bartlett_response(config.sens_avg)
    f_out = config.output_rate_hz
    n = round(average_s * f_out)
    idx = poll_indices(config, n)
    taps = idx[:, None] - np.arange(len(h))
    weights = np.bincount((taps - taps.min()).ravel(), weights=np.tile(h, n))
    return average_s * float(np.sum(weights**2)) / n**2


class VirtualADIS16364:
    """A virtual ADIS16364: registers, burst reads and fast bulk frame generation."""

    def __init__(
        self,
        config: DeviceConfig,
        scenario: Scenario | None = None,
        seed: int = 0,
        start_time_ns: int = 1_700_000_000_000_000_000,
    ) -> None:
        self.scenario = scenario if scenario is not None else Scenario()
        self.seed = seed
        self.start_time_ns = start_time_ns
        self._phase = float(keyed_rng(seed, 300).random())
        self._k = 0  # frames produced
        self._epoch = -1
        self._last_j = -1
        self._diag_latch = 0
        self._last_burst = np.zeros(len(BURST_WORDS), dtype=np.uint16)
        self._unread = np.zeros(len(BURST_WORDS), dtype=bool)
        self._regs = {REGISTERS[n]: 0 for n in _WRITABLE}
        self._regs[REGISTERS["MSC_CTRL"]] = 0x0006
        self._sigma_internal = self._solve_internal_sigma(config)
        self._configure(config, t0_s=0.0)

    # ---- signal chain ---------------------------------------------------------------------
    def _solve_internal_sigma(self, config: DeviceConfig) -> dict[str, float]:
        gain = white_gain(config)
        out = {}
        for axis, terms in self.scenario.noise.items():
            lsb = config.gyro_scale_dps if axis.startswith("gyro") else ACCEL_MG_PER_LSB
            n2 = terms.random_walk**2 - lsb**2 / (12.0 * config.output_rate_hz)
            out[axis] = math.sqrt(max(n2, 0.0) / gain)
        return out

    def _configure(self, config: DeviceConfig, t0_s: float) -> None:
        """(Re)build the chain for ``config``, starting at time ``t0_s`` with frame ``self._k``."""
        if config.rate_method == "smpl_prd":
            f_int = config.internal_rate_sps
            if abs(config.output_rate_hz - f_int) > 1e-4 * f_int:
                raise ConfigError(
                    f"rate_method 'smpl_prd' needs output_rate_hz = {f_int} for "
                    f"SMPL_PRD 0x{config.smpl_prd:04X}, got {config.output_rate_hz}"
                )
        self.config = config
        self._epoch += 1
        self._t0, self._k0 = t0_s, self._k
        self._regs[REGISTERS["SMPL_PRD"]] = config.smpl_prd
        self._regs[REGISTERS["SENS_AVG"]] = config.sens_avg
        self._h = bartlett_response(config.sens_avg)
        f_int, f_out = config.internal_rate_sps, config.output_rate_hz
        self._disjoint = (
            config.rate_method == "host_poll"
            and self.scenario.jitter_s == 0.0
            and math.floor(f_int / f_out) >= len(self._h)
        )
        dt = 1.0 / f_out
        self._white: dict[str, NormalStream] = {}
        self._colored: dict[str, list[Any]] = {}
        for i, axis in enumerate(AXES):
            terms = self.scenario.noise[axis]
            key = (self._epoch, i)
            self._white[axis] = NormalStream(self.seed, *key, 0)
            gens: list[Any] = []
            if terms.bias_instability > 0:
                gens.append(
                    FlickerNoise(terms.bias_instability, dt, NormalStream(self.seed, *key, 1))
                )
            if terms.rrw > 0:
                gens.append(RateRandomWalk(terms.rrw, dt, NormalStream(self.seed, *key, 2)))
            if terms.gm_sigma > 0:
                gens.append(
                    GaussMarkov(
                        terms.gm_sigma, terms.gm_tau_s, dt, NormalStream(self.seed, *key, 3)
                    )
                )
            self._colored[axis] = gens
        self._jitter = NormalStream(self.seed, self._epoch, 100)
        first_j = int(self._poll_times(np.array([self._k]))[1][0])
        # per axis: (internal index of the first buffered white sample, the samples)
        self._wbuf = {a: (first_j - len(self._h) + 1, np.empty(0)) for a in AXES}

    def _poll_times(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poll time (s since start) and internal sample index of frames ``k`` (no jitter)."""
        f_int = self.config.internal_rate_sps
        if self.config.rate_method == "smpl_prd":
            j = math.floor(self._t0 * f_int) + (k - self._k0 + 1)
            return j / f_int, j
        t = self._t0 + (k - self._k0 + 1) / self.config.output_rate_hz
        return t, np.floor(t * f_int - self._phase).astype(np.int64)

    def _internal_time(self, j: np.ndarray) -> np.ndarray:
        phase = 0.0 if self.config.rate_method == "smpl_prd" else self._phase
        return (j + phase) / self.config.internal_rate_sps

    def _filtered_white(self, axis: str, j: np.ndarray) -> np.ndarray:
        sigma = self._sigma_internal[axis]
        if self._disjoint:
            return sigma * math.sqrt(float(np.sum(self._h**2))) * self._white[axis].take(len(j))
        start, buf = self._wbuf[axis]
        need = max(int(j[-1]) + 1 - (start + len(buf)), 0)
        buf = np.concatenate([buf, self._white[axis].take(need)])
        filtered = np.convolve(buf, self._h, "valid")  # [e] is internal index start + L-1 + e
        out = sigma * filtered[j - start - (len(self._h) - 1)]
        keep_from = int(j[-1]) - len(self._h) + 1
        self._wbuf[axis] = (keep_from, buf[keep_from - start :])
        return out

    def _spikes(self, axis: str, t: np.ndarray) -> np.ndarray:
        out = np.zeros_like(t)
        for number, spec in enumerate(self.scenario.spikes):
            if spec.axis != axis:
                continue
            first = max(int((t.min() - spec.duration_s) // SPIKE_SEGMENT_S), 0)
            starts = []
            for seg in range(first, int(t.max() // SPIKE_SEGMENT_S) + 1):
                rng = keyed_rng(self.seed, 200, number, seg)
                count = rng.poisson(spec.rate_per_hour * SPIKE_SEGMENT_S / 3600.0)
                starts.append(seg * SPIKE_SEGMENT_S + SPIKE_SEGMENT_S * rng.random(count))
            onsets = np.sort(np.concatenate(starts))
            active = np.searchsorted(onsets, t, "right") - np.searchsorted(
                onsets + spec.duration_s, t, "right"
            )
            out += spec.amplitude * active
        return out

    def _generate(self, n: int, read_diag: bool) -> FrameBlock:
        k = self._k + np.arange(n)
        t, j = self._poll_times(k)
        if self.scenario.jitter_s > 0 and self.config.rate_method == "host_poll":
            period = 1.0 / self.config.output_rate_hz
            t = t + np.minimum(np.abs(self.scenario.jitter_s * self._jitter.take(n)), period / 2)
            j = np.floor(t * self.config.internal_rate_sps - self._phase).astype(np.int64)
        burst = np.zeros((n, len(BURST_WORDS)), dtype=np.uint16)
        saturated = np.zeros(n, dtype=bool)
        grid_t = None
        for i, axis in enumerate(AXES):
            terms = self.scenario.noise[axis]
            value = terms.bias + self._filtered_white(axis, j)
            for gen in self._colored[axis]:
                value += gen.take(n)
            if self.scenario.has_effects(axis) or any(s.axis == axis for s in self.scenario.spikes):
                if grid_t is None:
                    grid_t = self._internal_time(j[:, None] - np.arange(len(self._h)))
                effects = self.scenario.deterministic(axis, grid_t) + self._spikes(axis, grid_t)
                value += effects @ self._h
            lsb = self.config.gyro_scale_dps if i < 3 else ACCEL_MG_PER_LSB
            words, sat = encode_words(np.rint(value / lsb), 14, signed=True)
            burst[:, 1 + i] = words
            saturated |= sat
        t_int = self._internal_time(j)
        temp = self.scenario.temperature.at(t_int)
        temp_words, _ = encode_words(np.rint((temp - TEMP_ZERO_C) / TEMP_C_PER_LSB), 12, True)
        burst[:, 7:10] = temp_words[:, None]
        volts = self.scenario.supply.at(t_int)
        burst[:, 0], _ = encode_words(np.rint(volts / SUPPLY_V_PER_LSB), 12, False)

        condition = np.where(saturated, DIAG_OVER_RANGE, 0)
        condition |= np.where(volts > SUPPLY_HIGH_V, DIAG_SUPPLY_HIGH, 0)
        condition |= np.where(volts < SUPPLY_LOW_V, DIAG_SUPPLY_LOW, 0)
        condition[0] |= self._diag_latch
        latched = condition if read_diag else np.bitwise_or.accumulate(condition)
        self._diag_latch = 0 if read_diag else int(latched[-1])
        new_data = j != np.concatenate([[self._last_j], j[:-1]])
        flags = np.where(new_data, ND_BIT, 0) | np.where(latched != 0, EA_BIT, 0)
        burst |= flags.astype(np.uint16)[:, None]

        self._k += n
        self._last_j = int(j[-1])
        self._last_burst = burst[-1].copy()
        self._unread[:] = True
        return FrameBlock(
            stamp_ns=self.start_time_ns + np.rint(t * 1e9).astype(np.int64),
            counter=k.astype(np.uint32),
            burst=burst,
            diag_stat=(latched if read_diag else np.zeros(n)).astype(np.uint16),
            diag_valid=np.full(n, read_diag),
        )

    # ---- bulk API ---------------------------------------------------------------------------
    def frames(self, n: int) -> FrameBlock:
        """The next ``n`` output frames (DIAG_STAT read with every frame, which clears it)."""
        if n <= 0:
            raise ValueError("frames(n) needs n >= 1")
        return self._generate(n, read_diag=True)

    def truth(self) -> dict[str, Any]:
        """Ground truth: scenario parameters/effects, device set-up and derived noise levels."""
        truth = self.scenario.truth_dict()
        f_int = self.config.internal_rate_sps
        for axis, sigma in self._sigma_internal.items():
            unit = "°/s" if axis.startswith("gyro") else "mg"
            truth["noise"][axis]["internal_white"] = {
                "sigma_per_sample": sigma,
                "density_per_sqrt_hz": sigma / math.sqrt(f_int / 2.0),
                "sample_rate_sps": f_int,
                "unit": unit,
                "note": "std of the white noise on each internal sample before the Bartlett "
                "filter, solved so the output random walk equals random_walk; density is "
                "one-sided, per √Hz, over 0..f_int/2",
            }
        truth["device"] = {
            **asdict(self.config),
            "internal_rate_sps": f_int,
            "bartlett_taps_per_stage": bartlett_taps(self.config.sens_avg),
            "filter_impulse_response": self._h.tolist(),
            "white_noise_shortcut": self._disjoint,
        }
        truth["seed"] = self.seed
        truth["start_time_ns"] = self.start_time_ns
        truth["simulator"] = "imupipe.recording.simulator.VirtualADIS16364"
        return truth

    # ---- register level -------------------------------------------------------------------
    def burst_read(self) -> list[int]:
        """The 11 burst words of the next frame (DIAG_STAT not read: EA keeps latched flags)."""
        words = self._generate(1, read_diag=False).burst[0]
        self._unread[:] = False
        return [int(w) for w in words]

    def read_register(self, addr: int) -> int:
        """16-bit value of the register at (even) ``addr``; reading DIAG_STAT clears it."""
        addr &= 0x7E
        if addr in _OUTPUT_REGS:
            if self._k == 0:
                self._generate(1, read_diag=False)
            i = _OUTPUT_REGS[addr]
            word = int(self._last_burst[i]) & ~ND_BIT
            if self._unread[i]:
                word |= ND_BIT
            self._unread[i] = False
            return word
        if addr == REGISTERS["DIAG_STAT"]:
            value, self._diag_latch = self._diag_latch, 0
            return value
        if addr == REGISTERS["PROD_ID"]:
            return PROD_ID_VALUE
        if addr == REGISTERS["SERIAL_NUM"]:
            return self.config.serial_number & 0xFFFF
        return self._regs.get(addr, 0)

    def write_byte(self, addr: int, byte: int) -> None:
        """One SPI write command: ``byte`` into the register byte at ``addr`` (odd = high)."""
        reg = addr & 0x7E
        if reg not in _WRITABLE_ADDR:
            return
        shift = 8 * (addr & 1)
        value = (self._regs[reg] & ~(0xFF << shift)) | ((byte & 0xFF) << shift)
        self._regs[reg] = value
        if reg in (REGISTERS["SMPL_PRD"], REGISTERS["SENS_AVG"]):
            self._reconfigure()

    def write_register(self, addr: int, value: int) -> None:
        """A 16-bit write, as the part receives it: low byte, then high byte."""
        self.write_byte(addr & 0x7E, value & 0xFF)
        self.write_byte((addr & 0x7E) | 1, (value >> 8) & 0xFF)

    def _reconfigure(self) -> None:
        smpl_prd = self._regs[REGISTERS["SMPL_PRD"]] & 0xFF
        sens_avg = self._regs[REGISTERS["SENS_AVG"]]
        if (smpl_prd, sens_avg) == (self.config.smpl_prd, self.config.sens_avg):
            return
        if ((sens_avg >> 8) & 0x7) not in (1, 2, 4):
            return  # half-written SENS_AVG: wait for the other byte
        changes: dict[str, Any] = {"smpl_prd": smpl_prd, "sens_avg": sens_avg}
        if self.config.rate_method == "smpl_prd":
            changes["output_rate_hz"] = sample_rate_sps(smpl_prd)
        t_now = float(self._poll_times(np.array([self._k - 1]))[0][0]) if self._k else 0.0
        self._configure(replace(self.config, **changes), t0_s=t_now)
