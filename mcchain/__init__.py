"""mcchain: batch Monte Carlo studies of planar linkages with revolute-joint clearance.

Heavy modules (numba kernels, xarray, dask, rerun) are imported lazily so that light
commands such as ``mcchain runs`` start fast.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

if TYPE_CHECKING:
    import xarray


def open_run(run: str | os.PathLike[str]) -> xarray.Dataset:
    """The ensemble of a run folder (path, or id under ``runs/``) as a lazy Dataset."""
    from mcchain.runner.runs import open_run as _open_run

    return _open_run(os.fspath(run))


def __getattr__(name: str) -> Any:
    if name in {"load_scene", "compile_model"}:
        from mcchain import scene

        return getattr(scene, name)
    raise AttributeError(f"module 'mcchain' has no attribute {name!r}")
