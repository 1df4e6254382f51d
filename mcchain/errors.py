"""Errors raised for bad user input (never inside kernels).

Every message is one line that names the offending key path or argument and the reason,
e.g. ``joint.O.clearance: must be >= 0, got -0.001``. The CLI prints it and exits with 2.
"""

from __future__ import annotations


class McchainError(Exception):
    """Base class of mcchain's user-facing errors."""


class SceneError(McchainError, ValueError):
    """A scene file that cannot be run: malformed, inconsistent or not assemblable."""


class RunError(McchainError):
    """A run folder or CLI argument that cannot be used (exists, not found, bad flag)."""


class RunFailed(RunError):
    """A run that failed once started, for a reason outside the scene: its file system
    filled up, its folder was removed or made unwritable. The finished chunks are kept
    where the folder is; the CLI prints the one line and exits with 1."""


def check_positive(name: str, value: int | None) -> None:
    """``value`` is ``None`` or an integer >= 1; else a :class:`RunError` naming ``name``."""
    if value is not None and (not isinstance(value, int) or value < 1):
        raise RunError(f"{name}: must be an integer >= 1, got {value!r}")
