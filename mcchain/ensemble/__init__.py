"""The ensemble: variable registry (names, dims, units, dtypes), Datasets, netCDF I/O.

* :mod:`mcchain.ensemble.registry` declares every variable once and builds/validates
  Datasets from solver output dicts.
* :mod:`mcchain.ensemble.io` writes part files atomically and merges them by streaming into
  one compressed ``ensemble.nc``.
"""

from __future__ import annotations

from mcchain.ensemble.io import (
    MergeError,
    MergeStats,
    Part,
    compression_options,
    list_parts,
    merge_parts,
    open_ensemble,
    open_parts,
    write_part,
)
from mcchain.ensemble.registry import (
    COORDINATES,
    VARIABLES,
    VariableSpec,
    build_dataset,
    by_analysis,
    coerce_outputs,
    validate_dataset,
)

__all__ = [
    "COORDINATES",
    "VARIABLES",
    "MergeError",
    "MergeStats",
    "Part",
    "VariableSpec",
    "build_dataset",
    "by_analysis",
    "coerce_outputs",
    "compression_options",
    "list_parts",
    "merge_parts",
    "open_ensemble",
    "open_parts",
    "validate_dataset",
    "write_part",
]
