"""Where compiled code is kept, and what happens when that place cannot be written.

Three caches: numba's machine code (``NUMBA_CACHE_DIR``, else beside the sources in
``__pycache__``, else numba's user-wide folder), and in ``MCCHAIN_CACHE_DIR``
(:func:`mcchain_cache`) the machine code of the generated lane kernels (``native``,
:mod:`mcchain.codegen.native`; ``generated``: their text, where numba compiles them), their
text as generated (``lane-text``, :func:`generated_text`: a warm run reads it instead of
generating it again) and the quasi-random sample designs drawn before
(:func:`mcchain.scene.sampling.unit_design`). A
cache that cannot be written (a read-only home or installation) never stops a run: the cache
moves to the temporary folder, with one warning line on stderr, and kernels then compile once
per machine boot instead of once per installation. That folder has a predictable name
(``<tmp>/mcchain-<name>-<uid>``): it is used only if it is private to the user
(:func:`not_private`), since another user who made it first could plant machine code in it.

A plain module: it imports nothing of mcchain, so the kernels (:mod:`mcchain.kernels.config`)
and the code generator both use it without a cycle. What ``mcchain cache status`` reports is
in :mod:`mcchain.compiled.report`.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from mcchain.folders import temporary_cache, warn_fallback, writable


def mcchain_cache(name: str) -> Path:
    """The folder ``name`` of mcchain's cache: under ``$MCCHAIN_CACHE_DIR``, else
    ``~/.cache/mcchain`` (``<tmp>/mcchain-<name>-<uid>`` with a warning when that cannot be
    written)."""
    root = os.environ.get("MCCHAIN_CACHE_DIR")
    if root:
        path = Path(root)
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        path = Path(base) / "mcchain"
    if writable(path / name):
        return path / name
    fallback = temporary_cache(name)
    warn_fallback("MCCHAIN_CACHE_DIR", path, fallback)
    return fallback


def numba_index_folder() -> Path | None:
    """The folder in which numba keeps the index files of mcchain's hand-written kernels
    (``mcchain/kernels``), worked out as :func:`ensure_numba_cache` and numba's cache
    locators choose it (``NUMBA_CACHE_DIR``, else ``__pycache__`` beside the sources, else
    numba's user-wide folder, else the temporary one), without importing numba or a kernel
    module. None on Windows, whose user-wide folder this does not look up."""
    import hashlib

    sources = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep + "kernels"
    subpath = "kernels_" + hashlib.sha1(sources.encode()).hexdigest()
    configured = os.environ.get("NUMBA_CACHE_DIR")
    if configured:
        root = Path(configured) if writable(Path(configured)) else temporary_cache("numba")
        return root / subpath
    in_tree = Path(sources) / "__pycache__"
    if writable(in_tree):
        return in_tree
    if sys.platform == "win32":
        return None
    if sys.platform == "darwin":
        user_wide = Path.home() / "Library" / "Caches" / "numba"
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        user_wide = Path(base) / "numba"
    return (user_wide if writable(user_wide) else temporary_cache("numba")) / subpath


def kernels_cached(kernels: list[str]) -> bool | None:
    """Whether numba's cache holds an index for every kernel named in ``kernels``
    (``"module.function"`` in ``mcchain.kernels``, e.g. ``"assembly.assemble_batch"``),
    without importing numba or the kernels: a kernel module's import decorates its kernels,
    which imports numba (0.4 s). None: cannot tell (Windows, :func:`numba_index_folder`).

    An index names the function's first line, which this does not parse: any line counts.
    A kernel edited since it was cached is compiled again however this answers."""
    folder = numba_index_folder()
    if folder is None:
        return None
    suffix = f".py{sys.version_info[0]}{sys.version_info[1]}.nbi"
    return all(any(folder.glob(f"{name}-*{suffix}")) for name in kernels)


def write_atomically(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file renamed onto it, so that a reader
    never sees it half written; a cache that cannot be written is passed over silently (the
    next process makes the data again)."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except OSError:
        pass


@contextlib.contextmanager
def compile_turn(path: Path) -> Iterator[None]:
    """Run the block holding the exclusive lock (``flock``) of the lock file ``path``,
    created if missing: processes that would compile the same cache file at once (commands
    started side by side on a cold cache, two test workers) take turns, and the later one
    finds the file the first wrote instead of compiling it again. Where no
    lock can be taken (no ``fcntl``, a cache folder on NFS without locks, an unwritable
    folder) the block runs without one, as two compiles at once did: the same file twice.

    The lock file is removed when the turn ends (no file left per cache entry): a process
    that opened it before then still takes its turn after this one, on the removed file,
    and finds the cache file written; one arriving later makes a new lock file. At worst
    (a turn that wrote nothing) two processes compile the same file, never a wrong one."""
    try:
        import fcntl

        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
    except (ImportError, OSError):
        yield
        return
    try:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        os.close(fd)  # releases the lock


def evict_oldest(
    folder: Path, max_bytes: int, keep: Path | None = None, pattern: str = "*.bin"
) -> list[Path]:
    """Remove the files ``pattern`` of ``folder`` used least recently (modification time,
    touched at every load) until they hold at most ``max_bytes``; never ``keep`` (the file
    just written). Returns the files removed."""
    files = []
    for path in folder.glob(pattern):
        with contextlib.suppress(OSError):
            info = path.stat()
            files.append((info.st_mtime, info.st_size, path))
    total = sum(size for _, size, _ in files)
    removed = []
    for _, size, path in sorted(files):
        if total <= max_bytes:
            break
        if path == keep:
            continue
        with contextlib.suppress(OSError):
            path.unlink()
            removed.append(path)
            total -= size
    return removed


@functools.cache
def sources_digest() -> str:
    """Hash of every ``.py`` file of the mcchain package (paths and bytes): whatever mcchain
    generates from its own code is keyed by it, so an edited source never meets a text made
    by the old one (6 ms for the whole package)."""
    from mcchain.kernels.config import package_sources_digest

    return package_sources_digest()


TEXT_MAX_BYTES = 64 << 20
"""Size above which the least recently used generated texts are removed."""


def generated_text(name: str, key: str, make: Callable[[], str]) -> str:
    """The text ``make()`` returns, kept in mcchain's cache (``lane-text``) under ``name`` and
    the hash of ``key`` (everything besides mcchain's sources that ``make`` reads: a
    topology, a variant, the target CPU) and :func:`sources_digest`: a warm run reads the
    text instead of making it again (the Flores slider-crank's rk45 lane text: 0.13 s of CPU
    once the generator is imported, 0.7 s with its first call's imports)."""
    folder = mcchain_cache("lane-text")
    digest = hashlib.sha256(f"{key}\0{sources_digest()}".encode()).hexdigest()[:24]
    path = folder / f"{name}-{digest}.txt"
    with contextlib.suppress(OSError, UnicodeDecodeError):
        text = path.read_text(encoding="utf-8")
        with contextlib.suppress(OSError):
            os.utime(path)  # recently used: the last to be evicted
        return text
    text = make()
    write_atomically(path, text.encode("utf-8"))
    evict_oldest(folder, TEXT_MAX_BYTES, keep=path, pattern="*.txt")
    return text
