"""The execute stage of a run: solve its chunks here or as Dask tasks.

Each chunk (:func:`mcchain.runner.runs.run_chunks`) is solved by
``solve(model.select(start, stop), scene)`` (``mcchain.solvers.solve_chunk`` by default,
with the plan's solve steps: :class:`mcchain.runner.steps.Solve`), handed to the store's
``write`` (the part-file writer), then to each observer's
:meth:`~mcchain.runner.steps.Observer.on_chunk_done`, always on the thread that called
:func:`run_local`/:func:`run_dask`, where the chunk's results arrive — never on the writer
thread, a numba thread or a Dask worker. Because the solvers are deterministic per sample,
the data never depend on the chunking or the scheduler.

* **in-process** (default): chunks one after the other, each solved by the numba kernels on
  all threads (``threads`` sets ``numba.set_num_threads``); the store writes on a thread
  apart from the compute, with at most one chunk waiting, so memory is O(chunk).
* **Dask** (``address="local"`` starts a :class:`~distributed.LocalCluster` of process
  workers, one thread each, ``NUMBA_NUM_THREADS=1`` in their environment; any other address
  is an existing scheduler): chunks are tasks, at most two per worker in flight; the kernels
  are warmed on every worker before the first chunk.

The kernels are warmed before the first chunk, by solving its first samples
(:func:`warm_model`): here through the plan's kernels (the compile lifecycle's
:meth:`mcchain.compiled.ready.Kernels.warm`), on every Dask worker as they are.
"""

from __future__ import annotations

import logging
import os
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol

from mcchain.runner.steps import Solve, SolvedChunk

if TYPE_CHECKING:
    from mcchain.model import Model
    from mcchain.runner.steps import RunState, SolveFn, SolveStep

log = logging.getLogger(__name__)


WriteFn = Callable[[SolvedChunk], None]
"""``write(chunk)``: store one solved chunk (the store's part writer)."""

WarmFn = Callable[["Model", Any, "SolveFn"], None]
"""``warm(first, scene, solve)``: compile or load the kernels before the first chunk, by
solving ``first``, the first samples of the run's model."""

DoneFn = Callable[["RunState", SolvedChunk], None]
"""``done(run, chunk)``: an observer's :meth:`~mcchain.runner.steps.Observer.on_chunk_done`."""

WORKER_ENV = {
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}
"""Environment of LocalCluster worker processes: one compute thread each."""


WARM_SAMPLES = 2
"""Samples solved to warm the kernels (compile or load them from numba's cache)."""


def warm_model(model: Model) -> Model:
    """The first few samples: enough to take every code path of a real chunk."""
    return model.select(0, min(WARM_SAMPLES, model.nsample))


WARM_STEPS = 4
"""Steps of ``dt`` a warm-up integrates (:func:`warm_scene`)."""


def warm_scene(scene: Any) -> Any:
    """``scene`` with its ``[simulate]`` cut to :data:`WARM_STEPS` steps of ``dt``: a warm-up
    loads or compiles the kernels, and the whole history of its samples was compute thrown
    away (a warm ``radau`` run of the Flores slider-crank spent 3 s on it). A kernel that only
    a later time reaches (an event's handler) loads when the first chunk reaches it."""
    sim = getattr(scene, "simulate", None)
    if sim is None or sim.t_end <= WARM_STEPS * sim.dt:
        return scene
    return scene.model_copy(
        update={"simulate": sim.model_copy(update={"t_end": WARM_STEPS * sim.dt})}
    )


def default_solve() -> SolveFn:
    """The real solver, ``mcchain.solvers.solve_chunk`` (imported lazily)."""
    from mcchain.solvers import solve_chunk

    return solve_chunk


@dataclass
class ExecutionStats:
    """Timings of one execution (seconds) and what it computed."""

    scheduler: str = "in-process"
    threads: int = 1
    workers: int = 1
    chunks: int = 0
    samples: int = 0
    steps: int | None = None  # integration steps the samples took, summed (None: not counted)
    warmup: float = 0.0
    compute: float = 0.0
    kernel: float = 0.0
    write: float = 0.0
    worker_info: list[dict[str, Any]] = field(default_factory=list)

    def count(self, chunk: SolvedChunk) -> None:
        """Count a solved chunk handed to the store (its outputs are not kept). The figures
        are read once every write has ended."""
        self.chunks += 1
        self.samples += chunk.stop - chunk.start
        if chunk.steps is not None:
            self.steps = (self.steps or 0) + chunk.steps

    def __add__(self, other: ExecutionStats) -> ExecutionStats:
        """The figures of two executions of one session (``until`` batches), summed."""
        last = other if other.chunks else self
        return replace(
            last,
            chunks=self.chunks + other.chunks,
            samples=self.samples + other.samples,
            warmup=self.warmup + other.warmup,
            compute=self.compute + other.compute,
            kernel=self.kernel + other.kernel,
            write=self.write + other.write,
            worker_info=self.worker_info + other.worker_info,
        )


def solve_coerced(
    solve: SolveFn, model: Model, scene: Any, history_dtype: str, start: int, stop: int
) -> SolvedChunk:
    """Solve the chunk ``start:stop`` (``model`` holds its samples) and cast its arrays to
    storage dtypes, with the seconds it took and the integration steps its samples took."""
    import numpy as np

    from mcchain.ensemble.outputs import model_output_variables
    from mcchain.ensemble.registry import STEPS_TAKEN, coerce_outputs

    t0 = time.perf_counter()
    outputs = solve(model, scene)
    seconds = time.perf_counter() - t0
    taken = outputs.get(STEPS_TAKEN)
    steps = None if taken is None else int(np.sum(taken, dtype=np.int64))
    coerced = coerce_outputs(outputs, history_dtype, model_output_variables(model))
    return SolvedChunk(start, stop, coerced, seconds, steps)


def execute(
    plan: ExecutionPlan, run: RunState, write: WriteFn, done: Sequence[DoneFn] = ()
) -> ExecutionStats:
    """Solve ``run.todo`` as the plan says: here (after the plan's kernels are warm) or on
    Dask, the plan's solve steps after its solver; nothing when every chunk is there."""
    if not run.todo:
        return ExecutionStats(scheduler="none (all chunks present)")
    solve = plan.solve or default_solve()
    if plan.solve_steps:
        solve = Solve(solve, plan.solve_steps)
    if plan.dask:
        return run_dask(
            run, run.todo, write, done, address=plan.dask, workers=plan.threads, solve=solve
        )
    warm = plan.kernels.warm
    return run_local(run, run.todo, write, done, threads=plan.threads, solve=solve, warm=warm)


class ExecutionPlan(Protocol):
    """What :func:`execute` reads of a plan (:class:`mcchain.runner.pipeline.Plan`)."""

    dask: str | None
    threads: int | None
    solve: SolveFn | None
    solve_steps: Sequence[SolveStep]

    @property
    def kernels(self) -> Warmer: ...


class Warmer(Protocol):
    """Something that warms the kernels (:class:`mcchain.compiled.ready.Kernels`)."""

    def warm(self, model: Model, scene: Any, solve: SolveFn) -> None: ...


# -- in-process ------------------------------------------------------------------------------


def _set_threads(threads: int | None) -> int:
    from mcchain.kernels import config

    if config.INTERPRETED:
        return 1  # plain Python: the kernels run on this thread (solvers.threads)
    import numba

    if threads is not None:
        numba.set_num_threads(threads)
    return int(numba.get_num_threads())


def run_local(
    run: RunState,
    chunks: Sequence[tuple[int, int]],
    write: WriteFn,
    done: Sequence[DoneFn] = (),
    *,
    threads: int | None = None,
    solve: SolveFn | None = None,
    warm: WarmFn | None = None,
) -> ExecutionStats:
    """Solve ``chunks`` of ``run.job`` in this process, writing each on a thread apart from
    the compute, after ``warm`` (default: solving the first samples) loaded the kernels.

    The ``done`` hooks (the observers' :meth:`~mcchain.runner.steps.Observer.on_chunk_done`)
    get each solved chunk on this thread, after the chunk is handed to the writer, so that
    writing and observing overlap; the next chunk is solved after them.
    """
    model, scene, dtype = run.job.model, run.job.scene, run.job.history_dtype
    solve = solve or default_solve()
    stats = ExecutionStats(scheduler="in-process", threads=_set_threads(threads))
    t0 = time.perf_counter()
    first, short = warm_model(model), warm_scene(scene)
    if warm is None:
        solve(first, short)  # compile or load the cached kernels
    else:
        warm(first, short, solve)
    stats.warmup = time.perf_counter() - t0
    log.info("kernels warmed in %.2f s (%d threads)", stats.warmup, stats.threads)

    def timed_write(chunk: SolvedChunk) -> float:
        t = time.perf_counter()
        write(chunk)
        _written(chunk)
        return time.perf_counter() - t

    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcchain-writer") as writer:
        pending: Future[float] | None = None
        for start, stop in chunks:
            chunk = solve_coerced(solve, model.select(start, stop), scene, dtype, start, stop)
            stats.kernel += chunk.seconds
            if pending is not None:  # at most one chunk waits for the writer
                stats.write += pending.result()
            stats.count(chunk)
            pending = writer.submit(timed_write, chunk)
            for hook in done:
                hook(run, chunk)
            del chunk
        if pending is not None:
            stats.write += pending.result()
    stats.compute = time.perf_counter() - t0
    return stats


def _written(chunk: SolvedChunk) -> None:
    log.info("chunk %d:%d solved in %.3f s and written", chunk.start, chunk.stop, chunk.seconds)


# -- Dask ------------------------------------------------------------------------------------


def _worker_setup(solve: SolveFn, model: Model, scene: Any) -> dict[str, Any]:
    """Run on every worker before the first chunk: one numba thread, warm kernels."""
    import numba

    t0 = time.perf_counter()
    solve(model, scene)
    return {
        "pid": os.getpid(),
        "numba_threads": int(numba.config.NUMBA_NUM_THREADS),  # type: ignore[attr-defined]
        "warmup": time.perf_counter() - t0,
    }


def _dask_task(
    solve: SolveFn, model: Model, scene: Any, history_dtype: str, start: int, stop: int
) -> SolvedChunk:
    import numba

    numba.set_num_threads(1)
    return solve_coerced(solve, model, scene, history_dtype, start, stop)


CONNECT_TIMEOUT = 5.0
"""Seconds to wait for a Dask scheduler to answer (a first contact: it answers in ms)."""

DASK_EXTRA = "pip install 'mcchain[cluster]'"
"""How to install the optional Dask dependency."""


def require_dask() -> None:
    """Raise ``RunError`` naming ``--dask`` and the extra to install if dask.distributed
    cannot be imported."""
    from mcchain.errors import RunError

    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise RunError(
            f"--dask: needs dask.distributed, which is not installed ({DASK_EXTRA})"
        ) from None


def check_scheduler(address: str, timeout: float | None = None) -> None:
    """Raise ``RunError`` naming ``--dask`` if dask is missing or, for an address other than
    ``"local"``, no scheduler answers there within ``timeout`` s (default
    :data:`CONNECT_TIMEOUT`). Called before a run writes anything."""
    from mcchain.errors import RunError

    require_dask()
    if address == "local":
        return
    from dask.distributed import Client

    wait = CONNECT_TIMEOUT if timeout is None else timeout
    try:
        client = Client(address, timeout=wait)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).strip() or type(exc).__name__
        raise RunError(f"--dask: no Dask scheduler answers at {address} ({reason})") from None
    client.close()


@contextmanager
def dask_client(address: str, workers: int | None = None) -> Iterator[Any]:
    """A Dask client: a fresh LocalCluster for ``"local"``, else the scheduler at ``address``."""
    require_dask()
    from dask.distributed import Client, LocalCluster

    if address == "local":
        n = workers or os.cpu_count() or 1
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env=dict(WORKER_ENV),
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
            cluster.close()
    else:
        client = Client(address, timeout=CONNECT_TIMEOUT)
        try:
            yield client
        finally:
            client.close()


def run_dask(
    run: RunState,
    chunks: Sequence[tuple[int, int]],
    write: WriteFn,
    done: Sequence[DoneFn] = (),
    *,
    address: str,
    workers: int | None = None,
    solve: SolveFn | None = None,
) -> ExecutionStats:
    """Solve ``chunks`` of ``run.job`` as Dask tasks; the results are written here, as they
    arrive, and handed to the ``done`` hooks here too, after the write."""
    from dask.distributed import as_completed

    model, scene, dtype = run.job.model, run.job.scene, run.job.history_dtype
    solve = solve or default_solve()
    stats = ExecutionStats(scheduler=f"dask {address}")
    t0 = time.perf_counter()
    with dask_client(address, workers) as client:
        info = client.scheduler_info()
        nthreads = {w: d.get("nthreads", 1) for w, d in info.get("workers", {}).items()}
        stats.workers = len(nthreads)
        stats.threads = sum(nthreads.values())
        if stats.workers == 0:
            raise RuntimeError(f"dask scheduler {address} has no workers")
        for worker, n in nthreads.items():
            if n != 1:
                log.warning("worker %s has %d threads; mcchain expects 1 per process", worker, n)
        setup = client.run(_worker_setup, solve, warm_model(model), warm_scene(scene))
        stats.worker_info = [{"worker": w, **d} for w, d in setup.items()]
        for entry in stats.worker_info:
            log.info("worker %(worker)s warmed in %(warmup).2f s", entry)
            if entry["numba_threads"] != 1:
                log.warning(
                    "worker %s runs %d numba threads (set NUMBA_NUM_THREADS=1 for its process)",
                    entry["worker"],
                    entry["numba_threads"],
                )
        stats.warmup = time.perf_counter() - t0

        t0 = time.perf_counter()
        scene_future = client.scatter(scene, broadcast=True)
        queue = deque(chunks)
        in_flight = as_completed()

        def submit() -> None:
            start, stop = queue.popleft()
            in_flight.add(
                client.submit(
                    _dask_task,
                    solve,
                    model.select(start, stop),
                    scene_future,
                    dtype,
                    start,
                    stop,
                    pure=False,
                )
            )

        for _ in range(min(2 * stats.workers, len(queue))):
            submit()
        for future in in_flight:
            chunk = future.result()
            future.release()
            if queue:
                submit()
            stats.kernel += chunk.seconds
            stats.count(chunk)
            t = time.perf_counter()
            write(chunk)
            stats.write += time.perf_counter() - t
            _written(chunk)
            for hook in done:
                hook(run, chunk)
            del chunk
        stats.compute = time.perf_counter() - t0
    return stats
