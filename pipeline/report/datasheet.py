"""Datasheet noise specifications to print next to the measured terms (``--datasheet FILE``).

A datasheet is a small TOML file: ``part`` and ``source`` (where the numbers come from), and per
sensor (``[gyro]``, ``[accel]``) any of ``N`` (white noise: angle/velocity random walk), ``B``
(bias instability), ``K`` (rate random walk) and ``rms`` (output noise), each
``{ value = 2.0, unit = "°/√h" }`` with a unit of :data:`imupipe.units.SI_PER_UNIT`.  The
ADIS16364's ships with imupipe (:func:`adis16364`) and is used for ADIS16364 recordings.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from imupipe.errors import DatasheetError
from imupipe.units import SI_PER_UNIT, to_si

QUANTITY = {"N": "random_walk", "B": "bias_instability", "K": "rate_random_walk", "rms": "rms"}
"""TOML key → the report's quantity name."""


@dataclass(frozen=True)
class Spec:
    """One datasheet value in its own unit."""

    value: float
    unit: str

    def si(self) -> float:
        return to_si(self.value, self.unit)


@dataclass(frozen=True)
class Datasheet:
    """``specs[(sensor, quantity)]`` (quantity as in :data:`QUANTITY`'s values)."""

    part: str
    source: str
    specs: dict[tuple[str, str], Spec]

    def get(self, sensor: str, quantity: str) -> Spec | None:
        return self.specs.get((sensor, quantity))


def parse_datasheet(text: str, where: str) -> Datasheet:
    """A :class:`Datasheet` from TOML ``text``; ``where`` names it in errors."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DatasheetError(f"{where}: not TOML ({exc})") from None
    specs = {}
    for sensor in ("gyro", "accel"):
        for key, entry in doc.get(sensor, {}).items():
            if key not in QUANTITY:
                raise DatasheetError(f"{where}: [{sensor}] {key!r}: use N, B, K or rms")
            if not isinstance(entry, dict) or set(entry) != {"value", "unit"}:
                raise DatasheetError(
                    f"{where}: [{sensor}] {key} must be {{value = ..., unit = ...}}"
                )
            value, unit = entry["value"], entry["unit"]
            if not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
                raise DatasheetError(
                    f"{where}: [{sensor}] {key} value {value!r} is not a number >= 0"
                )
            if unit not in SI_PER_UNIT:
                raise DatasheetError(
                    f"{where}: [{sensor}] {key} unit {unit!r} unknown; known: "
                    + ", ".join(SI_PER_UNIT)
                )
            specs[(sensor, QUANTITY[key])] = Spec(float(value), unit)
    if not specs:
        raise DatasheetError(f"{where}: no [gyro] or [accel] values")
    return Datasheet(str(doc.get("part", "")), str(doc.get("source", where)), specs)


def load_datasheet(path: Path) -> Datasheet:
    """The datasheet TOML file at ``path``."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasheetError(f"{path}: unreadable ({exc})") from None
    return parse_datasheet(text, str(path))


def adis16364() -> Datasheet:
    """The ADIS16364's values (package data, from the paper's table)."""
    text = (
        resources.files("imupipe.report").joinpath("datasheets/adis16364.toml").read_text("utf-8")
    )
    return parse_datasheet(text, "adis16364.toml")
