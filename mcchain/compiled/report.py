"""What ``mcchain cache status`` and ``mcchain cache clear`` report: the files in mcchain's
cache folders (:func:`mcchain.compiled.caches.mcchain_cache`) and numba's files of mcchain's
kernels (:func:`mcchain.compiled.caches.numba_index_folder`), the versions and CPU the lane
kernels are keyed by, and the background compile's state. Only the CLI imports this module.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

from mcchain.compiled.caches import mcchain_cache, numba_index_folder

MCCHAIN_FOLDERS = ("native", "generated", "lane-text", "compile", "designs")
"""The folders of mcchain's cache (:func:`mcchain_cache`): the lane kernels' machine code
(:mod:`mcchain.codegen.native`) and text (where numba compiles it; as generated, read by warm
runs: :func:`mcchain.compiled.caches.generated_text`), the background
compile's lock, record and log (:mod:`mcchain.compiled.background`), the sample designs."""

NUMBA_SUFFIXES = (".nbi", ".nbc")
"""numba's index and machine-code files (of mcchain's kernels in :func:`numba_index_folder`;
those of the generated modules in the ``generated`` folder's ``__pycache__``)."""


def _files(folder: Path, suffixes: tuple[str, ...] | None = None) -> list[Path]:
    if not folder.is_dir():
        return []
    found = [p for p in folder.rglob("*") if p.is_file()]
    return [p for p in found if suffixes is None or p.suffix in suffixes]


def _size(files: list[Path]) -> str:
    total = 0
    for path in files:
        with contextlib.suppress(OSError):
            total += path.stat().st_size
    return f"{len(files)} files, {total / 1e6:.1f} MB"


def status_lines() -> list[str]:
    """What ``mcchain cache status`` prints: each cache folder with its files and size, the
    lane kernels compiled by variant and entry point, the versions and target CPU their
    machine code is keyed by, and the background compile's state."""
    import re

    lines = []
    for name in MCCHAIN_FOLDERS:
        folder = mcchain_cache(name)
        lines.append(f"{name}: {folder} ({_size(_files(folder))})")
        if name == "native":
            entries: dict[str, int] = {}
            for path in _files(folder, (".bin",)):
                match = re.match(
                    r"mcchain_gen_(\w+?)_[0-9a-f]{20}-(\w+)-[0-9a-f]+\.bin$", path.name
                )
                what = f"{match[1]}.{match[2]}" if match else "others (not lane kernels)"
                entries[what] = entries.get(what, 0) + 1
            for what, count in sorted(entries.items()):
                lines.append(f"  {what}: {count} compiled (scenes × argument types)")
    numba_folder = numba_index_folder()
    if numba_folder is not None:
        lines.append(
            f"numba (mcchain's kernels): {numba_folder} "
            f"({_size(_files(numba_folder, NUMBA_SUFFIXES))})"
        )
    from mcchain.codegen.layout import LMAX, target_cpu
    from mcchain.codegen.native import key_versions, lane_compiler

    cpu, _features = target_cpu()
    lines.append(f"lane kernels: compiled by {lane_compiler()}, for CPU {cpu}, {LMAX} lanes")
    lines.append("keyed by: " + ", ".join(key_versions()))
    from mcchain.compiled.background import read_background

    record = read_background()
    if record is not None:
        state = record.get("state")
        detail = record.get("error") if state in ("failed", "ended") else record.get("scene")
        lines.append(f"background compile: {state} ({detail})")
    return lines


def clear() -> list[str]:
    """Remove all of mcchain's cached files (``mcchain cache clear``): its folders
    (:data:`MCCHAIN_FOLDERS`) and numba's files of mcchain's kernels. Returns one line per
    folder, saying what it removed."""
    import shutil

    lines = []
    for name in MCCHAIN_FOLDERS:
        folder = mcchain_cache(name)
        files = _files(folder)
        removed = _size(files)
        for child in list(folder.iterdir()):
            with contextlib.suppress(OSError):
                if child.is_dir() and not child.is_symlink():
                    shutil.rmtree(child)
                else:
                    child.unlink()
        lines.append(f"{name}: removed {removed} from {folder}")
    numba_folder = numba_index_folder()
    if numba_folder is not None:
        files = _files(numba_folder, NUMBA_SUFFIXES)
        removed = _size(files)
        for path in files:
            with contextlib.suppress(OSError):
                path.unlink()
        lines.append(f"numba (mcchain's kernels): removed {removed} from {numba_folder}")
    return lines
