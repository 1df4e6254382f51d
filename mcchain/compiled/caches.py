"""Where compiled code is kept, and what happens when that place cannot be written.

Three caches: numba's machine code (``NUMBA_CACHE_DIR``, else beside the sources in
``__pycache__``, else numba's user-wide folder), and in ``MCCHAIN_CACHE_DIR``
(:func:`mcchain_cache`) the machine code of the generated lane kernels (``native``,
:mod:`mcchain.codegen.native`; ``generated``: their text, where numba compiles them) and the
quasi-random sample designs drawn before (:func:`mcchain.scene.sampling.unit_design`). A
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
import os
import stat
import sys
import tempfile
from pathlib import Path

_warned: set[str] = set()


def writable(folder: Path) -> bool:
    """Whether ``folder`` exists or can be made, and a file can be written in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def temporary_cache(name: str) -> Path:
    """``<tmp>/mcchain-<name>-<uid>``, made private (mode 0700) if new, or checked: a folder
    another user could write (made before by someone else, or with a wider mode) is never
    loaded from, since a cache file is machine code unpickled as it is read. Such a folder is
    replaced, for this process, by a fresh private one (``mkdtemp``), with one warning line."""
    uid = os.getuid() if hasattr(os, "getuid") else None
    folder = Path(tempfile.gettempdir()) / f"mcchain-{name}-{uid or 0}"
    fresh = _fresh.get(folder)
    if fresh is not None:
        return fresh
    with contextlib.suppress(FileExistsError):
        folder.mkdir(mode=0o700)
    problem = None if uid is None else not_private(folder, uid)
    if problem is None:
        return folder
    fresh = Path(tempfile.mkdtemp(prefix=f"mcchain-{name}-{uid}-"))
    _fresh[folder] = fresh
    print(
        f"mcchain: warning: {folder} is not private ({problem}): it is not used, compiled "
        f"kernels are cached in {fresh} for this process only",
        file=sys.stderr,
        flush=True,
    )
    return fresh


_fresh: dict[Path, Path] = {}
"""The private folders made instead of temporary caches that failed :func:`not_private`."""


def not_private(folder: Path, uid: int) -> str | None:
    """Why ``folder`` is not a private folder of user ``uid`` (a folder, not a link, owned by
    ``uid``, that no one else may write or read), or None if it is."""
    try:
        info = os.lstat(folder)
    except OSError as exc:
        return f"cannot be read: {exc.strerror}"
    if stat.S_ISLNK(info.st_mode):
        return "a symbolic link"
    if not stat.S_ISDIR(info.st_mode):
        return "not a folder"
    if info.st_uid != uid:
        return f"owned by uid {info.st_uid}"
    if info.st_mode & 0o077:
        return f"mode {stat.S_IMODE(info.st_mode):04o}, not 0700"
    return None


def warn_fallback(what: str, folder: Path | str, fallback: Path) -> None:
    """One line on stderr (once per process and cache) that ``folder`` is not writable."""
    if what in _warned:
        return
    _warned.add(what)
    print(
        f"mcchain: warning: {what} {folder} cannot be written: compiled kernels are cached in "
        f"{fallback} instead (set {what} to a writable folder to keep them across reboots)",
        file=sys.stderr,
        flush=True,
    )


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
    in_tree = Path(__file__).parents[1] / "kernels" / "__pycache__"
    if writable(in_tree):
        return "beside mcchain's sources (__pycache__)"
    user_wide = Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)
    if writable(user_wide):
        return str(user_wide)
    fallback = temporary_cache("numba")
    warn_fallback("NUMBA_CACHE_DIR", in_tree.parent, fallback)
    config.CACHE_DIR = str(fallback)  # type: ignore[attr-defined]
    return str(fallback)


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
