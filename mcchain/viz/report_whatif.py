"""``whatif.png``: P(fail) if one parameter were tighter, from the same samples
(:mod:`mcchain.decision.whatif`).

One row of panels per requirement, one panel per sampled parameter: against the share s
kept (1 = as sampled, tightening to the right), each change's estimate (points; a hollow
triangle on the floor where no sample fails) and its
bounds (band, each end one-sided at the requirement's confidence), the target (dotted) and
the current P(fail) (s = 1). A band wholly below the target marks a tightening that this
ensemble already supports; ``mcchain confirm`` decides it on fresh samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from mcchain.viz.figures import figure, panel_title, suptitle

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


class WhatIf(Protocol):
    """What the figure reads of a row of ``whatif.csv`` (:class:`mcchain.decision.whatif.
    WhatIf`, whose module draws this figure: named by its fields here, so that the two
    modules form no import circle)."""

    @property
    def requirement(self) -> str: ...

    @property
    def parameter(self) -> str: ...

    @property
    def unit(self) -> str: ...

    @property
    def change(self) -> str: ...

    @property
    def share(self) -> float: ...

    @property
    def p_fail(self) -> float: ...

    @property
    def p_lower(self) -> float: ...

    @property
    def p_upper(self) -> float: ...

    @property
    def confidence(self) -> float: ...

    @property
    def target(self) -> float: ...


STYLES = {
    "central": ("C0", "central range"),
    "lower": ("C1", "lower part (<= s-quantile)"),
    "upper": ("C2", "upper part (>= (1-s)-quantile)"),
    "sigma": ("C3", "standard deviation x s"),
}
"""Colour and legend label of each change."""
FLOOR_SHARE = 0.01
"""The log axis starts at this share of the smallest positive value drawn (zeros sit there)."""


def _panel(ax: Axes, rows: Sequence[WhatIf]) -> None:
    first = rows[0]
    positive = [v for r in rows for v in (r.p_fail, r.p_upper, r.target) if v > 0]
    floor = FLOOR_SHARE * min(positive)
    for change, (colour, label) in STYLES.items():
        mine = sorted((r for r in rows if r.change == change), key=lambda r: -r.share)
        if not mine:
            continue
        s = np.array([r.share for r in mine])
        p = np.array([r.p_fail for r in mine])
        lo = np.maximum([r.p_lower for r in mine], floor)
        hi = np.array([r.p_upper for r in mine])
        ax.fill_between(s, lo, hi, color=colour, alpha=0.15, linewidth=0)
        ax.plot(
            s,
            np.where(p > 0, p, np.nan),
            "o-",
            color=colour,
            markersize=3,
            linewidth=1,
            label=label,
        )
        zero = p == 0  # no failure left: a hollow marker on the axis floor
        if zero.any():  # (an empty unclipped line collapses the constrained layout)
            ax.plot(s[zero], np.full(int(zero.sum()), floor), "v", color=colour, markersize=4,
                    markerfacecolor="none", clip_on=False)  # fmt: skip
    ax.axhline(first.target, color="k", linestyle=":", linewidth=1.0)
    ax.set_yscale("log")
    ax.set_ylim(floor, 1.5)
    ax.set_xlim(1.02, 0.0)  # tighter to the right
    ax.set_xlabel("share kept s (of probability; of the std for 'sigma')")
    ax.set_ylabel("P(fail)")
    unit = "" if first.unit in ("1", "") else f" [{first.unit}]"
    level = f"{100 * first.confidence:g} %"
    panel_title(ax, f"{first.requirement}: {first.parameter}{unit} (bands: one-sided {level})")


def whatif_figure(rows: Sequence[WhatIf]) -> Figure:
    """The figure of ``whatif.csv``'s rows (module docstring); rows must not be empty."""
    requirements = list(dict.fromkeys(r.requirement for r in rows))
    parameters = list(dict.fromkeys(r.parameter for r in rows))
    fig, axes = figure(len(requirements), len(parameters), w=4.2, h=3.3)
    for i, requirement in enumerate(requirements):
        for j, parameter in enumerate(parameters):
            mine = [r for r in rows if r.requirement == requirement and r.parameter == parameter]
            if mine:
                _panel(axes[i, j], mine)
            else:
                axes[i, j].set_axis_off()
    from matplotlib.lines import Line2D

    present = {r.change for r in rows}
    handles = [Line2D([], [], color=c, marker="o", markersize=3, label=label)
               for change, (c, label) in STYLES.items() if change in present]  # fmt: skip
    handles.append(Line2D([], [], color="k", linestyle=":", label="target"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=7)
    suptitle(
        fig,
        "What if one parameter were tighter: P(fail) reweighted from the same samples, the "
        "others as sampled (each band alone; confirm a choice with `mcchain confirm`)",
    )
    return fig
