"""Blocks of samples (or lane groups) run on threads: how the kernels use every core.

Every batch kernel is a serial numba function over ``start:stop`` that releases the GIL, so
a thread pool runs contiguous blocks side by side. A ``prange`` loop did the same but made
numba build, optimise and emit each kernel's whole call tree once more for the parallel
body (benchmarks/results/startup/breakdown.md). Samples never interact, so each sample's numbers do
not depend on the blocks or the thread count. A kernel that takes its samples from a queue
(the lane kernels) runs once on every thread instead (:func:`on_every_thread`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from mcchain.kernels import config

BLOCKS_PER_THREAD = 4
"""Blocks per thread: items differ in cost (Newton iterations, adaptive steps), so a thread
that finishes early takes another block."""
MIN_BLOCK = 16
"""Fewest samples in a block of a static kernel, so a small batch stays on one thread."""


def item_blocks(
    count: int,
    threads: int,
    min_block: int = 1,
    per_thread: int = BLOCKS_PER_THREAD,
    max_block: int | None = None,
) -> list[tuple[int, int]]:
    """Contiguous ``(start, stop)`` blocks covering ``0:count`` for ``threads`` threads
    (``per_thread`` blocks each), each at least ``min_block`` long (but one) and, where
    ``max_block`` is given, at most that long (more blocks then)."""
    nblock = max(1, min(threads * per_thread, count // min_block))
    if max_block is not None:
        nblock = max(nblock, -(-count // max_block))
    edges = [count * k // nblock for k in range(nblock + 1)]
    return [(a, b) for a, b in itertools.pairwise(edges) if b > a]


def _numba_threads() -> int:
    import numba

    return int(numba.get_num_threads())


def over_samples(
    kernel: Callable[..., Any],
    count: int,
    *args: Any,
    min_block: int = MIN_BLOCK,
    per_thread: int = BLOCKS_PER_THREAD,
    max_block: int | None = None,
) -> None:
    """Call ``kernel(start, stop, *args)`` on blocks covering ``0:count`` (samples, or lane
    groups with ``min_block=1``), on as many threads as numba may use
    (``numba.get_num_threads()``, which ``--threads`` sets; one where the kernels run
    interpreted, :func:`mcchain.kernels.config.interpret_kernels`); ``per_thread`` blocks
    per thread (more where blocks would be longer than ``max_block``)."""
    threads = 1 if config.INTERPRETED else _numba_threads()
    blocks = item_blocks(count, threads, min_block, per_thread, max_block)
    if threads == 1 or len(blocks) == 1:
        for start, stop in blocks:
            kernel(start, stop, *args)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for future in [pool.submit(kernel, start, stop, *args) for start, stop in blocks]:
            future.result()


def on_every_thread(kernel: Callable[..., Any], count: int, *args: Any) -> None:
    """Call ``kernel(0, count, *args)`` once on each thread numba may use (once in all where
    the kernels run interpreted): a kernel whose threads share its items through a queue
    in ``args`` (:func:`mcchain.kernels.config.take_next`), so that a thread which finishes
    early takes the others' remaining items one at a time instead of waiting."""
    threads = 1 if config.INTERPRETED else _numba_threads()
    if threads == 1:
        kernel(0, count, *args)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for future in [pool.submit(kernel, 0, count, *args) for _ in range(threads)]:
            future.result()
