"""Loading the numbers in ``data/``: every quantity with its value, unit and source.

A *quantity table* in a TOML file looks like::

    [car_body_mass_kg]
    value = 41800
    unit = "kg"
    source = "paper 001, Table 1"

Quantity tables may be nested inside ordinary tables (e.g. one table per track class).
The loader rejects unknown keys, missing units or sources and non-physical values, each
with one line naming the file and the key (:class:`DataError`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

from railpaper.paths import DATA_DIR

#: Units whose values must be strictly positive (mass, inertia, stiffness, damping, speed,
#: length, time, frequency, force, spectral constants).
POSITIVE_UNITS = frozenset({
    "kg", "kg*m^2", "N/m", "N*s/m", "N*m/rad", "N*m*s/rad", "m/s", "km/h", "m", "s", "Hz",
    "N", "rad/m", "m/N^(2/3)", "m^2*rad/m", "cm^2*rad/m", "m*rad", "mm^2*m", "m/s^2",
})
QUANTITY_FIELDS = frozenset({"value", "unit", "source", "note"})


class DataError(ValueError):
    """A data file is malformed; the message is one line naming the file and the key."""


@dataclass(frozen=True)
class Quantity:
    """A number with its unit and where it comes from."""

    value: float | list
    unit: str
    source: str
    note: str = ""


def data_path(name: str) -> Path:
    """Path of a file in the repository's ``data/`` directory."""
    return DATA_DIR / name


def read_toml(path: Path | str) -> dict[str, Any]:
    """Read a TOML file, turning syntax errors into :class:`DataError`."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise DataError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML ({exc})") from None


def _check_quantity(path: Path, key: str, table: Mapping[str, Any]) -> Quantity:
    extra = set(table) - QUANTITY_FIELDS
    if extra:
        raise DataError(f"{path}: key '{key}': unknown field(s) {sorted(extra)}")
    for field in ("unit", "source"):
        if not isinstance(table.get(field), str) or not table[field].strip():
            raise DataError(f"{path}: key '{key}': missing {field}")
    value = table["value"]
    numbers = value if isinstance(value, list) else [value]
    for number in numbers:
        if isinstance(number, bool) or not isinstance(number, (int, float)):
            raise DataError(f"{path}: key '{key}': value {number!r} is not a number")
        if not math.isfinite(number):
            raise DataError(f"{path}: key '{key}': value {number!r} is not finite")
        if table["unit"] in POSITIVE_UNITS and number <= 0:
            raise DataError(
                f"{path}: key '{key}': non-physical value {number!r} {table['unit']} (must be > 0)")
    if isinstance(value, list):
        value = [float(v) for v in value]
    else:
        value = float(value)
    return Quantity(value, table["unit"], table["source"], table.get("note", ""))


def load_quantities(path: Path | str, expected: Iterable[str] | None = None,
                    section: str | None = None) -> dict[str, Quantity]:
    """Load a flat set of quantity tables.

    Parameters
    ----------
    path : path-like
        TOML file.
    expected : iterable of str, optional
        The keys the code knows; any other key, or a missing one, is an error.
    section : str, optional
        Read the quantity tables inside this top-level table instead of the file's top level.

    Returns
    -------
    dict of str to Quantity
    """
    path = Path(path)
    document = read_toml(path)
    if section is not None:
        if section not in document:
            raise DataError(f"{path}: missing table '{section}'")
        document = document[section]
    quantities = {}
    for key, table in document.items():
        if key == "meta":
            continue
        if not isinstance(table, dict) or "value" not in table:
            raise DataError(f"{path}: key '{key}': expected a table with value, unit and source")
        quantities[key] = _check_quantity(path, key, table)
    if expected is not None:
        expected = set(expected)
        unknown = sorted(set(quantities) - expected)
        if unknown:
            raise DataError(f"{path}: unknown key '{unknown[0]}' (expected one of {sorted(expected)})")
        missing = sorted(expected - set(quantities))
        if missing:
            raise DataError(f"{path}: missing key '{missing[0]}'")
    return quantities


def values(quantities: Mapping[str, Quantity]) -> dict[str, float]:
    """The bare values of a mapping of quantities."""
    return {key: q.value for key, q in quantities.items()}
