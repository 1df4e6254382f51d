"""Which time histories an ensemble stores (``[storage] histories``), written and read.

* ``"all"`` (default): every sample's histories, along ``sample`` as the registry declares.
* ``"none"``: no time history (and no ``time`` coordinate); every per-sample variable is
  stored as it is with ``"all"``, bit for bit.
* ``"failed"``: the histories of the samples that fail a ``[[requirement]]`` or carry any
  ``status`` flag (failure or warning: the ones worth replaying), along their own dimension
  :data:`HISTORY_SAMPLE`, whose coordinate holds each one's global sample index. ``q`` then
  has dims ``(history_sample, time, body, dof)``; ``ds.q.sel(history_sample=17)`` is
  sample 17's (:func:`sample_history` reads it in any mode, or says it was not stored).

A variable is a time history when it has a ``time`` dimension. Written by the run's
:class:`mcchain.runner.store.PartWriter` (:func:`mcchain.runner.store.kept_histories`,
with :func:`replay_mask`); read by :func:`stored_samples`, :func:`sample_history`,
:func:`select_with_histories`, :func:`without_histories` and :func:`not_stored_reason`.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable
from typing import TYPE_CHECKING

import numpy as np

from mcchain.errors import RunError

if TYPE_CHECKING:
    import xarray as xr

HISTORY_MODES = ("all", "none", "failed")
"""The values of ``[storage] histories``."""

HISTORY_SAMPLE = "history_sample"
"""The dimension of the histories a ``"failed"`` run stores; its coordinate holds the
global sample index of each."""

ROW_DIMS = ("sample", HISTORY_SAMPLE)
"""Dimensions along which part files are concatenated into ``ensemble.nc``."""

HISTORY_SAMPLE_ATTRS = {
    "long_name": "global sample index of each stored time history "
    '([storage] histories = "failed": samples that fail a requirement or carry a status flag)',
    "units": "1",
}


def is_history(dims: Iterable[Hashable]) -> bool:
    """Whether a variable with ``dims`` is a time history."""
    return "time" in tuple(dims)


def replay_mask(status: np.ndarray, requirement_met: np.ndarray | None) -> np.ndarray:
    """(nsample,) bool: the samples a ``"failed"`` run keeps the histories of: any bit in
    ``status`` (nsample,), or a 0 in ``requirement_met`` (nsample, nrequirement)."""
    keep = np.asarray(status) != 0
    if requirement_met is not None and np.size(requirement_met):
        keep |= (np.asarray(requirement_met) == 0).any(axis=1)
    return np.asarray(keep, dtype=bool)


# -- reading ---------------------------------------------------------------------------------


def stored_mode(ds: xr.Dataset) -> str:
    """``"all"``, ``"failed"`` or ``"none"``: what ``ds`` holds of its time histories
    (``"none"`` also for an ensemble of a scene without ``[simulate]``)."""
    if HISTORY_SAMPLE in ds.dims:
        return "failed"
    if any(is_history(v.dims) for v in ds.data_vars.values()):
        return "all"
    return "none"


def history_names(ds: xr.Dataset) -> list[str]:
    """The time-history variables ``ds`` holds."""
    return [str(name) for name, v in ds.data_vars.items() if is_history(v.dims)]


def stored_samples(ds: xr.Dataset) -> np.ndarray:
    """Global indices of the samples whose histories ``ds`` holds, ascending."""
    mode = stored_mode(ds)
    if mode == "failed":
        return np.asarray(ds[HISTORY_SAMPLE].values, dtype=np.int64)
    if mode == "none":
        return np.empty(0, dtype=np.int64)
    if "sample" in ds.coords:
        return np.asarray(ds["sample"].values, dtype=np.int64)
    return np.arange(ds.sizes["sample"], dtype=np.int64)


def history_dim(ds: xr.Dataset) -> str:
    """The leading dimension of ``ds``'s histories: ``sample`` or :data:`HISTORY_SAMPLE`."""
    return HISTORY_SAMPLE if HISTORY_SAMPLE in ds.dims else "sample"


def not_stored_message(ds: xr.Dataset, samples: Iterable[int]) -> str:
    """The line that says which of ``samples`` have no stored history, and why."""
    missing = [int(s) for s in samples]
    listed = ", ".join(str(s) for s in missing[:8]) + (", ..." if len(missing) > 8 else "")
    which = "sample" if len(missing) == 1 else "samples"
    mode = stored_mode(ds)
    if mode == "failed":
        n = ds.sizes[HISTORY_SAMPLE]
        return (
            f'{which} {listed}: time history not stored ([storage] histories = "failed" kept '
            f"the histories of the {n} samples that fail a requirement or carry a status flag; "
            'run the scene again with histories = "all" to see it: the same seed gives the '
            "same samples, bit for bit)"
        )
    return (
        f"{which} {listed}: time history not stored (this run has no time histories: "
        '[storage] histories = "none", or no [simulate]; run the scene again with '
        'histories = "all" to see it: the same seed gives the same samples, bit for bit)'
    )


def check_stored(ds: xr.Dataset, samples: Iterable[int]) -> None:
    """Raise :class:`RunError` (:func:`not_stored_message`) when one of ``samples`` has no
    stored history."""
    samples = [int(s) for s in samples]
    have = set(stored_samples(ds).tolist())
    missing = [s for s in samples if s not in have]
    if missing:
        raise RunError(not_stored_message(ds, missing))


def sample_history(ds: xr.Dataset, name: str, sample: int) -> xr.DataArray:
    """Time history ``name`` of global sample ``sample`` (dims ``time, ...``), whatever
    the run stored; :class:`RunError` when that sample's history was not stored."""
    check_stored(ds, [sample])
    dim = history_dim(ds)
    if dim == "sample" and "sample" not in ds.coords:
        return ds[name].isel(sample=int(sample))
    return ds[name].sel({dim: int(sample)})


def histories_setting(ds: xr.Dataset) -> str:
    """The ``[storage] histories`` the run was made with (its ``settings`` attribute;
    ``"all"`` for an ensemble from before the key, and for a scene without ``[simulate]``,
    which has no history to leave out)."""
    import json

    try:
        scene = json.loads(str(ds.attrs.get("settings", "{}")))["scene"]
        value = scene["storage"].get("histories", "all") if scene.get("simulate") else "all"
    except (ValueError, KeyError, TypeError, AttributeError):
        return "all"
    return str(value) if value in HISTORY_MODES else "all"


def not_stored_reason(ds: xr.Dataset) -> str | None:
    """Why a figure of the histories over all samples cannot be drawn from ``ds``: a run
    whose ``[storage] histories`` kept none or only some; None when every sample's are
    there (or the run has none to keep: no ``[simulate]``)."""
    mode = stored_mode(ds)
    if mode == "all" or (mode == "none" and histories_setting(ds) == "all"):
        return None
    if mode == "failed":
        return (
            f'histories not stored for every sample ([storage] histories = "failed": '
            f"{ds.sizes[HISTORY_SAMPLE]} of {ds.sizes['sample']} samples, those that fail a "
            "requirement or carry a status flag)"
        )
    return 'histories not stored ([storage] histories = "none")'


def without_histories(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with its per-sample variables only: no time history, ``time`` or
    :data:`HISTORY_SAMPLE` (what a figure over all samples may read of a light run)."""
    drop = history_names(ds) + [name for name in ("time", HISTORY_SAMPLE) if name in ds.variables]
    return ds.drop_vars(drop)


def select_with_histories(ds: xr.Dataset, samples: Iterable[int]) -> xr.Dataset:
    """``samples`` (global indices) of ``ds`` with their time histories along ``sample``,
    as an ensemble that stores every history has them (what playback reads);
    :class:`RunError` when one of them has no stored history."""
    samples = [int(s) for s in samples]
    if not_stored_reason(ds) is None:
        return ds
    check_stored(ds, samples)
    names = history_names(ds)
    picked = ds[names].sel({HISTORY_SAMPLE: samples}).rename({HISTORY_SAMPLE: "sample"})
    rest = without_histories(ds).sel(sample=samples)
    return rest.assign({name: picked[name] for name in names}).assign_coords(time=ds["time"])
