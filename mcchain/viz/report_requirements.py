"""``requirements.png``: what an ensemble says about each ``[[requirement]]``.

One row per requirement:

* first panel: the exceedance curve of the output on a log scale — P(output > x) for a
  ``max`` (P(output < x) for a ``min``), the share of samples beyond x — with its pointwise
  band between the one-sided bounds at the requirement's confidence, the limit (vertical)
  and the target (horizontal). The curve crosses the limit at the failure probability; it
  crosses the target at the quantile of ``requirements.csv``.
* one panel per sampled parameter: P(fail) in equal-count bins of the parameter on a log
  axis, each bin with failures between its exact one-sided bounds at the requirement's
  confidence (as the verdict reads P(fail)), each bin without a failure as its upper bound
  (hollow ▽), the target, and the allocated
  bound of ``allocation.csv`` (the kept side unshaded).

Axes are in reading units (kN, mm: :mod:`mcchain.ensemble.units`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mcchain.decision.requirements import requirement_values, stored_requirements
from mcchain.decision.stats import one_sided_bounds_arrays
from mcchain.decision.summary import allocations, met_of, output_label, quantile_side
from mcchain.ensemble.units import reading_unit, units_of
from mcchain.viz.figures import figure, panel_title, suptitle
from mcchain.viz.scatter import param_reading

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from mcchain.decision.summary import AllocationRow
    from mcchain.scene.study import Requirement

CURVE_POINTS = 400
"""Points of an exceedance curve (at sample quantiles: the curve's shape, not every sample)."""
MAX_BINS = 12
"""Bins of P(fail) against a parameter, at most (fewer when samples are few: >= 20 each)."""
MIN_PER_BIN = 20


def exceedance(
    values: np.ndarray, side: str, confidence: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x, share beyond x, band low, band high) of the failing tail: beyond = above x for
    ``max``, below x for ``min``; NaN values count as beyond every x."""
    v = np.asarray(values, dtype=np.float64)
    n = v.size
    finite = np.sort(v[~np.isnan(v)])
    if finite.size == 0:
        empty = np.array([])
        return empty, empty, empty, empty
    grid = np.unique(np.quantile(finite, np.linspace(0.0, 1.0, CURVE_POINTS)))
    undefined = n - finite.size
    if side == "max":
        beyond = finite.size - np.searchsorted(finite, grid, side="right") + undefined
    else:
        beyond = np.searchsorted(finite, grid, side="left") + undefined
    lo, hi = one_sided_bounds_arrays(beyond, np.full(beyond.shape, n), confidence)
    return grid, beyond / n, lo, hi


def output_axis(
    ds: xr.Dataset, requirement: Requirement, values: np.ndarray
) -> tuple[str, str, float]:
    """(axis label ``peak_contact_force[joint=B] [kN]``, reading unit, scale) of a
    requirement's output, in the reading unit of its largest finite value
    (:mod:`mcchain.ensemble.units`)."""
    units = units_of(ds[requirement.output].attrs, requirement.output) or ""
    finite = np.abs(values[np.isfinite(values)])
    unit, scale = reading_unit(units, float(finite.max()) if finite.size else 0.0)
    return f"{output_label(requirement)} [{unit or '-'}]", unit, scale


def _exceedance_panel(
    ax: Axes, requirement: Requirement, values: np.ndarray, axis: tuple[str, str, float]
) -> None:
    side = quantile_side(requirement, values)
    x, share, lo, hi = exceedance(values, side, requirement.confidence)
    floor = 0.5 / max(values.size, 1)  # zero cannot be drawn on a log axis
    label = "P(output > x)" if side == "max" else "P(output < x)"
    xlabel, unit, scale = axis
    ax.fill_between(scale * x, np.maximum(lo, floor), hi, color="C0", alpha=0.25, linewidth=0)
    # where no sample is beyond x the share is 0: not drawn (the band's top bounds it)
    ax.step(scale * x, np.where(share > 0, share, np.nan), where="post", color="C0", label=label)
    limit = requirement.max if side == "max" else requirement.min
    assert limit is not None  # quantile_side picks a side the requirement has
    for value in (requirement.min, requirement.max):
        if value is not None:
            ax.axvline(scale * value, color="C3", linestyle="--", linewidth=1.0)
    ax.axhline(requirement.target, color="k", linestyle=":", linewidth=1.0)
    ax.set_yscale("log")
    ax.set_ylim(floor, 1.05)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(label)
    panel_title(
        ax,
        f"{requirement.name}: exceedance, {100 * requirement.confidence:g} % band; limit "
        f"{scale * limit:.4g}{' ' + unit if unit else ''} (dashed), target "
        f"{requirement.target:g} (dotted)",
    )


def binned_failure(
    x: np.ndarray, failed: np.ndarray, confidence: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(bin centres, P(fail), lower bound, upper bound, bin edges, samples per bin) in
    equal-count bins of ``x``; the bounds are the exact one-sided bounds at ``confidence``
    each, as the verdict reads them (:func:`mcchain.decision.stats.one_sided_bounds`; with
    no failure the upper one is 1 − (1 − C)^(1/n))."""
    n = x.size
    nbins = int(max(1, min(MAX_BINS, n // MIN_PER_BIN)))
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, nbins + 1)))
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(edges.size - 2, 0))
    count = np.bincount(which, minlength=max(edges.size - 1, 1))
    fails = np.bincount(which, weights=failed.astype(float), minlength=count.size)
    keep = count > 0
    lo, hi = one_sided_bounds_arrays(fails[keep], count[keep], confidence)
    centres = 0.5 * (edges[:-1] + edges[1:]) if edges.size > 1 else edges
    return centres[keep], fails[keep] / count[keep], lo, hi, edges, count[keep]


def _parameter_panel(
    ax: Axes,
    requirement: Requirement,
    path: str,
    x: np.ndarray,
    failed: np.ndarray,
    allocation: AllocationRow | None,
) -> None:
    """P(fail) in bins of one parameter on a log axis: bins with failures as points between
    their one-sided bounds, bins without as their upper bound (a hollow ▽: zero cannot be
    drawn on a log axis, and "≤ bound" is what such a bin shows)."""
    name, unit, scale = param_reading(path, x)
    centres, p, lo, hi, edges, _ = binned_failure(x, failed, requirement.confidence)
    some = p > 0
    if some.any():
        ax.errorbar(
            scale * centres[some],
            p[some],
            yerr=[p[some] - lo[some], hi[some] - p[some]],
            fmt="o",
            color="C0",
            markersize=3,
            capsize=2,
            label="P(fail), one-sided bounds",
        )
    bound = hi[~some]  # no failure: its one-sided upper bound, 1 − (1 − C)^(1/n)
    if bound.size:
        ax.plot(
            scale * centres[~some], bound, "v", color="C0", markerfacecolor="none", markersize=5,
            label=f"no failure: one-sided {100 * requirement.confidence:g} % upper bound",
        )  # fmt: skip
    ax.axhline(requirement.target, color="k", linestyle=":", linewidth=1.0)
    title = f"P(fail) by {name}, {100 * requirement.confidence:g} % bounds"
    u = f" {unit}" if unit else ""
    if allocation is not None and allocation.meets_target and allocation.side != "all":
        left, right = scale * edges[0], scale * edges[-1]
        kept = []
        if allocation.side in ("lower", "both"):  # the cut below: shaded, green at the face
            ax.axvline(scale * allocation.low, color="C2", linewidth=1.5)
            ax.axvspan(left, scale * allocation.low, color="0.85", zorder=0)
            kept.append(f"≥ {scale * allocation.low:.4g}{u}")
        if allocation.side in ("upper", "both"):
            ax.axvline(scale * allocation.high, color="C2", linewidth=1.5)
            ax.axvspan(scale * allocation.high, right, color="0.85", zorder=0)
            kept.append(f"≤ {scale * allocation.high:.4g}{u}")
        title += f"; allocated {' and '.join(kept)} (green)"
    elif allocation is not None and allocation.meets_target:
        title += "; the whole sampled range meets the target"
    elif allocation is not None:
        title += "; no range meets the target"
    drawn = np.concatenate([lo[some & (lo > 0)], bound, [requirement.target]])
    ax.set_yscale("log")
    ax.set_ylim(max(float(drawn.min()) / 3.0, 1e-12), 1.5)
    ax.set_xlabel(f"{name} [{unit or '-'}]")
    ax.set_ylabel("P(fail)")
    ax.legend(fontsize=6, frameon=False, loc="lower left")
    panel_title(ax, title)


def requirements_figure(ds: xr.Dataset) -> Figure | str:
    """The figure (see the module docstring), or why there is none."""
    requirements = stored_requirements(ds)
    if not requirements:
        return "the run has no [[requirement]]"
    has_params = "parameters" in ds.data_vars and "param" in ds.dims
    paths = [str(p) for p in ds["param"].values] if has_params else []
    params = (
        np.asarray(ds["parameters"].transpose("sample", "param").values, dtype=np.float64)
        if has_params
        else np.empty((0, 0))
    )
    rows = {(r.requirement, r.parameter): r for r in allocations(ds)}
    fig, axes = figure(len(requirements), 1 + len(paths), w=4.0, h=3.2)
    for i, requirement in enumerate(requirements):
        values = requirement_values(ds, requirement)
        failed = met_of(ds, requirement, values) == 0
        _exceedance_panel(axes[i, 0], requirement, values, output_axis(ds, requirement, values))
        for j, path in enumerate(paths):
            allocation = rows.get((requirement.name, path))
            _parameter_panel(axes[i, 1 + j], requirement, path, params[:, j], failed, allocation)
    suptitle(
        fig,
        "Requirements: exceedance of each output with its limit and target; P(fail) against "
        "each sampled parameter with the allocated bound (kept side unshaded)",
    )
    return fig
