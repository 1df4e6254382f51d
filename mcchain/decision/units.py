"""Numbers with their units, as the decision layer prints them: one place.

A limit, quantile or bound is printed in the output's unit, exactly as the scene writes it,
and, where a prefixed unit reads better, again in that unit: ``5000 N (5 kN)``,
``2.4e-05 m (0.024 mm)``, ``0.001 s (1 ms)``. The unit of an output is its CF ``units``
(the Dataset's attribute, else the registry's); a mixed unit such as ``q_eq``'s ``m (x, y),
rad (theta)`` is resolved by the requirement's ``dof`` selection.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

READABLE = {"rad s-1": "rad/s", "m s-1": "m/s", "s-1": "1/s", "kg m2": "kg m^2"}
"""CF unit strings written the way a reader writes them."""

SCALES: dict[str, tuple[tuple[float, float, str], ...]] = {
    "m": ((1.0, 1.0, "m"), (1e-6, 1e-3, "mm"), (0.0, 1e-9, "nm")),
    "s": ((1.0, 1.0, "s"), (1e-3, 1e-3, "ms"), (1e-6, 1e-6, "µs"), (0.0, 1e-9, "ns")),
    "N": ((1e6, 1e6, "MN"), (1e3, 1e3, "kN"), (1.0, 1.0, "N"), (0.0, 1e-3, "mN")),
    "N m": ((1e6, 1e6, "MN m"), (1e3, 1e3, "kN m"), (1.0, 1.0, "N m"), (0.0, 1e-3, "mN m")),
    "J": ((1e6, 1e6, "MJ"), (1e3, 1e3, "kJ"), (1.0, 1.0, "J"), (0.0, 1e-3, "mJ")),
    "Pa": ((1e9, 1e9, "GPa"), (1e6, 1e6, "MPa"), (1e3, 1e3, "kPa"), (0.0, 1.0, "Pa")),
}
"""Units with readable multiples: (from magnitude, factor, name), largest first. Lengths
from 1 µm to 1 m read in mm (engineers write clearances in mm: 0.024 mm, not 24 µm)."""

_MIXED = re.compile(r"\s*([^,()]+?)\s*\(([^)]*)\)")
DOF_NAMES = ("x", "y", "theta")


def output_units(
    output: str, select: Mapping[str, Any] | None = None, attrs: Mapping[str, Any] | None = None
) -> str:
    """The unit of a requirement's output: ``attrs["units"]`` (a Dataset variable's), else the
    registry's; a mixed unit resolved by ``select``'s ``dof`` (label or index); ``""`` for a
    pure number (CF ``"1"``) or an unknown output."""
    units = str((attrs or {}).get("units", ""))
    if not units:
        from mcchain.ensemble.registry import VARIABLES

        spec = VARIABLES.get(output)
        units = spec.units if spec is not None else ""
    pieces = _MIXED.findall(units)
    if pieces and "dof" in (select or {}):
        dof = (select or {})["dof"]
        label = DOF_NAMES[dof] if isinstance(dof, int) and 0 <= dof < len(DOF_NAMES) else str(dof)
        for unit, labels in pieces:
            if label in [x.strip() for x in labels.split(",")]:
                units = unit
                break
    return "" if units in ("1", "mixed") else READABLE.get(units, units)


def _number(value: float, digits: int) -> str:
    return f"{value:.{digits}g}"


def format_quantity(value: float, units: str, digits: int = 6) -> str:
    """``value`` with its unit, and in a readable multiple when that differs: ``5000 N (5 kN)``,
    ``2.4e-05 m (0.024 mm)``, ``0.5 m``, ``3 (no unit)`` -> ``3``; NaN and ±inf as such."""
    if isinstance(value, float) and math.isnan(value):
        return "NaN"
    if math.isinf(value):
        text = "inf" if value > 0 else "-inf"
        return f"{text} {units}" if units else text
    raw = _number(float(value), digits)
    if not units:
        return raw
    text = f"{raw} {units}"
    scales = SCALES.get(units)
    if not scales or value == 0:
        return text
    magnitude = abs(float(value))
    _, factor, name = next(s for s in scales if magnitude >= s[0])
    if name == units:
        return text
    return f"{text} ({_number(value / factor, 4)} {name})"
