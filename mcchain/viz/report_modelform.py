"""Model-form notes of the report page: which model of a clearance joint a result rests on,
and whether a peak is a start-up transient.

Per clearance joint (from the stored histories and the per-sample summaries):

* a joint with a contact law (``model = "auto"`` or ``"contact"``): the share of samples
  that left the link (``first_separation_time``), that had impacts (``impact_count``), and
  the share of the run's time on the link, in contact and in free flight. Free flight comes
  from ``free_flight_time`` (continuous); link and contact from ``contact_mode`` at the stored
  points (every ``output_dt``), the only record of them;
* a joint on the massless link only: every sample and all the time on the link; the samples
  flagged ``contact_lost`` and the share of time after the loss, where the link pulls (λ ≤ 0)
  and its reactions describe no real joint;
* statics (``[equilibrium]``, ``[modes]``) always uses the link.

Per requirement on a continuous peak (``peak_contact_force``, ``peak_joint_force``,
``peak_driver_torque``, ``peak_driver_force``, ``max_penetration``): the time of the peak is
not stored, so it is located at the largest stored value of the matching history
(:data:`PEAK_HISTORIES`), to ``output_dt``; the note says how close that stored value comes to
the continuous peak. The peak is a **start-up** peak when that time lies in the first
:data:`STARTUP_SHARE` of the simulated time (t ≤ 5 % of ``t_end``: the transient of a
mechanism started from an assembled, not a periodic, state). At a joint with a contact law,
the note also gives the model in use at that time (link or contact law).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mcchain.contact import MODE_CONTACT, MODE_FREE, MODE_LINK
from mcchain.ensemble.histories import histories_setting
from mcchain.ensemble.queries import dim_names
from mcchain.ensemble.units import with_units
from mcchain.viz.figures import block
from mcchain.viz.page import esc

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.scene.study import Requirement

STARTUP_SHARE = 0.05
"""A peak located in the first 5 % of the simulated time is a start-up peak."""
PEAK_HISTORIES = {
    "peak_contact_force": "contact_force",
    "peak_joint_force": "joint_force",
    "peak_driver_torque": "driver_torque",
    "peak_driver_force": "driver_force",
    "max_penetration": "penetration",
}
"""Per-sample peak -> the stored history it is the continuous maximum of (|value|; the norm
of the xy components for ``joint_force``)."""
STATICS_OUTPUTS = ("q_eq", "joint_force_eq", "joint_moment_eq", "omega", "damped_omega")
"""Outputs of ``[equilibrium]`` and ``[modes]``: always from the link model."""
LAW_MODELS = ("contact", "auto", "contact law")


def _percent(share: float) -> str:
    return "NaN" if math.isnan(share) else f"{100 * share:.3g} %"


@dataclass(frozen=True)
class PeakTimes:
    """Where the peaks of one requirement's output lie in time (stored points only).

    Attributes:
        time: (nsample,) time of the largest stored |value| (NaN: no finite value).
        stored_ratio: (nsample,) largest stored |value| / the continuous peak.
        mode: (nsample,) ``contact_mode`` at that time (−1: no contact law).
        window: the start-up window's end, s.
    """

    time: np.ndarray
    stored_ratio: np.ndarray
    mode: np.ndarray
    window: float


def _t_end(ds: xr.Dataset) -> float:
    return float(ds["time"].values[-1]) if "time" in ds.coords and ds.sizes["time"] else math.nan


def peak_times(ds: xr.Dataset, requirement: Requirement) -> PeakTimes | str:
    """Locate a requirement's per-sample peaks in time (see the module docstring), or say
    why they cannot be."""
    history = PEAK_HISTORIES.get(requirement.output)
    if history is None:
        return f"{requirement.output} is not the peak of a stored history: no time to locate"
    if history not in ds.data_vars or "time" not in ds.dims:
        light = histories_setting(ds)
        if light != "all":
            stored = f'[storage] histories = "{light}"'
            return f"histories not stored ({stored}): the time of the peak is unknown"
        return f"the run stores no {history} history: the time of the peak is unknown"
    da = ds[history]
    select = {k: v for k, v in (requirement.select or {}).items() if k in da.dims}
    da = da.sel(select)
    extra = [str(d) for d in da.dims if d not in ("sample", "time", "xy")]
    if extra:
        return f"{requirement.output}: select one {', '.join(extra)} to locate its peak"
    da = da.transpose("sample", "time", ...)
    mode_da = None
    if "contact_mode" in ds.data_vars and "joint" in select:
        mode_da = ds["contact_mode"].sel(joint=select["joint"]).transpose("sample", "time")
    times = np.asarray(ds["time"].values, dtype=np.float64)
    n = ds.sizes["sample"]
    at, largest, mode = np.full(n, -1), np.full(n, np.nan), np.full(n, -1, dtype=np.int64)
    step = block(ds, history, "sample")
    for start in range(0, n, step):
        part = np.abs(np.asarray(da.isel(sample=slice(start, start + step)).values, np.float64))
        if part.ndim == 3:  # xy components: the magnitude
            part = np.hypot(part[..., 0], part[..., 1])
        finite = np.isfinite(part).any(axis=1)
        k = np.argmax(np.where(np.isfinite(part), part, -np.inf), axis=1)
        rows = np.arange(part.shape[0])
        at[start : start + part.shape[0]] = np.where(finite, k, -1)
        largest[start : start + part.shape[0]] = np.where(finite, part[rows, k], np.nan)
        if mode_da is not None:
            m = np.asarray(mode_da.isel(sample=slice(start, start + step)).values)
            mode[start : start + part.shape[0]] = np.where(finite, m[rows, k], -1)
    peak = np.asarray(ds[requirement.output].sel(select).values, dtype=np.float64).reshape(n)
    with np.errstate(all="ignore"):
        ratio = largest / np.abs(peak)
    return PeakTimes(
        np.where(at >= 0, times[np.maximum(at, 0)], np.nan),
        ratio,
        mode,
        STARTUP_SHARE * _t_end(ds),
    )


def peak_note(ds: xr.Dataset, requirement: Requirement, failed: np.ndarray) -> str:
    """One requirement's peaks in words: how many lie in the start-up window (of all and of
    the failing samples), on which model, and how well the stored points locate them."""
    found = peak_times(ds, requirement)
    if isinstance(found, str):
        return esc(found) + "."
    located = np.isfinite(found.time)
    n, nfail = int(located.sum()), int((failed & located).sum())
    if not n:
        return "No sample has a finite stored value to locate its peak."
    early = located & (found.time <= found.window)
    window = with_units(found.window, "s")
    parts = [
        f"The largest stored value lies in the start-up window (t ≤ {esc(window)}, the first "
        f"{100 * STARTUP_SHARE:g} % of the run) in {int(early.sum())} of {n} samples"
        + (f" and {int((early & failed).sum())} of the {nfail} failing ones" if nfail else "")
        + "."
    ]
    if (early & failed).sum() > 0.5 * max(nfail, 1) and nfail:
        parts.append(
            '<b class="warn">Most failures come from a start-up peak: the verdict rests on the '
            "transient of the assembled initial state.</b>"
        )
    law = found.mode >= 0
    if law.any():
        on_link = law & located & (found.mode == MODE_LINK)
        parts.append(
            f"At that time the joint was on the link model in {int(on_link.sum())} samples"
            + (f" ({int((on_link & failed).sum())} failing)" if nfail else "")
            + f", under the contact law in {int((law & located & ~on_link).sum())}."
        )
    ratio = found.stored_ratio[located & np.isfinite(found.stored_ratio)]
    if ratio.size:
        parts.append(
            "The time of a peak is not stored: it is located at the largest stored point "
            f"(every {esc(with_units(_stored_step(ds), 's'))}), whose value is "
            f"{_percent(float(np.median(ratio)))} of the continuous peak in the median sample "
            f"(lowest {_percent(float(ratio.min()))})."
        )
    return " ".join(parts)


def _stored_step(ds: xr.Dataset) -> float:
    time = np.asarray(ds["time"].values, dtype=np.float64)
    return float(np.median(np.diff(time))) if time.size > 1 else math.nan


def _mode_shares(ds: xr.Dataset, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(nsample, 3) share of stored times on the link, in contact, free at joint ``k``, and
    (nsample, 3) whether each state was ever seen."""
    da = ds["contact_mode"].isel(joint=k).transpose("sample", "time")
    n = ds.sizes["sample"]
    share, seen = np.zeros((n, 3)), np.zeros((n, 3), dtype=bool)
    step = block(ds, "contact_mode", "sample")
    for start in range(0, n, step):
        m = np.asarray(da.isel(sample=slice(start, start + step)).values)
        for c, code in enumerate((MODE_LINK, MODE_CONTACT, MODE_FREE)):
            share[start : start + m.shape[0], c] = (m == code).mean(axis=1)
            seen[start : start + m.shape[0], c] = (m == code).any(axis=1)
    return share, seen


def joint_note(ds: xr.Dataset, k: int, model: str) -> str:
    """What one clearance joint's model was over the samples and the run (HTML)."""
    name = dim_names(ds, "joint")[k]
    n = ds.sizes["sample"]
    t_end = _t_end(ds)
    if model == "link" or "contact_mode" not in ds.data_vars:
        text = f"<b>{esc(name)}</b> (massless link throughout): all {n} samples on the link."
        if "contact_lost_time" in ds.data_vars and math.isfinite(t_end):
            lost = np.asarray(ds["contact_lost_time"].values, dtype=np.float64)
            after = np.where(np.isfinite(lost), (t_end - lost) / t_end, 0.0)
            text += (
                f" {int(np.isfinite(lost).sum())} samples lost contact (λ ≤ 0: the link then "
                f"pulls and describes no real joint), {_percent(float(after.mean()))} of the "
                "run's time over all samples."
            )
        return text
    share, seen = _mode_shares(ds, k)
    mean = share.mean(axis=0)
    text = (
        f"<b>{esc(name)}</b> ({esc(model)}: contact law): "
        f"{int(seen[:, 1].sum())} of {n} samples were in "
        f"contact and {int(seen[:, 2].sum())} flew free at some stored time; of the run's time, "
        f"on the link {_percent(float(mean[0]))}, in contact {_percent(float(mean[1]))}, free "
        f"{_percent(float(mean[2]))} (stored points)"
    )
    if "free_flight_time" in ds.data_vars and math.isfinite(t_end) and t_end > 0:
        free = np.asarray(ds["free_flight_time"].isel(joint=k).values, dtype=np.float64)
        text += f"; free flight {_percent(float(np.nanmean(free)) / t_end)} (continuous)"
    if "first_separation_time" in ds.data_vars:
        first = np.asarray(ds["first_separation_time"].isel(joint=k).values, np.float64)
        left = np.isfinite(first)
        if left.any():
            earliest, latest = float(first[left].min()), float(first[left].max())
            span = with_units(earliest, "s")
            if latest > earliest:
                span += f" – {with_units(latest, 's')}"
            text += f". {int(left.sum())} samples left the link, first at {esc(span)}"
    if "impact_count" in ds.data_vars:
        impacts = np.asarray(ds["impact_count"].isel(joint=k).values)
        text += f"; {int((impacts > 0).sum())} had impacts"
    return text + "."


def modelform_section(
    ds: xr.Dataset, models: list[str | None], requirements: list[tuple[Requirement, np.ndarray]]
) -> str:
    """The page's model-form section: per clearance joint, then per requirement (with the
    failing samples of each, ``failed``)."""
    clearance = [(k, m) for k, m in enumerate(models) if m is not None]
    items = []
    statics = [v for v in STATICS_OUTPUTS if v in ds.data_vars]
    if clearance and statics:
        items.append(
            f"Statics ({', '.join(statics)}) uses the massless link at every clearance "
            "joint: it is the only model of an equilibrium."
        )
    if clearance and "time" in ds.dims:
        items += [joint_note(ds, k, str(m)) for k, m in clearance]
    elif clearance and histories_setting(ds) != "all":
        items.append(
            "The share of the run's time each joint spent on the link, in contact and in free "
            f'flight: histories not stored ([storage] histories = "{histories_setting(ds)}").'
        )
    for requirement, failed in requirements:
        if requirement.output in STATICS_OUTPUTS and clearance:
            note = "a statics output: it rests on the link model."
        else:
            note = peak_note(ds, requirement, failed)
        items.append(f"<b>{esc(requirement.name)}</b>: {note}")
    if not items:
        return ""
    body = "".join(f"<li>{item}</li>" for item in items)
    return (
        '<section id="model-form"><h2>Model form</h2>'
        "<p>Which model of the clearance joints the results rest on, and where the peaks "
        f"lie in time (start-up window: the first {100 * STARTUP_SHARE:g} % of the run).</p>"
        f"<ul>{body}</ul></section>"
    )
