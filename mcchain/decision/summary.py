"""The answer of a run with requirements: one row per requirement, the tolerance
allocation, and the same in words (``mcchain export RUN --requirements``, the end of
``mcchain run``, the report).

Files written into ``RUN/export/``:

* ``requirements.csv`` — :data:`REQUIREMENT_COLUMNS`, one row per requirement;
* ``allocation.csv`` — :data:`ALLOCATION_COLUMNS`, one row per requirement and sampled
  parameter;
* ``requirements.txt`` — :func:`summary_lines`: verdicts in words, samples needed, the
  success-run figure, and which interval the design gets.

Interval validity: with ``design = "random"`` the samples are independent draws and the
Clopper–Pearson interval is exact. ``sobol``, ``lhs`` and ``saltelli`` samples are not
independent; the same interval is reported labelled *approximate* (``verdict`` reads e.g.
``pass (approximate)``), with no coverage claimed.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.decision.requirements import (
    VARIABLE,
    allocate,
    requirement_met,
    requirement_values,
    stored_requirements,
)
from mcchain.decision.sequential import sequential_bounds
from mcchain.decision.stats import (
    UNDECIDED,
    clopper_pearson,
    quantile_interval,
    samples_to_decide,
    success_run_samples,
    verdict,
)
from mcchain.decision.until import sequential_settings

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.scene.study import Requirement

REQUIREMENT_COLUMNS = (
    "requirement",
    "samples",
    "failures",
    "undefined",
    "p_fail",
    "p_lower",
    "p_upper",
    "confidence",
    "target",
    "verdict",
    "quantile",
    "quantile_lower",
    "quantile_upper",
)
"""Columns of ``requirements.csv``, exactly (a contract)."""
ALLOCATION_COLUMNS = ("requirement", "parameter", "side", "bound", "samples_kept", "p_upper")
"""Columns of ``allocation.csv``, exactly (a contract)."""
EXACT_DESIGNS = ("random",)
"""Designs whose samples are independent draws: the binomial interval is exact."""
APPROXIMATE = " (approximate)"
"""Appended to a verdict whose interval is not exact for the design."""


@dataclass(frozen=True)
class RequirementSummary:
    """One requirement over an ensemble: the row of ``requirements.csv`` and what
    ``requirements.txt`` adds.

    Attributes:
        name, samples, failures, undefined, p_fail, p_lower, p_upper, confidence, target,
        quantile, quantile_lower, quantile_upper: the CSV's columns (see docs/scenes.md).
        decision: ``pass``, ``fail`` or ``undecided``.
        exact: whether the interval is exact for the design (else approximate).
        side: ``max`` or ``min``: the limit the quantile is taken at.
        level: the quantile's level (1 − target for ``max``, target for ``min``).
        limit: that limit's value.
        quantile_samples_needed: samples from which the quantile interval has both ends.
        samples_needed: samples the observed rate needs to decide (= samples if decided,
            NaN if the rate equals the target).
        success_run: the one-sided success-run figure ln(1 − C)/ln(1 − target).
        output: the output and its selection, as text (``omega[mode=0]``).
    """

    name: str
    samples: int
    failures: int
    undefined: int
    p_fail: float
    p_lower: float
    p_upper: float
    confidence: float
    target: float
    decision: str
    exact: bool
    quantile: float
    quantile_lower: float
    quantile_upper: float
    side: str
    level: float
    limit: float
    quantile_samples_needed: int
    samples_needed: float
    success_run: float
    output: str

    @property
    def verdict(self) -> str:
        """The CSV's verdict: the decision, labelled approximate when the interval is."""
        return self.decision if self.exact else self.decision + APPROXIMATE

    def row(self) -> dict[str, Any]:
        """The row of ``requirements.csv``."""
        return {
            "requirement": self.name,
            "samples": self.samples,
            "failures": self.failures,
            "undefined": self.undefined,
            "p_fail": self.p_fail,
            "p_lower": self.p_lower,
            "p_upper": self.p_upper,
            "confidence": self.confidence,
            "target": self.target,
            "verdict": self.verdict,
            "quantile": self.quantile,
            "quantile_lower": self.quantile_lower,
            "quantile_upper": self.quantile_upper,
        }


@dataclass(frozen=True)
class AllocationRow:
    """One row of ``allocation.csv``."""

    requirement: str
    parameter: str
    side: str
    bound: float
    samples_kept: int
    p_upper: float

    def row(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in ALLOCATION_COLUMNS}


def design_of(ds: xr.Dataset) -> str | None:
    """The sampling design of a stored ensemble (``[sample] design``), None without
    ``[sample]``."""
    settings = json.loads(str(ds.attrs.get("settings", "{}")))
    sample = (settings.get("scene") or {}).get("sample")
    return None if not sample else str(sample.get("design", "random"))


def output_label(requirement: Requirement) -> str:
    """``omega[mode=0]``: a requirement's output and selection as text."""
    if not requirement.select:
        return requirement.output
    inner = ",".join(f"{k}={v}" for k, v in requirement.select.items())
    return f"{requirement.output}[{inner}]"


def met_of(ds: xr.Dataset, requirement: Requirement, values: np.ndarray) -> np.ndarray:
    """``requirement_met`` of one requirement as stored (computed from ``values`` for a run
    that predates the variable)."""
    if VARIABLE in ds.data_vars and requirement.name in [str(v) for v in ds["requirement"].values]:
        return np.asarray(ds[VARIABLE].sel(requirement=requirement.name).values, dtype=np.float64)
    return requirement_met(values, requirement)


def quantile_side(requirement: Requirement, values: np.ndarray) -> str:
    """``max`` or ``min``: the limit the quantile is taken at (with both, the one broken
    more often; ties: ``max``)."""
    if requirement.min is None:
        return "max"
    if requirement.max is None:
        return "min"
    above = int(np.sum(values > requirement.max))
    below = int(np.sum(values < requirement.min))
    return "min" if below > above else "max"


def summarize_requirement(
    requirement: Requirement, values: np.ndarray, met: np.ndarray, design: str | None
) -> RequirementSummary:
    """The summary of one requirement from its per-sample values and ``requirement_met``."""
    values = np.asarray(values, dtype=np.float64)
    n = int(values.size)
    failures = int(np.sum(np.asarray(met) == 0))
    undefined = int(np.sum(np.isnan(values)))
    lo, hi = clopper_pearson(failures, n, requirement.confidence)
    decision = verdict(lo, hi, requirement.target)
    side = quantile_side(requirement, values)
    if side == "max":
        level, limit, worst = 1.0 - requirement.target, requirement.max, math.inf
    else:
        level, limit, worst = requirement.target, requirement.min, -math.inf
    # a failed instance (NaN) counts beyond the limit, as it counts as a failure
    q = quantile_interval(np.where(np.isnan(values), worst, values), level, requirement.confidence)
    return RequirementSummary(
        name=requirement.name,
        samples=n,
        failures=failures,
        undefined=undefined,
        p_fail=failures / n if n else math.nan,
        p_lower=lo,
        p_upper=hi,
        confidence=requirement.confidence,
        target=requirement.target,
        decision=decision,
        exact=design in EXACT_DESIGNS,
        quantile=q.value,
        quantile_lower=q.lower,
        quantile_upper=q.upper,
        side=side,
        level=level,
        limit=float(limit) if limit is not None else math.nan,
        quantile_samples_needed=q.samples_needed,
        samples_needed=samples_to_decide(failures, n, requirement.target, requirement.confidence),
        success_run=success_run_samples(requirement.target, requirement.confidence),
        output=output_label(requirement),
    )


def summarize(ds: xr.Dataset) -> list[RequirementSummary]:
    """Every requirement of a stored ensemble, summarized ([] without requirements).

    A run that added samples until decided (``[sample] until``) reports the interval that
    kept its confidence over its looks (:func:`mcchain.decision.sequential.sequential_bounds`)
    and the verdict from it; the counts and the quantile are the same as for a fixed count.
    """
    design = design_of(ds)
    sequential = sequential_settings(ds.attrs)
    out = []
    for requirement in stored_requirements(ds):
        values = requirement_values(ds, requirement)
        met = met_of(ds, requirement, values)
        summary = summarize_requirement(requirement, values, met, design)
        if sequential is not None:
            lo, hi = sequential_bounds(
                met == 0, int(sequential["batch"]), requirement.confidence, requirement.target
            )
            summary = replace(
                summary, p_lower=lo, p_upper=hi, decision=verdict(lo, hi, requirement.target)
            )
        out.append(summary)
    return out


def allocations(ds: xr.Dataset) -> list[AllocationRow]:
    """The tolerance allocation of every requirement over every sampled parameter."""
    requirements = stored_requirements(ds)
    if not requirements or "parameters" not in ds.data_vars or "param" not in ds.dims:
        return []
    params = np.asarray(ds["parameters"].transpose("sample", "param").values, dtype=np.float64)
    paths = [str(p) for p in ds["param"].values]
    rows = []
    for requirement in requirements:
        met = met_of(ds, requirement, requirement_values(ds, requirement))
        for j, path in enumerate(paths):
            a = allocate(params[:, j], met, requirement.target, requirement.confidence)
            rows.append(
                AllocationRow(requirement.name, path, a.side, a.bound, a.samples_kept, a.p_upper)
            )
    return rows


# -- words ---------------------------------------------------------------------------------
def _g(x: float, digits: int = 4) -> str:
    return "NaN" if isinstance(x, float) and math.isnan(x) else f"{x:.{digits}g}"


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


def requirement_lines(s: RequirementSummary, design: str | None) -> list[str]:
    """What one requirement's row says, in words."""
    limit = f"{s.output} {'<=' if s.side == 'max' else '>='} {_g(s.limit, 6)}"
    words = {
        "pass": f"PASS: P(fail) <= {_g(s.target)} shown",
        "fail": f"FAIL: P(fail) > {_g(s.target)} shown",
        UNDECIDED: f"UNDECIDED: the interval contains the target {_g(s.target)}",
    }[s.decision]
    if s.exact:
        approx = ""
    elif design is None:
        approx = " [approximate: no [sample], the instances are all the same]"
    else:
        approx = f" [approximate: design {design!r} does not draw independent samples]"
    lines = [
        f"requirement {s.name} ({limit}; target {_g(s.target)}, confidence {_g(s.confidence)}): "
        f"{words}{approx}",
        f"  {s.failures} of {s.samples} samples failed ({s.undefined} undefined: failed "
        f"instances); P(fail) = {_g(s.p_fail)}, {_pct(s.confidence)} interval "
        f"[{_g(s.p_lower)}, {_g(s.p_upper)}]",
    ]
    bound = "upper" if s.side == "max" else "lower"
    q_text = (
        f"  {_g(100 * s.level)} % quantile of {s.output}: {_g(s.quantile, 6)}, "
        f"{_pct(s.confidence)} interval [{_g(s.quantile_lower, 6)}, {_g(s.quantile_upper, 6)}]"
    )
    if math.isnan(s.quantile_lower) or math.isnan(s.quantile_upper):
        q_text += (
            f" (too few samples for its {bound if math.isnan(s.quantile_upper) else 'other'} "
            f"end: {s.quantile_samples_needed} needed)"
        )
    lines.append(q_text)
    if s.decision == UNDECIDED:
        if math.isnan(s.samples_needed):
            lines.append("  the observed rate equals the target: no sample count decides it")
        else:
            lines.append(
                f"  to decide at the observed rate: about {int(s.samples_needed)} samples "
                f"({int(s.samples_needed) - s.samples} more)"
            )
    if s.failures == 0:
        two_sided = math.ceil(success_run_samples(s.target, (1 + s.confidence) / 2))
        lines.append(
            f"  no failure: the success-run figure n = ln(1 - C)/ln(1 - p) = "
            f"{_g(s.success_run, 6)} failure-free samples show P(fail) <= {_g(s.target)} at "
            f"one-sided {_pct(s.confidence)}; the two-sided interval above needs {two_sided}"
        )
    return lines


def allocation_lines(rows: list[AllocationRow], requirement: str) -> list[str]:
    """The allocation of one requirement in words."""
    lines = []
    for r in rows:
        if r.requirement != requirement:
            continue
        if math.isnan(r.bound):
            lines.append(
                f"  {r.parameter}: no one-sided range reaches the target (best: p_upper "
                f"{_g(r.p_upper)} keeping {r.samples_kept} samples, cut from the {r.side} side)"
            )
        else:
            op = "<=" if r.side == "upper" else ">="
            lines.append(
                f"  {r.parameter} {op} {_g(r.bound, 6)} keeps p_upper {_g(r.p_upper)} "
                f"({r.samples_kept} samples kept)"
            )
    return lines


def summary_lines(
    summaries: list[RequirementSummary],
    rows: list[AllocationRow],
    design: str | None,
    sequential: Mapping[str, Any] | None = None,
) -> list[str]:
    """``requirements.txt`` (and the end of ``mcchain run``): every requirement in words,
    its allocation, and the interval's validity for the design."""
    lines = []
    for s in summaries:
        lines += requirement_lines(s, design)
        alloc = allocation_lines(rows, s.name)
        if alloc:
            lines.append("  tolerance allocation (each parameter alone, the others as sampled):")
            lines += alloc
    if summaries and sequential is not None:
        lines.append(
            f"intervals: sequential ({sequential['method']}), samples added {sequential['batch']} "
            "at a time until decided: valid whenever the run stopped; each verdict is wrong with "
            "probability at most 1 - confidence"
            + ("" if design in EXACT_DESIGNS else f", APPROXIMATE for design {design!r}")
        )
    elif summaries:
        if design in EXACT_DESIGNS:
            lines.append(
                "intervals: exact Clopper-Pearson (independent random draws); each verdict "
                "is wrong with probability at most (1 - confidence)/2"
            )
        else:
            lines.append(
                f"intervals: binomial (Clopper-Pearson), APPROXIMATE for design {design!r}: "
                'its samples are not independent draws; use design = "random" for a decision'
                if design is not None
                else "intervals: the scene has no [sample]: its instances are all the same, so "
                "the binomial interval describes no scatter (add a [sample] table)"
            )
    return lines


# -- files ---------------------------------------------------------------------------------
def _csv_value(value: Any) -> Any:
    if isinstance(value, float):
        return "NaN" if math.isnan(value) else repr(value)
    return value


def write_csv(path: Path, columns: tuple[str, ...], rows: list[dict[str, Any]]) -> None:
    """A CSV of ``rows`` under ``columns``, written atomically (floats exactly, NaN as NaN)."""
    import io

    from mcchain.ensemble.io import write_text_atomic

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_value(v) for k, v in row.items()})
    write_text_atomic(path, buffer.getvalue())


def write_requirements(ds: xr.Dataset, folder: Path) -> list[Path]:
    """``requirements.csv``, ``allocation.csv`` and ``requirements.txt`` into ``folder``."""
    from mcchain.ensemble.io import write_text_atomic

    summaries = summarize(ds)
    rows = allocations(ds)
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / "requirements.csv", folder / "allocation.csv", folder / "requirements.txt"]
    write_csv(paths[0], REQUIREMENT_COLUMNS, [s.row() for s in summaries])
    write_csv(paths[1], ALLOCATION_COLUMNS, [r.row() for r in rows])
    write_text_atomic(
        paths[2],
        "\n".join(summary_lines(summaries, rows, design_of(ds), sequential_settings(ds.attrs)))
        + "\n",
    )
    return paths


def export_requirements(run: str | Path) -> list[Path]:
    """``mcchain export RUN --requirements``: the three files into ``RUN/export/``.

    Raises:
        RunError: the run has no requirements.
    """
    from mcchain.errors import RunError
    from mcchain.runner.runs import open_run, resolve_run, writable_folder

    folder = resolve_run(run)
    ds = open_run(folder)
    if not stored_requirements(ds):
        raise RunError(
            f"{run}: the run has no [[requirement]]: nothing to export with --requirements"
        )
    target = folder / "export"
    writable_folder(target, "--requirements")
    return write_requirements(ds, target)
