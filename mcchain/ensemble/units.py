"""Values with their units, as a reader wants them: reading units (mm, kN, Hz) beside SI.

The ensemble stores SI values under CF ``units`` strings (``N``, ``rad s-1``, ``m``: the
variable registry, :mod:`mcchain.ensemble.registry`, and ``param_units`` of the sampled
parameters). A page or a printed line shows a value in the unit an engineer reads it in and
the stored SI value beside it, so the number a CSV holds can always be found again:

* :func:`reading_unit` — the reading unit and its scale for values of a given magnitude
  (one choice per column or axis, so that every value of one quantity reads alike);
* :func:`with_units` — ``"0.02399 mm (2.39912e-05 m)"``, ``"5 kN (5000 N)"``,
  ``"10 Hz (62.83 rad/s)"``; a value already in its reading unit is written once;
* :func:`in_reading_unit` — the reading value alone (``"5 kN"``), for titles;
* :func:`interval_with_units` — a value and its interval in one unit;
* :func:`pretty_units` — a CF string as text (``rad s-1`` -> ``rad/s``, ``1`` -> ``""``);
* :func:`output_units` — the CF unit of a requirement's output (a mixed unit resolved by
  its ``dof`` selection);
* :func:`format_quantity` — a limit as the user wrote it, SI first and its reading beside:
  ``"5000 N (5 kN)"``, ``"2.4e-05 m (0.024 mm)"`` (the decision layer's printed lines).

Rules (documented here only): lengths below 0.1 m read in mm, below 1 µm in nm; forces,
moments, pressures and energies of 1000 and more in k..., of 10⁶ and more in M... (and G
for pressures); times below 1 s in ms, below 1 ms in µs; pulsations (rad/s) in Hz
(f = ω/2π); angles in degrees. Any other unit is kept as it is.
"""

from __future__ import annotations

import math
import re
from collections.abc import Hashable, Mapping
from typing import Any

PRETTY = {
    "1": "",
    "rad s-1": "rad/s",
    "m s-1": "m/s",
    "m s-2": "m/s²",
    "rad s-2": "rad/s²",
    "N m-1": "N/m",
    "N m-1.5": "N/m^1.5",
    "N s m-1": "N s/m",
    "kg m2": "kg m²",
}
"""CF unit strings written as text; others are shown as they are."""

SMALL_LENGTH = 0.1
"""Lengths (m) whose magnitude stays below this read in mm."""
TINY_LENGTH = 1e-6
"""Lengths (m) whose magnitude stays below this read in nm (from 1 µm up, mm: engineers
write clearances and penetrations in mm, 0.024 mm)."""

_PREFIXED = {"N": ("kN", "MN"), "N m": ("kN m", "MN m"), "J": ("kJ", "MJ"), "Pa": ("kPa", "MPa")}
"""Units read with a k or M prefix from 10³ and 10⁶ on (pressures: G from 10⁹)."""


def pretty_units(units: str) -> str:
    """A CF units string as a reader writes it (``rad s-1`` -> ``rad/s``; ``1`` -> ``""``)."""
    return PRETTY.get(units.strip(), units.strip())


def reading_unit(units: str, magnitude: float) -> tuple[str, float]:
    """The unit a value of SI ``units`` and typical size ``magnitude`` (its absolute value,
    or the largest of a column) is read in, and the factor that converts to it:
    ``reading_unit("m", 2.4e-4) == ("mm", 1e3)``; ``reading_unit("rad s-1", 62.8) ==
    ("Hz", 1/(2π))``. A unit without a reading form gives ``(pretty_units(units), 1.0)``."""
    units = units.strip()
    size = abs(float(magnitude)) if math.isfinite(magnitude) else 0.0
    if units == "m" and 0.0 < size < SMALL_LENGTH:
        return ("nm", 1e9) if size < TINY_LENGTH else ("mm", 1e3)
    if units == "s" and 0.0 < size < 1.0:
        return ("µs", 1e6) if size < 1e-3 else ("ms", 1e3)
    if units == "rad s-1":
        return "Hz", 1.0 / (2.0 * math.pi)
    if units == "rad":
        return "°", 180.0 / math.pi
    if units == "Pa" and size >= 1e9:
        return "GPa", 1e-9
    if units in _PREFIXED and size >= 1e3:
        kilo, mega = _PREFIXED[units]
        return (mega, 1e-6) if size >= 1e6 else (kilo, 1e-3)
    return pretty_units(units), 1.0


def _number(value: float, digits: int) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "∞" if value > 0 else "−∞"
    return f"{value:.{digits}g}"


def _joined(number: str, unit: str) -> str:
    return number if not unit else (f"{number}{unit}" if unit == "°" else f"{number} {unit}")


def with_units(
    value: float, units: str, magnitude: float | None = None, digits: int = 4, si_digits: int = 6
) -> str:
    """``value`` (SI, in CF ``units``) in its reading unit with the SI value beside it:
    ``with_units(5000.0, "N") == "5 kN (5000 N)"``, ``with_units(2.39912e-05, "m",
    magnitude=4e-4) == "0.02399 mm (2.39912e-05 m)"``; a value whose reading unit is its SI
    unit is written once (``"0.9"``, ``"12 N"``).

    Args:
        magnitude: the size that picks the reading unit (default ``|value|``): pass a
            column's largest value so that its rows share one unit.
        digits, si_digits: significant digits of the reading and the SI value.
    """
    value = float(value)
    if not math.isfinite(value):
        return _number(value, digits)  # NaN has no unit to read
    unit, scale = reading_unit(units, abs(value) if magnitude is None else magnitude)
    si = pretty_units(units)
    if scale == 1.0 and unit == si:
        return _joined(_number(value, si_digits), si)
    reading = _joined(_number(scale * value, digits), unit)
    return f"{reading} ({_joined(_number(value, si_digits), si)})"


def in_reading_unit(
    value: float, units: str, magnitude: float | None = None, digits: int = 4
) -> str:
    """``value`` in its reading unit only (``"5 kN"``), for a title or a label where the SI
    value is given elsewhere."""
    value = float(value)
    if not math.isfinite(value):
        return _number(value, digits)
    unit, scale = reading_unit(units, abs(value) if magnitude is None else magnitude)
    return _joined(_number(scale * value, digits), unit)


def interval_with_units(
    value: float, lower: float, upper: float, units: str, magnitude: float | None = None
) -> str:
    """A value and its interval in one reading unit, the SI values beside:
    ``"16.3 kN [13.3, 19.01] (16302.9 [13304.7, 19014.3] N)"``; an end that is NaN (too
    few samples for it) reads ``—``."""
    size = abs(float(value)) if magnitude is None else magnitude
    unit, scale = reading_unit(units, size if math.isfinite(size) else 0.0)
    si = pretty_units(units)

    def numbers(factor: float, digits: int) -> str:
        ends = ", ".join(
            "—" if math.isnan(x) else _number(factor * x, digits) for x in (lower, upper)
        )
        return f"{_number(factor * value, digits)} [{ends}]"

    if scale == 1.0 and unit == si:
        return _joined(numbers(1.0, 6), si)
    return f"{_joined(numbers(scale, 4), unit)} ({_joined(numbers(1.0, 6), si)})"


def units_of(attrs: Mapping[Hashable, Any], name: str) -> str | None:
    """The CF ``units`` in a variable's attributes (``ds[name].attrs``: what the run wrote,
    also for variables a newer registry declares), else the registry's declaration, else
    None (shown without a unit)."""
    found = attrs.get("units")
    if isinstance(found, str):
        return found
    from mcchain.ensemble.registry import VARIABLES

    return VARIABLES[name].units if name in VARIABLES else None


_MIXED = re.compile(r"\s*([^,()]+?)\s*\(([^)]*)\)")
DOF_NAMES = ("x", "y", "theta")


def output_units(
    output: str, select: Mapping[str, Any] | None = None, attrs: Mapping[str, Any] | None = None
) -> str:
    """The CF unit of a requirement's output: ``attrs["units"]`` (a Dataset variable's), else
    the registry's; a mixed unit (``q_eq``: ``m (x, y), rad (theta)``) resolved by
    ``select``'s ``dof`` (label or index); ``""`` for a pure number or an unknown output."""
    units = str((attrs or {}).get("units", "")) or (units_of({}, output) or "")
    pieces = _MIXED.findall(units)
    if pieces and "dof" in (select or {}):
        dof = (select or {})["dof"]
        label = DOF_NAMES[dof] if isinstance(dof, int) and 0 <= dof < len(DOF_NAMES) else str(dof)
        for unit, labels in pieces:
            if label in [x.strip() for x in labels.split(",")]:
                units = unit
                break
    return "" if units in ("1", "mixed") else units


def format_quantity(value: float, units: str, digits: int = 6) -> str:
    """``value`` (SI, CF ``units``) as a limit is written, then in its reading unit when that
    differs: ``"5000 N (5 kN)"``, ``"2.4e-05 m (0.024 mm)"``, ``"5 N"``, ``"3"`` (no unit);
    NaN and ±inf as such (``"inf s"``)."""
    value = float(value)
    si = pretty_units(units)
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        text = "inf" if value > 0 else "-inf"
        return f"{text} {si}" if si else text
    text = _joined(f"{value:.{digits}g}", si)
    if not si or value == 0.0:
        return text
    unit, scale = reading_unit(units, abs(value))
    if unit == si:
        return text
    return f"{text} ({_joined(_number(scale * value, 4), unit)})"
