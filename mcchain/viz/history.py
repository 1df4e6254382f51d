"""Report figures of the time histories: reaction envelopes and contact loss.

``reaction_envelopes.png``: per joint |f| over time (and the normal contact force of clearance
joints, driver torques), median and 5–95 % band over the samples. ``contact_loss.png``: which
samples lost contact under the link model, and when.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.ensemble.queries import dim_names
from mcchain.viz.figures import block, figure, grid, save

if TYPE_CHECKING:
    import xarray as xr

MAX_ENVELOPE_TIMES = 400
"""Time points at which envelopes are evaluated (evenly strided; a plot needs no more)."""


def _envelope(ds: xr.Dataset, name: str, reduce: Callable[[np.ndarray], np.ndarray]) -> Any:
    """Quantiles (3, ntime_shown, ncomp) of ``reduce(block)`` over samples, and the times."""
    da = ds[name].transpose("time", "sample", ...)
    nt = ds.sizes["time"]
    idx = np.unique(np.linspace(0, nt - 1, min(nt, MAX_ENVELOPE_TIMES)).round().astype(int))
    step = block(ds, name, "time")
    parts = []
    for start in range(0, len(idx), step):
        a = reduce(np.asarray(da.isel(time=idx[start : start + step]).values, float))
        a = a.reshape(a.shape[0], a.shape[1], -1)  # (time, sample, comp)
        with warnings.catch_warnings():  # all-NaN columns (failed samples) give NaN quietly
            warnings.simplefilter("ignore", RuntimeWarning)
            parts.append(np.nanquantile(a, [0.05, 0.5, 0.95], axis=1))
    time = np.asarray(ds["time"].values, float)[idx]
    return np.concatenate(parts, axis=1), time


def reaction_envelopes(ds: xr.Dataset, path: Path) -> Path | str:
    """Median and 5–95 % band over the samples of every reaction over time."""
    if "time" not in ds.dims or "joint_force" not in ds.data_vars:
        return "the run has no time history of joint forces ([simulate] absent)"
    panels: list[tuple[str, np.ndarray, np.ndarray, str]] = []
    q, time = _envelope(ds, "joint_force", lambda a: np.hypot(a[..., 0], a[..., 1]))
    for k, j in enumerate(dim_names(ds, "joint")):
        panels.append((f"|f {j}|", q[..., k], time, "N"))
    if "contact_force" in ds.data_vars:
        q, time = _envelope(ds, "contact_force", lambda a: a)
        for k, j in enumerate(dim_names(ds, "joint")):
            if np.isfinite(q[..., k]).any():
                panels.append((f"λ {j} (contact)", q[..., k], time, "N"))
    if "driver_torque" in ds.data_vars and ds.sizes.get("driver", 0):
        q, time = _envelope(ds, "driver_torque", lambda a: a)
        for k, d in enumerate(dim_names(ds, "driver")):
            panels.append((f"driver torque {d}", q[..., k], time, "N m"))
    nrow, ncol = grid(len(panels), 2)
    fig, axes = figure(nrow, ncol, w=4.5, h=2.6)
    for ax, (title, quant, t, units) in zip(axes.flat, panels, strict=False):
        ax.fill_between(t, quant[0], quant[2], color="C0", alpha=0.3, lw=0, label="5–95 %")
        ax.plot(t, quant[1], color="C0", lw=1.2, label="median")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(units)
        ax.legend(fontsize=7, frameon=False)
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    fig.suptitle(f"reactions over time, {ds.sizes['sample']} samples")
    return save(fig, path)


def contact_loss(ds: xr.Dataset, path: Path) -> Path | str:
    """Which samples lost contact at a clearance joint, and when."""
    if "contact_lost_time" not in ds.data_vars:
        return "the run has no contact_lost_time (no clearance joint or no [simulate])"
    t_lost = np.asarray(ds["contact_lost_time"].values, float)
    ids = np.asarray(ds["sample"].values) if "sample" in ds.coords else np.arange(len(t_lost))
    lost = np.isfinite(t_lost)
    fig, axes = figure(1, 2, w=4.5, h=3.2)
    ax = axes[0, 0]
    ax.scatter(t_lost[lost], ids[lost], s=8, color="C3")
    ax.set_xlabel("contact_lost_time (s)")
    ax.set_ylabel("sample")
    if len(ids):
        ax.set_ylim(float(ids.min()) - 0.5, float(ids.max()) + 0.5)
    ax.set_title(f"{int(lost.sum())} of {len(t_lost)} samples lost contact", fontsize=9)
    if "time" in ds.coords and ds.sizes.get("time", 0):
        time = np.asarray(ds["time"].values, float)
        ax.set_xlim(time[0], time[-1] if time[-1] > time[0] else time[0] + 1.0)
    else:
        time = np.sort(t_lost[lost]) if lost.any() else np.zeros(1)
    ax = axes[0, 1]
    frac = np.searchsorted(np.sort(t_lost[lost]), time, side="right") / max(len(t_lost), 1)
    ax.step(time, 100.0 * frac, where="post", color="C3")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("% of samples")
    ax.set_ylim(-2, 102)
    ax.set_title("samples that lost contact by time t", fontsize=9)
    return save(fig, path)
