"""Report figures of the time histories: reaction envelopes and contact loss.

``reaction_envelopes.png``: per joint |f| over time (and the normal contact force of clearance
joints, driver torques), median and 5–95 % band over the samples AT THE STORED TIMES (every
``output_dt``: a peak between them is not in the bands, which the title says), with the true
per-sample peaks tracked at every step (``peak_joint_force``, ``peak_contact_force``,
``peak_driver_torque``) marked as dashed lines (their median and 95 % quantile over the
samples), each titled with the model
that produced it (link, or contact law and its model); samples flagged ``contact_lost`` are
left out after their ``contact_lost_time`` and those times shaded; the state of each joint
with a contact law (link, contact, free, ...) as shares of the samples over time.
``contact_loss.png``: which samples lost contact under the link model, and when (and when
joints with a contact law first separated), against each sampled parameter.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mcchain.ensemble.queries import dim_names
from mcchain.ensemble.units import reading_unit
from mcchain.viz.contact import FAILED, LINK, LINK_LOST, STATE_COLORS, STATES, joint_models
from mcchain.viz.figures import block, figure, grid, panel_title, save_or_reason, suptitle
from mcchain.viz.scatter import param_axis

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

MAX_ENVELOPE_TIMES = 400
"""Time points at which envelopes are evaluated (evenly strided; a plot needs no more)."""


def _shown_times(ds: xr.Dataset) -> np.ndarray:
    """Indices of the (at most :data:`MAX_ENVELOPE_TIMES`, evenly strided) times drawn."""
    nt = ds.sizes["time"]
    return np.unique(np.linspace(0, nt - 1, min(nt, MAX_ENVELOPE_TIMES)).round().astype(int))


def _lost_times(ds: xr.Dataset) -> np.ndarray:
    """(nsample,) ``contact_lost_time`` (NaN: never lost, or the run has none)."""
    if "contact_lost_time" not in ds.data_vars:
        return np.full(ds.sizes["sample"], np.nan)
    return np.asarray(ds["contact_lost_time"].transpose("sample").values, np.float64)


def _envelope(
    ds: xr.Dataset,
    name: str,
    reduce: Callable[[np.ndarray], np.ndarray],
    idx: np.ndarray,
    lost: np.ndarray,
) -> np.ndarray:
    """Quantiles (3, len(idx), ncomp) over the samples of ``reduce(values)`` at the times
    ``idx``, leaving out each sample from its ``lost`` time (``contact_lost_time``) on."""
    da = ds[name].transpose("time", "sample", ...)
    time = np.asarray(ds["time"].values, float)
    step = block(ds, name, "time")
    parts = []
    for start in range(0, len(idx), step):
        at = idx[start : start + step]
        a = reduce(np.asarray(da.isel(time=at).values, float))
        a = a.reshape(a.shape[0], a.shape[1], -1)  # (time, sample, comp)
        a[time[at][:, None] >= lost[None, :]] = np.nan  # the link pulled: not physical
        with warnings.catch_warnings():  # all-NaN columns (failed samples) give NaN quietly
            warnings.simplefilter("ignore", RuntimeWarning)
            parts.append(np.nanquantile(a, [0.05, 0.5, 0.95], axis=1))
    return np.concatenate(parts, axis=1)


def model_tag(model: str | None) -> str:
    """What a panel title says of a joint's model: ``" — link"``, ``" — contact law
    (auto)"``, ... (:func:`mcchain.viz.contact.joint_models`); ``""`` for ideal joints."""
    if model is None:
        return ""
    if model == "link":
        return " — link"
    return " — contact law" + ("" if model == "contact law" else f" ({model})")


def state_shares(ds: xr.Dataset, joint: int, idx: np.ndarray, lost: np.ndarray) -> np.ndarray:
    """(len(STATES), len(idx)) share of the samples in each state of :data:`STATES` at a
    joint with a contact law, at the times ``idx``."""
    mode = np.asarray(ds["contact_mode"].isel(time=idx, joint=joint).transpose("time", "sample"))
    time = np.asarray(ds["time"].values, float)[idx]
    after = time[:, None] >= lost[None, :]
    states = np.where(mode < 0, FAILED, mode)
    states = np.where((states == LINK) & after, LINK_LOST, states)
    return np.stack([(states == code).mean(axis=1) for code in range(len(STATES))])


def reaction_envelopes(
    ds: xr.Dataset, path: Path, models: list[str | None] | None = None
) -> Path | str:
    """``reaction_envelopes.png``: :func:`reaction_envelopes_figure`, saved."""
    return save_or_reason(reaction_envelopes_figure(ds, models), path)


def reaction_envelopes_figure(
    ds: xr.Dataset, models: list[str | None] | None = None
) -> Figure | str:
    """Median and 5–95 % band over the samples of every reaction over time.

    Titles say which model a clearance joint's reactions come from (``models``:
    :func:`mcchain.viz.contact.joint_models`, default from the data). A sample flagged
    ``contact_lost`` is left out from its ``contact_lost_time`` on (the link then pulls: not
    physical); the times where some sample is left out are shaded. For each joint with a
    contact law, a panel shows the share of the samples in each state over time.
    """
    if "time" not in ds.dims or "joint_force" not in ds.data_vars:
        return "the run has no time history of joint forces ([simulate] absent)"
    models = models if models is not None else joint_models(ds)
    joints = dim_names(ds, "joint")
    idx, lost = _shown_times(ds), _lost_times(ds)
    time = np.asarray(ds["time"].values, float)[idx]
    masked = (time[:, None] >= lost[None, :]).mean(axis=1)
    panels: list[tuple[str, np.ndarray, str, np.ndarray | None]] = []
    q = _envelope(ds, "joint_force", lambda a: np.hypot(a[..., 0], a[..., 1]), idx, lost)
    for k, j in enumerate(joints):
        peaks = _peaks(ds, "peak_joint_force", k)
        panels.append((f"|f {j}|{model_tag(models[k])}", q[..., k], "N", peaks))
    if "contact_force" in ds.data_vars:
        q = _envelope(ds, "contact_force", lambda a: a, idx, lost)
        for k, j in enumerate(joints):
            if not np.isfinite(q[..., k]).any():
                continue
            what = {"link": "λ", "contact": "F_n"}.get(str(models[k]), "λ (link) / F_n (law)")
            peaks = _peaks(ds, "peak_contact_force", k)
            if peaks is None or not np.isfinite(peaks).any():  # the link: its peak |λ|
                peaks = _peaks(ds, "peak_joint_force", k)
            panels.append((f"{what} {j}{model_tag(models[k])}", q[..., k], "N", peaks))
    for name, what, units in (("driver_torque", "torque", "N m"), ("driver_force", "force", "N")):
        if name not in ds.data_vars or not ds.sizes.get("driver", 0):
            continue
        q = _envelope(ds, name, lambda a: a, idx, lost)
        for k, d in enumerate(dim_names(ds, "driver")):
            if np.isfinite(q[..., k]).any():  # a slider driver has a force, not a torque
                peaks = _peaks(ds, f"peak_{name}", k)
                panels.append((f"driver {what} {d}", q[..., k], units, peaks))
    shares = []
    if "contact_mode" in ds.data_vars:
        law = [k for k, m in enumerate(models) if m not in (None, "link")]
        shares = [(k, state_shares(ds, k, idx, lost)) for k in law]
    nrow, ncol = grid(len(panels) + len(shares), 2)
    fig, axes = figure(nrow, ncol, w=4.5, h=2.6)
    nlost = int(np.isfinite(lost).sum())
    marked = False
    for ax, (title, quant, units, peaks) in zip(axes.flat, panels, strict=False):
        unit, scale = reading_unit(units, _largest(quant, peaks))  # kN for kilonewtons
        quant = scale * quant
        ax.fill_between(time, quant[0], quant[2], color="C0", alpha=0.3, lw=0, label="5–95 %")
        ax.plot(time, quant[1], color="C0", lw=1.2, label="median")
        if peaks is not None and np.isfinite(peaks).any():
            median, high = scale * np.nanquantile(peaks, [0.5, 0.95])
            ax.axhline(median, color="C3", lw=1.0, ls="--", label="per-sample peak: median")
            ax.axhline(high, color="C3", lw=0.8, ls=":", label="per-sample peak: 95 %")
            marked = True
        if nlost:
            ax.fill_between(
                time, 0, 1, where=masked > 0, transform=ax.get_xaxis_transform(),
                color="C3", alpha=0.12, lw=0, label="samples left out (contact_lost)",
            )  # fmt: skip
        panel_title(ax, title)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(unit)
        ax.legend(fontsize=7, frameon=False)
    for ax, (k, share) in zip(list(axes.flat)[len(panels) :], shares, strict=False):
        seen = [code for code in range(len(STATES)) if share[code].any()]
        colors = [STATE_COLORS[code] / 255.0 for code in seen]
        labels = [STATES[code] for code in seen]
        ax.stackplot(time, 100.0 * share[seen], colors=colors, labels=labels, alpha=0.85)
        panel_title(ax, f"state of {joints[k]}{model_tag(models[k])}")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("% of samples")
        ax.set_ylim(0, 100)
        ax.legend(fontsize=7, frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    for ax in list(axes.flat)[len(panels) + len(shares) :]:
        ax.set_visible(False)
    title = (
        f"reactions over time, {ds.sizes['sample']} samples: bands from the stored points "
        f"(every {_stored_step(ds)}), which miss peaks between them"
    )
    if marked:
        title += ";\nred: the true per-sample peaks, tracked at every step (median, 95 %)"
    if nlost:
        title += (
            f"\n{nlost} samples lost contact under the link model (λ ≤ 0 needed): left out "
            "from their contact_lost_time on (shaded)"
        )
    suptitle(fig, title)
    return fig


def _largest(quant: np.ndarray, peaks: np.ndarray | None) -> float:
    """The largest finite |value| of a panel's bands and peaks (0 if none): what picks its
    reading unit."""
    values = [np.abs(quant[np.isfinite(quant)])]
    if peaks is not None:
        values.append(np.abs(peaks[np.isfinite(peaks)]))
    found = np.concatenate(values)
    return float(found.max()) if found.size else 0.0


def _peaks(ds: xr.Dataset, name: str, k: int) -> np.ndarray | None:
    """(nsample,) the per-sample peak variable ``name`` at entry ``k`` of its second axis
    (joint or driver); None where the run has none (an older run)."""
    if name not in ds.data_vars:
        return None
    da = ds[name]
    return np.asarray(da.isel({da.dims[1]: k}).transpose("sample").values, np.float64)


def _stored_step(ds: xr.Dataset) -> str:
    """The stored times' spacing as a title states it (``1 ms``)."""
    time = np.asarray(ds["time"].values, float)
    if len(time) < 2:
        return "stored time"
    step = float(np.median(np.diff(time)))
    return f"{step * 1e3:.3g} ms" if step < 1.0 else f"{step:.3g} s"


def contact_loss(ds: xr.Dataset, path: Path) -> Path | str:
    """``contact_loss.png``: :func:`contact_loss_figure`, saved."""
    return save_or_reason(contact_loss_figure(ds), path)


def contact_loss_figure(ds: xr.Dataset) -> Figure | str:
    """Which samples lost contact at a clearance joint, and when: ``contact_lost_time`` under
    the link model and, for joints with a contact law, the first separation (the earliest
    ``first_separation_time`` over a sample's joints).

    The first panel is the share of the samples that lost contact by time t; one panel per
    sampled parameter then shows the time of loss against the parameter's value (samples that
    kept contact drawn hollow along the top edge, at the end of the history), so that what
    drives the loss can be read off. Without sampled parameters the time is drawn against the
    sample id.
    """
    if "contact_lost_time" not in ds.data_vars:
        return "the run has no contact_lost_time (no clearance joint or no [simulate])"
    events = [("contact_lost (link model)", np.asarray(ds["contact_lost_time"].values, float))]
    if "first_separation_time" in ds.data_vars:
        first = ds["first_separation_time"].transpose("sample", "joint").values
        with warnings.catch_warnings():  # samples that never separated: NaN quietly
            warnings.simplefilter("ignore", RuntimeWarning)
            separated = np.nanmin(np.asarray(first, float), axis=1, initial=np.inf)
        events.append(
            ("first separation (contact law)", np.where(separated < np.inf, separated, np.nan))
        )
    events = [(label, t) for label, t in events if np.isfinite(t).any()] or events[:1]
    n = len(events[0][1])
    if "time" in ds.coords and ds.sizes.get("time", 0):
        time = np.asarray(ds["time"].values, float)
    else:
        time = np.unique(np.concatenate([t[np.isfinite(t)] for _, t in events] + [np.zeros(1)]))
    t_end = time[-1] if time[-1] > time[0] else time[0] + 1.0
    xs = _loss_axes(ds, n)
    nrow, ncol = grid(1 + len(xs), 3)
    fig, axes = figure(nrow, ncol, w=3.6, h=2.9)
    flat = list(axes.flat)
    counts = []
    for (label, t), color in zip(events, ("C3", "C2"), strict=False):
        at = np.isfinite(t)
        counts.append(f"{int(at.sum())} of {n} samples: {label}")
        frac = np.searchsorted(np.sort(t[at]), time, side="right") / max(n, 1)
        flat[0].step(time, 100.0 * frac, where="post", color=color, label=label)
        for ax, (_, x) in zip(flat[1:], xs, strict=False):
            ax.scatter(x[at], t[at], s=7, color=color, linewidths=0, alpha=0.7)
            ax.scatter(
                x[~at], np.full(int((~at).sum()), t_end), s=9, facecolors="none",
                edgecolors=color, linewidths=0.6, alpha=0.7,
            )  # fmt: skip
    ax = flat[0]
    ax.set_xlabel("time [s]")
    ax.set_ylabel("% of samples")
    ax.set_ylim(-2, 102)
    ax.set_xlim(time[0], t_end)
    panel_title(ax, "samples that lost contact by time t")
    ax.legend(fontsize=7, frameon=False, loc="best")
    for ax, (label, _) in zip(flat[1:], xs, strict=False):
        ax.set_xlabel(label, fontsize=8)
        ax.set_ylabel("time of loss [s]", fontsize=8)
        ax.set_ylim(time[0], t_end * 1.04)
        ax.tick_params(labelsize=7)
    for ax in flat[1 + len(xs) :]:
        ax.set_visible(False)
    text = "; ".join(counts)
    if any(np.isfinite(t).sum() < n for _, t in events):
        text += " (hollow at the top: kept contact to the end)"
    suptitle(fig, "contact loss: " + text)
    return fig


def _loss_axes(ds: xr.Dataset, n: int) -> list[tuple[str, np.ndarray]]:
    """(axis label, values scaled to that label) of each varying sampled parameter, or the
    sample id when the run samples none."""
    found = []
    if "parameters" in ds.data_vars and ds.sizes.get("param", 0):
        params = np.asarray(ds["parameters"].transpose("sample", "param").values, float)
        for j, path in enumerate(dim_names(ds, "param")):
            x = params[:, j]
            if np.isfinite(x).any() and np.nanmax(x) > np.nanmin(x):
                label, scale = param_axis(path, x)
                found.append((label, scale * x))
    if not found:
        ids = np.asarray(ds["sample"].values) if "sample" in ds.coords else np.arange(n)
        found.append(("sample (no parameter sampled)", np.asarray(ids, float)))
    return found
