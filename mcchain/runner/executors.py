"""Chunked execution of an ensemble: in-process or as Dask tasks.

The samples ``0:nsample`` are cut into chunks (:func:`plan_chunks`). Each chunk is solved
by ``solve(model.select(start, stop), scene)`` (``mcchain.solvers.solve_chunk`` by
default) and handed to a *sink* (the run folder's part-file writer) and, when given, to an
*observer* (``mcchain run --rerun``: a live rerun stream), which is always called on the
thread that called :func:`run_local`/:func:`run_dask`, where the chunk's results arrive —
never on the writer thread, a numba thread or a Dask worker. Because the solvers are
deterministic per sample, the data never depend on the chunking or the scheduler.

* **in-process** (default): chunks one after the other, each solved by the numba kernels on
  all threads (``threads`` sets ``numba.set_num_threads``); the sink runs on a writer thread
  apart from the compute, with at most one chunk waiting, so memory is O(chunk).
* **Dask** (``address="local"`` starts a :class:`~distributed.LocalCluster` of process
  workers, one thread each, ``NUMBA_NUM_THREADS=1`` in their environment; any other address
  is an existing scheduler): chunks are tasks, at most two per worker in flight; the kernels
  are warmed on every worker before the first chunk.

Progress (chunks done, samples/s, ETA) goes to stderr through tqdm, only on a terminal.
"""

from __future__ import annotations

import itertools
import logging
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from mcchain.model import Model

log = logging.getLogger(__name__)


class HelperCompile(Protocol):
    """What the warm-up asks of a cold first run's helper compile
    (:class:`mcchain.compiled.ahead.CompileAhead`, which imports this module: named by its
    methods here, so that the two modules form no import circle)."""

    started: float
    """``time.perf_counter()`` when the helper started (the compile notice's start)."""

    def compile_beside(self, model: Model, scene: Any) -> None:
        """Compile, in this process, what the helper leaves out."""

    def wait(self) -> None:
        """Wait until the helper has compiled (or failed)."""


SolveFn = Callable[["Model", Any], Mapping[str, Any]]
"""``solve(model_chunk, scene) -> {variable: array}`` (see ``mcchain.solvers.solve_chunk``)."""

SinkFn = Callable[[dict[str, np.ndarray], int, int], None]
"""``sink(outputs, start, stop)``: store one solved chunk (outputs already coerced)."""

ObserverFn = Callable[[dict[str, np.ndarray], int, int], None]
"""``observe(outputs, start, stop)``: look at one solved chunk (read only: the same arrays go
to the sink, possibly at the same time on the writer thread)."""

WORKER_ENV = {
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}
"""Environment of LocalCluster worker processes: one compute thread each."""


def plan_chunks(
    nsample: int, chunk_size: int, restarts: Sequence[int] = ()
) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``0:nsample`` in chunks of ``chunk_size``.

    ``restarts``: sample indices where the chunking starts again (the sizes a run had before
    ``--extend`` or an ``until`` batch added samples), so that the chunks a run computed
    before it grew are still chunks of its plan.
    """
    if nsample < 1:
        raise ValueError(f"nsample: must be >= 1, got {nsample}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size: must be >= 1, got {chunk_size}")
    bounds = sorted({0, nsample, *(b for b in restarts if 0 < b < nsample)})
    return [
        (s, min(s + chunk_size, stop))
        for begin, stop in itertools.pairwise(bounds)
        for s in range(begin, stop, chunk_size)
    ]


WARM_SAMPLES = 2
"""Samples solved to warm the kernels (compile or load them from numba's cache)."""


def warm_model(model: Model) -> Model:
    """The first few samples: enough to take every code path of a real chunk."""
    return model.select(0, min(WARM_SAMPLES, model.nsample))


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


def solve_coerced(
    solve: SolveFn, model: Model, scene: Any, history_dtype: str
) -> tuple[dict[str, np.ndarray], float, int | None]:
    """Solve one chunk and cast its arrays to storage dtypes; returns (outputs, seconds,
    the integration steps its samples took, summed: None when the solver counts none)."""
    from mcchain.ensemble.registry import STEPS_TAKEN, coerce_outputs

    t0 = time.perf_counter()
    outputs = solve(model, scene)
    seconds = time.perf_counter() - t0
    taken = outputs.get(STEPS_TAKEN)
    steps = None if taken is None else int(np.sum(taken, dtype=np.int64))
    return coerce_outputs(outputs, history_dtype), seconds, steps


# -- progress ------------------------------------------------------------------------------


class Progress:
    """Chunks done, samples/s and ETA on stderr (tqdm), silent when stderr is no terminal."""

    def __init__(self, total: int, done: int, enabled: bool | None = None) -> None:
        if enabled is None:
            enabled = sys.stderr.isatty()
        self.samples = 0
        self.t0 = time.perf_counter()
        self._bar: Any = None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(
                total=total, initial=done, unit="chunk", file=sys.stderr, dynamic_ncols=True
            )

    def update(self, samples: int) -> None:
        self.samples += samples
        if self._bar is not None:
            rate = self.samples / max(time.perf_counter() - self.t0, 1e-9)
            self._bar.set_postfix_str(f"{rate:,.0f} samples/s", refresh=False)
            self._bar.update(1)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


# -- compile notice ---------------------------------------------------------------------------

COMPILE_NOTICE_AFTER = 1.0
"""Seconds of kernel warm-up after which the compile notice is printed (a warm cache loads
in less, so a warm run prints nothing)."""


def kernel_cache_folders() -> str:
    """Where compiled kernels are kept, as the notice names them."""
    from mcchain.compiled.caches import mcchain_cache
    from mcchain.kernels.config import numba_cache

    return (
        f"numba: {numba_cache()} (NUMBA_CACHE_DIR); lane kernels: {mcchain_cache('native')} "
        "(MCCHAIN_CACHE_DIR)"
    )


@contextmanager
def compile_notice(
    after: float = COMPILE_NOTICE_AFTER, stream: Any = None, announced_at: float | None = None
) -> Iterator[None]:
    """Print one line on stderr if the block (the kernel warm-up) is still running after
    ``after`` seconds: what is compiled, that it happens once, and where it is cached; then
    how long it took. ``announced_at``: the line was printed then (:func:`announce_compile`),
    only the time is printed, counted from then."""
    import threading

    stream = sys.stderr if stream is None else stream
    t0 = time.perf_counter() if announced_at is None else announced_at
    said = threading.Event()
    if announced_at is not None:
        said.set()

    def say() -> None:
        said.set()
        announce_compile(stream)

    timer = threading.Timer(after, say)
    timer.daemon = True
    if announced_at is None:
        timer.start()
    try:
        yield
    finally:
        timer.cancel()
        if announced_at is None:
            timer.join()  # a notice being printed ends before the ready line
        if said.is_set():
            print(f"kernels ready in {time.perf_counter() - t0:.1f} s", file=stream, flush=True)


def announce_compile(stream: Any = None, ahead: bool = False) -> None:
    """The compile notice's line (``ahead``: two processes compile, see
    :mod:`mcchain.compiled.ahead`)."""
    how = " (in two processes)" if ahead else ""
    print(
        f"compiling the kernels of this scene's analyses and topology{how}: once per "
        f"installation and topology, then loaded from the cache ({kernel_cache_folders()})",
        file=sys.stderr if stream is None else stream,
        flush=True,
    )


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
    model: Model,
    scene: Any,
    chunks: Sequence[tuple[int, int]],
    sink: SinkFn,
    *,
    history_dtype: str = "float32",
    threads: int | None = None,
    solve: SolveFn | None = None,
    progress: Progress | None = None,
    observe: ObserverFn | None = None,
    compile_ahead: HelperCompile | None = None,
) -> ExecutionStats:
    """Solve ``chunks`` in this process, writing each on a thread apart from the compute.

    ``compile_ahead``: this process compiles the eigen step while that helper process
    compiles the rest into the cache; the warm-up then waits for the helper and loads it.

    ``observe`` (optional) gets each solved chunk on this thread, after the chunk is handed
    to the writer, so that writing and observing overlap; the next chunk is solved after it
    returns.
    """
    solve = solve or default_solve()
    stats = ExecutionStats(scheduler="in-process", threads=_set_threads(threads))
    t0 = time.perf_counter()
    announced = None if compile_ahead is None else compile_ahead.started
    with compile_notice(announced_at=announced):
        if compile_ahead is not None:
            compile_ahead.compile_beside(model, scene)
            compile_ahead.wait()
        solve(warm_model(model), scene)  # compile or load the cached kernels
    stats.warmup = time.perf_counter() - t0
    log.info("kernels warmed in %.2f s (%d threads)", stats.warmup, stats.threads)

    def write(outputs: dict[str, np.ndarray], start: int, stop: int) -> float:
        t = time.perf_counter()
        sink(outputs, start, stop)
        return time.perf_counter() - t

    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcchain-writer") as writer:
        pending: tuple[Future[float], tuple[int, int, float, int | None]] | None = None
        for start, stop in chunks:
            chunk = model.select(start, stop)
            outputs, seconds, steps = solve_coerced(solve, chunk, scene, history_dtype)
            stats.kernel += seconds
            if pending is not None:  # at most one chunk waits for the writer
                stats.write += pending[0].result()
                _chunk_done(stats, progress, pending[1])
            pending = (writer.submit(write, outputs, start, stop), (start, stop, seconds, steps))
            if observe is not None:
                observe(outputs, start, stop)
            del outputs
        if pending is not None:
            stats.write += pending[0].result()
            _chunk_done(stats, progress, pending[1])
    stats.compute = time.perf_counter() - t0
    return stats


def _chunk_done(
    stats: ExecutionStats, progress: Progress | None, chunk: tuple[int, int, float, int | None]
) -> None:
    start, stop, seconds, steps = chunk
    stats.chunks += 1
    stats.samples += stop - start
    if steps is not None:
        stats.steps = (stats.steps or 0) + steps
    log.info("chunk %d:%d solved in %.3f s and written", start, stop, seconds)
    if progress is not None:
        progress.update(stop - start)


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
) -> tuple[int, int, dict[str, np.ndarray], float, int | None]:
    import numba

    numba.set_num_threads(1)
    outputs, seconds, steps = solve_coerced(solve, model, scene, history_dtype)
    return start, stop, outputs, seconds, steps


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
    model: Model,
    scene: Any,
    chunks: Sequence[tuple[int, int]],
    sink: SinkFn,
    *,
    address: str,
    workers: int | None = None,
    history_dtype: str = "float32",
    solve: SolveFn | None = None,
    progress: Progress | None = None,
    observe: ObserverFn | None = None,
) -> ExecutionStats:
    """Solve ``chunks`` as Dask tasks; the results are written here, as they arrive, and
    handed to ``observe`` (optional) here too, after the write."""
    from dask.distributed import as_completed

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
        setup = client.run(_worker_setup, solve, warm_model(model), scene)
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
                    history_dtype,
                    start,
                    stop,
                    pure=False,
                )
            )

        for _ in range(min(2 * stats.workers, len(queue))):
            submit()
        for future in in_flight:
            start, stop, outputs, seconds, steps = future.result()
            future.release()
            if queue:
                submit()
            stats.kernel += seconds
            t = time.perf_counter()
            sink(outputs, start, stop)
            stats.write += time.perf_counter() - t
            if observe is not None:
                observe(outputs, start, stop)
            del outputs
            _chunk_done(stats, progress, (start, stop, seconds, steps))
        stats.compute = time.perf_counter() - t0
    return stats
