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

The kernels are decorated with :func:`njit`, which is numba's unless this process runs them
interpreted (:func:`interpret_kernels`): as plain Python functions on the same arrays, one
sample at a time, without importing numba.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

from mcchain.folders import temporary_cache, warn_fallback, writable

INTERPRETED = False
"""True where :func:`interpret_kernels` took effect: the kernels are plain Python."""

INTERPRET_MAX_COORDINATES = 100
"""Largest scene (3 coordinates per body) whose kernels a command may run interpreted: their
time grows with the cube of the size or faster (``mcchain validate`` of a 32-bar chain,
96 coordinates: 0.64 s, against 1.04 s compiled in all; a sample of a 16-bar chain's
statics, 48 coordinates: 6 s), the compiled kernels' hardly."""

hypot: Callable[[float, float], float] = math.hypot
"""√(x² + y²) as the kernels call it: ``math.hypot``, which numba compiles to libm's
``hypot``; ``numpy.hypot`` (libm's as well) where they run interpreted. Python's own
``math.hypot`` can differ from libm's in the last place, and a position 1 ulp off moved an
eigenpulsation by 2e-13: with libm's in both, interpreted and compiled kernels give the same
bits on every shipped scene."""


def fma(a: float, b: float, c: float) -> float:
    """a·b + c rounded once (IEEE 754 fused multiply-add), as the kernels call it.

    Compiled (numba, and the lane text through :mod:`mcchain.codegen.native`) it is LLVM's
    ``llvm.fma`` (:func:`register_intrinsics`), one instruction on a CPU with FMA; here, where the
    kernels run interpreted, the exact product and sum in rationals rounded once (the same
    value for finite operands and result, but the sign of a zero result: +0.0); with an inf
    or NaN operand or an overflowing result, a·b + c as Python rounds it (the same inf or
    NaN)."""
    try:
        return float(Fraction(a) * Fraction(b) + Fraction(c))
    except (ValueError, OverflowError):
        return a * b + c


def prefetch(array: Any, sample: int, index: int) -> None:
    """A hint that the lane kernels will soon write the row ``array[sample, index]`` (its
    first element's cache line): nothing to compute, no value. Compiled through
    :mod:`mcchain.codegen.native` it is ``llvm.prefetch`` for a write (``prefetchw``; an
    address past the array is allowed: a prefetch never faults); numba's compile of the same
    text (:func:`register_intrinsics`) and plain Python do nothing."""


def take_next(queue: Any) -> int:
    """The next item of a queue that threads share: ``queue[0]`` (an int64 array) before it
    is raised by one, as one atomic step where the kernels are compiled (``atomicrmw add``,
    through :mod:`mcchain.codegen.native` and numba alike: :func:`register_intrinsics`), so
    that threads taking items of one queue take each exactly once. Interpreted kernels run on
    one thread (:func:`mcchain.solvers.threads.on_every_thread`)."""
    item = int(queue[0])
    queue[0] = item + 1
    return item


@functools.cache
def register_intrinsics() -> None:
    """:func:`fma` compiled by numba as ``llvm.fma``, :func:`prefetch` as nothing and
    :func:`take_next` as an atomic add (once per process; before a kernel that calls them
    is compiled: :func:`njit` and the numba-compiled lane modules call this)."""
    from llvmlite import ir
    from numba.core import types
    from numba.extending import intrinsic, overload

    @intrinsic
    def llvm_fma(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            double = ir.DoubleType()
            function = builder.module.declare_intrinsic(
                "llvm.fma", [double], ir.FunctionType(double, [double] * 3)
            )
            return builder.call(function, args)

        return types.float64(types.float64, types.float64, types.float64), codegen

    @overload(fma)
    def fma_compiled(a, b, c):  # type: ignore[no-untyped-def]  # numba: as fma's signature
        return lambda a, b, c: llvm_fma(float(a), float(b), float(c))

    @overload(prefetch)
    def prefetch_compiled(array, sample, index):  # type: ignore[no-untyped-def]  # as above
        return lambda array, sample, index: None

    @intrinsic
    def atomic_take(typingctx: Any, queue: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            array = context.make_array(signature.args[0])(context, builder, args[0])
            one = ir.Constant(ir.IntType(64), 1)
            return builder.atomic_rmw("add", array.data, one, "monotonic")

        return types.int64(queue), codegen

    @overload(take_next)
    def take_next_compiled(queue):  # type: ignore[no-untyped-def]  # as above
        if not (isinstance(queue, types.Array) and queue.dtype == types.int64):
            raise TypeError("take_next: the queue is an int64 array")
        return lambda queue: atomic_take(queue)


def interpret_kernels() -> bool:
    """Run the kernels of this process as plain Python, without numba, and return whether
    they will: only possible before the first kernel module is imported (otherwise they stay
    compiled, and nothing changes).

    For a check of one instance (``mcchain validate``): importing numba and its first
    dispatch cost about 0.6 s, the interpreted check of a small mechanism about 0.2 s. The
    values are the compiled kernels' bit for bit on every shipped scene (the same IEEE
    operations in the same order, libm's :data:`hypot` in both; tested), but a degenerate
    instance can raise where numba gives inf or NaN (a Python float divided by zero,
    ``math.sqrt`` of a negative number): the caller must treat any exception as "use the
    compiled kernels".
    """
    global INTERPRETED, hypot
    loaded = [name for name in sys.modules if name.startswith("mcchain.kernels.")]
    if any(name != __name__ for name in loaded) and not INTERPRETED:
        return False
    import numpy as np

    INTERPRETED = True
    hypot = np.hypot
    return True


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit(*args, **options)``, or the function unchanged where the kernels run
    interpreted (:data:`INTERPRETED`)."""
    if INTERPRETED:
        if args and callable(args[0]):
            return args[0]
        return lambda function: function
    numba_cache()  # a writable cache, before any kernel is decorated with cache=True
    register_intrinsics()
    from numba import njit as numba_njit

    if args and callable(args[0]):
        return _loaded_lightly(_one_compile_per_type(numba_njit(*args, **options)))
    decorate = numba_njit(*args, **options)
    return lambda function: _loaded_lightly(_one_compile_per_type(decorate(function)))


def _one_compile_per_type(dispatcher: Any) -> Any:
    """``dispatcher`` compiled once per type of its arguments, not once per constant.

    Called from another kernel with a constant, as in ``cubic_peak(..., 0)``, numba types the
    argument as ``Literal[int](0)`` and compiles a specialisation for that value: a helper
    called with 0, 1 and 2 compiled four times (each ~0.2-0.5 s, with every function it calls
    optimised again), though the ``int64`` one serves them all. Here a call from a kernel
    asks for the argument types without their literal values. The values are the same: an
    integer argument reaches the same arithmetic whether numba folded it in before LLVM or
    LLVM after inlining the callee (no fast-math in these kernels); only the number of
    compiles falls (a cold compile of the loop kernels, Radau and generalized-α on the
    contact-start tests: 203 compiles, 101 s of CPU, before; 181 and 87 s after).
    """
    from numba.core import types

    by_value = dispatcher.get_call_template

    def by_type(args: tuple[Any, ...], kws: dict[str, Any]) -> Any:
        return by_value(
            tuple(types.unliteral(a) for a in args),
            {name: types.unliteral(a) for name, a in kws.items()},
        )

    dispatcher.get_call_template = by_type
    return dispatcher


def _loaded_lightly(dispatcher: Any) -> Any:
    """``dispatcher`` whose machine code, where numba's cache holds it, is loaded by
    :func:`load_cached` (a dispatcher without ``cache=True`` is returned unchanged)."""
    cache = getattr(dispatcher, "_cache", None)
    if cache is not None and hasattr(cache, "_load_overload"):
        cache.load_overload = functools.partial(load_cached, cache)
    return dispatcher


def load_cached(cache: Any, signature: Any, target_context: Any) -> Any:
    """A kernel's machine code from numba's cache (``cache``: a dispatcher's), as numba's
    ``Cache.load_overload`` loads it, but without refreshing ``target_context`` first.

    That refresh installs the implementations of every function numba can compile (its
    registries: 0.3 s of CPU, and ``scipy.linalg``, which ``numba.np.arraymath`` imports to
    check for BLAS: 0.2 s more), on each process's first cached load; a warm run compiles
    nothing, and loading machine code needs only numba's runtime (NRT, initialised here).
    A compile refreshes the contexts itself (``numba.core.compiler``), and compiled code
    that calls LAPACK imports SciPy's when it first does. Where loading raises, numba's own
    load (with the refresh) is tried.
    """
    from numba.core.runtime import rtsys

    try:
        rtsys.initialize(target_context)
        with cache._guard_against_spurious_io_errors():
            return cache._load_overload(signature, target_context)
        return None  # the guard swallowed an I/O error: compiled, as numba does
    except Exception:
        return type(cache).load_overload(cache, signature, target_context)


@functools.cache
def numba_cache() -> str:
    """Where numba caches the kernels, made writable before any kernel is decorated with
    ``cache=True`` (:func:`ensure_numba_cache`), its kernels of other sources dropped
    (:func:`drop_stale_kernels`); once per process."""
    try:
        where = ensure_numba_cache()
    except ImportError:  # generating kernel source needs these options, not numba itself
        return "none (numba is not importable)"
    drop_stale_kernels()
    return where


KERNEL_SOURCE_DIRS = ("", "kernels", "codegen", "testing")
"""Folders of the mcchain package (relative; "" the top level: codes, status, contact) whose
``.py`` files the numba kernels are compiled from, callees and constants included."""
KERNEL_STAMP = "mcchain-kernel-sources.sha256"
"""File beside numba's cache files of a folder: the digest of the sources they came from."""


def package_sources_digest(patterns: tuple[str, ...] = ("**/*.py",)) -> str:
    """Hash of the mcchain package's files matching ``patterns`` (relative glob patterns;
    paths and bytes, in sorted order)."""
    import hashlib

    package = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for pattern in patterns:
        for path in sorted(package.glob(pattern)):
            h.update(str(path.relative_to(package)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def kernel_sources_digest() -> str:
    """Hash of the ``.py`` files of :data:`KERNEL_SOURCE_DIRS` (paths and bytes)."""
    return package_sources_digest(tuple(f"{d}/*.py" if d else "*.py" for d in KERNEL_SOURCE_DIRS))


def kernel_cache_folders() -> list[Path]:
    """Where numba keeps the cached kernels of each folder of :data:`KERNEL_SOURCE_DIRS`
    (its own locators' rule: ``NUMBA_CACHE_DIR``, beside the sources, or user-wide)."""
    from numba import config
    from numba.core.caching import _CacheLocator
    from numba.misc.appdirs import AppDirs

    package = Path(__file__).resolve().parents[1]
    sources = [package / folder / "x.py" for folder in KERNEL_SOURCE_DIRS]
    configured = getattr(config, "CACHE_DIR", "")
    in_tree = package / "kernels" / "__pycache__"
    if not configured and writable(in_tree):
        return [source.parent / "__pycache__" for source in sources]
    root = configured or AppDirs(appname="numba", appauthor=False).user_cache_dir
    return [Path(root) / _CacheLocator.get_suitable_cache_subpath(str(s)) for s in sources]


def drop_stale_kernels() -> int:
    """Remove numba's cached kernels compiled from other sources than these.

    Numba checks a cached function against its own file's time stamp only, yet a kernel
    holds the code of the functions it calls (inlined from other files) and the constants it
    reads: after an edit of a callee, or an update that leaves a caller's file alone, it
    would load the old callee's machine code (with 0-length histories, stores past the end
    of an array). A digest of every kernel source is kept beside the cache files; when it
    differs, mcchain's cached kernels are removed (numba compiles them again). Returns the
    number of files removed."""
    import os

    digest = kernel_sources_digest()
    removed = 0
    for folder in kernel_cache_folders():
        stamp = folder / KERNEL_STAMP
        try:
            if stamp.read_text(encoding="ascii").strip() == digest:
                continue
        except OSError:  # no stamp: a cache of an older mcchain, or none yet
            pass
        if not folder.is_dir():
            continue
        for path in folder.iterdir():
            if path.suffix in (".nbi", ".nbc"):
                try:
                    path.unlink()
                    removed += 1
                except OSError:  # another process removed it, or it is not ours to remove
                    pass
        try:
            temporary = folder / f".{KERNEL_STAMP}.{os.getpid()}"
            temporary.write_text(digest + "\n", encoding="ascii")
            os.replace(temporary, stamp)
        except OSError:  # read-only cache: numba falls back as ensure_numba_cache says
            pass
    return removed


def ensure_numba_cache() -> str:
    """Make sure numba has a writable cache location before any kernel is decorated.

    Numba tries ``NUMBA_CACHE_DIR``, then ``__pycache__`` beside each source, then its
    user-wide folder, and raises at decoration when none can be written. This picks the
    temporary folder (and warns) where the one it would use is not writable.

    Returns:
        The folder numba caches mcchain's kernels in, for messages.
    """
    from numba import config
    from numba.misc.appdirs import AppDirs

    configured = getattr(config, "CACHE_DIR", "")
    if configured:
        if writable(Path(configured)):
            return str(configured)
        fallback = temporary_cache("numba")
        warn_fallback("NUMBA_CACHE_DIR", configured, fallback)
        config.CACHE_DIR = str(fallback)  # type: ignore[attr-defined]
        return str(fallback)
    in_tree = Path(__file__).parent / "__pycache__"
    if writable(in_tree):
        return "beside mcchain's sources (__pycache__)"
    user_wide = Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)
    if writable(user_wide):
        return str(user_wide)
    fallback = temporary_cache("numba")
    warn_fallback("NUMBA_CACHE_DIR", in_tree.parent, fallback)
    config.CACHE_DIR = str(fallback)  # type: ignore[attr-defined]
    return str(fallback)


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
