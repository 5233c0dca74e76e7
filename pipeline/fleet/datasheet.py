"""A part's datasheet values, read from TOML, to check a fleet against.

::

    part = "ADIS16405"
    source = "ADIS16405 datasheet rev. B, p. 4 (typical, 25 °C)"

    [gyro]
    random_walk = { value = 2.0, unit = "°/√h" }                 # kind = "typical" (default)
    bias_instability = { value = 0.0105, unit = "°/s", kind = "max" }

    [accel]
    random_walk = { value = 0.2, unit = "m/s/√h" }

Sections are sensors (``gyro``, ``accel``); keys are IEEE 952 terms (:data:`TERM_NAMES`);
``unit`` any unit of :data:`imupipe.units.SI_PER_UNIT`.  A ``typical`` value is checked against
the population median, a ``max`` value against the upper 95 %/95 % tolerance bound (see
:mod:`imupipe.fleet.population`).  Datasheets quote "in-run bias stability" as the floor of the
Allan deviation; imupipe's B is that floor / 0.664 (IEEE Std 952-1997, C.2), so a datasheet floor
σ_min goes in as ``bias_instability = σ_min / 0.664``.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from imupipe.errors import DatasheetError
from imupipe.units import SI_PER_UNIT, to_si
from imupipe.vocab import TERM_NAMES

Kind = Literal["typical", "max"]
KINDS: tuple[str, ...] = ("typical", "max")


@dataclass(frozen=True)
class DatasheetValue:
    """One datasheet value: ``si`` (the term's SI unit), as written (``value`` in ``unit``)."""

    sensor: str
    term: str
    si: float
    value: float
    unit: str
    kind: Kind


@dataclass(frozen=True)
class Datasheet:
    part: str
    source: str
    values: dict[tuple[str, str], DatasheetValue]
    """Keyed by (sensor, term)."""

    def get(self, sensor: str, term: str) -> DatasheetValue | None:
        return self.values.get((sensor, term))


def _entry(sensor: str, term: str, raw: object, where: str) -> DatasheetValue:
    if term not in TERM_NAMES:
        raise DatasheetError(f"{where}: unknown term {term!r} (one of {', '.join(TERM_NAMES)})")
    if not isinstance(raw, dict) or not isinstance(raw.get("value"), int | float):
        raise DatasheetError(f"{where}: {sensor}.{term} needs {{ value = NUMBER, unit = TEXT }}")
    unit, kind = raw.get("unit"), raw.get("kind", "typical")
    if unit not in SI_PER_UNIT:
        raise DatasheetError(f"{where}: {sensor}.{term}: unknown unit {unit!r}")
    if kind not in KINDS:
        raise DatasheetError(f"{where}: {sensor}.{term}: kind must be typical or max")
    value = float(raw["value"])
    if not value > 0:
        raise DatasheetError(f"{where}: {sensor}.{term}: value must be positive")
    return DatasheetValue(sensor, term, to_si(value, unit), value, unit, kind)


def load_datasheet(path: Path) -> Datasheet:
    """Read a datasheet TOML (format in the module doc).

    Raises:
        DatasheetError: unreadable file, unknown sensor, term, unit or kind.
    """
    try:
        doc = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DatasheetError(f"{path}: cannot read the datasheet: {exc}") from exc
    values: dict[tuple[str, str], DatasheetValue] = {}
    for key, section in doc.items():
        if key in ("part", "source"):
            continue
        if key not in ("gyro", "accel") or not isinstance(section, dict):
            raise DatasheetError(f"{path}: unknown section {key!r} (gyro or accel)")
        for term, raw in section.items():
            values[(key, term)] = _entry(key, term, raw, str(path))
    if not values:
        raise DatasheetError(f"{path}: no datasheet values")
    return Datasheet(str(doc.get("part", "")), str(doc.get("source", "")), values)
