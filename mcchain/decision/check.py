"""``mcchain check RUN --tighten F``: is the answer numerically sound?

Peaks after impacts are sensitive to the integrator's accuracy. The check re-solves a
stated subset of a run's samples (``--samples M``, default 64, spread evenly over the run:
indices round(i (n − 1)/(M − 1))) with the time integration F times tighter — ``rtol`` and
``atol`` divided by F for the adaptive methods (``rk45``, ``radau``), ``dt`` divided by F
for the fixed-step ones — and compares with the values the run stored:

* per requirement: how many of the subset's verdicts flip (``requirement_met`` differs) and
  the spread of the output's differences (absolute and relative to the run's value; samples
  where either value is NaN are left out of the spread, a flip still counts them);
* without requirements: the same spread for every per-sample output, element by element.

The table goes to ``RUN/export/check.csv`` (columns :data:`CHECK_COLUMNS`) and is printed;
the tightened values to ``RUN/check/tighten-<F>.nc`` (sample = the run's indices). The
run's ``ensemble.nc`` is never touched. With F = 1 the re-solve reproduces the run bit for
bit (the kernels compute each sample alone), which is how the test checks the subset.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.errors import RunError

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.runner.job import Job

DEFAULT_SAMPLES = 64
"""Samples re-solved by default."""

ADAPTIVE_METHODS = ("rk45", "radau")
"""Methods whose accuracy is set by rtol/atol (the others by dt)."""

CHECK_COLUMNS = (
    "requirement",
    "samples",
    "flips",
    "abs_diff_median",
    "abs_diff_max",
    "rel_diff_median",
    "rel_diff_max",
    "tighten",
)
"""Columns of ``export/check.csv``."""


@dataclass(frozen=True)
class CheckRow:
    """One line of the check: a requirement (or, without requirements, an output)."""

    requirement: str
    samples: int
    flips: float  # an integer count; NaN for an output without a requirement
    abs_diff_median: float
    abs_diff_max: float
    rel_diff_median: float
    rel_diff_max: float
    tighten: float

    def row(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in CHECK_COLUMNS}


def spread_indices(nsample: int, count: int) -> np.ndarray:
    """``count`` sample indices spread evenly over ``0:nsample`` (all of them if fewer)."""
    if count >= nsample:
        return np.arange(nsample)
    if count == 1:
        return np.zeros(1, dtype=np.int64)
    return np.round(np.arange(count) * (nsample - 1) / (count - 1)).astype(np.int64)


def tightened_scene(scene: Any, factor: float) -> tuple[Any, str]:
    """The scene with ``[simulate]`` ``factor`` times tighter, and what changed, in words."""
    sim = getattr(scene, "simulate", None)
    if sim is None:
        raise RunError(
            "check: the run has no [simulate] (equilibria and modes are solved to Newton's "
            "tolerance): no time integration to tighten"
        )
    if sim.method in ADAPTIVE_METHODS:
        update = {"rtol": _divided(sim.rtol, factor), "atol": _divided(sim.atol, factor)}
        said = f"rtol {sim.rtol:g} -> {update['rtol']:g}, atol {sim.atol:g} -> {update['atol']:g}"
    else:
        update = {"dt": _divided(sim.dt, factor)}
        said = f"dt {sim.dt:g} -> {update['dt']:g} s"
    return scene.model_copy(update={"simulate": sim.model_copy(update=update)}), said


def _divided(value: float, factor: float) -> float:
    """``value / factor`` to 15 significant digits: 1e-10 / 10 is the 1e-11 the table
    prints, not the 1.0000000000000001e-11 of binary division."""
    return float(f"{value / factor:.15g}")


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


def compare_requirements(
    ds: xr.Dataset, index: np.ndarray, outputs: Mapping[str, np.ndarray], factor: float
) -> list[CheckRow]:
    """Per requirement of the run: flips and differences of the re-solved ``outputs``
    (samples ``index`` of ``ds``, in that order)."""
    from mcchain.decision.requirements import (
        requirement_met,
        requirement_values,
        stored_requirements,
    )

    rows = []
    subset = ds.isel(sample=index)
    tight_ds = _as_dataset(ds, index, outputs)
    for requirement in stored_requirements(ds):
        base = requirement_values(subset, requirement)
        tight = requirement_values(tight_ds, requirement)
        flips = int(
            np.sum(requirement_met(base, requirement) != requirement_met(tight, requirement))
        )
        rows.append(
            CheckRow(requirement.name, index.size, flips, *_differences(base, tight), factor)
        )
    return rows


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
        d: ds[d] for d in ds.coords if "sample" not in ds[d].dims and "time" not in ds[d].dims
    }
    out = xr.Dataset(variables, coords={**coords, "sample": np.asarray(index)})
    out.attrs = dict(ds.attrs)
    return out


@dataclass(frozen=True)
class CheckResult:
    """What :func:`check_run` found and wrote."""

    rows: list[CheckRow]
    changed: str
    csv: Path
    values: Path

    def lines(self) -> list[str]:
        """The printed table."""
        header = (
            "requirement",
            "samples",
            "flips",
            "|diff| median",
            "|diff| max",
            "rel median",
            "rel max",
        )
        table = [header]
        for r in self.rows:
            flips = "-" if math.isnan(r.flips) else str(int(r.flips))
            table.append(
                (
                    r.requirement,
                    str(r.samples),
                    flips,
                    f"{r.abs_diff_median:.3g}",
                    f"{r.abs_diff_max:.3g}",
                    f"{r.rel_diff_median:.3g}",
                    f"{r.rel_diff_max:.3g}",
                )
            )
        widths = [max(len(row[i]) for row in table) for i in range(len(header))]
        text = [
            "  ".join(
                c.rjust(w) if i else c.ljust(w)
                for i, (c, w) in enumerate(zip(row, widths, strict=True))
            )
            for row in table
        ]
        return [
            f"check: {self.changed} ({self.rows[0].tighten:g}x tighter)"
            if self.rows
            else f"check: {self.changed}",
            *text,
        ]


def check_run(
    run: str | Path,
    tighten: float,
    samples: int = DEFAULT_SAMPLES,
    *,
    solve: Any = None,
) -> CheckResult:
    """Re-solve ``samples`` samples of a completed run ``tighten`` times tighter and compare
    (see the module docstring). ``solve``: the chunk solver (default the real one)."""
    from mcchain.decision.requirements import job_requirements
    from mcchain.decision.summary import write_csv
    from mcchain.ensemble.registry import coerce_outputs
    from mcchain.runner.executors import default_solve
    from mcchain.runner.runs import COMPLETED, ENSEMBLE, open_run, read_record, resolve_run

    if not (isinstance(tighten, (int, float)) and math.isfinite(tighten) and tighten >= 1):
        raise RunError(f"--tighten: must be a number >= 1, got {tighten!r}")
    if not isinstance(samples, int) or samples < 1:
        raise RunError(f"--samples: must be an integer >= 1, got {samples!r}")
    folder = resolve_run(run)
    record = read_record(folder)
    if record.get("status") != COMPLETED or not (folder / ENSEMBLE).exists():
        raise RunError(f"check: {run} is not completed (mcchain run --resume {run})")
    job = _run_job(folder, record)
    scene, changed = tightened_scene(job.scene, float(tighten))
    index = spread_indices(job.nsample, samples)
    outputs = (solve or default_solve())(job.model.take(index), scene)
    outputs = coerce_outputs(outputs, job.history_dtype)
    requirements = job_requirements(job)
    if requirements is not None:
        outputs = requirements.add_to(outputs)
    with open_run(folder) as ds:
        if requirements is not None:
            rows = compare_requirements(ds, index, outputs, float(tighten))
        else:
            rows = compare_outputs(ds, index, outputs, float(tighten))
        tight = _as_dataset(ds, index, outputs)
    values = _write_values(tight, folder / "check" / f"tighten-{tighten:g}.nc")
    path = folder / "export" / "check.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_csv(path, CHECK_COLUMNS, [r.row() for r in rows])
    return CheckResult(rows, changed, path, values)


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
