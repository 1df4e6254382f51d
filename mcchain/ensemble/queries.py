"""Queries on an ensemble that ``mcchain show`` and ``mcchain report`` share.

* which samples a dataset holds (:func:`sample_ids`, :func:`positions`) and the names along
  a dimension (:func:`dim_names`);
* picking samples: by index (``--samples``), by ``--worst VARIABLE:N`` (largest peak
  ``|VARIABLE|``, :func:`peak_abs`), by ``--status FLAG`` (:func:`status_mask`), all in
  :func:`select_samples`;
* peaks over time per component (:func:`peak_abs_over_time`), the largest values
  (:func:`largest`);
* the run's ``[sample] design`` (:func:`run_design`).

A lazy ensemble is read in blocks of samples, never whole. Errors are
:class:`~mcchain.errors.RunError` naming the option they come from.
"""

from __future__ import annotations

import json
import logging
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mcchain.ensemble.registry import VARIABLES
from mcchain.errors import RunError
from mcchain.status import Status

if TYPE_CHECKING:
    import xarray as xr

log = logging.getLogger(__name__)

DEFAULT_LIMIT = 16
"""Most samples ``--status`` alone picks (a recording of thousands of samples is unusable)."""
PEAK_BLOCK = 512
"""Samples read at once when ranking ``--worst`` (bounds memory on long histories)."""


# -- what a dataset holds ----------------------------------------------------------------------
def sample_ids(ds: xr.Dataset) -> np.ndarray:
    if "sample" in ds.coords:
        return np.asarray(ds["sample"].values, dtype=np.int64)
    return np.arange(ds.sizes["sample"], dtype=np.int64)


def positions(ds: xr.Dataset, samples: Sequence[int]) -> list[int]:
    ids = sample_ids(ds)
    where = {int(s): i for i, s in enumerate(ids)}
    missing = [s for s in samples if int(s) not in where]
    if missing:
        raise RunError(f"sample {missing[0]} is not in the dataset")
    return [where[int(s)] for s in samples]


def dim_names(ds: xr.Dataset, dim: str) -> list[str]:
    if dim in ds.coords:
        return [str(v) for v in ds[dim].values]
    return [str(i) for i in range(ds.sizes.get(dim, 0))]


# -- picking samples --------------------------------------------------------------------------
def parse_samples(text: str | None) -> list[int]:
    """``"0,17"`` -> ``[0, 17]``; raises :class:`RunError` naming ``--samples``."""
    if not text:
        return []
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise RunError(f"--samples: expected comma-separated integers, got {text!r}") from None
    if any(v < 0 for v in values):
        raise RunError(f"--samples: sample indices are >= 0, got {text!r}")
    return list(dict.fromkeys(values))


def parse_worst(text: str) -> tuple[str, int]:
    """``"contact_force:3"`` -> ``("contact_force", 3)``; raises :class:`RunError`."""
    name, sep, count = text.rpartition(":")
    if not sep or not name:
        raise RunError(f"--worst: expected VARIABLE:N, got {text!r}")
    try:
        n = int(count)
    except ValueError:
        raise RunError(f"--worst: N must be an integer, got {count!r}") from None
    if n < 1:
        raise RunError(f"--worst: N must be >= 1, got {n}")
    return name, n


def peak_abs(ds: xr.Dataset, variable: str, block: int = PEAK_BLOCK) -> np.ndarray:
    """Peak ``|variable|`` of every sample over all its other axes (NaN if all NaN).

    Reads ``block`` samples at a time, so a lazy ensemble is never loaded whole. A time
    history that a light run (``[storage] histories``) kept for some samples only has a
    peak for those (NaN for the others); one it kept for none is a :class:`RunError`.
    """
    from mcchain.ensemble.histories import HISTORY_SAMPLE, not_stored_reason

    if variable in VARIABLES and "time" in VARIABLES[variable].dims:
        reason = not_stored_reason(ds)
        if reason is not None and variable not in ds.data_vars:
            raise RunError(f"--worst: {variable}: {reason}")
        if reason is not None:
            stored = ds[variable].rename({HISTORY_SAMPLE: "sample"})
            at = positions(ds, ds[HISTORY_SAMPLE].values.tolist())
            peak = np.full(ds.sizes["sample"], np.nan)
            peak[at] = peak_abs(stored.to_dataset(), variable, block)
            return peak
    if variable not in ds.data_vars or "sample" not in ds[variable].dims:
        choices = sorted(
            str(name)
            for name, v in ds.data_vars.items()
            if "sample" in v.dims and v.dtype.kind == "f"
        )
        raise RunError(
            f"--worst: no per-sample variable {variable!r} in the run "
            f"(choose from {', '.join(choices)})"
        )
    da = ds[variable].transpose("sample", ...)
    n = ds.sizes["sample"]
    peak = np.full(n, np.nan)
    for start in range(0, n, block):
        values = np.abs(np.asarray(da.isel(sample=slice(start, start + block)).values, float))
        flat = values.reshape(values.shape[0], -1)
        finite = np.isfinite(flat)
        has = finite.any(axis=1)
        peak_block = np.where(finite, flat, -np.inf).max(axis=1, initial=-np.inf)
        peak[start : start + len(flat)] = np.where(has, peak_block, np.nan)
    return peak


def largest(values: np.ndarray, n: int) -> np.ndarray:
    """Positions of the ``n`` largest finite ``values`` (nsample,), largest first (ties in
    sample order); NaN values are never picked, so fewer than ``n`` may come back."""
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    order = np.argsort(-np.where(finite, values, -np.inf), kind="stable")
    return order[: min(n, int(finite.sum()))]


def status_mask(ds: xr.Dataset, names: str) -> np.ndarray:
    known = {flag.meaning: int(flag.value) for flag in Status}
    status = np.asarray(ds["status"].values, dtype=np.int64)
    mask = np.zeros(status.shape, dtype=bool)
    for name in (part.strip() for part in names.split(",") if part.strip()):
        if name == "ok":
            mask |= status == 0
        elif name in known:
            mask |= (status & known[name]) != 0
        else:
            raise RunError(f"--status: unknown flag {name!r} (choose from ok, {', '.join(known)})")
    return mask


def select_samples(
    ds: xr.Dataset,
    samples: Sequence[int] = (),
    worst: str | None = None,
    status: str | None = None,
    limit: int = DEFAULT_LIMIT,
) -> list[int]:
    """Global sample indices to show, in order: ``samples`` first, then those the criteria pick.

    ``status`` (comma-separated flag names) filters the candidates; ``worst``
    (``VARIABLE:N``) takes the N candidates with the largest peak ``|VARIABLE|`` (samples with
    no finite value are never "worst"); ``status`` alone takes the first ``limit``. With no
    argument at all: the first sample.
    """
    ids = sample_ids(ds)
    known = set(ids.tolist())
    chosen = list(dict.fromkeys(int(s) for s in samples))
    missing = [s for s in chosen if s not in known]
    if missing:
        raise RunError(
            f"--samples: {missing[0]} is not a sample of the run "
            f"({len(ids)} samples, {ids.min()}..{ids.max()})"
        )
    picked: list[int] = []
    if worst is not None or status is not None:
        candidates = np.ones(len(ids), dtype=bool)
        if status is not None:
            candidates &= status_mask(ds, status)
        if worst is not None:
            variable, n = parse_worst(worst)
            peak = np.where(candidates, peak_abs(ds, variable), np.nan)
            picked = [int(ids[i]) for i in largest(peak, n)]
        else:
            where = np.flatnonzero(candidates)
            if len(where) > limit:
                log.info(
                    "--status %s matches %d samples; showing the first %d (--limit)",
                    status,
                    len(where),
                    limit,
                )
            picked = [int(ids[i]) for i in where[:limit]]
        if not picked and not chosen:
            raise RunError(
                f"no sample matches {' '.join(filter(None, [worst, status]))!s} in the run"
            )
    elif not chosen:
        chosen = [int(ids[0])]
    return list(dict.fromkeys(chosen + picked))


# -- results over time ------------------------------------------------------------------------
def peak_abs_over_time(ds: xr.Dataset, name: str, block: int) -> np.ndarray:
    """max over time of |name| per sample and trailing component: (nsample, ...)."""
    da = ds[name].transpose("sample", "time", ...)
    n, step = ds.sizes["sample"], block
    out = None
    for start in range(0, n, step):
        a = np.abs(np.asarray(da.isel(sample=slice(start, start + step)).values, float))
        finite = np.isfinite(a)
        peak = np.where(finite, a, -np.inf).max(axis=1, initial=-np.inf)
        peak = np.where(finite.any(axis=1), peak, np.nan)
        if out is None:
            out = np.full((n, *peak.shape[1:]), np.nan)
        out[start : start + len(peak)] = peak
    return out if out is not None else np.empty((0,))


# -- the run's design ----------------------------------------------------------------------------
def run_design(run: str | Path, ds: xr.Dataset | None = None) -> str | None:
    """The ``[sample] design`` of a run, as the ensemble describes itself: from its resolved
    settings (the ``settings`` attribute), else its scene text attribute, else
    ``RUN/scene.toml`` (an ensemble without attributes); ``"random"`` when the scene samples
    without naming a design; ``None`` if there is no scene or no ``[sample]``."""
    texts = []
    if ds is not None:
        try:
            settings = json.loads(str(ds.attrs.get("settings", "")))
        except ValueError:
            settings = None
        scene = settings.get("scene") if isinstance(settings, dict) else None
        if isinstance(scene, dict) and "sample" in scene:
            sample = scene["sample"]
            return str(sample.get("design", "random")) if isinstance(sample, dict) else None
        texts += [v for k, v in ds.attrs.items() if "scene" in str(k) and isinstance(v, str)]
    path = Path(run) / "scene.toml"
    if path.is_file():
        texts.append(path.read_text())
    for text in texts:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError:
            continue
        sample = data.get("sample")
        if isinstance(sample, dict):
            return str(sample.get("design", "random"))
        return None
    return None
