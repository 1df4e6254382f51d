"""The run as one pipeline: plan -> execute -> store, with observers at fixed points.

:func:`run_pipeline` executes a :class:`Plan` (made by :mod:`mcchain.runner.plan` for
``mcchain run``, ``--resume`` and ``--extend``) and reads top to bottom:

1. **store**, opened: the folder locked, the session in ``run.json``
   (:meth:`mcchain.runner.store.Store.session_held`, which also records a failure);
2. **execute**: the chunks the folder lacks (:func:`mcchain.runner.runs.missing_chunks`)
   are solved here or on Dask (:mod:`mcchain.runner.executors`), each written as a part file
   by the store and handed to the observers; then, while an observer asks for more samples
   (``until``), the run grows and its new chunks are computed;
3. **store**, closed: the parts merged into ``ensemble.nc``, ``run.json`` completed.

The observers (:class:`mcchain.runner.steps.Observer`: progress, the live rerun stream,
``until``, the requirements' verdict lines) are called at fixed points of this loop and never
call back into it; see :mod:`mcchain.runner` for where a new one goes.

Phases timed in ``run.json["timings"]`` (seconds, summed over sessions): ``prepare``
(load, compile, check), ``warmup`` (kernel compile/cache load, cluster start),
``compute`` (the chunk loop, writes overlapping), ``kernel`` (time inside the solver),
``write`` (part files), ``merge``, ``total``.

Throughput (this session): ``samples_per_s`` = samples computed / ``compute``;
``steps_per_sample`` = the integration steps the samples took (as the solver counted
them: fixed-step methods the steps to t_end, the last one shortened to land on it; rk45
the accepted ones), summed, / samples computed; ``instance_steps_per_s`` = those steps
/ ``compute`` (both ``[simulate]`` only);
``outside_kernel_share`` = 1 − ``kernel`` / (workers × (``compute`` + ``merge``)), the
share of the chunk loop and merge spent outside the solver (I/O, merge, Python; compile
excluded). With Dask, ``kernel`` sums the workers' solver time and workers is their count.

Nothing here depends on timing: ``ensemble.nc`` holds no timestamps or host names, so the
same scene and seed give a byte-identical file whatever the chunk size, thread count or
scheduler, and a resumed run equals an uninterrupted one.

This module imports only the standard library at import time, and each stage's module
when the stage comes; numpy, xarray, netCDF4, numba, the solvers and rerun are imported
when a run executes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.runner.steps import Observer

if TYPE_CHECKING:
    from mcchain.compiled.ready import Kernels
    from mcchain.runner.job import Job
    from mcchain.runner.steps import SolveFn, SolveStep


@dataclass
class Plan:
    """A run ready to execute: everything :func:`run_pipeline` needs.

    Attributes:
        job: what the run computes from.
        folder: the run folder (made, with its ``scene.toml``).
        record: its ``run.json`` (the run's samples, seed, chunk size, restarts, ...).
        versions: the software versions of this process
            (:func:`mcchain.runner.provenance.software_versions`).
        observers: called in this order at each point of the pipeline.
        kernels: what the compile lifecycle answered (:class:`mcchain.compiled.ready.Kernels`,
            after its :meth:`~mcchain.compiled.ready.Kernels.after_checks`).
        dask: a Dask scheduler address, or ``"local"`` (a LocalCluster); None: here.
        threads: numba threads here, or the workers of ``"local"``.
        solve: the chunk solver (default ``mcchain.solvers.solve_chunk``), followed by each
            of ``solve_steps`` where it runs (:class:`mcchain.runner.steps.Solve`).
        argv, prepare_seconds: recorded in the session of ``run.json``.
        keep_parts: keep the part files after the merge.
    """

    job: Job
    folder: Path
    record: dict[str, Any]
    versions: dict[str, str]
    observers: Sequence[Observer]
    kernels: Kernels
    dask: str | None = None
    threads: int | None = None
    solve: SolveFn | None = None
    solve_steps: Sequence[SolveStep] = ()
    argv: Sequence[str] = ()
    prepare_seconds: float = 0.0
    keep_parts: bool = False


def run_pipeline(plan: Plan) -> RunResult:
    """Compute the chunks a planned run lacks, merge them, and complete ``run.json``.

    The run has ``run.json["samples"]`` samples, chunked by
    :func:`mcchain.runner.runs.run_chunks`. While an ``--extend`` is unfinished,
    ``ensemble.nc`` holds the samples the run had before it: they are merged with the new
    parts, never computed again. A failure or Ctrl-C marks the run ``FAILED``, keeping its
    finished part files (see :meth:`mcchain.runner.store.Store.session_held`).
    """
    on_start, on_chunk_done, more_samples, on_chunks_done, on_merged = (
        _hooks(plan.observers, name) for name in HOOKS
    )
    compiled = plan.kernels.provenance
    from mcchain.runner.store import Store

    store = Store(
        plan.job, plan.folder, plan.record, plan.versions,
        kernel_compiler=compiled["kernel_compiler"], argv=plan.argv,
        prepare_seconds=plan.prepare_seconds, keep_parts=plan.keep_parts,
    )  # fmt: skip
    with store.session_held() as run:
        try:
            for hook in on_start:
                hook(run)
            from mcchain.runner.executors import execute

            stats = execute(plan, run, store.write, on_chunk_done)
            while True:  # the first observer that answers a count decides (until)
                more = None
                for hook in more_samples:
                    more = hook(run)
                    if more is not None:
                        break
                if more is None or more <= run.nsample:
                    break
                store.grow(more)
                stats += execute(plan, run, store.write, on_chunk_done)
        finally:
            for hook in on_chunks_done:
                hook(run)
        merged = store.merge()
        for hook in on_merged:
            hook(run)
        failed = store.complete(stats, merged, compiled)
    return RunResult(plan.folder, plan.record, failed)


HOOKS = ("on_start", "on_chunk_done", "more_samples", "on_chunks_done", "on_merged")
"""The observers' hooks, in the order a session calls them."""


def _hooks(observers: Sequence[Observer], name: str) -> list[Callable[..., Any]]:
    """The hook ``name`` of each observer that overrides the base's (which does nothing)."""
    base = getattr(Observer, name)
    return [getattr(o, name) for o in observers if getattr(type(o), name) is not base]


@dataclass
class RunResult:
    """What a run returns (:func:`run_pipeline`; ``start_run``, ``resume_run`` and
    ``extend_run`` of :mod:`mcchain.runner.plan`): its folder and ``run.json`` (what
    ``mcchain run`` prints of it: :func:`mcchain.runner.summary.run_summary`)."""

    folder: Path
    record: dict[str, Any]
    failed: int = 0
    """Samples carrying a failure flag (:data:`mcchain.status.FAILURE_BITS`)."""

    @property
    def all_failed(self) -> bool:
        """Whether every sample of the run failed (the CLI then exits with 3)."""
        return self.failed > 0 and self.failed == int(self.record["samples"])
