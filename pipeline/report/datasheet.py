"""Datasheet noise specifications to print next to the measured terms (``--datasheet FILE``).

A datasheet is a small TOML file: ``part`` and ``source`` (where the numbers come from), and per
sensor (``[gyro]``, ``[accel]``) any of ``N`` (white noise: angle/velocity random walk), ``B``
(bias instability), ``K`` (rate random walk) and ``rms`` (output noise) — or the same by their
IEEE 952 names (``random_walk``, ``bias_instability``, ``rate_random_walk``) — each
``{ value = 2.0, unit = "°/√h" }`` with a unit of :data:`imupipe.units.SI_PER_UNIT` and
optionally ``kind = "typical"`` (the default) or ``"max"``.  A fleet checks a typical value
against the population median and a max value against the upper 95 %/95 % tolerance bound
(:mod:`imupipe.fleet.population`).  Datasheets quote "in-run bias stability" as the floor of the
Allan deviation; imupipe's B is that floor / 0.664 (IEEE Std 952-1997, C.2).  The ADIS16364's
ships with imupipe (:func:`adis16364`) and is used for ADIS16364 recordings.
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
"""TOML key → the report's quantity name (the quantity names themselves are keys too)."""
KINDS = ("typical", "max")


@dataclass(frozen=True)
class Spec:
    """One datasheet value in its own unit."""

    value: float
    unit: str
    kind: str = "typical"  # or "max" (module doc)

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
    unknown = sorted(set(doc) - {"part", "source", "gyro", "accel"})
    if unknown:
        raise DatasheetError(f"{where}: unknown section(s) {unknown}: part, source, gyro, accel")
    specs = {}
    for sensor in ("gyro", "accel"):
        for key, entry in doc.get(sensor, {}).items():
            quantity = QUANTITY.get(key, key)
            if quantity not in QUANTITY.values():
                raise DatasheetError(f"{where}: [{sensor}] {key!r}: use N, B, K or rms")
            if not isinstance(entry, dict) or not {"value", "unit"} <= set(entry) <= {
                "value",
                "unit",
                "kind",
            }:
                raise DatasheetError(
                    f"{where}: [{sensor}] {key} must be {{value = ..., unit = ...}}"
                )
            kind = entry.get("kind", "typical")
            if kind not in KINDS:
                raise DatasheetError(f"{where}: [{sensor}] {key} kind {kind!r}: typical or max")
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
            specs[(sensor, quantity)] = Spec(float(value), unit, kind)
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
