"""The answer of a run with requirements: one row per requirement, the tolerance
allocation, and the same in words (``mcchain export RUN --requirements``, the end of
``mcchain run``, the report).

Files written into ``RUN/export/``:

* ``requirements.csv`` — :data:`REQUIREMENT_COLUMNS`, one row per requirement;
* ``allocation.csv`` — :data:`ALLOCATION_COLUMNS`, one row per requirement and sampled
  parameter; ``allocation-box.csv`` — :data:`BOX_COLUMNS`, the box over all the parameters
  (:mod:`mcchain.decision.allocation_table`);
* ``whatif.csv`` and ``whatif.png`` — P(fail) for narrowed parameter ranges, reweighted
  from the same samples (:mod:`mcchain.decision.whatif`);
* ``requirements.txt`` — :func:`summary_lines`: verdicts in words, samples needed, the
  success-run figure, and which interval the design gets.

Interval validity: with ``design = "random"`` the samples are independent draws and the
Clopper–Pearson interval is exact. ``sobol``, ``lhs`` and ``saltelli`` samples are not
independent; the same interval is reported labelled *approximate* (``verdict`` reads e.g.
``pass (approximate)``), with no coverage claimed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.decision.allocation_table import (
    ALLOCATION_COLUMNS,
    BOX_COLUMNS,
    AllocationRow,
    BoxRow,
    allocation_lines,
    allocations,
    box_allocations,
)
from mcchain.decision.requirements import (
    dataset_requirement_met,
    decision_values,
    defined_mask,
    requirement_met,
    requirement_values,
    stored_requirements,
)
from mcchain.decision.sampled import EXACT_DESIGNS, design_of
from mcchain.decision.sequential import confidence_sequence, sequential_bounds
from mcchain.decision.stats import (
    EMPTY,
    UNDECIDED,
    Interval,
    family_confidence,
    one_sided_bounds,
    quantile_bounds,
    samples_to_decide,
    verdict,
)
from mcchain.decision.tables import write_csv
from mcchain.decision.until import sequential_settings
from mcchain.ensemble.units import format_quantity, output_units, pretty_units

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.ensemble.per_sample import StoredEnsemble
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
APPROXIMATE = " (approximate)"
"""Appended to a verdict whose interval is not exact for the design."""


@dataclass(frozen=True)
class RequirementSummary:
    """One requirement over an ensemble: the row of ``requirements.csv`` and what
    ``requirements.txt`` adds.

    Attributes:
        name, samples, failures, undefined, p_fail, p_lower, p_upper, confidence, target,
        quantile, quantile_lower, quantile_upper: the CSV's columns (see docs/scenes.md).
            [p_lower, p_upper] = [lower_C, upper_C], each end a one-sided bound at C.
        decision: ``pass``, ``fail``, ``undecided`` or ``empty`` (an empty running
            intersection of an ``until`` run's sequence: no verdict).
        exact: whether the interval is exact for the design (else approximate).
        side: ``max`` or ``min``: the limit the quantile is taken at.
        level: the quantile's level (1 − target for ``max``, target for ``min``).
        limit: that limit's value.
        quantile_samples_needed: samples from which both quantile bounds exist.
        samples_needed: samples the observed rate needs to decide by the interval that
            decides (= samples if decided, NaN if the rate equals the target).
        success_run: failure-free samples that pass by the interval that decides
            (⌈ln(1 − C)/ln(1 − target)⌉ for a fixed count; an ``until`` run's sequence needs
            more, counted in whole batches).
        output: the output and its selection, as text (``omega[mode=0]``).
        units: the output's unit (:func:`mcchain.ensemble.units.output_units`).
        minimum, maximum: the requirement's limits (NaN: none).
        observed_min, observed_max: the smallest and largest finite value over the defined
            samples (NaN if none).
        sequential: whether the interval is an ``until`` run's confidence sequence.
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
    units: str = ""
    minimum: float = math.nan
    maximum: float = math.nan
    observed_min: float = math.nan
    observed_max: float = math.nan
    sequential: bool = False

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


def output_label(requirement: Requirement) -> str:
    """``omega[mode=0]``: a requirement's output and selection as text."""
    if not requirement.select:
        return requirement.output
    inner = ",".join(f"{k}={v}" for k, v in requirement.select.items())
    return f"{requirement.output}[{inner}]"


def met_of(
    ds: xr.Dataset, requirement: Requirement, values: np.ndarray | None = None
) -> np.ndarray:
    """``requirement_met`` of one requirement, recomputed from the Dataset's values and
    ``status`` (:func:`mcchain.decision.requirements.dataset_requirement_met`): what a run
    stores, and right for a run stored before a failure bit decided. ``values`` is unused
    (kept for callers that pass it)."""
    return dataset_requirement_met(ds, requirement)


def quantile_side(requirement: Requirement, values: np.ndarray) -> str:
    """``max`` or ``min``: the limit the quantile is taken at (with both, the one broken
    more often; ties: ``max``)."""
    if requirement.min is None:
        return "max"
    if requirement.max is None:
        return "min"
    with np.errstate(invalid="ignore"):
        above = int(np.sum(values > requirement.max))
        below = int(np.sum(values < requirement.min))
    return "min" if below > above else "max"


def _limit(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _exact_decimal(x: float) -> Fraction:
    return Fraction(repr(float(x)))


def summarize_requirement(
    requirement: Requirement,
    values: np.ndarray,
    met: np.ndarray,
    design: str | None,
    *,
    units: str = "",
    sequential: Mapping[str, Any] | None = None,
) -> RequirementSummary:
    """The summary of one requirement.

    Args:
        values: (nsample,) the values the requirement reads
            (:func:`mcchain.decision.requirements.decision_values`): NaN where the sample is
            undefined, +inf for an event that never happened.
        met: (nsample,) ``requirement_met`` (1 met, 0 failed).
        design: the sampling design (None without ``[sample]``).
        units: the output's unit, for the words.
        sequential: an ``until`` run's ``sequential`` settings (``batch``): the interval is
            its confidence sequence over the looks; None: a fixed count.
    """
    values = np.asarray(values, dtype=np.float64)
    failed = np.asarray(met) == 0
    n = int(values.size)
    failures = int(np.sum(failed))
    undefined = int(np.sum(np.isnan(values)))
    confidence, target = float(requirement.confidence), float(requirement.target)
    interval: Interval
    if sequential is None:

        def interval(k: int, m: int) -> tuple[float, float]:
            return one_sided_bounds(k, m, confidence)

        lo, hi = interval(failures, n)
        batch = 1
    else:
        batch = int(sequential["batch"])

        def interval(k: int, m: int) -> tuple[float, float]:
            lower, upper = confidence_sequence(np.asarray(k), np.asarray(m), confidence, target)
            return float(lower), float(upper)

        looks = sequential.get("looks") or ()
        lo, hi = sequential_bounds(failed, batch, confidence, target, looks)
    side = quantile_side(requirement, values)
    if side == "max":
        level, limit, worst = 1 - _exact_decimal(target), requirement.max, math.inf
    else:
        level, limit, worst = _exact_decimal(target), requirement.min, -math.inf
    # an undefined sample counts beyond the limit, as it counts as a failure
    q = quantile_bounds(np.where(np.isnan(values), worst, values), level, confidence)
    finite = values[np.isfinite(values)]
    return RequirementSummary(
        name=requirement.name,
        samples=n,
        failures=failures,
        undefined=undefined,
        p_fail=failures / n if n else math.nan,
        p_lower=lo,
        p_upper=hi,
        confidence=confidence,
        target=target,
        decision=verdict(lo, hi, target),
        exact=design in EXACT_DESIGNS,
        quantile=q.value,
        quantile_lower=q.lower,
        quantile_upper=q.upper,
        side=side,
        level=float(level),
        limit=_limit(limit),
        quantile_samples_needed=q.samples_needed,
        samples_needed=_whole_batches(
            samples_to_decide(failures, n, target, confidence, interval=interval), batch
        ),
        success_run=_whole_batches(
            samples_to_decide(0, 0, target, confidence, interval=interval), batch
        ),
        output=output_label(requirement),
        units=units,
        minimum=_limit(requirement.min),
        maximum=_limit(requirement.max),
        observed_min=float(finite.min()) if finite.size else math.nan,
        observed_max=float(finite.max()) if finite.size else math.nan,
        sequential=sequential is not None,
    )


def _whole_batches(count: float, batch: int) -> float:
    """``count`` rounded up to the next look of a run that looks every ``batch`` samples."""
    return count if math.isnan(count) else float(math.ceil(count / batch) * batch)


def summarize(ds: StoredEnsemble) -> list[RequirementSummary]:
    """Every requirement of a stored ensemble, summarized ([] without requirements).

    Each requirement reads its output with the failure bits of ``status`` (a failed sample
    fails, undefined) and the event-time rule
    (:func:`mcchain.decision.requirements.requirement_decision_values`). A run that added
    samples until decided (``[sample] until``) reports the interval that kept its confidence
    over its looks (:func:`mcchain.decision.sequential.sequential_bounds`), the verdict and
    the sample counts from it; the quantile is the same as for a fixed count.
    """
    design = design_of(ds)
    sequential = sequential_settings(ds.attrs)
    defined = defined_mask(ds)
    out = []
    for requirement in stored_requirements(ds):
        raw = requirement_values(ds, requirement)
        values = decision_values(raw, defined, requirement.output)
        met = requirement_met(raw, requirement, defined)
        units = output_units(requirement.output, requirement.select, ds[requirement.output].attrs)
        out.append(
            summarize_requirement(
                requirement, values, met, design, units=units, sequential=sequential
            )
        )
    return out


# -- words ---------------------------------------------------------------------------------
def _g(x: float, digits: int = 4) -> str:
    return "NaN" if isinstance(x, float) and math.isnan(x) else f"{x:.{digits}g}"


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


def limit_text(s: RequirementSummary) -> str:
    """The requirement as written, with units: ``peak_contact_force[joint=B] <= 5000 N (5
    kN)``, or ``0.001 s (1 ms) <= ... <= 0.02 s (20 ms)`` with both limits."""
    low, high = (format_quantity(x, s.units) for x in (s.minimum, s.maximum))
    if not math.isnan(s.minimum) and not math.isnan(s.maximum):
        return f"{low} <= {s.output} <= {high}"
    if not math.isnan(s.maximum):
        return f"{s.output} <= {high}"
    return f"{s.output} >= {low}"


def interval_name(s: RequirementSummary) -> str:
    """How [p_lower, p_upper] is named: each end a one-sided bound at C."""
    c = _pct(s.confidence)
    if s.sequential:
        return f"{c} sequential bounds (each one-sided, valid at every look)"
    return f"{c} bounds (each one-sided; together a {_pct(2 * s.confidence - 1)} interval)"


def all_fail_warning(s: RequirementSummary) -> str | None:
    """A ``warning:`` line when every sample fails the requirement (often a limit in the
    wrong unit: ``max = 5.0`` on a force in N), with the range the output took; None
    otherwise."""
    if s.samples == 0 or s.failures < s.samples:
        return None
    head = f"warning: requirement {s.name}: every one of the {s.samples} samples fails it"
    if math.isnan(s.observed_min):
        return (
            f"{head} ({limit_text(s)}): no sample has a value to compare (all {s.undefined} "
            "undefined: a failure bit in status)"
        )
    units = f" (the output is in {pretty_units(s.units)})" if s.units else ""
    undefined = f"; {s.undefined} undefined" if s.undefined else ""
    return (
        f"{head}: the limit is {limit_text(s)}{units}, the samples' values range over "
        f"{format_quantity(s.observed_min, s.units)} to {format_quantity(s.observed_max, s.units)}"
        f"{undefined}: is the limit written in the output's unit?"
    )


def requirement_lines(s: RequirementSummary, design: str | None) -> list[str]:
    """What one requirement's row says, in words (every limit, quantile and bound with the
    output's unit)."""
    c = _pct(s.confidence)
    words = {
        "pass": f"PASS: P(fail) <= {_g(s.target)} shown at {c}",
        "fail": f"FAIL: P(fail) > {_g(s.target)} shown at {c}",
        UNDECIDED: f"UNDECIDED: the bounds enclose the target {_g(s.target)}",
        EMPTY: "NO VERDICT: the running intersection of the sequential interval is empty "
        f"(lower bound {_g(s.p_lower)} > upper bound {_g(s.p_upper)}): the looks contradict "
        "each other (an event of probability <= 1 - C, or samples that are not independent)",
    }[s.decision]
    if s.exact:
        approx = ""
    elif design is None:
        approx = " [approximate: no [sample], the instances are all the same]"
    else:
        approx = f" [approximate: design {design!r} does not draw independent samples]"
    lines = [
        f"requirement {s.name} ({limit_text(s)}; target {_g(s.target)}, confidence "
        f"{_g(s.confidence)}): {words}{approx}",
        f"  {s.failures} of {s.samples} samples failed ({s.undefined} undefined: a failure bit "
        f"in status); P(fail) = {_g(s.p_fail)}, {interval_name(s)} "
        f"[{_g(s.p_lower)}, {_g(s.p_upper)}]",
    ]
    bound = "upper" if s.side == "max" else "lower"
    q_text = (
        f"  {_g(100 * s.level)} % quantile of {s.output}: {format_quantity(s.quantile, s.units)}, "
        f"{c} bounds [{format_quantity(s.quantile_lower, s.units)}, "
        f"{format_quantity(s.quantile_upper, s.units)}]"
    )
    if s.undefined:
        q_text += f" (the {s.undefined} undefined counted beyond the limit)"
    if math.isnan(s.quantile_lower) or math.isnan(s.quantile_upper):
        q_text += (
            f" (too few samples for its {bound if math.isnan(s.quantile_upper) else 'other'} "
            f"bound: {s.quantile_samples_needed} needed)"
        )
    lines.append(q_text)
    by = " (whole batches, by the sequential interval)" if s.sequential else ""
    if s.decision == UNDECIDED:
        if math.isnan(s.samples_needed):
            lines.append("  the observed rate equals the target: no sample count decides it")
        else:
            lines.append(
                f"  to decide at the observed rate: about {int(s.samples_needed)} samples "
                f"({int(s.samples_needed) - s.samples} more){by}"
            )
    if s.failures == 0 and not math.isnan(s.success_run):
        figure = (
            f"{int(s.success_run)} failure-free samples pass at {c}{by}"
            if s.sequential
            else f"the success-run figure ceil(ln(1 - C)/ln(1 - p)) = {int(s.success_run)} "
            f"failure-free samples show P(fail) <= {_g(s.target)} at {c}"
        )
        lines.append(f"  no failure: {figure}")
    warning = all_fail_warning(s)
    if warning is not None:
        lines.append(warning)
    return lines


def family_line(summaries: list[RequirementSummary]) -> str | None:
    """The statement over several requirements' verdicts together (Bonferroni); None for
    fewer than two."""
    if len(summaries) < 2:
        return None
    k = len(summaries)
    together = family_confidence([s.confidence for s in summaries])
    sum_text = (
        f"1 - {k} x {_g(1 - summaries[0].confidence)}"
        if len({s.confidence for s in summaries}) == 1
        else "1 - sum(1 - C)"
    )
    if together <= 0:
        return (
            f"together: {k} verdicts, each wrong with probability at most 1 - C; "
            f"{sum_text} = {_g(together)}: nothing is claimed for all of them at once"
        )
    return (
        f"together: all {k} verdicts hold at once with probability >= {sum_text} = "
        f"{_g(together)} (Bonferroni, whatever the dependence between the requirements)"
    )


def summary_lines(
    summaries: list[RequirementSummary],
    rows: list[AllocationRow],
    design: str | None,
    sequential: Mapping[str, Any] | None = None,
    boxes: list[BoxRow] | None = None,
) -> list[str]:
    """``requirements.txt`` (and the end of ``mcchain run``): every requirement in words,
    its allocation (``boxes``: the box over the parameters too), and the interval's
    validity for the design."""
    lines = []
    for s in summaries:
        lines += requirement_lines(s, design)
        alloc = allocation_lines(rows, s.name, boxes)
        if alloc:
            lines.append(
                "  tolerance allocation (each parameter alone, the others as sampled; bounds "
                "valid over every cut tried):"
            )
            lines += alloc
    return lines + validity_lines(summaries, design, sequential)


def validity_lines(
    summaries: list[RequirementSummary],
    design: str | None,
    sequential: Mapping[str, Any] | None = None,
) -> list[str]:
    """What the verdicts claim: the family statement over several requirements, and which
    interval the design gets ([] without requirements)."""
    lines = []
    together = family_line(summaries)
    if together is not None:
        lines.append(together)
    if sequential is None and any(s.sequential for s in summaries):
        sequential = {"method": "confidence sequence", "batch": "a batch"}  # a caller without it
    if summaries and sequential is not None:
        how = (
            f"looked at every {sequential['batch']} samples since the run of "
            f"{sequential['extended_from']} was extended (a Clopper-Pearson interval does not "
            "hold for a run extended until it decides)"
            if sequential.get("extended_from")
            else f"samples added {sequential['batch']} at a time until decided"
        )
        lines.append(
            f"intervals: sequential ({sequential['method']}), {how}: each bound one-sided at "
            "the requirement's confidence C and valid whenever the run stopped; PASS iff the "
            "upper bound <= target, FAIL iff the lower bound > target: each verdict is wrong "
            "with probability at most 1 - C"
            + ("" if design in EXACT_DESIGNS else f", APPROXIMATE for design {design!r}")
        )
    elif summaries:
        if design in EXACT_DESIGNS:
            lines.append(
                "intervals: exact Clopper-Pearson bounds (independent random draws), each "
                "one-sided at the requirement's confidence C; PASS iff the upper bound <= "
                "target, FAIL iff the lower bound > target: each verdict is wrong with "
                "probability at most 1 - C"
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
def write_requirements(ds: StoredEnsemble, folder: Path) -> list[Path]:
    """``requirements.csv``, ``allocation.csv``, ``requirements.txt``, then
    ``allocation-box.csv`` (two or more sampled parameters), ``whatif.csv`` and
    ``whatif.png`` into ``folder``; returns their paths in that order."""
    from mcchain.decision.whatif import write_whatif
    from mcchain.ensemble.io import write_text_atomic

    summaries = summarize(ds)
    rows = allocations(ds)
    boxes = box_allocations(ds)
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / "requirements.csv", folder / "allocation.csv", folder / "requirements.txt"]
    write_csv(paths[0], REQUIREMENT_COLUMNS, [s.row() for s in summaries])
    write_csv(paths[1], ALLOCATION_COLUMNS, [r.row() for r in rows])
    lines = summary_lines(summaries, rows, design_of(ds), sequential_settings(ds.attrs), boxes)
    write_text_atomic(paths[2], "\n".join(lines) + "\n")
    if boxes:
        paths.append(folder / "allocation-box.csv")
        write_csv(paths[-1], BOX_COLUMNS, [b.row() for b in boxes])
    return paths + write_whatif(ds, folder)


def export_requirements(run: str | Path) -> list[Path]:
    """``mcchain export RUN --requirements``: the files of :func:`write_requirements` into
    ``RUN/export/``.

    Raises:
        RunError: the run has no requirements.
    """
    from mcchain.errors import RunError
    from mcchain.runner.runs import open_stored_run, resolve_run, writable_folder

    folder = resolve_run(run)
    with open_stored_run(folder) as ds:  # closed after: the file is shared with later opens
        if not stored_requirements(ds):
            raise RunError(
                f"{run}: the run has no [[requirement]]: nothing to export with --requirements"
            )
        target = folder / "export"
        writable_folder(target, "--requirements")
        return write_requirements(ds, target)
