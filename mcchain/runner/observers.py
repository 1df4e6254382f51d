"""The observers of a run (:func:`observers_for`), and the runner's own: the progress bar
and the requirements' verdict lines.

Each is an :class:`mcchain.runner.steps.Observer`; :func:`observers_for` lists them, in the
order the pipeline calls them, beside those of other packages (the live rerun stream,
:class:`mcchain.viz.live.LiveRun`; ``until``, :class:`mcchain.decision.until.Until`).

This module imports only the standard library at import time.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
import traceback
from typing import TYPE_CHECKING, Any

from mcchain.runner.steps import Observer, RunState, SolvedChunk

if TYPE_CHECKING:
    from mcchain.decision.until import Until
    from mcchain.runner.job import Job
    from mcchain.runner.steps import SolveFn, SolveStep
    from mcchain.viz.live import LiveOptions

log = logging.getLogger("mcchain")


def observers_for(
    job: Job,
    *,
    progress: bool | None = None,
    rerun: LiveOptions | None = None,
    grow: Until | None = None,
) -> list[Observer]:
    """The observers of a run of ``job``, in the order the pipeline calls them: the live
    rerun stream (``--rerun``), the progress bar (``progress``: None on a terminal only),
    ``until`` (``grow``), the requirements' verdict lines (a scene with ``[[requirement]]``)."""
    observers: list[Observer] = []
    if rerun is not None:
        from mcchain.viz.live import LiveRun

        observers.append(LiveRun(rerun))
    observers.append(Progress(progress))
    if grow is not None:
        observers.append(grow)
    if getattr(getattr(job.scene, "simulate", None), "retry_failed", False):
        observers.append(RetryCounts())
    if getattr(job.scene, "requirement", None):
        observers.append(VerdictLines())
    return observers


def solve_steps_for(job: Job, solve: SolveFn | None = None) -> list[SolveStep]:
    """The solve steps of a run of ``job``, in order: the retry of failed samples
    (``[simulate] retry_failed``, :class:`mcchain.solvers.retry.RetryFailed`, re-solving with
    ``solve``, the plan's chunk solver)."""
    if not getattr(getattr(job.scene, "simulate", None), "retry_failed", False):
        return []
    from mcchain.solvers.retry import RetryFailed

    return [RetryFailed(solve)]


class Progress(Observer):
    """Chunks done, samples/s and ETA on stderr (tqdm), silent when stderr is no terminal
    (``enabled=None``) or when ``enabled`` is False (``--quiet``)."""

    def __init__(self, enabled: bool | None = None) -> None:
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.samples = 0
        self.t0 = time.perf_counter()
        self._bar: Any = None

    def on_start(self, run: RunState) -> None:
        """Open the bar at the chunks done before this session (none to do: no bar)."""
        if self.enabled and run.todo:
            from tqdm import tqdm

            total = int(run.record["chunks"])
            self.t0 = time.perf_counter()
            self._bar = tqdm(
                total=total,
                initial=total - len(run.todo),
                unit="chunk",
                file=sys.stderr,
                dynamic_ncols=True,
            )

    def on_chunk_done(self, run: RunState, chunk: SolvedChunk) -> None:
        self.samples += chunk.stop - chunk.start
        bar = self._bar
        if bar is not None:
            if bar.total != run.record["chunks"]:  # ``until`` grew the run
                bar.total = int(run.record["chunks"])
            rate = self.samples / max(time.perf_counter() - self.t0, 1e-9)
            bar.set_postfix_str(f"{rate:,.0f} samples/s", refresh=False)
            bar.update(1)

    def on_chunks_done(self, run: RunState) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


class RetryCounts(Observer):
    """What solved the run's samples (``solved_by``, :mod:`mcchain.solvers.retry`), counted
    over the merged ensemble into ``run.json["retries"]``, with the note line ``mcchain
    run`` prints when a sample was retried."""

    def on_merged(self, run: RunState) -> None:
        from mcchain.ensemble.per_sample import open_stored
        from mcchain.runner.runs import ENSEMBLE
        from mcchain.solvers.retry import SOLVED_BY, retry_counts

        with open_stored(run.folder / ENSEMBLE) as ds:  # reads one small variable
            if SOLVED_BY in ds.data_vars:
                solved_by = ds[SOLVED_BY].values
                run.record["retries"] = retry_counts(solved_by, run.job.scene.simulate)


class VerdictLines(Observer):
    """The requirements' answer in words (:func:`mcchain.decision.summary.summary_lines`),
    from the merged ensemble, in ``run.json["requirements"]`` (``mcchain run`` prints it,
    ``mcchain export --requirements`` writes it with the CSVs). The ensemble is complete
    then, so a failure here never fails the run: it becomes the summary's one line."""

    _imports: threading.Thread | None = None

    def on_chunk_done(self, run: RunState, chunk: SolvedChunk) -> None:
        """After the first chunk: the summary's modules (``scipy.special``: 0.2-0.3 s of CPU,
        its array-API layer importing ``numpy.f2py``) imported on a thread of their own while
        the next chunks compute (the lane kernels release the GIL), not after the merge,
        when nothing else runs. Only when they are imported; their values are the same."""
        if self._imports is None:
            self._imports = threading.Thread(
                target=_import_summary, name="mcchain-verdict-imports", daemon=True
            )
            self._imports.start()

    def on_chunks_done(self, run: RunState) -> None:
        if self._imports is not None:  # nothing this run started goes on after its compute
            self._imports.join()

    def on_merged(self, run: RunState) -> None:
        try:
            run.record["requirements"] = verdict_lines(run)
        except Exception as error:
            log.error("requirement summary failed: %s\n%s", error, traceback.format_exc())
            run.record["requirements"] = [
                f"requirements: the summary failed ({error}); see run.log"
            ]


def _import_summary() -> None:
    """Import the modules :func:`verdict_lines` uses (:meth:`VerdictLines.on_chunk_done`);
    an error is left to that import, where the summary reports it."""
    with contextlib.suppress(Exception):
        import mcchain.decision.summary  # noqa: F401


def verdict_lines(run: RunState) -> list[str]:
    """The summary lines of the run's merged ensemble (:class:`VerdictLines`), read with
    netCDF4 alone (:func:`mcchain.ensemble.per_sample.open_stored`: the values xarray would
    give, without importing xarray, pandas and dask.array nor decoding every variable)."""
    from mcchain.decision.summary import allocations, design_of, summarize, summary_lines
    from mcchain.decision.until import sequential_settings
    from mcchain.ensemble.per_sample import open_stored
    from mcchain.runner.runs import ENSEMBLE

    with open_stored(run.folder / ENSEMBLE) as ds:
        sequential = sequential_settings(ds.attrs)
        return summary_lines(summarize(ds), allocations(ds), design_of(ds), sequential)
