"""Where a run was made: software versions, the git state of mcchain, the host.

``run.json`` records all three; ``ensemble.nc`` records the versions only (it holds no host
name or timestamp, so the same scene and seed give a byte-identical file anywhere).

This module imports only the standard library at import time (netCDF4 is imported when the
versions are read).
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import os
import platform
import socket
import subprocess
from pathlib import Path
from typing import Any

from mcchain import __version__

DEPENDENCIES = ("numpy", "numba", "llvmlite", "scipy", "xarray", "netCDF4", "pydantic")
"""Packages whose versions are recorded in ``ensemble.nc`` and ``run.json``."""


def software_versions() -> dict[str, str]:
    """mcchain, Python, the dependencies, and the netCDF-C/HDF5 libraries."""
    versions = {"mcchain": __version__, "python": platform.python_version()}
    for name in DEPENDENCIES:
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            versions[name] = importlib.metadata.version(name)
    try:
        import netCDF4

        versions["netcdf-c"] = str(netCDF4.__netcdf4libversion__)
        versions["hdf5"] = str(netCDF4.__hdf5libversion__)
    except ImportError:  # pragma: no cover - netCDF4 is a dependency
        pass
    return versions


def git_state(path: Path | None = None) -> dict[str, Any]:
    """Commit and dirty flag of the git checkout holding mcchain (``None`` outside git)."""
    path = path or Path(__file__).resolve().parent

    def git(*args: str) -> str:
        done = subprocess.run(
            ["git", *args], cwd=path, capture_output=True, text=True, timeout=10, check=True
        )
        return done.stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        changes = git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    return {"commit": commit, "dirty": bool(changes)}


def host_info() -> dict[str, Any]:
    """Host name, CPU model and count, platform."""
    cpu = platform.processor() or ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return {
        "name": socket.gethostname(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
    }
