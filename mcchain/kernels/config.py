"""Numba settings for every kernel, in one place.

* ``cache=True``: compiled kernels are stored beside the sources, so CI and users compile
  once (PERFORMANCE.md: a prange kernel took 11.5 s cold, 0.46 s from cache).
* ``fastmath=False``: results stay reproducible and bit-identical across thread counts.
* ``nogil=True``: a kernel can run on a writer/worker thread beside Python code.
* ``error_model="numpy"``: a division by zero gives inf/NaN (then a status bit) instead of
  raising ZeroDivisionError, which a ``prange`` loop would lose (PERFORMANCE.md).
"""

JIT = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")
"""Options of serial kernels (``@njit(**JIT)``)."""

PJIT = dict(JIT, parallel=True)
"""Options of batch kernels that loop ``prange`` over samples or lane groups.

A ``prange`` index is int64 when the kernel is typed and uint64 inside the parallel body that
numba builds from it, so a callee taking the index is compiled twice unless the index is cast:
every batch kernel passes ``np.int64(index)`` (measured: erk_group's cold compile halved)."""

LANE_JIT = dict(JIT, fastmath={"contract"})
"""Options of generated lane kernels (``mcchain.codegen`` writes them into the module's header).

fastmath "contract" only: a·b + c may become one fused multiply-add (≈ 1.25× faster lanes,
rounding no worse). No reassociation or finite-math assumptions, so NaN still propagates to
the failure checks, and every lane runs the same instructions: results stay bit-identical
across thread counts, lane counts and chunk sizes (tested)."""

LANE_PJIT = dict(LANE_JIT, parallel=True)
"""Options of generated batch lane kernels (``prange`` over lane groups)."""
