"""Report figures of clearance joints: peak contact force and impacts against the sampled
parameters, and the journal orbit of the worst samples.

==============================  ==========================================================
``scatter_peak_contact_force``  peak normal force of each clearance joint against each
``.png``                        sampled parameter: ``peak_contact_force`` (F_n, and λ while
                                an ``"auto"`` joint is the link) for joints with a contact
                                law, ``peak_joint_force`` (peak |λ|) for link joints: the
                                continuous peaks tracked at every step (a run stored before
                                them: max |λ| at the stored points, which the label says);
                                a binned median and
                                Spearman's ρ, no straight line (the relations are not linear)
``scatter_impact_count.png``    ``impact_count`` of each joint with a contact law against
                                each sampled parameter, drawn the same way
``journal_orbit.png``           d / c of the journal in its clearance circle (the unit
                                circle) over the history, coloured by the joint's state
                                (:data:`mcchain.viz.contact.STATES`), for the
                                :data:`ORBIT_SAMPLES` samples with the largest peak force at
                                each clearance joint
==============================  ==========================================================

Parameter axes are named ``key item [units]`` (``clearance B [mm]``, ``restitution B [-]``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mcchain.ensemble.queries import dim_names, largest, peak_abs_over_time, sample_ids
from mcchain.ensemble.units import in_reading_unit, reading_unit
from mcchain.viz import contact
from mcchain.viz.figures import block, figure, panel_title, suptitle
from mcchain.viz.scatter import param_axis, parameter_scatter

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from mcchain.model import Model

ORBIT_SAMPLES = 4
"""Samples drawn per clearance joint in ``journal_orbit.png`` (largest peak force first)."""
LAW_MODELS = ("contact", "auto", "contact law")
"""Names of :func:`mcchain.viz.contact.joint_models` that use a contact law."""


# -- axes and values ---------------------------------------------------------------------------
def peak_contact_forces(
    ds: xr.Dataset, models: list[str | None]
) -> tuple[list[str], np.ndarray, list[int]]:
    """Peak normal force of each clearance joint over the history.

    Args:
        models: :func:`mcchain.viz.contact.joint_models` of the run.

    Returns:
        Labels (``peak F_n B`` under a contact law, ``peak |λ B|`` for the link), the peaks
        (nsample, nj) in N (NaN where a sample has none) and the joint indices.
    """
    names = dim_names(ds, "joint")
    joints = [k for k, m in enumerate(models) if m is not None]
    if not joints:
        return [], np.empty((ds.sizes.get("sample", 0), 0)), []
    n = ds.sizes["sample"]
    peaks = np.full((n, len(joints)), np.nan)
    stored = "peak_joint_force" not in ds.data_vars  # a run from before the tracked peaks
    if stored and "contact_force" in ds.data_vars and "time" in ds["contact_force"].dims:
        every = peak_abs_over_time(ds, "contact_force", block(ds, "contact_force", "sample"))
        peaks[:] = every.reshape(n, -1)[:, joints]
    labels = []
    for i, k in enumerate(joints):
        law = models[k] in LAW_MODELS
        if law and "peak_contact_force" in ds.data_vars:
            peaks[:, i] = np.asarray(
                ds["peak_contact_force"].isel(joint=k).values, dtype=np.float64
            )
        elif not stored:  # the link's peak |λ|, tracked at every step
            peaks[:, i] = np.asarray(ds["peak_joint_force"].isel(joint=k).values, np.float64)
        label = f"peak F_n {names[k]}" if law else f"peak |λ {names[k]}|"
        labels.append(label + (" (stored points)" if stored and not law else ""))
    return labels, peaks, joints


# -- scatter figures ---------------------------------------------------------------------------
def peak_force_figure(ds: xr.Dataset, models: list[str | None]) -> Figure | str:
    """``scatter_peak_contact_force.png`` (see the module docstring)."""
    labels, peaks, joints = peak_contact_forces(ds, models)
    rows = [
        (f"{label} ({models[k]})", peaks[:, i])
        for i, (label, k) in enumerate(zip(labels, joints, strict=True))
        if np.isfinite(peaks[:, i]).any()
    ]
    if not rows:
        return "the run has no contact force history of a clearance joint"
    title = "peak contact force against the sampled parameters"
    finite = np.abs(np.concatenate([y[np.isfinite(y)] for _, y in rows]))
    unit, scale = reading_unit("N", float(finite.max()))  # kN for kilonewtons
    return parameter_scatter(ds, [(f"{label} [{unit}]", scale * y) for label, y in rows], title)


def impact_figure(ds: xr.Dataset) -> Figure | str:
    """``scatter_impact_count.png`` (see the module docstring)."""
    if "impact_count" not in ds.data_vars:
        return "the run has no impact_count (no joint with a contact law)"
    counts = np.asarray(ds["impact_count"].transpose("sample", "joint").values, np.float64)
    counts[counts < 0] = np.nan  # -1: joint without a law, or a failed sample
    rows = [
        (f"impacts {name}", counts[:, k])
        for k, name in enumerate(dim_names(ds, "joint"))
        if np.isfinite(counts[:, k]).any()
    ]
    if not rows:
        return "no joint has a contact law"
    title = "impacts (located contact onsets) against the sampled parameters"
    return parameter_scatter(ds, [(f"{label} [-]", y) for label, y in rows], title)


# -- journal orbit -----------------------------------------------------------------------------
def _value_text(label: str, value: float) -> str:
    """``"clearance B [mm]"``, 0.108 -> ``"clearance B = 0.108 mm"`` (no unit for ``[-]``)."""
    name, _, units = label.partition(" [")
    units = units.rstrip("]")
    return f"{name} = {value:.3g}" + ("" if units in ("-", "") else f" {units}")


def _draw_orbit(ax: Axes, offset: np.ndarray, state: np.ndarray) -> set[int]:
    """One joint's orbit (T, 2) in the unit clearance circle; returns the states drawn."""
    phi = np.linspace(0.0, 2.0 * np.pi, 181)
    ax.plot(np.cos(phi), np.sin(phi), color="black", lw=1.0)
    ax.plot(offset[:, 0], offset[:, 1], color="0.75", lw=0.5, zorder=1)
    drawn = set()
    for code in np.unique(state):
        at = state == code
        color = contact.STATE_COLORS[int(code)] / 255.0
        ax.scatter(offset[at, 0], offset[at, 1], s=5, color=color, linewidths=0, zorder=2)
        drawn.add(int(code))
    ax.plot(*offset[0], marker="x", color="black", ms=6, zorder=3)
    reach = np.nanmax(np.abs(offset)) if np.isfinite(offset).any() else 1.0
    lim = 1.08 * max(1.0, float(reach))
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    return drawn


def orbit_figure(
    ds: xr.Dataset,
    model: Model | None,
    models: list[str | None],
    count: int = ORBIT_SAMPLES,
) -> Figure | str:
    """``journal_orbit.png``: the journal orbit of the ``count`` samples with the largest
    peak force at each clearance joint (:func:`peak_contact_forces`), one row per joint."""
    if model is None:
        return "the model of the samples is unknown (its scene cannot be rebuilt): no joint points"
    if "q" not in ds.data_vars:
        return "the run has no time history ([simulate] absent)"
    labels, peaks, joints = peak_contact_forces(ds, models)
    if not joints:
        return "the run has no clearance joint"
    ids = sample_ids(ds)
    chosen = [largest(peaks[:, i], count) for i in range(len(joints))]
    ncol = max((len(c) for c in chosen), default=0)
    if not ncol:
        return "no sample has a finite peak contact force"
    fig, axes = figure(len(joints), ncol, w=2.9, h=3.0)
    params = None
    if "parameters" in ds.data_vars and ds.sizes.get("param", 0):
        params = np.asarray(ds["parameters"].transpose("sample", "param").values, np.float64)
    paths = dim_names(ds, "param")
    drawn: set[int] = set()
    for i, (k, picked) in enumerate(zip(joints, chosen, strict=True)):
        for j in range(ncol):
            ax = axes[i, j]
            if j >= len(picked):
                ax.set_visible(False)
                continue
            pos = int(picked[j])
            orbit = contact.sample_orbit(ds, model, pos, int(ids[pos]))
            assert orbit is not None  # q present and joint k is a clearance joint
            at = int(np.flatnonzero(orbit.joints == k)[0])
            drawn |= _draw_orbit(ax, orbit.offset[:, at], orbit.state[:, at])
            force = in_reading_unit(float(peaks[pos, i]), "N")
            lines = [f"sample {ids[pos]}: {labels[i]} = {force}"]
            if params is not None:
                named = [param_axis(p, params[:, c]) for c, p in enumerate(paths)]
                values = [scale * params[pos, c] for c, (_, scale) in enumerate(named)]
                lines += map(_value_text, [n for n, _ in named], values)  # one per line
            panel_title(ax, "\n".join(lines), 7.0)
            ax.set_xlabel(f"d_x / c  ({orbit.names[at]}, {models[k]})", fontsize=8)
            ax.set_ylabel("d_y / c", fontsize=8)
            ax.tick_params(labelsize=7)
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], ls="", marker="o", ms=5, color=contact.STATE_COLORS[c] / 255.0)
        for c in sorted(drawn)
    ]
    handles.append(Line2D([], [], ls="", marker="x", color="black"))
    names = [contact.STATES[c] for c in sorted(drawn)] + ["t = 0"]
    fig.legend(handles, names, loc="outside lower center", ncol=len(names), fontsize=8)
    suptitle(
        fig,
        "journal orbit d / c in the clearance circle (d = journal − bearing centre), "
        f"the {ncol} samples with the largest peak force (orbits drawn from the stored points)",
    )
    return fig
