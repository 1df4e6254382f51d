"""Figure helpers the report modules share: sizes, grids, saving, block reads.

Figures are :class:`matplotlib.figure.Figure` objects on the Agg canvas (no pyplot, no global
backend switch); matplotlib is imported only when a figure is made.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

BLOCK_BYTES = 64 * 2**20
"""Memory budget of one block read from the ensemble."""
DPI = 100
CHAR_WIDTH = 0.55
"""Mean glyph width of the default sans-serif font, in units of the font size (a bound that
keeps wrapped titles inside the figure with a margin)."""


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


VECTOR_FIGURES = frozenset({"requirements", "status_counts"})
"""Figures also written as SVG (``<name>.svg`` beside the PNG): few marks, read closely and
printed; the report page carries the SVG. Dense figures (thousands of points, bands of
hundreds of times) stay PNG only: as SVG they were 2-12x larger (journal orbit: 1.0 MB
against 82 kB)."""


def save(fig: Figure, path: Path) -> Path:
    """Write ``fig`` as a PNG at :data:`DPI` (and as an SVG beside it for the names of
    :data:`VECTOR_FIGURES`); returns ``path``."""
    fig.savefig(path, dpi=DPI)
    if path.stem in VECTOR_FIGURES:
        save_svg(fig, path.with_suffix(".svg"))
    return path


def save_svg(fig: Figure, path: Path) -> Path:
    """Write ``fig`` as an SVG whose text stays text (searchable, a third smaller) and whose
    element ids are salted with the file's name (several SVGs inlined in one page never
    share an id); returns ``path``."""
    import matplotlib

    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": path.stem}):
        fig.savefig(path, format="svg")
    return path


def save_or_reason(found: Figure | str, path: Path) -> Path | str:
    """Save a figure (returns ``path``), or pass on the reason why there is none."""
    return found if isinstance(found, str) else save(found, path)


AXES_SHARE = 0.8
"""Least share of a grid cell's width that its axes spans (the rest: y label, tick labels)."""


def wrap(text: str, width_in: float, fontsize: float) -> str:
    """``text`` with each of its lines wrapped to fit ``width_in`` inches at ``fontsize``
    points."""
    chars = max(20, int(width_in * 72.0 / (CHAR_WIDTH * fontsize)))
    return "\n".join(textwrap.fill(line, chars) for line in text.split("\n"))


def suptitle(fig: Figure, text: str, fontsize: float = 10.0) -> None:
    """The figure's title, wrapped to the figure's width (never cut off at the edges)."""
    fig.suptitle(wrap(text, float(fig.get_figwidth()), fontsize), fontsize=fontsize)


def panel_title(ax: Axes, text: str, fontsize: float = 9.0) -> None:
    """A panel's title, wrapped to the width of the panel's axes (:data:`AXES_SHARE` of its
    grid cell: the title is centred on the axes, not on the cell with its tick labels)."""
    fig = ax.get_figure(root=True)
    spec = ax.get_subplotspec()
    share = 1.0
    if spec is not None:
        columns = spec.colspan
        share = (columns.stop - columns.start) / spec.get_gridspec().ncols
    width = AXES_SHARE * float(fig.get_figwidth()) * share if fig is not None else 3.0
    ax.set_title(wrap(text, width, fontsize), fontsize=fontsize)
