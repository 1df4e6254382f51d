"""Figure helpers the report modules share: sizes, grids, saving, block reads.

Figures are :class:`matplotlib.figure.Figure` objects on the Agg canvas (no pyplot, no global
backend switch); matplotlib is imported only when a figure is made.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

BLOCK_BYTES = 64 * 2**20
"""Memory budget of one block read from the ensemble."""
DPI = 100


def block(ds: xr.Dataset, name: str, axis: str) -> int:
    """How many entries along ``axis`` of variable ``name`` fit in :data:`BLOCK_BYTES` of
    float64."""
    da = ds[name]
    per = 8 * int(np.prod([da.sizes[d] for d in da.dims if d != axis], dtype=np.int64))
    return max(1, BLOCK_BYTES // max(per, 1))


def figure(nrow: int, ncol: int, w: float = 3.2, h: float = 2.5) -> tuple[Figure, np.ndarray]:
    """A constrained-layout figure of ``nrow`` × ``ncol`` panels of ``w`` × ``h`` inches,
    and its axes as an (nrow, ncol) array."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(4.0, w * ncol), max(3.0, h * nrow)), dpi=DPI, layout="constrained")
    axes = np.asarray(fig.subplots(nrow, ncol, squeeze=False))
    return fig, axes


def grid(n: int, max_col: int = 4) -> tuple[int, int]:
    """(rows, columns) of a grid of ``n`` panels, at most ``max_col`` wide."""
    ncol = min(n, max_col)
    return (n + ncol - 1) // ncol, ncol


def save(fig: Figure, path: Path) -> Path:
    """Write ``fig`` as a PNG at :data:`DPI`; returns ``path``."""
    fig.savefig(path, dpi=DPI)
    return path


def save_or_reason(found: Figure | str, path: Path) -> Path | str:
    """Save a figure (returns ``path``), or pass on the reason why there is none."""
    return found if isinstance(found, str) else save(found, path)
