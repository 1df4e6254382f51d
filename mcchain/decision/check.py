"""``mcchain check RUN [--tighten F] [--samples M]``: the integrator's share of the verdict.

Peaks after impacts are sensitive to the integrator's accuracy, and a sample near a limit
may meet it at one tolerance and fail it at another. The check re-solves samples with the
time integration F times tighter (default 10: ``rtol`` and ``atol`` divided by F for the
adaptive methods, ``dt`` for the fixed-step ones) and gives the verdict again on the
tightened values. Which samples (:func:`plan_check`):

1. **spread** — M samples spread evenly over the run (indices round(i (n − 1)/(M − 1))).
   Their changes give each requirement's error scale ε: the largest change over them,
   relative to max(|value|, |limit|) (a change of state — failed to solved, an event that
   happens at one tolerance and never at the other — is infinitely large: every sample is
   then re-solved). Default M: the count that makes the flip bound below a tenth of the
   narrowest interval, :func:`spread_count` (at least 64, at most the run).
2. **near** — every other sample a change ``BAND`` (3) times ε could flip: |value − limit| <=
   3 ε max(|value|, |limit|), and every undefined sample (a failure bit: only a re-solve tells
   whether it fails).

Per requirement: the verdict on the run's values and on the values with the re-solved ones
replaced (``verdict_tightened``, by the run's own interval: fixed-count or sequential), the
flips (``requirement_met`` changed) and the spread of the changes. **The flip bound** for
the samples not re-solved: a flip there needs a change more than 3 times the largest of M
spread samples; the share of samples whose change exceeds the largest of M exchangeable
draws is below 1 − (1 − C)^(1/M) with probability C (an exact one-sided binomial bound:
0 such changes in M, :func:`mcchain.decision.stats.one_sided_bounds`). 0 when every sample
was re-solved. When the tightened verdict differs, the flips or the bound are not small
(:data:`SMALL` of the interval width), one ``advice:`` line says which tolerance to use.

Written: ``RUN/export/check.csv`` (:data:`CHECK_COLUMNS`) and the tightened per-sample
values ``RUN/check/tighten-<F>.nc`` (sample = the run's indices); the run's
``ensemble.nc`` is never touched. With F = 1 the re-solve reproduces the run bit for bit
(the kernels compute each sample alone). Without requirements: the spread samples only, one
row per per-sample output.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.errors import RunError

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.decision.summary import RequirementSummary
    from mcchain.runner.job import Job
    from mcchain.scene.study import Requirement

DEFAULT_TIGHTEN = 10.0
"""F when ``--tighten`` is not given."""
DEFAULT_SAMPLES = 64
"""The fewest spread samples re-solved (and all of them without requirements)."""
BAND = 3.0
"""Samples within BAND × ε of a limit are re-solved (ε: the largest change seen)."""
SMALL = 0.1
"""A flip share is small when below this fraction of the interval's width."""

CHECK_COLUMNS = (
    "requirement",
    "samples",
    "flips",
    "abs_diff_median",
    "abs_diff_max",
    "rel_diff_median",
    "rel_diff_max",
    "tighten",
    "near",
    "verdict",
    "verdict_tightened",
    "flip_bound",
)
"""Columns of ``export/check.csv``."""


@dataclass(frozen=True)
class CheckRow:
    """One line of the check: a requirement (or, without requirements, an output).

    Attributes:
        samples: samples re-solved (spread + near, over every requirement).
        flips: re-solved samples whose ``requirement_met`` changed (NaN for an output).
        abs_diff_*, rel_diff_*: median and max of |tightened − run| (and over |run|) on the
            re-solved samples where both are finite.
        near: this requirement's samples within the band (or undefined), spread ones apart.
        verdict, verdict_tightened: on the run's values, and with the re-solved ones
            replaced ("" for an output).
        flip_bound: the share of the samples not re-solved that may flip, one-sided at the
            requirement's confidence (0: every sample re-solved; NaN for an output).
    """

    requirement: str
    samples: int
    flips: float
    abs_diff_median: float
    abs_diff_max: float
    rel_diff_median: float
    rel_diff_max: float
    tighten: float
    near: int = 0
    verdict: str = ""
    verdict_tightened: str = ""
    flip_bound: float = math.nan

    def row(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in CHECK_COLUMNS}


def spread_indices(nsample: int, count: int) -> np.ndarray:
    """``count`` sample indices spread evenly over ``0:nsample`` (all of them if fewer)."""
    if count >= nsample:
        return np.arange(nsample)
    if count == 1:
        return np.zeros(1, dtype=np.int64)
    return np.round(np.arange(count) * (nsample - 1) / (count - 1)).astype(np.int64)


def spread_count(widths: Sequence[float], confidences: Sequence[float], nsample: int) -> int:
    """The default spread count: the fewest M whose flip bound 1 − (1 − C)^(1/M) is at most
    :data:`SMALL` of the narrowest interval (the success-run count for that share), at least
    :data:`DEFAULT_SAMPLES`, at most ``nsample``."""
    from mcchain.decision.stats import success_run_count

    need = DEFAULT_SAMPLES
    for width, confidence in zip(widths, confidences, strict=True):
        share = SMALL * width
        need = nsample if not 0 < share < 1 else max(need, success_run_count(share, confidence))
    return int(min(max(need, DEFAULT_SAMPLES), nsample))


def tightened_scene(scene: Any, factor: float) -> tuple[Any, str]:
    """The scene with ``[simulate]`` ``factor`` times tighter, and what changed, in words
    (:func:`mcchain.solvers.retry.tightened_simulate`)."""
    from mcchain.solvers.retry import tightened_simulate

    sim = getattr(scene, "simulate", None)
    if sim is None:
        raise RunError(
            "check: the run has no [simulate] (equilibria and modes are solved to Newton's "
            "tolerance): no time integration to tighten"
        )
    tight, said = tightened_simulate(sim, factor)
    return scene.model_copy(update={"simulate": tight}), said


def tolerance_text(scene: Any) -> str:
    """The integration settings a scene runs at: ``rtol 1e-08, atol 1e-11`` or ``dt 1e-05 s``."""
    from mcchain.solvers.retry import ADAPTIVE_METHODS

    sim = scene.simulate
    if sim.method in ADAPTIVE_METHODS:
        return f"rtol {sim.rtol:g}, atol {sim.atol:g}"
    return f"dt {sim.dt:g} s"


def _differences(base: np.ndarray, tight: np.ndarray) -> tuple[float, float, float, float]:
    """Median and max of |tight − base| and of |tight − base| / |base| over the elements
    where both are finite (NaN if none; a zero base value gives no relative difference)."""
    base = np.asarray(base, dtype=np.float64).ravel()
    tight = np.asarray(tight, dtype=np.float64).ravel()
    both = np.isfinite(base) & np.isfinite(tight)
    if not both.any():
        return (math.nan,) * 4
    diff = np.abs(tight[both] - base[both])
    scale = np.abs(base[both])
    rel = diff[scale > 0] / scale[scale > 0]
    rel_median = float(np.median(rel)) if rel.size else math.nan
    rel_max = float(np.max(rel)) if rel.size else math.nan
    return float(np.median(diff)), float(np.max(diff)), rel_median, rel_max


# -- which samples: the error scale and the band ---------------------------------------------
def nearest_limit(values: np.ndarray, requirement: Requirement) -> np.ndarray:
    """Per sample, the requirement's limit nearest to its value (the only one, with one)."""
    x = np.asarray(values, dtype=np.float64)
    if requirement.min is None or requirement.max is None:
        only = requirement.max if requirement.min is None else requirement.min
        return np.full(x.shape, float(only))  # type: ignore[arg-type]
    lo, hi = float(requirement.min), float(requirement.max)
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(x - lo) <= np.abs(x - hi), lo, hi)


def relative_changes(base: np.ndarray, tight: np.ndarray, requirement: Requirement) -> np.ndarray:
    """|tight − base| / max(|base|, |limit|) per sample, from the values a requirement reads
    (NaN: undefined, +inf: never). Both undefined or both the same infinity: 0. One
    undefined, or one infinite and the other not: +inf (a change of state has no size)."""
    base = np.asarray(base, dtype=np.float64)
    tight = np.asarray(tight, dtype=np.float64)
    scale = np.maximum(np.abs(base), np.abs(nearest_limit(base, requirement)))
    with np.errstate(invalid="ignore", divide="ignore"):
        change = np.abs(tight - base)
        rel = np.where(change == 0, 0.0, change / scale)
    same = (np.isnan(base) & np.isnan(tight)) | (base == tight)
    return np.where(same, 0.0, np.where(np.isnan(rel), np.inf, rel))


def near_limit(values: np.ndarray, requirement: Requirement, scale: float) -> np.ndarray:
    """(nsample,) bool: the samples a change of ``BAND × scale`` × max(|value|, |limit|)
    could move across a limit, and the undefined ones (NaN). ``scale`` = inf: all."""
    x = np.asarray(values, dtype=np.float64)
    if math.isinf(scale):
        return np.ones(x.shape, dtype=bool)
    limit = nearest_limit(x, requirement)
    with np.errstate(invalid="ignore"):
        margin = np.abs(x - limit)
        near = margin <= BAND * scale * np.maximum(np.abs(x), np.abs(limit))
    # an event that never happened (+inf) is no distance from a finite limit a change of
    # this size could bridge; an undefined sample (NaN) is near: only a re-solve tells
    return (near & np.isfinite(x)) | np.isnan(x)


# -- the check ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class RequirementCheck:
    """One requirement's check, for the words: the two summaries and the flip bound."""

    run: RequirementSummary
    tightened: RequirementSummary
    resolved: int
    spread: int
    flips: int
    flip_bound: float


@dataclass(frozen=True)
class CheckResult:
    """What :func:`check_run` found and wrote."""

    rows: list[CheckRow]
    changed: str
    csv: Path
    values: Path
    checks: list[RequirementCheck]
    nsample: int = 0
    spread: int = 0
    tightened_tolerance: str = ""
    run_tolerance: str = ""

    def lines(self) -> list[str]:
        """The printed table, then per requirement the two verdicts, the flip bound and,
        where needed, the advice."""
        header = ["requirement", "samples", "flips", "|diff| median", "|diff| max"]
        header += ["rel median", "rel max"]
        if self.checks:
            header += ["near", "verdict", "tightened"]
        table = [tuple(header)]
        for r in self.rows:
            flips = "-" if math.isnan(r.flips) else str(int(r.flips))
            cells = [r.requirement, str(r.samples), flips]
            cells += [f"{x:.3g}" for x in (r.abs_diff_median, r.abs_diff_max)]
            cells += [f"{x:.3g}" for x in (r.rel_diff_median, r.rel_diff_max)]
            if self.checks:
                cells += [str(r.near), r.verdict, r.verdict_tightened]
            table.append(tuple(cells))
        widths = [max(len(row[i]) for row in table) for i in range(len(header))]
        text = [
            "  ".join(
                c.rjust(w) if 0 < i < 7 else c.ljust(w)
                for i, (c, w) in enumerate(zip(row, widths, strict=True))
            ).rstrip()
            for row in table
        ]
        head = f"check: {self.changed}"
        if self.rows:
            head += f" ({self.rows[0].tighten:g}x tighter)"
        if self.checks:
            near = self.rows[0].samples - self.spread
            head += (
                f"; re-solved {self.rows[0].samples} of {self.nsample} samples: {self.spread} "
                f"spread evenly, {near} more near a limit or undefined"
            )
        return [head, *text, *[line for c in self.checks for line in self._words(c)]]

    def _words(self, c: RequirementCheck) -> list[str]:
        def said(s: RequirementSummary) -> str:
            return f"{s.decision.upper()} [{s.p_lower:.4g}, {s.p_upper:.4g}]"

        unchecked = self.nsample - c.resolved
        conf = f"{100 * c.run.confidence:.3g} %"
        kind = ", sequential" if c.tightened.sequential else ""
        if unchecked:
            bound = (
                f"the {unchecked} samples not re-solved flip with probability <= "
                f"{c.flip_bound:.3g} (one-sided {conf}: a flip there needs a change over "
                f"{BAND:g}x the largest of the {c.spread} spread samples')"
            )
        else:
            bound = "every sample re-solved: no flip left unseen"
        lines = [
            f"{c.run.name}: run {said(c.run)} -> tightened {said(c.tightened)} "
            f"({conf} one-sided bounds{kind}); {c.flips} of {c.resolved} re-solved flipped; "
            + bound
        ]
        advice = self._advice(c)
        if advice:
            lines.append(advice)
        return lines

    def _advice(self, c: RequirementCheck) -> str | None:
        """One line when the tolerance matters: which one to use, and why."""
        width = max(c.tightened.p_upper - c.tightened.p_lower, 0.0)
        small = SMALL * width
        flip_share = c.flips / self.nsample if self.nsample else 0.0
        tight = f"use {self.tightened_tolerance} (the check's) and check that run again"
        if c.tightened.decision != c.run.decision:
            return (
                f"advice: {c.run.name}: {tight}: the verdict changes "
                f"({c.run.decision} -> {c.tightened.decision})"
            )
        if flip_share > small:
            return (
                f"advice: {c.run.name}: {tight}: {c.flips} flips ({flip_share:.3g} of the run) "
                f"against an interval {width:.3g} wide"
            )
        if c.flip_bound > small:
            from mcchain.decision.stats import success_run_count

            more = min(success_run_count(small, c.run.confidence), self.nsample) if small else 0
            again = (
                f"check with --samples {more} to bound it by {small:.3g}"
                if small and more < self.nsample
                else f"check with --samples {self.nsample} (all of them)"
            )
            return (
                f"advice: {c.run.name}: keep {self.run_tolerance} (no flip changes the verdict), "
                f"but the bound {c.flip_bound:.3g} is not small against the interval "
                f"({width:.3g} wide): {again}, or use {self.tightened_tolerance}"
            )
        return None


def check_run(
    run: str | Path,
    tighten: float = DEFAULT_TIGHTEN,
    samples: int | None = None,
    *,
    solve: Any = None,
) -> CheckResult:
    """Re-solve a completed run's samples ``tighten`` times tighter and give the verdicts
    again (see the module docstring). ``samples``: the spread count (default
    :func:`spread_count`); ``solve``: the chunk solver (default the real one)."""
    from mcchain.decision.summary import write_csv
    from mcchain.runner.runs import COMPLETED, ENSEMBLE, open_run, read_record, resolve_run

    if not (isinstance(tighten, (int, float)) and math.isfinite(tighten) and tighten >= 1):
        raise RunError(f"--tighten: must be a number >= 1, got {tighten!r}")
    if samples is not None and (not isinstance(samples, int) or samples < 1):
        raise RunError(f"--samples: must be an integer >= 1, got {samples!r}")
    folder = resolve_run(run)
    record = read_record(folder)
    if record.get("status") != COMPLETED or not (folder / ENSEMBLE).exists():
        raise RunError(f"check: {run} is not completed (mcchain run --resume {run})")
    job = _run_job(folder, record)
    scene, changed = tightened_scene(job.scene, float(tighten))
    with open_run(folder) as ds:
        solver = _Resolver(job, float(tighten), solve, _solved_by(ds))
        from mcchain.decision.requirements import stored_requirements

        requirements = stored_requirements(ds)
        if requirements:
            rows, checks, spread = _check_requirements(
                ds, requirements, solver, samples, float(tighten)
            )
        else:
            index = spread_indices(job.nsample, samples or DEFAULT_SAMPLES)
            rows = compare_outputs(ds, index, solver.values(index), float(tighten))
            checks, spread = [], int(index.size)
        tight = _as_dataset(ds, solver.index(), solver.values(solver.index()))
    values = _write_values(tight, folder / "check" / f"tighten-{tighten:g}.nc")
    path = folder / "export" / "check.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_csv(path, CHECK_COLUMNS, [r.row() for r in rows])
    return CheckResult(
        rows,
        changed,
        path,
        values,
        checks,
        nsample=job.nsample,
        spread=spread,
        tightened_tolerance=tolerance_text(scene),
        run_tolerance=tolerance_text(job.scene),
    )


def _solved_by(ds: xr.Dataset) -> np.ndarray | None:
    """What solved each sample of a run that retried its failures (None: it did not)."""
    from mcchain.solvers.retry import SOLVED_BY

    return ds[SOLVED_BY].values if SOLVED_BY in ds.data_vars else None


class _Resolver:
    """Re-solves samples of a run ``factor`` times tighter, chunk by chunk, keeping only the
    per-sample outputs (and ``requirement_met``), and remembers what it solved. A sample a
    retry solved (``solved_by``, :mod:`mcchain.solvers.retry`) is tightened from the
    settings that solved it, the others from the scene's."""

    def __init__(
        self, job: Job, factor: float, solve: Any, solved_by: np.ndarray | None = None
    ) -> None:
        from mcchain.decision.requirements import job_requirements
        from mcchain.runner.executors import default_solve

        self.job, self.factor = job, factor
        self.solve = solve or default_solve()
        self.requirements = job_requirements(job)
        self.solved_by = solved_by
        self.solved: dict[int, dict[str, np.ndarray]] = {}

    def add(self, index: np.ndarray) -> None:
        from mcchain.solvers.retry import attempt_scene

        todo = np.array([i for i in np.asarray(index).tolist() if i not in self.solved], int)
        codes = np.zeros(todo.size, int) if self.solved_by is None else self.solved_by[todo]
        for code in np.unique(codes).tolist():
            scene, _ = tightened_scene(attempt_scene(self.job.scene, code), self.factor)
            self._add(todo[codes == code], scene)

    def _add(self, todo: np.ndarray, scene: Any) -> None:
        from mcchain.ensemble.outputs import model_output_variables
        from mcchain.ensemble.registry import VARIABLES, coerce_outputs

        specs = {**VARIABLES, **model_output_variables(self.job.model)}  # the [[output]]s too
        step = max(int(self.job.chunk_size), 1)
        for start in range(0, todo.size, step):
            part = todo[start : start + step]
            out = coerce_outputs(
                self.solve(self.job.model.take(part), scene), self.job.history_dtype,
                model_output_variables(self.job.model),
            )  # fmt: skip
            if self.requirements is not None:
                out = self.requirements.add_to(out)
            dims = {k: specs[k].dims for k in out if k in specs}
            keep = {k: v for k, v in out.items() if k in dims and "time" not in dims[k]}
            for j, i in enumerate(part.tolist()):
                self.solved[i] = {k: v[j] for k, v in keep.items()}

    def index(self) -> np.ndarray:
        return np.array(sorted(self.solved), dtype=np.int64)

    def values(self, index: np.ndarray) -> dict[str, np.ndarray]:
        """The per-sample outputs of ``index`` (solving those not solved yet), stacked."""
        self.add(index)
        rows = [self.solved[int(i)] for i in np.asarray(index)]
        if not rows:
            return {}
        return {k: np.stack([r[k] for r in rows]) for k in rows[0]}


def _check_requirements(
    ds: xr.Dataset,
    requirements: Sequence[Requirement],
    solver: _Resolver,
    samples: int | None,
    factor: float,
) -> tuple[list[CheckRow], list[RequirementCheck], int]:
    """The spread samples, the error scales, the near samples, and every requirement's
    verdict before and after (see the module docstring)."""
    from mcchain.decision.requirements import (
        decision_values,
        defined_mask,
        defined_samples,
        requirement_met,
        requirement_values,
    )
    from mcchain.decision.stats import one_sided_bounds
    from mcchain.decision.summary import summarize

    nsample = ds.sizes["sample"]
    run = {s.name: s for s in summarize(ds)}
    if samples is None:
        samples = spread_count(
            [run[r.name].p_upper - run[r.name].p_lower for r in requirements],
            [float(r.confidence) for r in requirements],
            nsample,
        )
    spread = spread_indices(nsample, samples)
    defined = defined_mask(ds)
    raw = {r.name: requirement_values(ds, r) for r in requirements}
    values = {r.name: decision_values(raw[r.name], defined, r.output) for r in requirements}

    def tightened(index: np.ndarray, requirement: Requirement) -> tuple[np.ndarray, np.ndarray]:
        out = solver.values(index)
        tight_ds = _as_dataset(ds, index, out)
        tight_raw = requirement_values(tight_ds, requirement)
        ok = defined_samples(out["status"])
        return tight_raw, ok

    near: dict[str, np.ndarray] = {}
    for r in requirements:
        tight_raw, ok = tightened(spread, r)
        tight_values = decision_values(tight_raw, ok, r.output)
        changes = relative_changes(values[r.name][spread], tight_values, r)
        scale = float(np.max(changes)) if changes.size else 0.0
        mask = near_limit(values[r.name], r, scale)
        mask[spread] = False
        near[r.name] = np.flatnonzero(mask)
    solver.add(np.unique(np.concatenate([spread, *near.values()])))
    index = solver.index()

    rows, checks = [], []
    for r in requirements:
        tight_raw, ok = tightened(index, r)
        all_raw, all_defined = raw[r.name].copy(), defined.copy()
        all_raw[index], all_defined[index] = tight_raw, ok
        met = requirement_met(raw[r.name], r, defined)
        met_t = requirement_met(all_raw, r, all_defined)
        tight_values = decision_values(all_raw, all_defined, r.output)
        after = _summary_like(run[r.name], r, tight_values, met_t, ds)
        flips = int(np.sum(met != met_t))
        bound = 0.0 if index.size >= nsample else one_sided_bounds(0, spread.size, r.confidence)[1]
        base, moved = values[r.name][index], tight_values[index]
        rows.append(
            CheckRow(
                r.name,
                int(index.size),
                flips,
                *_differences(base, moved),
                factor,
                near=int(near[r.name].size),
                verdict=run[r.name].verdict,
                verdict_tightened=after.verdict,
                flip_bound=bound,
            )
        )
        checks.append(
            RequirementCheck(run[r.name], after, int(index.size), int(spread.size), flips, bound)
        )
    return rows, checks, int(spread.size)


def _summary_like(
    summary: RequirementSummary,
    requirement: Requirement,
    values: np.ndarray,
    met: np.ndarray,
    ds: xr.Dataset,
) -> RequirementSummary:
    """The summary of ``requirement`` on tightened values, by the run's own interval."""
    from mcchain.decision.summary import design_of, summarize_requirement
    from mcchain.decision.until import sequential_settings

    return summarize_requirement(
        requirement,
        values,
        met,
        design_of(ds),
        units=summary.units,
        sequential=sequential_settings(ds.attrs),
    )


def compare_outputs(
    ds: xr.Dataset, index: np.ndarray, outputs: Mapping[str, np.ndarray], factor: float
) -> list[CheckRow]:
    """Without requirements: the differences of every per-sample output, one row each."""
    rows = []
    for name in sorted(outputs):
        if name not in ds.data_vars or name in ("status", "parameters"):
            continue
        dims = ds[name].dims
        if dims[0] != "sample" or "time" in dims or ds[name].dtype.kind not in "fiu":
            continue
        base = np.asarray(ds[name].isel(sample=index).values)
        rows.append(
            CheckRow(name, index.size, math.nan, *_differences(base, outputs[name]), factor)
        )
    return rows


def _as_dataset(ds: xr.Dataset, index: np.ndarray, outputs: Mapping[str, np.ndarray]) -> xr.Dataset:
    """The re-solved per-sample outputs as a Dataset laid out like ``ds`` (sample = the
    run's indices)."""
    import xarray as xr

    variables = {}
    for name, values in outputs.items():
        if name not in ds.data_vars:
            continue
        dims = ds[name].dims
        if dims[0] != "sample" or "time" in dims:
            continue
        variables[name] = xr.Variable(dims, np.asarray(values), ds[name].attrs)
    coords = {
        d: ds[d]
        for d in ds.coords
        if not {"sample", "time", "history_sample"} & set(ds[d].dims)  # per-sample only
    }
    out = xr.Dataset(variables, coords={**coords, "sample": np.asarray(index)})
    out.attrs = dict(ds.attrs)
    return out


def _run_job(folder: Path, record: Mapping[str, Any]) -> Job:
    """The run's job as it ran (scene copy, count, seed, kernels)."""
    from mcchain.runner.plan import keep_kernels, recorded_job

    return keep_kernels(recorded_job(folder, record), record.get("kernels"))


def _write_values(tight: xr.Dataset, path: Path) -> Path:
    """The tightened values, written atomically."""
    from mcchain.ensemble.io import commit_file, temporary_name

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_name(path)
    try:
        tight.to_netcdf(tmp, engine="netcdf4")
        commit_file(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
