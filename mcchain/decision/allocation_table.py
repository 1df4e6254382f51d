"""``allocation.csv`` and ``allocation-box.csv``: the tolerance allocation of every
requirement (:mod:`mcchain.decision.allocation`) as rows and in words."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.decision.allocation import ALL, BOTH, LOWER, UPPER, allocate, allocate_box
from mcchain.decision.requirements import dataset_requirement_met, stored_requirements
from mcchain.decision.sampled import sampled_parameters

if TYPE_CHECKING:
    from mcchain.ensemble.per_sample import StoredEnsemble

ALLOCATION_COLUMNS = (
    "requirement",
    "parameter",
    "side",
    "bound",
    "samples_kept",
    "p_upper",
    "low",
    "high",
    "unit",
    "failures",
    "confidence",
    "target",
    "meets_target",
)
"""Columns of ``allocation.csv``: the first six as before, then the range and its counts."""
BOX_COLUMNS = (
    "requirement",
    "parameter",
    "low",
    "high",
    "unit",
    "samples_kept",
    "failures",
    "p_upper",
    "confidence",
    "target",
    "meets_target",
    "selection_samples",
    "verification_samples",
)
"""Columns of ``allocation-box.csv``: one row per parameter of each requirement's box."""


@dataclass(frozen=True)
class AllocationRow:
    """One row of ``allocation.csv`` (docs/scenes.md): one requirement, one parameter."""

    requirement: str
    parameter: str
    side: str
    bound: float
    samples_kept: int
    p_upper: float
    low: float = math.nan
    high: float = math.nan
    unit: str = "1"
    failures: int = 0
    confidence: float = math.nan
    target: float = math.nan
    meets_target: bool = False

    def row(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in ALLOCATION_COLUMNS}


@dataclass(frozen=True)
class BoxRow:
    """One row of ``allocation-box.csv``: one parameter's side of a requirement's box."""

    requirement: str
    parameter: str
    low: float
    high: float
    unit: str
    samples_kept: int
    failures: int
    p_upper: float
    confidence: float
    target: float
    meets_target: bool
    selection_samples: int
    verification_samples: int
    support: tuple[float, float] = (-math.inf, math.inf)
    """The parameter's sampled range (not a column): a face equal to it was not cut."""

    def row(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in BOX_COLUMNS}

    @property
    def cut(self) -> bool:
        """Whether the box narrows this parameter."""
        return (self.low, self.high) != self.support


def failed_samples(ds: StoredEnsemble, requirement: Any) -> np.ndarray:
    """(nsample,) bool: the samples that fail a requirement (``requirement_met`` = 0,
    recomputed from the values and ``status``: a failure bit fails)."""
    return dataset_requirement_met(ds, requirement) == 0


def allocations(ds: StoredEnsemble) -> list[AllocationRow]:
    """The allocation of every requirement over every sampled parameter alone."""
    params = sampled_parameters(ds)
    rows = []
    for requirement in stored_requirements(ds) if params else []:
        failed = failed_samples(ds, requirement)
        t, c = requirement.target, requirement.confidence
        for p in params:
            r = allocate(p.values, failed, t, c, p.support)
            rows.append(
                AllocationRow(
                    requirement.name,
                    p.path,
                    r.side,
                    r.bound,
                    r.samples_kept,
                    r.p_upper,
                    r.low,
                    r.high,
                    p.units,
                    r.failures,
                    c,
                    t,
                    r.passes,
                )
            )
    return rows


def box_allocations(ds: StoredEnsemble) -> list[BoxRow]:
    """The box of every requirement over all its sampled parameters (two or more)."""
    params = sampled_parameters(ds)
    if len(params) < 2:
        return []
    x = np.stack([p.values for p in params], axis=1)
    supports = np.array([p.support for p in params], dtype=np.float64)
    rows = []
    for requirement in stored_requirements(ds):
        t, c = requirement.target, requirement.confidence
        box = allocate_box(x, failed_samples(ds, requirement), t, c, supports)
        for j, p in enumerate(params):
            rows.append(
                BoxRow(
                    requirement.name,
                    p.path,
                    float(box.low[j]),
                    float(box.high[j]),
                    p.units,
                    box.samples_kept,
                    box.failures,
                    box.p_upper,
                    c,
                    t,
                    box.passes,
                    box.selection,
                    box.verification,
                    p.support,
                )
            )
    return rows


# -- words ---------------------------------------------------------------------------------
def _g(x: float, digits: int = 4) -> str:
    return "NaN" if isinstance(x, float) and math.isnan(x) else f"{x:.{digits}g}"


def with_unit(x: float, unit: str) -> str:
    """A value and its CF unit (none for ``1``)."""
    return _g(x, 6) + ("" if unit in ("1", "") else f" {unit}")


def range_text(parameter: str, side: str, low: float, high: float, unit: str) -> str:
    """``joint.B.clearance <= 0.000113 m``, ``... in [a, b] m``, ``... >= a m``."""
    if side == UPPER or (side != ALL and math.isinf(low) and not math.isinf(high)):
        return f"{parameter} <= {with_unit(high, unit)}"
    if side == LOWER or (side != ALL and math.isinf(high) and not math.isinf(low)):
        return f"{parameter} >= {with_unit(low, unit)}"
    if side == ALL:
        return f"{parameter} as sampled"
    return f"{parameter} in [{_g(low, 6)}, {with_unit(high, unit)}]"


def _side(low_uncut: bool, high_uncut: bool) -> str:
    return UPPER if low_uncut else LOWER if high_uncut else BOTH


def allocation_lines(
    rows: list[AllocationRow], requirement: str, boxes: list[BoxRow] | None = None
) -> list[str]:
    """The allocation of one requirement in words: each parameter's range (the best one,
    its bound, even when it misses the target), the box, and what holds at once."""
    lines = []
    mine = [r for r in rows if r.requirement == requirement]
    for r in mine:
        where = range_text(r.parameter, r.side, r.low, r.high, r.unit)
        counts = f"{r.samples_kept} samples kept, {r.failures} failed"
        if r.meets_target and r.side == ALL:
            lines.append(
                f"  {r.parameter}: the whole sampled range meets the target: P(fail) <= "
                f"{_g(r.p_upper)} ({counts})"
            )
        elif r.meets_target:
            lines.append(f"  {where} keeps P(fail) <= {_g(r.p_upper)} ({counts})")
        else:
            lines.append(
                f"  {r.parameter}: no range reaches the target {_g(r.target)}; best: {where} "
                f"with P(fail) <= {_g(r.p_upper)} ({counts})"
            )
    box = [b for b in boxes or [] if b.requirement == requirement]
    if box:
        cut = [
            range_text(
                b.parameter,
                _side(b.low == b.support[0], b.high == b.support[1]),
                b.low,
                b.high,
                b.unit,
            )
            for b in box
            if b.cut
        ]
        b = box[0]
        sides = ", ".join(cut) if cut else "every parameter as sampled"
        counts = (
            f"{b.samples_kept} of the {b.verification_samples} held-out samples kept, "
            f"{b.failures} failed"
        )
        if b.meets_target:
            lines.append(f"  box: {sides} keeps P(fail) <= {_g(b.p_upper)} ({counts})")
        else:
            lines.append(
                f"  box: none reaches the target; best: {sides} with P(fail) <= "
                f"{_g(b.p_upper)} ({counts})"
            )
    if mine:
        n = len(mine) + (1 if box else 0)
        alpha = 1.0 - mine[0].confidence
        lines.append(
            f"  each bound is one-sided at {_g(100 * mine[0].confidence, 3)} % and holds over "
            f"every cut its line tried; the {n} lines together are wrong with probability at "
            f"most {_g(min(1.0, n * alpha), 3)}; `mcchain confirm RUN --requirement "
            f"{requirement}` samples inside a range and decides there"
        )
    return lines
