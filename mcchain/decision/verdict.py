"""``mcchain verdict RUN``: the requirements' verdicts as a table, and an exit code for
scripts and CI gates.

Exit codes (:func:`exit_code`): 0 when every requirement passes, 1 when one fails, 4 when
none fails but one is undecided (or has no verdict: an empty running intersection). A bad
RUN (no folder, not completed, unreadable) or a run without requirements is one line on
stderr and exit 2 (:class:`mcchain.errors.RunError`, turned into the line by the CLI).

The table has one row per requirement: its limit with the output's unit, samples, failures,
undefined samples, P(fail), the bounds [lower_C, upper_C] (each one-sided at the
requirement's confidence C), the target and the verdict; below it the ``warning:`` lines of
requirements every sample fails, the family statement over several requirements and what
the intervals claim (:func:`mcchain.decision.summary.validity_lines`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.decision.stats import EMPTY, FAIL, UNDECIDED
from mcchain.errors import RunError

if TYPE_CHECKING:
    from mcchain.decision.summary import RequirementSummary

EXIT_PASS = 0
EXIT_FAIL = 1
EXIT_UNDECIDED = 4
"""``mcchain verdict``: every requirement passes / one fails / none fails, one undecided."""


def exit_code(decisions: Sequence[str]) -> int:
    """1 if any decision is ``fail``, else 4 if any is ``undecided`` or ``empty``, else 0."""
    if FAIL in decisions:
        return EXIT_FAIL
    if UNDECIDED in decisions or EMPTY in decisions:
        return EXIT_UNDECIDED
    return EXIT_PASS


@dataclass(frozen=True)
class VerdictTable:
    """The verdicts of a run's requirements."""

    summaries: list[RequirementSummary]
    design: str | None
    sequential: Mapping[str, Any] | None
    notes: Sequence[str] = ()
    """``note:`` lines about the values counted (the failed samples a retry solved)."""

    @property
    def exit_code(self) -> int:
        return exit_code([s.decision for s in self.summaries])

    def lines(self) -> list[str]:
        """The table, then the warnings, the family statement and the intervals' claim."""
        from mcchain.decision.summary import all_fail_warning, limit_text, validity_lines

        header = ["requirement", "limit", "samples", "failed", "undefined", "P(fail)"]
        header += ["bounds (one-sided each)", "target", "verdict"]
        table: list[tuple[str, ...]] = [tuple(header)]
        for s in self.summaries:
            bounds = f"[{s.p_lower:.4g}, {s.p_upper:.4g}] at {100 * s.confidence:.3g} %"
            table.append(
                (
                    s.name,
                    limit_text(s),
                    str(s.samples),
                    str(s.failures),
                    str(s.undefined),
                    f"{s.p_fail:.4g}",
                    bounds,
                    f"{s.target:g}",
                    _verdict_word(s),
                )
            )
        widths = [max(len(row[i]) for row in table) for i in range(len(header))]
        numeric = {2, 3, 4, 5, 7}
        text = [
            "  ".join(
                c.rjust(w) if i in numeric else c.ljust(w)
                for i, (c, w) in enumerate(zip(row, widths, strict=True))
            ).rstrip()
            for row in table
        ]
        warnings = [w for s in self.summaries if (w := all_fail_warning(s)) is not None]
        notes = [f"note: {line}" for line in self.notes]
        return (
            text + warnings + notes + validity_lines(self.summaries, self.design, self.sequential)
        )


def _verdict_word(s: RequirementSummary) -> str:
    word = "NO VERDICT (empty interval)" if s.decision == EMPTY else s.decision.upper()
    return word if s.exact else f"{word} (approximate)"


def run_verdict(run: str | Path) -> VerdictTable:
    """The verdict table of a completed run.

    Raises:
        RunError: no such run, a run not completed or unreadable, a run without requirements.
    """
    from mcchain.decision.requirements import stored_requirements
    from mcchain.decision.summary import design_of, summarize
    from mcchain.decision.until import sequential_settings
    from mcchain.runner.runs import COMPLETED, ENSEMBLE, open_stored_run, read_record, resolve_run

    folder = resolve_run(run)
    record = read_record(folder)
    if record.get("status") != COMPLETED or not (folder / ENSEMBLE).is_file():
        raise RunError(f"verdict: {run} is not completed (mcchain run --resume {run})")
    try:  # as the run's own summary reads it: netCDF4 alone, xarray where a variable decodes
        ds = open_stored_run(folder)
    except (OSError, ValueError) as exc:
        raise RunError(f"verdict: {folder / ENSEMBLE} is unreadable ({exc})") from None
    with ds:
        if not stored_requirements(ds):
            raise RunError(f"verdict: {run} has no [[requirement]]: nothing to decide")
        retried = (record.get("retries") or {}).get("line")
        notes = [retried] if retried else []
        return VerdictTable(summarize(ds), design_of(ds), sequential_settings(ds.attrs), notes)
