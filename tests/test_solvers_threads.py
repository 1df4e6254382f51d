"""Blocks of samples on threads (mcchain.solvers.threads): every sample exactly once, in
contiguous blocks, whatever the thread count."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from mcchain.solvers.threads import MIN_BLOCK, item_blocks, over_samples


@pytest.mark.parametrize("count", [0, 1, 7, 16, 100, 1000, 12345])
@pytest.mark.parametrize("threads", [1, 2, 3, 8])
@pytest.mark.parametrize("min_block", [1, MIN_BLOCK])
def test_item_blocks__cover_every_item_once_in_order(count, threads, min_block) -> None:
    blocks = item_blocks(count, threads, min_block)
    assert [i for a, b in blocks for i in range(a, b)] == list(range(count))
    assert all(b - a >= min_block for a, b in blocks) or len(blocks) == 1


def _count_visits(start: int, stop: int, visits: np.ndarray) -> None:
    visits[start:stop] += 1  # disjoint blocks: no two threads touch one element


@pytest.mark.parametrize("threads", [1, 2])
def test_over_samples__calls_the_kernel_once_per_sample(threads: int) -> None:
    previous = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        visits = np.zeros(1000, dtype=np.int64)
        over_samples(_count_visits, visits.size, visits)
        np.testing.assert_array_equal(visits, 1)
    finally:
        numba.set_num_threads(previous)
