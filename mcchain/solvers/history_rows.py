"""The loop kernels' histories as float64 rows, stored in the history arrays' own type.

The loop kernels (:func:`mcchain.kernels.explicit.rk4_run`,
:func:`mcchain.kernels.implicit.generalized_alpha_run`) and Radau's writes
(:func:`mcchain.kernels.explicit.write_outputs`) take float64 histories only. numba compiles a
kernel once per type of its arrays, and each of these call trees takes 10-20 s of CPU to
compile: float32 histories (the product's default) beside float64 ones (the ideal mechanism's
tabulated run, references) compiled each of them twice. Where the histories are float32, a
kernel writes a block of samples into float64 rows, which are then stored: the same values
(each float64 rounded to float32 as IEEE's conversion rounds it, which a store of the kernel
did before).
"""

from __future__ import annotations

import numpy as np

ROWS_BLOCK = 32
"""Most samples a loop kernel writes in float64 rows before they are stored, where the
histories are float32: the rows' memory is that block's histories at 8 bytes a value."""


def float64_rows(flat: tuple[np.ndarray, ...], start: int, stop: int) -> tuple[np.ndarray, ...]:
    """The rows of samples ``start:stop`` of the history arrays ``flat`` (each (sample, time,
    ...)) as float64 arrays: views of the float64 ones, new arrays for the others (to be
    stored with :func:`store_rows`)."""
    return tuple(
        a[start:stop] if a.dtype == np.float64 else np.empty((stop - start, *a.shape[1:]))
        for a in flat
    )


def store_rows(flat: tuple[np.ndarray, ...], start: int, rows: tuple[np.ndarray, ...]) -> None:
    """Store the rows of :func:`float64_rows` (samples from ``start`` on) into ``flat``
    where they are not its own views."""
    for array, block in zip(flat, rows, strict=True):
        if array.dtype != np.float64:
            array[start : start + block.shape[0]] = block
