"""The answer of the report page: one sentence per requirement, then the tables behind it.

Each sentence says the verdict, P(fail) with its interval (named as the decision layer names
it: :func:`mcchain.decision.summary.interval_name`) and confidence, and the
binding parameter with its allocated range, every value in its reading unit with SI beside
it (:func:`mcchain.ensemble.units.with_units`).

The binding parameter (from the tolerance allocation, one row per sampled parameter):

* some parameter's range (one- or two-sided) reaches the target only by cutting samples: the
  one that keeps the fewest (the range that must shrink most) binds;
* every parameter's whole sampled range reaches it: none binds, and the allocated ranges are
  the sampled ones;
* no parameter alone reaches it: none can be allocated, and the one whose best range gives
  the lowest upper bound of P(fail) is named as the nearest.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from mcchain.decision.summary import interval_name
from mcchain.ensemble.queries import dim_names
from mcchain.ensemble.units import in_reading_unit, interval_with_units, units_of, with_units
from mcchain.viz.page import esc, table
from mcchain.viz.scatter import param_reading

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.decision.summary import AllocationRow, RequirementSummary

VERDICT_WORDS = {"pass": "PASS", "fail": "FAIL", "undecided": "UNDECIDED", "empty": "NO VERDICT"}


def percent(p: float) -> str:
    """A probability as a percentage (``0.918 -> "91.8 %"``, ``0 -> "0 %"``)."""
    return "NaN" if math.isnan(p) else f"{100 * p:.3g} %"


class Units:
    """Units and reading magnitudes of the run's outputs and sampled parameters."""

    def __init__(self, ds: xr.Dataset) -> None:
        self.ds = ds
        self.paths = dim_names(ds, "param") if "param" in ds.dims else []
        self.params = (
            np.asarray(ds["parameters"].transpose("sample", "param").values, dtype=np.float64)
            if self.paths and "parameters" in ds.data_vars
            else np.empty((ds.sizes.get("sample", 0), 0))
        )
        units = ds["param_units"].values if "param_units" in ds.coords else ["1"] * len(self.paths)
        self.param_units = {p: str(u) for p, u in zip(self.paths, units, strict=True)}

    def output(self, name: str) -> str:
        """CF units of an output variable ("" when unknown)."""
        attrs = self.ds[name].attrs if name in self.ds.variables else {}
        return units_of(attrs, name) or ""

    def of(self, s: RequirementSummary) -> str:
        """CF units of a requirement's output: the variable's, or, for a mixed unit (``q_eq``:
        ``m (x, y), rad (theta)``), the one the decision layer resolved from the selection."""
        units = self.output(s.output.split("[", 1)[0])
        return s.units if "(" in units else units

    def limits(self, s: RequirementSummary, reading_only: bool = False) -> str:
        """A requirement's band as text, both limits when it has both:
        ``"0.5 Hz (3.142 rad/s) ≤ omega[mode=0] ≤ 2 Hz (12.57 rad/s)"``, ``"x ≤ 5 kN"``."""
        low, high = (None if math.isnan(v) else v for v in (s.minimum, s.maximum))
        if low is None and high is None:  # a summary without its limits: the side judged
            low, high = (None, s.limit) if s.side == "max" else (s.limit, None)
        unit = self.of(s)
        size = max(abs(v) for v in (low, high) if v is not None)
        shown = in_reading_unit if reading_only else with_units
        text = s.output
        if low is not None:
            text = f"{shown(low, unit, magnitude=size)} ≤ {text}"
        if high is not None:
            text = f"{text} ≤ {shown(high, unit, magnitude=size)}"
        return text

    def param(self, path: str) -> tuple[str, str, float]:
        """(name as an axis reads it, CF units, largest |value| sampled) of a parameter."""
        j = self.paths.index(path)
        x = np.abs(self.params[:, j])
        x = x[np.isfinite(x)]
        name = param_reading(path, x)[0]
        return name, self.param_units.get(path, "1"), float(x.max()) if x.size else 0.0

    def param_value(self, path: str, value: float) -> str:
        """A value of a parameter in its reading unit (the unit its axes use)."""
        _, units, size = self.param(path)
        return with_units(value, units, magnitude=size)


def binding(s: RequirementSummary, rows: list[AllocationRow]) -> tuple[str, AllocationRow | None]:
    """How the allocation binds (``"cut"``, ``"none-binds"``, ``"unreachable"``, or
    ``"none"`` without sampled parameters) and the row named (see the module docstring)."""
    mine = [r for r in rows if r.requirement == s.name]
    if not mine:
        return "none", None
    reach = [r for r in mine if r.meets_target]
    if not reach:
        return "unreachable", min(mine, key=lambda r: r.p_upper)
    cut = [r for r in reach if r.side != "all"]
    if not cut and len(reach) == len(mine):
        return "none-binds", None
    return "cut", min(cut or reach, key=lambda r: r.samples_kept)


def _range(units: Units, r: AllocationRow) -> str:
    """The allocated range of a row (``allocation.csv``'s side, low and high)."""
    name = esc(units.param(r.parameter)[0])
    low, high = (esc(units.param_value(r.parameter, v)) for v in (r.low, r.high))
    return {
        "upper": f"{name} ≤ {high}",
        "lower": f"{name} ≥ {low}",
        "both": f"{low} ≤ {name} ≤ {high}",
    }.get(r.side, f"{name} as sampled")


def sentence(s: RequirementSummary, rows: list[AllocationRow], units: Units) -> str:
    """The answer for one requirement, as HTML (one paragraph)."""
    interval = f"{interval_name(s)}: {percent(s.p_lower)}–{percent(s.p_upper)}"
    compare = {
        "pass": "within",
        "fail": "beyond",
        "undecided": "undecided against",
        "empty": "not comparable (the sequential bounds crossed) with",
    }[s.decision]
    text = (
        f'<b class="{s.decision}">{esc(s.name)}: {VERDICT_WORDS[s.decision]}.</b> '
        f"{esc(units.limits(s))} fails in {s.failures} of {s.samples} samples"
        + (f" ({s.undefined} undefined: failed instances)" if s.undefined else "")
        + f": P(fail) = {percent(s.p_fail)} ({esc(interval)}), {compare} the target "
        f"{percent(s.target)}."
    )
    how, row = binding(s, rows)
    if how == "cut" and row is not None:
        text += (
            f" Binding parameter: <b>{_range(units, row)}</b> keeps the upper bound of P(fail) "
            f"at {percent(row.p_upper)} ({row.samples_kept} of {s.samples} samples kept)."
        )
    elif how == "none-binds":
        ranges = "; ".join(_range(units, r) for r in rows if r.requirement == s.name)
        text += f" No parameter binds: the sampled ranges meet the target ({ranges})."
    elif how == "unreachable" and row is not None:
        name = units.param(row.parameter)[0]
        text += (
            " No range of a single parameter reaches the target; the nearest is "
            f"<b>{esc(name)}</b> (its best range, {_range(units, row)}, keeps "
            f"{row.samples_kept} samples and P(fail) ≤ {percent(row.p_upper)})."
        )
    if not s.exact:
        text += " The bounds are approximate: the design's samples are not independent draws."
    return f'<p class="answer {s.decision}">{text}</p>'


def answer_section(
    summaries: list[RequirementSummary], rows: list[AllocationRow], ds: xr.Dataset
) -> str:
    """The page's first section: one sentence per requirement (or why there is none)."""
    if not summaries:
        return (
            '<section id="answer"><h2>Answer</h2><p>The scene has no [[requirement]]: the page '
            "shows the ensemble only.</p></section>"
        )
    units = Units(ds)
    parts = [sentence(s, rows, units) for s in summaries]
    return '<section id="answer"><h2>Answer</h2>\n' + "\n".join(parts) + "</section>"


def requirement_tables(
    summaries: list[RequirementSummary], rows: list[AllocationRow], ds: xr.Dataset
) -> str:
    """The evidence under the answer: each requirement's numbers and its allocation."""
    if not summaries:
        return ""
    units = Units(ds)
    body = []
    for s in summaries:
        unit = units.of(s)
        size = abs(s.limit) if math.isfinite(s.limit) else abs(s.quantile)

        def value(x: float, unit: str = unit, size: float = size) -> str:
            return esc(with_units(x, unit, magnitude=size))

        quantile = esc(
            interval_with_units(s.quantile, s.quantile_lower, s.quantile_upper, unit, size)
        )
        if math.isnan(s.quantile_lower) or math.isnan(s.quantile_upper):
            quantile += f" (— : needs {s.quantile_samples_needed} samples)"
        body.append(
            [
                esc(s.name),
                esc(units.limits(s)),
                f'<span class="{s.decision}">{esc(s.verdict)}</span>',
                f"{s.failures} / {s.samples} ({s.undefined} undefined)",
                f"{percent(s.p_fail)} [{percent(s.p_lower)}, {percent(s.p_upper)}]",
                esc(interval_name(s)),
                f"{percent(s.target)} at {percent(s.confidence)}",
                f"{100 * s.level:.3g} %: {quantile}",
            ]
        )
    header = [
        "requirement",
        "limit",
        "verdict",
        "failures / samples",
        "P(fail) [bounds]",
        "bounds",
        "target at confidence",
        "quantile at the target [bounds]",
    ]
    parts = ['<section id="requirements"><h2>Requirements</h2>', table(header, body)]
    if rows:
        alloc = []
        for r in rows:
            name = units.param(r.parameter)[0]
            bound = _range(units, r) if r.meets_target else f"none; best: {_range(units, r)}"
            alloc.append(
                [
                    esc(r.requirement),
                    f"{esc(name)}<br><code>{esc(r.parameter)}</code>",
                    bound,
                    esc(r.samples_kept),
                    percent(r.p_upper),
                ]
            )
        parts += [
            "<h3>Tolerance allocation</h3>",
            "<p>For each requirement and each sampled parameter alone (the others as sampled): "
            "the widest range, one- or two-sided, whose upper bound of P(fail) meets the "
            "target; the bound holds over every cut tried, and <code>mcchain confirm</code> "
            "decides the range on fresh samples.</p>",
            table(["requirement", "parameter", "range", "samples kept", "P(fail) ≤"], alloc),
        ]
    return "\n".join(parts) + "</section>"
