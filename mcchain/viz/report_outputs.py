"""Every per-sample output of a run as one table of the report page, whatever its name.

A per-sample output is any data variable of the ensemble with ``sample`` as its first
dimension and at most one more, a label dimension (joint, driver, mode, ...), and no time:
the registry's (``omega``, ``peak_contact_force``, ``free_flight_time``, ...) and any that a
newer mcchain or a scene's ``[[output]]`` adds. Each entry (``peak_contact_force[B]``) gets
its median, 5 % and 95 % quantiles and range over the samples, in the reading unit of its
largest value with SI beside (:mod:`mcchain.ensemble.units`, units from the variable's own
attributes first). Integer outputs use −1 for "not applicable" (``impact_count`` at a joint
without a contact law): those values are left out, and an entry with no value left is not
shown.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mcchain.ensemble.units import pretty_units, units_of, with_units
from mcchain.viz.page import esc, table

if TYPE_CHECKING:
    import xarray as xr

NOT_OUTPUTS = frozenset({"parameters", "status", "requirement_met", "iterations", "stable"})
"""Per-sample variables that are inputs, flags or bookkeeping, not results."""
HISTORY_DIMS = frozenset({"time", "phase"})


def per_sample_outputs(ds: xr.Dataset) -> list[str]:
    """Names of the per-sample outputs of ``ds`` (see the module docstring), in its order."""
    found = []
    for name, da in ds.data_vars.items():
        dims = tuple(str(d) for d in da.dims)
        if str(name) in NOT_OUTPUTS or not dims or dims[0] != "sample" or len(dims) > 2:
            continue
        if HISTORY_DIMS & set(dims) or da.dtype.kind not in "fiu":
            continue
        found.append(str(name))
    return found


def outputs_table(ds: xr.Dataset) -> str:
    """The table of every per-sample output (HTML; "" when the run has none)."""
    rows = []
    for name in per_sample_outputs(ds):
        da = ds[name]
        units = units_of(da.attrs, name) or ""
        values = np.asarray(da.values, dtype=np.float64).reshape(da.shape[0], -1)
        if da.dtype.kind in "iu":
            values[values < 0] = np.nan  # -1: not applicable
        labels = (
            [str(v) for v in ds[da.dims[1]].values]
            if da.ndim == 2 and da.dims[1] in ds.coords
            else [str(k) for k in range(values.shape[1])]
        )
        for k, label in enumerate(labels):
            x = values[:, k][np.isfinite(values[:, k])]
            if not x.size:
                continue
            size = float(np.abs(x).max())
            low, median, high = np.quantile(x, [0.05, 0.5, 0.95])

            def shown(v: float, size: float = size, units: str = units) -> str:
                return esc(with_units(float(v), units, magnitude=size))

            entry = name if da.ndim == 1 else f"{name}[{label}]"
            meaning = esc(da.attrs.get("long_name", ""))
            rows.append(
                [
                    f"<code>{esc(entry)}</code><br><small>{meaning}</small>",
                    esc(pretty_units(units) or "–"),
                    shown(median),
                    f"{shown(low)} – {shown(high)}",
                    f"{shown(x.min())} – {shown(x.max())}",
                    f"{x.size} of {values.shape[0]}",
                ]
            )
    if not rows:
        return ""
    header = ["output", "SI units", "median", "5 % – 95 %", "range", "samples with a value"]
    return "<h3>Per-sample outputs</h3>\n" + table(header, rows)
