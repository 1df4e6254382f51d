"""A merged ``ensemble.nc`` read with netCDF4 alone, for what a run reads back of it at its
end: the verdict lines and the retry counts (:mod:`mcchain.runner.observers`).

Opening it with xarray for a few per-sample arrays cost a run more than computing its verdict:
xarray's import (which brings pandas, and dask.array through its duck-array checks) and the CF
decoding of every variable (benchmarks/results/verdict/verdict.md). :class:`PerSampleEnsemble`
gives the readers of a stored ensemble (:mod:`mcchain.decision`) the part of
:class:`xarray.Dataset` they use — ``data_vars``, ``coords``, ``attrs``, ``dims``/``sizes``,
``ds[name]`` with ``values``, ``dims``, ``attrs``, ``dtype``, ``isel`` and ``transpose`` — with
the values xarray would decode: the same dtypes and bytes, labels as fixed-width unicode. A
variable is read when its values are first asked for (a history stays on disk).

That holds for the files mcchain writes: numbers stored as they are, labels as variable-length
strings, no CF encoding. A file that needs decoding (a ``_FillValue``, ``missing_value``,
``scale_factor``, ``add_offset``, ``_Unsigned`` or ``calendar`` attribute, a time unit
``... since ...``, a character array) raises :class:`NeedsDecoding` at :func:`open_per_sample`:
read it with xarray (:func:`mcchain.ensemble.io.open_ensemble`), as :func:`open_stored` does.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

from mcchain.ensemble.io import DamagedEnsemble

if TYPE_CHECKING:
    import netCDF4
    import xarray as xr

CF_ENCODING = ("_FillValue", "missing_value", "scale_factor", "add_offset", "_Unsigned", "calendar")
"""Attributes by which xarray would change a variable's values or dtype on reading."""


class NeedsDecoding(Exception):
    """The file has a variable xarray would decode (:data:`CF_ENCODING`, a time unit, a
    character array): read it with xarray."""


class StoredVariable:
    """One variable of a :class:`PerSampleEnsemble`: read from the file on first use of
    :attr:`values`, or a selection already in memory.

    Attributes:
        name: its name; dims: its dimensions; attrs: its attributes as netCDF4 gives them
            (``coordinates`` left out: xarray moves it to the encoding).
    """

    def __init__(
        self,
        name: str,
        dims: tuple[str, ...],
        attrs: dict[str, Any],
        *,
        var: netCDF4.Variable | None = None,
        values: np.ndarray | None = None,
    ) -> None:
        self.name, self.dims, self.attrs = name, dims, attrs
        self._var = var
        self._values = values

    @classmethod
    def of(cls, var: netCDF4.Variable) -> StoredVariable:
        """The variable ``var`` of an open file, unread."""
        attrs = {k: var.getncattr(k) for k in var.ncattrs() if k != "coordinates"}
        return cls(str(var.name), tuple(str(d) for d in var.dimensions), attrs, var=var)

    @property
    def values(self) -> np.ndarray:
        """The whole array as xarray decodes it: numbers as stored, labels as fixed-width
        unicode."""
        if self._values is None:
            assert self._var is not None
            raw = np.asarray(self._var[...])
            if raw.dtype.kind == "O":  # variable-length strings
                raw = np.asarray([str(s) for s in raw.ravel()], dtype=np.str_).reshape(raw.shape)
            self._values = raw
        return self._values

    @property
    def dtype(self) -> np.dtype:
        """The dtype of :attr:`values` (read for labels, whose width is their longest)."""
        if self._values is None and self._var is not None and self._var.dtype is not str:
            return np.dtype(self._var.dtype)
        return self.values.dtype

    def isel(self, indexers: Mapping[str, int]) -> StoredVariable:
        """The variable with one entry of each dim of ``indexers`` taken (those dims dropped)."""
        where = tuple(indexers[d] if d in indexers else slice(None) for d in self.dims)
        dims = tuple(d for d in self.dims if d not in indexers)
        return StoredVariable(self.name, dims, self.attrs, values=self.values[where])

    def transpose(self, *dims: str) -> StoredVariable:
        """The variable with its dims in the order ``dims`` (each of its dims once)."""
        if sorted(dims) != sorted(self.dims):
            raise ValueError(f"{self.name}: dims {dims} are not a permutation of {self.dims}")
        order = [self.dims.index(d) for d in dims]
        return StoredVariable(self.name, dims, self.attrs, values=self.values.transpose(order))


class PerSampleEnsemble:
    """An ``ensemble.nc`` opened with netCDF4 (:func:`open_per_sample`): what the decision
    readers use of an :class:`xarray.Dataset`, with the same values. A context manager that
    closes the file.

    Attributes:
        attrs: the global attributes; dims, sizes: dimension lengths by name;
        coords: the variables xarray makes coordinates (one named like its only dim, or named
            in another's ``coordinates`` attribute); data_vars: the others.
    """

    def __init__(self, nc: netCDF4.Dataset) -> None:
        self._nc = nc
        self.attrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
        self.sizes = {str(name): len(dim) for name, dim in nc.dimensions.items()}
        self.dims = self.sizes
        variables = {str(name): StoredVariable.of(var) for name, var in nc.variables.items()}
        named = {
            str(c)
            for var in nc.variables.values()
            if "coordinates" in var.ncattrs()
            for c in str(var.getncattr("coordinates")).split()
        }
        is_coord = {n: v.dims == (n,) or n in named for n, v in variables.items()}
        self.coords = {n: v for n, v in variables.items() if is_coord[n]}
        self.data_vars = {n: v for n, v in variables.items() if not is_coord[n]}

    def __getitem__(self, name: str) -> StoredVariable:
        return self.data_vars[name] if name in self.data_vars else self.coords[name]

    def close(self) -> None:
        """Close the file (the values already read stay)."""
        self._nc.close()

    def __enter__(self) -> PerSampleEnsemble:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


StoredEnsemble: TypeAlias = "xr.Dataset | PerSampleEnsemble"
"""What the decision readers take: an xarray Dataset (``mcchain export``, ``verdict``) or
the netCDF4 view a run reads its own verdict from."""


def needs_decoding(nc: netCDF4.Dataset) -> str | None:
    """Why xarray would decode a variable of ``nc`` (its name and the reason), None if
    none: every variable is then read as stored."""
    for name, var in nc.variables.items():
        attrs = set(var.ncattrs())
        found = sorted(attrs.intersection(CF_ENCODING))
        if found:
            return f"{name}: {', '.join(found)}"
        if " since " in str(var.getncattr("units") if "units" in attrs else ""):
            return f"{name}: a time unit"
        if var.dtype is not str and np.dtype(var.dtype).kind not in "biuf":
            return f"{name}: dtype {var.dtype}"
    return None


def open_per_sample(path: Path) -> PerSampleEnsemble:
    """``path`` (a merged ensemble) opened with netCDF4.

    Raises:
        NeedsDecoding: a variable xarray would decode (:func:`needs_decoding`).
        DamagedEnsemble: the file cannot be opened, or its ``status`` read (as
            :func:`mcchain.ensemble.io.open_ensemble` says).
    """
    import netCDF4

    try:
        nc = netCDF4.Dataset(path, "r")
    except (OSError, ValueError, RuntimeError) as exc:
        raise DamagedEnsemble(path, exc) from None
    try:
        nc.set_auto_maskandscale(False)  # what xarray's backend reads: the values as stored
        why = needs_decoding(nc)
        if why is not None:
            raise NeedsDecoding(why)
        ds = PerSampleEnsemble(nc)
        try:
            ds["status"].values  # noqa: B018 (a damaged file fails here, as open_ensemble does)
        except (OSError, ValueError, RuntimeError, KeyError) as exc:
            raise DamagedEnsemble(path, exc) from None
    except BaseException:
        nc.close()
        raise
    return ds


def open_stored(path: Path) -> StoredEnsemble:
    """``path`` for the decision readers: :func:`open_per_sample`, or the xarray Dataset
    (:func:`mcchain.ensemble.io.open_ensemble`, without Dask) of a file that needs decoding.
    Either closes as a context manager."""
    try:
        return open_per_sample(path)
    except NeedsDecoding:
        from mcchain.ensemble.io import open_ensemble

        return open_ensemble(path, dask=False)
