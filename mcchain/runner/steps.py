"""What plugs into a run: observers, which the pipeline calls in order at fixed points, and
solve steps, which complete a chunk's solve where it runs.

* An :class:`Observer` subclass overrides the hooks it needs (the pipeline,
  :func:`mcchain.runner.pipeline.run_pipeline`, calls only those: the base's do nothing),
  on every observer of the plan, in the plan's order, in the run's own process and thread.
  A hook reads the :class:`RunState` and the :class:`SolvedChunk`, may keep its own entry
  of ``run.json`` up to date (``run.record``, ``run.session``: the pipeline writes the
  file), and returns nothing; :meth:`Observer.more_samples` alone returns a decision. No
  hook calls back into the pipeline.
* A :data:`SolveStep` is ``step(model_chunk, scene, outputs) -> outputs``: it runs right
  after a chunk's solve, where the solve runs (this process, or a Dask worker: it must
  pickle), and what it returns is what the store writes and the observers see
  (:class:`Solve` chains them).

The hooks, in the order a session calls them:

1. ``on_start(run)``: the folder is locked and ``run.todo`` lists the chunks this session
   computes first (none when every part file is there).
2. ``on_chunk_done(run, chunk)``: a chunk was solved and handed to the store (the part
   file may still be being written, on the writer thread); ``chunk.outputs`` is read only.
3. ``more_samples(run)``: every chunk of ``run.nsample`` samples is stored; the first
   observer that answers a count decides: one larger than ``run.nsample`` grows the run to
   it and its new chunks are computed (2. again, then 3.); None, or no larger count, goes on.
4. ``on_chunks_done(run)``: the computing is over, also when it failed (close what was
   opened in 1.); ``run.json`` is written after it.
5. ``on_merged(run)``: ``ensemble.nc`` holds every sample; the record is completed and
   written after it (a failure of an observer here fails the run: guard what may fail).

This module imports only the standard library.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from mcchain.model import Model
    from mcchain.runner.job import Job


@dataclass(frozen=True)
class SolvedChunk:
    """The samples ``start:stop`` of a run, solved.

    Attributes:
        start, stop: global sample indices (``stop`` excluded).
        outputs: the solver's arrays by variable name, sample axis first, in storage
            dtypes (:func:`mcchain.ensemble.registry.coerce_outputs`).
        seconds: wall time spent in the solve (and its solve steps).
        steps: integration steps the samples took, summed (None: the solver counts none).
    """

    start: int
    stop: int
    outputs: Mapping[str, np.ndarray]
    seconds: float = 0.0
    steps: int | None = None


@dataclass
class RunState:
    """What the observers see of a run session.

    Attributes:
        job: what the run computes from (:class:`mcchain.runner.job.Job`).
        folder: the run folder.
        record: ``run.json`` as the pipeline last wrote it (or will write it next).
        session: this session's entry of ``record["sessions"]``.
        nsample: the samples the run has now (grows with :meth:`Observer.more_samples`).
        todo: the chunks this session computes in its current batch.
    """

    job: Job
    folder: Path
    record: dict[str, Any]
    session: dict[str, Any]
    nsample: int
    todo: list[tuple[int, int]] = field(default_factory=list)


class Observer:
    """A part of a run that watches it (progress, a live stream, a decision to add samples,
    a summary): override the hooks you need; see the module's docstring for when each is
    called."""

    def on_start(self, run: RunState) -> None:
        """Before the first chunk of the session."""

    def on_chunk_done(self, run: RunState, chunk: SolvedChunk) -> None:
        """After each solved chunk is handed to the store."""

    def more_samples(self, run: RunState) -> int | None:
        """After every chunk is stored: the count to grow the run to, or None."""
        return None

    def on_chunks_done(self, run: RunState) -> None:
        """When the computing is over (also after a failure)."""

    def on_merged(self, run: RunState) -> None:
        """When ``ensemble.nc`` is complete, before ``run.json`` is."""


SolveFn = Callable[["Model", Any], Mapping[str, Any]]
"""``solve(model_chunk, scene) -> {variable: array}`` (see ``mcchain.solvers.solve_chunk``)."""

SolveStep = Callable[["Model", Any, dict[str, Any]], dict[str, Any]]
"""``step(model_chunk, scene, outputs) -> outputs``: completes a chunk's solve (e.g. solves
its failed samples again); runs where the solve runs, so it must pickle."""


@dataclass(frozen=True)
class Solve:
    """A chunk's solve: ``solve``, then each solve step in order (picklable when they are)."""

    solve: SolveFn
    steps: Sequence[SolveStep] = ()

    def __call__(self, model: Model, scene: Any) -> Mapping[str, Any]:
        outputs = self.solve(model, scene)
        for step in self.steps:
            outputs = step(model, scene, dict(outputs))
        return outputs
