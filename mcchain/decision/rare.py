"""``mcchain rare SCENE.toml --requirement NAME``: a rare failure probability by subset
simulation (:mod:`mcchain.decision.subset`) driven by mcchain's batch kernels.

The requirement's output is the response: its margin beyond the limit (output − max for a
``max``, min − output for a ``min``; failure: margin > 0). With both limits the two sides
are two failure modes, each followed by its own subset simulation and the probabilities
added (the sides are disjoint): one side's margins, however small beside the other's, are
never hidden by a maximum. A sample with a failure bit in ``status`` (a failed instance)
fails, and is counted apart as undefined; an event time that is NaN on a sample without
one (``first_separation_time``: "never") is +inf. Every Markov-chain step of a level is one
batch of the scene's kernels (``mcchain.solvers.solve_chunk`` on a model compiled at the chains'
parameters). The result goes to a new run folder (``runs/<stamp>-<scene>/``):

* ``export/subset.csv`` — one row, columns :data:`SUBSET_COLUMNS`: the method, P(fail), its
  c.o.v. (and the fully-correlated bound ``cov_upper``), the kernel solves spent, the levels,
  N per level, and ``samples_plain_mc``, the independent samples plain Monte Carlo would
  need for the same c.o.v., (1 − P)/(P cov²);
* ``export/subset-levels.csv`` — per level: threshold (margin), conditional probability,
  its c.o.v. and the share of chain steps that moved;
* ``run.json`` (``kind = "rare"``) and ``scene.toml``. No ``ensemble.nc``: the chains'
  samples are not an ensemble of the design.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mcchain.errors import RunError

SUBSET_COLUMNS = (
    "requirement",
    "method",
    "p_fail",
    "cov",
    "cov_upper",
    "samples_spent",
    "levels",
    "per_level",
    "level_probability",
    "seed",
    "samples_plain_mc",
    "p_upper",
    "undefined",
    "cov_levels",
    "cov_lineage",
    "modes",
    "unit",
)
"""Columns of ``export/subset.csv`` (docs/scenes.md)."""

LEVEL_COLUMNS = ("level", "threshold", "probability", "cov", "acceptance", "mode", "unit")
"""Columns of ``export/subset-levels.csv``."""

DEFAULT_PER_LEVEL = 1000
"""N, samples per level."""


def margin(values: np.ndarray, minimum: float | None, maximum: float | None) -> np.ndarray:
    """The margins beyond a requirement's limits (> 0: failed; NaN stays NaN = failed): (n,)
    with one limit, (n, 2) with both (columns: output − max, min − output; two modes)."""
    x = np.asarray(values, dtype=np.float64)
    sides = []
    if maximum is not None:
        sides.append(x - maximum)
    if minimum is not None:
        sides.append(minimum - x)
    return sides[0] if len(sides) == 1 else np.stack(sides, axis=-1)


@dataclass(frozen=True)
class RareResult:
    """What :func:`rare_run` wrote: the folder, the estimate and the CSV paths."""

    folder: Path
    requirement: str
    result: Any  # mcchain.decision.subset.SubsetResult
    csv: Path
    levels_csv: Path

    def lines(self) -> list[str]:
        r = self.result
        modes = f" over {len(r.modes)} failure modes (its two limits)" if r.modes else ""
        if r.p_fail > 0:
            head = (
                f"requirement {self.requirement}: P(fail) = {r.p_fail:.3g}, c.o.v. {r.cov:.2f} "
                f"(at most {r.cov_upper:.2f} if the levels are correlated)"
            )
        else:
            head = (
                f"requirement {self.requirement}: no failure found: P(fail) < {r.p_upper:.3g} "
                "(approximate one-sided bound)"
            )
        lines = [
            f"{head}{modes}, {r.levels} levels of {r.per_level}, {r.samples_spent} kernel "
            f"solves ({r.undefined} undefined: failed instances, counted as failures)",
        ]
        if r.p_fail > 0:
            lines.append(
                f"plain Monte Carlo would need about {_plain_mc(r.p_fail, r.cov):,.0f} samples "
                "for the same c.o.v."
            )
        return lines + [f"warning: {w}" for w in r.warnings]


def level_rows(result: Any, unit: str) -> list[dict[str, Any]]:
    """The rows of ``subset-levels.csv``: every level of every failure mode."""
    rows = []
    for mode, r in enumerate(result.modes or [result], start=1):
        acceptance = [math.nan, *r.acceptance]
        for j, (b, p, c, a) in enumerate(
            zip(r.thresholds, r.level_probabilities, r.level_covs, acceptance, strict=True)
        ):
            rows.append(
                {
                    "level": j + 1,
                    "threshold": b,
                    "probability": p,
                    "cov": c,
                    "acceptance": a,
                    "mode": mode,
                    "unit": unit,
                }
            )
    return rows


def _plain_mc(p: float, cov: float) -> float:
    if not (0.0 < p < 1.0) or not math.isfinite(cov) or cov <= 0:
        return math.nan
    return (1.0 - p) / (p * cov * cov)


def rare_run(
    scene_path: str | Path,
    requirement: str,
    *,
    per_level: int = DEFAULT_PER_LEVEL,
    seed: int | None = None,
    out: str | Path = "runs",
    run_dir: str | Path | None = None,
    argv: Sequence[str] | None = None,
) -> RareResult:
    """Estimate P(fail) of one requirement of a scene by subset simulation (module
    docstring); every check happens before the run folder is made."""
    from mcchain.decision.subset import METHOD, parameters_of, subset_simulation
    from mcchain.decision.tables import write_csv
    from mcchain.runner.job import check_positive, prepare_job
    from mcchain.runner.provenance import software_versions
    from mcchain.runner.runs import (
        COMPLETED,
        SCENE_COPY,
        check_new_run_dir,
        create_run_folder,
        write_record,
    )

    t0 = time.perf_counter()
    check_positive("--per-level", per_level)
    if per_level % 10:
        raise RunError(f"--per-level: must be a multiple of 10 (p0 = 0.1), got {per_level}")
    if run_dir is not None:
        check_new_run_dir(run_dir)
    job = prepare_job(scene_path, samples=1, seed=seed)
    scene = job.scene
    sample = getattr(scene, "sample", None)
    if sample is None or not sample.vary:
        raise RunError("rare: the scene samples nothing ([sample.vary]): no probability")
    named = {r.name: r for r in getattr(scene, "requirement", None) or []}
    if requirement not in named:
        have = ", ".join(named) or "none"
        raise RunError(f"--requirement: no requirement {requirement!r} (the scene has: {have})")
    req = named[requirement]
    seed = int(sample.seed if seed is None else seed)
    distributions = list(sample.vary.values())
    respond = _response(scene, req, distributions, parameters_of)

    folder = create_run_folder(out, job.scene_name, run_dir)
    (folder / SCENE_COPY).write_text(job.scene_text, encoding="utf-8")
    result = subset_simulation(respond, len(distributions), per_level=per_level, seed=seed)
    export = folder / "export"
    export.mkdir()
    from mcchain.ensemble.registry import VARIABLES

    unit = VARIABLES[req.output].units if req.output in VARIABLES else "1"
    row = {
        "requirement": req.name,
        "method": METHOD,
        "p_fail": result.p_fail,
        "cov": result.cov,
        "cov_upper": result.cov_upper,
        "samples_spent": result.samples_spent,
        "levels": result.levels,
        "per_level": result.per_level,
        "level_probability": 0.1,
        "seed": seed,
        "samples_plain_mc": _plain_mc(result.p_fail, result.cov),
        "p_upper": result.p_upper,
        "undefined": result.undefined,
        "cov_levels": result.cov_levels,
        "cov_lineage": result.cov_lineage,
        "modes": max(1, len(result.modes)),
        "unit": unit,
    }
    csv_path, levels_path = export / "subset.csv", export / "subset-levels.csv"
    write_csv(csv_path, SUBSET_COLUMNS, [row])
    write_csv(levels_path, LEVEL_COLUMNS, level_rows(result, unit))
    write_record(
        folder,
        {
            "id": folder.name,
            "kind": "rare",
            "status": COMPLETED,
            "scene": job.scene_name,
            "scene_file": str(Path(scene_path).resolve()),
            "samples": result.samples_spent,
            "seed": seed,
            "argv": list(sys.argv if argv is None else argv),
            "versions": software_versions(),
            "wall_time": time.perf_counter() - t0,
            "status_counts": None,
            "rare": row,
        },
    )
    return RareResult(folder, req.name, result, csv_path, levels_path)


def _response(scene: Any, requirement: Any, distributions: list[Any], parameters_of: Any) -> Any:
    """The batch response of a requirement: margins at standard-normal points."""
    from mcchain.decision.requirements import (
        check_requirements,
        decision_values,
        defined_samples,
    )
    from mcchain.scene import compile_model
    from mcchain.solvers import solve_chunk

    index: tuple[Any, ...] | None = None

    def respond(u: np.ndarray) -> np.ndarray:
        nonlocal index
        n = len(u)
        model = compile_model(scene, nsample=n, parameters=parameters_of(u, distributions))
        if index is None:
            position = [r.name for r in scene.requirement].index(requirement.name)
            index = tuple(check_requirements(scene, model)[position].index)
        outputs = solve_chunk(model, scene)
        values = np.asarray(outputs[requirement.output])[(slice(None), *index)]
        values = decision_values(values, defined_samples(outputs["status"]), requirement.output)
        return margin(values, requirement.min, requirement.max)

    return respond
