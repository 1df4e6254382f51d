"""Folders mcchain writes for itself (its caches), and what happens when one cannot be
written: it moves to the temporary folder, with one warning line on stderr. That folder has a
predictable name (``<tmp>/mcchain-<name>-<uid>``): it is used only if it is private to the
user (:func:`not_private`), since another user who made it first could plant machine code in
it (a cache file is machine code, unpickled as it is read).

A plain module: it imports nothing of mcchain, so the kernels' numba settings
(:mod:`mcchain.kernels.config`) and the caches (:mod:`mcchain.compiled.caches`) both use it.
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
