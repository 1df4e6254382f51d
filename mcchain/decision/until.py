"""``[sample] until = "decided"``: a run that adds batches of samples until it can decide.

A run with ``until`` computes ``count`` samples (the batch: ``[sample] count`` or
``--samples``), looks at its requirements (``requirement_met`` of the part files written so
far), and adds another batch while any requirement with a target is undecided by its
sequential interval (:mod:`mcchain.decision.sequential`), up to ``max_count`` samples. The
samples are those of one run of the final count (the design continued batch after batch,
as ``--extend`` does), so the ensemble is that run's; its settings carry ``sequential``
(method, batch, max_count), from which ``mcchain export`` knows to report the sequential
interval instead of the fixed-sample one.

Every look is noted in ``run.json["until"]["looks"]``: the sample count and, per
requirement, failures, interval and verdict.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.errors import RunError, SceneError
from mcchain.runner.steps import Observer, RunState

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.runner.job import Job, Loader

log = logging.getLogger("mcchain")

METHOD = "confidence sequence (beta-binomial mixture, prior mean = target)"
"""How the sequential interval is named in the settings, ``run.json`` and the CSV."""

SETTINGS_KEY = "sequential"
"""The key of the resolved settings (``ensemble.nc`` attribute ``settings``) that marks a
run whose samples were added until decided: ``{"method", "batch", "max_count"}``."""


def sequential_settings(attrs: Mapping[str, Any]) -> dict[str, Any] | None:
    """The ``sequential`` entry of an ensemble's ``settings`` attribute, or None (a run of a
    fixed count)."""
    import json

    try:
        settings = json.loads(str(attrs.get("settings", "{}")))
    except ValueError:
        return None
    entry = settings.get(SETTINGS_KEY) if isinstance(settings, dict) else None
    return dict(entry) if isinstance(entry, dict) else None


@dataclass
class Until(Observer):
    """``until = "decided"``: the run's observer that asks for another batch of samples while
    a requirement is undecided (:meth:`more_samples`)."""

    batch: int
    max_count: int

    def more_samples(self, run: RunState) -> int | None:
        """Look at the part files of the run's first ``run.nsample`` samples: the count of
        one more batch, or None (every requirement decided, or ``max_count`` reached). The
        look is noted in ``run.json["until"]["looks"]``."""
        from mcchain.decision.stats import EMPTY, UNDECIDED
        from mcchain.ensemble.io import list_parts, open_parts
        from mcchain.runner.runs import PARTS

        record, nsample = run.record, run.nsample
        with open_parts(list_parts(Path(run.folder) / PARTS)) as ds:
            look = look_at(ds, nsample, self.batch)
        entry = record.setdefault("until", self.describe())
        looks = [item for item in entry.setdefault("looks", []) if item["samples"] != nsample]
        entry["looks"] = [*looks, look]
        undecided = [name for name, r in look["requirements"].items() if r["verdict"] == UNDECIDED]
        # an empty running intersection never fills again: no more samples decide it
        empty = [name for name, r in look["requirements"].items() if r["verdict"] == EMPTY]
        if not undecided:
            entry["stopped"] = f"decided after {nsample} samples" + (
                f"; no verdict (empty running intersection): {', '.join(empty)}" if empty else ""
            )
            log.info("until: every requirement decided after %d samples", nsample)
            return None
        if nsample >= self.max_count:
            entry["stopped"] = f"max_count {self.max_count} reached; undecided: " + ", ".join(
                undecided
            )
            log.info("until: max_count %d reached, undecided: %s", nsample, undecided)
            return None
        log.info("until: undecided after %d samples (%s): one more batch", nsample, undecided)
        return min(nsample + self.batch, self.max_count)

    def describe(self) -> dict[str, Any]:
        """The ``sequential`` settings entry (and the start of ``run.json["until"]``)."""
        return {"method": METHOD, "batch": self.batch, "max_count": self.max_count}


def look_at(ds: xr.Dataset, nsample: int, batch: int) -> dict[str, Any]:
    """The verdicts of the first ``nsample`` samples of ``ds`` by the sequential interval."""
    import numpy as np

    from mcchain.decision.sequential import sequential_bounds
    from mcchain.decision.stats import verdict

    if "requirement_met" not in ds.data_vars:
        raise RunError("until: the run stores no requirement_met (no [[requirement]])")
    met = ds["requirement_met"]
    values = np.asarray(met.isel(sample=slice(0, nsample)).values)
    names = [str(n) for n in ds["requirement"].values]
    targets = np.asarray(met.attrs["target"], dtype=np.float64).reshape(-1)
    confidences = np.asarray(met.attrs["confidence"], dtype=np.float64).reshape(-1)
    out: dict[str, Any] = {}
    for j, name in enumerate(names):
        failed = values[:, j] == 0
        lower, upper = sequential_bounds(failed, batch, float(confidences[j]), float(targets[j]))
        out[name] = {
            "failures": int(failed.sum()),
            "p_lower": lower,
            "p_upper": upper,
            "verdict": verdict(lower, upper, float(targets[j])),
        }
    return {"samples": int(nsample), "requirements": out}


def keep_sequential(job: Job, record: Mapping[str, Any]) -> Job:
    """``job`` (an ``--extend`` of a run, or its resume) with the ``sequential`` settings
    entry that judges it by the confidence sequence, valid at every count whenever the run
    stops:

    * a run made with ``until``: its own entry (its looks: every batch, then the total);
    * a fixed-count run with requirements, extended: looks every ``batch`` = the count it had
      before its first extension (``extended_from``). Extending a fixed-count run until its
      Clopper-Pearson interval decides is optional stopping: that interval then no longer
      holds (benchmarks/results/extend/bench.md measures it), the sequence does.

    Extended, the entry also lists ``looks``: the counts the run had before it grew
    (``run.json["restarts"]``: an ``until`` run's looks, each extension's start), so that
    the running intersection continues over every look it was judged at and never widens.
    """
    until = record.get("until")
    looks = sorted(int(n) for n in record.get("restarts") or ())
    if until:
        job.settings[SETTINGS_KEY] = {k: until[k] for k in ("method", "batch", "max_count")}
    elif record.get("extensions") and getattr(job.scene, "requirement", None):
        first = int(record["extensions"][0]["from"])
        job.settings[SETTINGS_KEY] = {
            "method": METHOD,
            "batch": first,
            "max_count": None,
            "extended_from": first,
        }
    else:
        return job
    if record.get("extensions"):  # where it was judged before each extension
        job.settings[SETTINGS_KEY]["looks"] = looks
    return job


def sequential_job(
    job: Job,
    scene_path: Path,
    *,
    seed: int | None,
    chunk_size: int | None,
    loader: Loader | None,
    batch: int | None = None,
    nsample: int | None = None,
) -> tuple[Job, Until | None]:
    """The job of an ``until`` run and its ``grow``; ``(job, None)`` for other scenes.

    ``job`` was prepared for its batch (``[sample] count`` or ``--samples``; a resume gives
    ``batch`` from ``run.json``); the job
    returned holds the model of ``max_count`` samples (so that every batch is a slice of
    it) and starts at ``nsample`` samples (default: one batch; a resume gives the count it
    reached). Its settings carry the ``sequential`` entry.
    """
    sample = getattr(job.scene, "sample", None)
    if getattr(sample, "until", None) is None:
        return job, None
    assert sample is not None
    if not getattr(job.scene, "requirement", None):
        raise SceneError('sample.until: "decided" needs at least one [[requirement]] to decide')
    batch = int(job.nsample if batch is None else batch)
    max_count = int(sample.until_max_count)
    if batch > max_count:
        raise RunError(f"--samples: {batch} is more than sample.max_count ({max_count})")
    from mcchain.runner.job import prepare_job

    until = Until(batch, max_count)
    full = prepare_job(
        scene_path, samples=max_count, seed=seed, chunk_size=chunk_size, loader=loader
    )
    full.settings[SETTINGS_KEY] = until.describe()
    return full.resized(batch if nsample is None else nsample), until
