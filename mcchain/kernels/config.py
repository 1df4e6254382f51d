"""Numba settings for every kernel, in one place.

* ``cache=True``: compiled kernels are stored beside the sources, so CI and users compile
  once (PERFORMANCE.md: a prange kernel took 11.5 s cold, 0.46 s from cache).
* ``fastmath=False``: results stay reproducible and bit-identical across thread counts.
* ``nogil=True``: batch kernels run blocks of samples on threads side by side
  (:mod:`mcchain.solvers.threads`), and beside the writer thread.
* ``error_model="numpy"``: a division by zero gives inf/NaN (then a status bit) instead of
  raising ZeroDivisionError, which would end a whole block for one sample.

No kernel is ``parallel=True``: numba's parallel loops compiled every kernel's call tree once
more (the threads of :mod:`mcchain.solvers.threads` run as fast).
"""

from mcchain.caches import ensure_numba_cache

try:
    NUMBA_CACHE = ensure_numba_cache()  # before any kernel is decorated with cache=True
except ImportError:  # generating kernel source needs these options, not numba itself
    NUMBA_CACHE = "none (numba is not importable)"
"""Where numba caches the kernels (a writable folder; see :mod:`mcchain.caches`)."""

JIT = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")
"""Options of hand-written kernels (``@njit(**JIT)``)."""

INLINE = dict(JIT, inline="always")
"""Options of small helpers and of functions with one caller: numba inlines their body into
the caller's before typing. Each function numba compiles on its own costs about 0.3 s
(typing, and LLVM optimising and emitting it with every function it calls, again at every
level of the call tree): the Quick start's cold compile lost a quarter this way."""

LANE_JIT = dict(JIT, fastmath={"contract"})
"""Options of generated lane kernels (``mcchain.codegen`` writes them into the module's header).

fastmath "contract" only: a·b + c may become one fused multiply-add (≈ 1.25× faster lanes,
rounding no worse). No reassociation or finite-math assumptions, so NaN still propagates to
the failure checks, and every lane runs the same instructions: results stay bit-identical
across thread counts, lane counts and chunk sizes (tested)."""
