"""One row per sample: the per-sample scalars of an ensemble as a table (``mcchain export``).

Columns, each ``name [units]`` (units as stored, CF notation):

* ``sample``, then every sampled parameter by its path;
* ``status``: the flags set, ``|``-separated (``ok`` for none);
* every per-sample variable of the ensemble, under its own name: a scalar keeps it
  (``stable``, ``iterations``, ``contact_lost_time``), one with a second axis gets a column
  per entry (``omega_0``, ``impact_count_B``, ``joint_force_eq_B_x``, ``q_eq_rocker_theta``),
  and each ``omega`` column a ``frequency`` twin in Hz. A column named after a variable holds
  exactly that variable's values: ``peak_joint_force_B``, ``peak_contact_force_B`` and
  ``peak_driver_torque_crank`` are the continuous peaks the integrator tracked at every step;
* each force-like time history reduced to its largest |value| among the STORED points (every
  ``output_dt``, so a peak between them is missed): ``max_stored_joint_force_B`` (the
  magnitude of the vector), ``max_stored_contact_force_B``, ``max_stored_driver_torque_crank``,
  ``max_stored_joint_moment_P``, ``max_stored_constraint_error``.

No column is written twice (:func:`sample_table` refuses a name already taken).

Positions, velocities, mode shapes and the modes along a cycle stay in the ensemble (they
are not one number per sample).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mcchain.ensemble.histories import not_stored_reason, without_histories
from mcchain.ensemble.queries import dim_names, peak_abs_over_time
from mcchain.status import Status

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

log = logging.getLogger(__name__)

PEAK_HISTORIES = ("joint_force", "contact_force", "driver_torque", "driver_force", "joint_moment")
"""Time histories exported as their largest stored |value| (vectors: the magnitude)."""
STORED_PREFIX = "max_stored_"
"""Prefix of the columns reduced from stored points (never the name of a variable)."""
BLOCK = 4096
"""Samples read at a time from a time history."""


def _header(name: str, units: str | None) -> str:
    return f"{name} [{units}]" if units and units not in ("1", "mixed") else name


def sample_table(ds: xr.Dataset) -> pd.DataFrame:
    """The per-sample table of ``ds`` (see the module docstring), in sample order. A light
    run (``[storage] histories = "none" | "failed"``) has no ``max_stored_*`` columns: the
    histories they reduce are not stored for every sample (logged)."""
    import pandas as pd

    not_stored = not_stored_reason(ds)
    if not_stored is not None:
        log.warning("export: no max_stored_* columns: %s", not_stored)
        ds = without_histories(ds)

    columns = _Columns()
    columns["sample"] = np.asarray(ds["sample"].values)
    if "parameters" in ds.data_vars and "param" in ds.dims:
        values = np.asarray(ds["parameters"].transpose("sample", "param").values, float)
        paths = dim_names(ds, "param")
        param_units = (
            [str(u) for u in ds["param_units"].values] if "param_units" in ds.coords else []
        )
        for j, path in enumerate(paths):
            columns[_header(path, param_units[j] if param_units else None)] = values[:, j]
    status = np.asarray(ds["status"].values, dtype=np.int64)
    columns["status"] = np.array(
        ["|".join(f.meaning for f in Status if bits & f.value) or "ok" for bits in status]
    )
    for name, da in ds.data_vars.items():
        name = str(name)
        if name in ("parameters", "status") or da.dims[0] != "sample" or "time" in da.dims:
            continue
        units = da.attrs.get("units")
        if da.ndim == 1:
            columns[_header(name, units)] = np.asarray(da.values)
            continue
        if da.ndim > 3 or "phase" in da.dims or name == "mode_shape":
            continue
        flat = np.asarray(da.values).reshape(da.sizes["sample"], -1)
        labels = _labels(ds, da.dims[1:])
        for k, label in enumerate(labels):
            columns[_header(f"{name}_{label}", _unit_of(units, label))] = flat[:, k]
            if name == "omega":
                columns[f"frequency_{label} [Hz]"] = flat[:, k] / (2.0 * np.pi)
    for name in PEAK_HISTORIES:
        if name not in ds.data_vars:
            continue
        da = ds[name]
        vector = "xy" in da.dims
        peak = _peak_norm(ds, name) if vector else peak_abs_over_time(ds, name, BLOCK)
        units = da.attrs.get("units")
        entries = [d for d in da.dims if d not in ("sample", "time", "xy")]
        for k, label in enumerate(_labels(ds, entries)):
            column = peak[:, k]
            if np.isnan(column).all():
                continue  # e.g. the contact force of an ideal joint
            columns[_header(f"{STORED_PREFIX}{name}_{label}", units)] = column
    if "constraint_error" in ds.data_vars:
        units = ds["constraint_error"].attrs.get("units")
        columns[_header(f"{STORED_PREFIX}constraint_error", units)] = peak_abs_over_time(
            ds, "constraint_error", BLOCK
        )
    return pd.DataFrame(dict(columns))


class _Columns(dict[str, np.ndarray]):
    """The table's columns by header; a header is written once (a second write would put
    one quantity's values under another's name)."""

    def __setitem__(self, key: str, value: np.ndarray) -> None:
        if key in self:
            raise ValueError(f"export: column {key!r} would be written twice")
        super().__setitem__(key, value)


def _unit_of(units: str | None, label: str) -> str | None:
    """The unit of one column of a variable whose units are per coordinate, as a body's
    ``m (x, y), rad (theta)``: the one of the column's last label part."""
    if not units or "(" not in units:
        return units
    part = label.rsplit("_", 1)[-1]
    for piece in units.split("),"):
        unit, _, names = piece.partition("(")
        if part in [n.strip(" )") for n in names.split(",")]:
            return unit.strip()
    return units


def _labels(ds: xr.Dataset, dims: tuple | list) -> list[str]:
    """``a_b`` labels of every entry of the trailing ``dims`` (names or indices), C order."""
    names = [
        dim_names(ds, d) if d in ds.coords else [str(i) for i in range(ds.sizes[d])] for d in dims
    ]
    labels = [""]
    for axis in names:
        labels = [f"{a}_{b}" if a else str(b) for a in labels for b in axis]
    return labels


def _peak_norm(ds: xr.Dataset, name: str) -> np.ndarray:
    """max over time of |vector| (the ``xy`` axis) per sample and joint: (nsample, njoint)."""
    da = ds[name].transpose("sample", "time", ..., "xy")
    n = ds.sizes["sample"]
    out = np.full((n, *da.shape[2:-1]), np.nan)
    for start in range(0, n, BLOCK):
        a = np.asarray(da.isel(sample=slice(start, start + BLOCK)).values, float)
        norm = np.hypot(a[..., 0], a[..., 1])
        finite = np.isfinite(norm)
        peak = np.where(finite, norm, -np.inf).max(axis=1, initial=-np.inf)
        out[start : start + len(peak)] = np.where(finite.any(axis=1), peak, np.nan)
    return out


def write_csv(ds: xr.Dataset, path: Path) -> Path:
    """Write :func:`sample_table` as CSV (full float precision) and return ``path``."""
    sample_table(ds).to_csv(path, index=False, float_format="%.17g")
    return path


def export_run(run: str | Path, out: str | Path | None = None) -> Path:
    """``mcchain export RUN --csv``: the per-sample table of a run folder (path or id under
    ``runs/``) into ``out`` (default ``RUN/export/samples.csv``); returns the file."""
    from mcchain.runner.runs import open_run, resolve_run, writable_folder

    folder = resolve_run(run)
    ds = open_run(folder)
    target = Path(out) if out else folder / "export" / "samples.csv"
    writable_folder(target.parent, "--out")
    return write_csv(ds, target)
