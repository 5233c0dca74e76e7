"""Simulation scenarios: per-axis noise terms and environmental effects, read from TOML.

The format is documented in README.md ("Scenario files").  Values are in the units of the ADIS16364
paper: gyro axes in °/s (random walk °/√s, rate random walk °/s/√s), accelerometer axes in mg
(mg/√s, mg/s/√s), time in s, temperature in °C, supply in V.  :meth:`Scenario.truth_dict` states
everything in those units and in SI (:mod:`imupipe.units`).

Defaults are the paper's measured table (12 h static at 100 Hz, 21 °C; section 4): random walk
0.05 °/√s per gyro and 0.29/0.27/0.28 mg/√s per accelerometer, bias instability 0.008 °/s and
0.107/0.161/0.135 mg, means 0.331/-0.104/-0.099 °/s and 27.3/-21.1/-998.6 mg (the paper prints
"0.0273 mg" etc., evidently g: gravity is on Z).  The random walk is output-referred: it is what
the Allan deviation of the recorded frames shows at τ = 1 s.  The paper measured no rate random
walk; the default K puts the RRW line K·√(τ/3) on the flicker plateau 0.664·B at τ = 6 h
(:data:`RRW_CROSSOVER_S`), so it lifts the last half-decade of a 12 h curve while raising the
curve's minimum by at most ~6 % (gyros; 2–3 % for accelerometers).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from imupipe.errors import ScenarioError
from imupipe.recording.noise import FLICKER_PLATEAU
from imupipe.units import PAPER_UNIT, SI_PER_UNIT, SI_UNIT
from imupipe.vocab import AXES, sensor_of

RRW_CROSSOVER_S = 6 * 3600.0
"""τ at which the default rate random walk meets the flicker plateau (s)."""

_PAPER_MEASURED = {
    # axis: (mean, random walk, bias instability), paper section 4
    "gyro_x": (0.331, 0.05, 0.008),
    "gyro_y": (-0.104, 0.05, 0.008),
    "gyro_z": (-0.099, 0.05, 0.008),
    "accel_x": (27.3, 0.29, 0.107),
    "accel_y": (-21.1, 0.27, 0.161),
    "accel_z": (-998.6, 0.28, 0.135),
}


def unit_of(axis: str) -> str:
    """The paper unit of an axis' values: °/s or mg."""
    return PAPER_UNIT[sensor_of(axis)]["mean"]  # type: ignore[index]


def si_per_unit(axis: str) -> float:
    """SI value (rad/s or m/s²) of one °/s or one mg."""
    return SI_PER_UNIT[unit_of(axis)]


@dataclass(frozen=True)
class AxisNoise:
    """Noise terms and turn-on bias of one axis (paper units, see module docstring).

    ``bias`` is the turn-on bias (the recording's mean); ``random_walk`` the white-noise
    coefficient N as seen at the output; ``bias_instability`` B (flicker, ADEV plateau 0.664·B);
    ``rate_random_walk`` K (None: the default crossover rule); ``gm_sigma``/``gm_tau_s`` an
    optional first-order Gauss–Markov term (std, correlation time in s; 0 = off).
    """

    bias: float
    random_walk: float
    bias_instability: float
    rate_random_walk: float | None = None
    gm_sigma: float = 0.0
    gm_tau_s: float = 0.0

    @property
    def rrw(self) -> float:
        """K, the rate random walk coefficient, with the default crossover rule applied."""
        if self.rate_random_walk is not None:
            return self.rate_random_walk
        return FLICKER_PLATEAU * self.bias_instability * math.sqrt(3.0 / RRW_CROSSOVER_S)


def default_noise() -> dict[str, AxisNoise]:
    """The paper's measured noise table (see module docstring)."""
    return {
        a: AxisNoise(bias=m, random_walk=n, bias_instability=b)
        for a, (m, n, b) in _PAPER_MEASURED.items()
    }


@dataclass(frozen=True)
class Temperature:
    """Die temperature (°C) vs time: ``mean_c``, or piecewise-linear ``points`` [(t_s, °C)], plus
    a sinusoid (``amplitude_c``, ``period_s``).  Axis outputs move by
    ``coefficients[axis]·(T - reference_c)`` (unit/°C); the TEMP registers follow T."""

    mean_c: float = 21.0
    points: tuple[tuple[float, float], ...] = ()
    amplitude_c: float = 0.0
    period_s: float = 0.0
    reference_c: float = 21.0
    coefficients: dict[str, float] = field(default_factory=dict)

    def at(self, t_s: np.ndarray) -> np.ndarray:
        """Temperature in °C at times ``t_s`` (s since start)."""
        t_s = np.asarray(t_s, dtype=float)
        if self.points:
            times, temps = zip(*self.points, strict=True)
            base = np.interp(t_s, times, temps)
        else:
            base = np.full_like(t_s, self.mean_c)
        if self.amplitude_c:
            base = base + self.amplitude_c * np.sin(2.0 * np.pi * t_s / self.period_s)
        return base


@dataclass(frozen=True)
class Supply:
    """Supply voltage (V): ``nominal_v`` plus a ripple ``ripple_amplitude_v``·sin(2π f t);
    axis outputs move by ``sensitivity[axis]·(V - nominal_v)`` (unit/V); SUPPLY_OUT follows V."""

    nominal_v: float = 5.0
    ripple_amplitude_v: float = 0.0
    ripple_frequency_hz: float = 0.0
    sensitivity: dict[str, float] = field(default_factory=dict)

    def at(self, t_s: np.ndarray) -> np.ndarray:
        """Supply voltage in V at times ``t_s``."""
        t_s = np.asarray(t_s, dtype=float)
        ripple = self.ripple_amplitude_v * np.sin(2.0 * np.pi * self.ripple_frequency_hz * t_s)
        return self.nominal_v + ripple


@dataclass(frozen=True)
class Sinusoid:
    """Sinusoidal disturbance amplitude·sin(2π f t + phase) on one axis (unit, Hz, rad)."""

    axis: str
    amplitude: float
    frequency_hz: float
    phase_rad: float = 0.0

    def at(self, t_s: np.ndarray) -> np.ndarray:
        return self.amplitude * np.sin(2.0 * np.pi * self.frequency_hz * t_s + self.phase_rad)


@dataclass(frozen=True)
class BiasStep:
    """The bias of ``axis`` jumps by ``size`` (unit) at ``time_s``."""

    axis: str
    time_s: float
    size: float

    def at(self, t_s: np.ndarray) -> np.ndarray:
        return np.where(t_s >= self.time_s, self.size, 0.0)


@dataclass(frozen=True)
class Drift:
    """Warm-up warmup_amplitude·exp(-t/warmup_tau_s) plus a linear drift slope_per_hour·t."""

    axis: str
    warmup_amplitude: float = 0.0
    warmup_tau_s: float = 1.0
    slope_per_hour: float = 0.0

    def at(self, t_s: np.ndarray) -> np.ndarray:
        warmup = self.warmup_amplitude * np.exp(-t_s / self.warmup_tau_s)
        return warmup + self.slope_per_hour * t_s / 3600.0


@dataclass(frozen=True)
class Spikes:
    """Rectangular spikes of ``amplitude`` (unit) and ``duration_s`` at Poisson times."""

    axis: str
    rate_per_hour: float
    amplitude: float
    duration_s: float = 0.02


_EFFECT_TABLES = {"sinusoid": Sinusoid, "bias_step": BiasStep, "drift": Drift, "spikes": Spikes}


@dataclass(frozen=True)
class Scenario:
    """Everything the virtual ADIS16364 simulates beyond its register model."""

    name: str = "default"
    description: str = "The ADIS16364 paper's static 12 h test: measured noise, 21 °C, 5.0 V."
    noise: dict[str, AxisNoise] = field(default_factory=default_noise)
    temperature: Temperature = field(default_factory=Temperature)
    supply: Supply = field(default_factory=Supply)
    jitter_s: float = 0.0
    sinusoid: tuple[Sinusoid, ...] = ()
    bias_step: tuple[BiasStep, ...] = ()
    drift: tuple[Drift, ...] = ()
    spikes: tuple[Spikes, ...] = ()

    def deterministic(self, axis: str, t_s: np.ndarray) -> np.ndarray:
        """Sum of the deterministic effects on ``axis`` at times ``t_s`` (unit; no bias)."""
        t_s = np.asarray(t_s, dtype=float)
        out = np.zeros_like(t_s)
        if axis in self.temperature.coefficients:
            delta = self.temperature.at(t_s) - self.temperature.reference_c
            out += self.temperature.coefficients[axis] * delta
        if axis in self.supply.sensitivity:
            out += self.supply.sensitivity[axis] * (self.supply.at(t_s) - self.supply.nominal_v)
        for effect in (*self.sinusoid, *self.bias_step, *self.drift):
            if effect.axis == axis:
                out += effect.at(t_s)
        return out

    def has_effects(self, axis: str) -> bool:
        """Whether any deterministic effect acts on ``axis``."""
        return (
            axis in self.temperature.coefficients
            or (axis in self.supply.sensitivity and self.supply.ripple_amplitude_v != 0.0)
            or any(e.axis == axis for e in (*self.sinusoid, *self.bias_step, *self.drift))
        )

    def truth_dict(self) -> dict[str, Any]:
        """All parameters and effects, in paper units and SI, JSON-serialisable."""
        axes = {}
        for axis, terms in self.noise.items():
            sensor = sensor_of(axis)
            paper = {
                "mean": terms.bias,
                "random_walk": terms.random_walk,
                "bias_instability": terms.bias_instability,
                "adev_plateau": FLICKER_PLATEAU * terms.bias_instability,
                "rate_random_walk": terms.rrw,
                "gauss_markov_sigma": terms.gm_sigma,
            }
            units = dict(PAPER_UNIT[sensor])  # type: ignore[index]
            units.update(adev_plateau=units["mean"], gauss_markov_sigma=units["mean"])
            si_units = dict(SI_UNIT[sensor])  # type: ignore[index]
            si_units.update(adev_plateau=si_units["mean"], gauss_markov_sigma=si_units["mean"])
            axes[axis] = {
                "paper_units": {**paper, "units": units},
                "si": {
                    **{k: v * SI_PER_UNIT[units[k]] for k, v in paper.items()},
                    "units": si_units,
                },
                "gauss_markov_tau_s": terms.gm_tau_s,
            }
        effects: dict[str, Any] = {}
        for kind in _EFFECT_TABLES:
            effects[kind] = [_effect_truth(e) for e in getattr(self, kind)]
        temperature = asdict(self.temperature)
        temperature["coefficients_si_per_kelvin"] = {
            a: c * si_per_unit(a) for a, c in self.temperature.coefficients.items()
        }
        supply = asdict(self.supply)
        supply["sensitivity_si_per_volt"] = {
            a: s * si_per_unit(a) for a, s in self.supply.sensitivity.items()
        }
        return {
            "scenario": self.name,
            "description": self.description,
            "unit_note": "paper_units: gyro °/s (random walk °/√s), accel mg (mg/√s); "
            "si: rad/s, m/s²; effects give 'amplitude'/'size'/slopes in the axis' paper unit "
            "and the same value in SI under '*_si'",
            "noise": axes,
            "temperature": temperature,
            "supply": supply,
            "host_jitter_s": self.jitter_s,
            "effects": effects,
        }


def _effect_truth(effect: Any) -> dict[str, Any]:
    """An effect's parameters, with every axis-unit value repeated in SI under ``*_si``."""
    out = asdict(effect)
    out["unit"] = unit_of(effect.axis)
    scale = si_per_unit(effect.axis)
    for key in ("amplitude", "size", "warmup_amplitude", "slope_per_hour"):
        if key in out:
            out[f"{key}_si"] = out[key] * scale
    return out


def _build(cls: type, table: Any, where: str) -> Any:
    """Instantiate dataclass ``cls`` from a TOML table, rejecting unknown keys and bad axes."""
    if not isinstance(table, dict):
        raise ScenarioError(f"{where}: expected a table, got {table!r}")
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(table) - names)
    if unknown:
        raise ScenarioError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(names)}")
    for key in ("coefficients", "sensitivity"):
        if key in table:
            _check_axes(table[key], f"{where}.{key}")
    if "axis" in table:
        _check_axes({table["axis"]: 0}, where)
    if "points" in table:
        table = {**table, "points": tuple(tuple(map(float, p)) for p in table["points"])}
    try:
        return cls(**table)
    except TypeError as exc:
        raise ScenarioError(f"{where}: {exc}") from exc


def _check_axes(mapping: Any, where: str) -> None:
    bad = sorted(set(mapping) - set(AXES))
    if bad:
        raise ScenarioError(f"{where}: unknown axis {bad}; axes are {list(AXES)}")


def _validate(s: Scenario) -> Scenario:
    for axis, terms in s.noise.items():
        if min(terms.random_walk, terms.bias_instability, terms.rrw, terms.gm_sigma) < 0:
            raise ScenarioError(f"noise.{axis}: noise coefficients must be >= 0")
        if terms.gm_sigma > 0 and terms.gm_tau_s <= 0:
            raise ScenarioError(f"noise.{axis}: gm_sigma needs gm_tau_s > 0")
    t = s.temperature
    if t.amplitude_c and t.period_s <= 0:
        raise ScenarioError("temperature: amplitude_c needs period_s > 0")
    if list(t.points) != sorted(t.points):
        raise ScenarioError("temperature.points must be in increasing time")
    if any(d.warmup_tau_s <= 0 for d in s.drift):
        raise ScenarioError("drift: warmup_tau_s must be > 0")
    if any(sp.rate_per_hour < 0 or sp.duration_s <= 0 for sp in s.spikes):
        raise ScenarioError("spikes: rate_per_hour must be >= 0 and duration_s > 0")
    if s.jitter_s < 0:
        raise ScenarioError("host.jitter_s must be >= 0")
    return s


def scenario_from_dict(data: dict[str, Any]) -> Scenario:
    """Build and validate a :class:`Scenario` from a parsed TOML document."""
    allowed = {"name", "description", "noise", "temperature", "supply", "host", *_EFFECT_TABLES}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ScenarioError(f"unknown top-level key(s) {unknown}; allowed: {sorted(allowed)}")
    noise = default_noise()
    overrides = data.get("noise", {})
    _check_axes(overrides, "noise")
    for axis, table in overrides.items():
        merged = {**asdict(noise[axis]), **table}
        noise[axis] = _build(AxisNoise, merged, f"noise.{axis}")
    host = data.get("host", {})
    if set(host) - {"jitter_s"}:
        raise ScenarioError(f"host: unknown key(s) {sorted(set(host) - {'jitter_s'})}")
    effects = {
        kind: tuple(_build(cls, t, f"{kind}[{i}]") for i, t in enumerate(data.get(kind, [])))
        for kind, cls in _EFFECT_TABLES.items()
    }
    return _validate(
        Scenario(
            name=str(data.get("name", "unnamed")),
            description=str(data.get("description", "")),
            noise=noise,
            temperature=_build(Temperature, data.get("temperature", {}), "temperature"),
            supply=_build(Supply, data.get("supply", {}), "supply"),
            jitter_s=float(host.get("jitter_s", 0.0)),
            **effects,
        )
    )


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario TOML file (format: README.md ("Scenario files"))."""
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ScenarioError(f"cannot read scenario {path}: {exc}") from exc
    return scenario_from_dict(data)
