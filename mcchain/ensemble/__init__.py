"""The ensemble: variable registry (names, dims, units, dtypes), Datasets, netCDF I/O.

* :mod:`mcchain.ensemble.registry` declares every variable once, builds a chunk's
  variables (or a Dataset) from solver output dicts and validates Datasets.
* :mod:`mcchain.ensemble.io` writes part files atomically and merges them by streaming into
  one compressed ``ensemble.nc``.
* :mod:`mcchain.ensemble.histories`: which time histories a run stores (``[storage]
  histories``: all, none, those of the failed samples along ``history_sample``) and how a
  reader finds a sample's history or learns it was not stored.
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
    ChunkVariables,
    VariableSpec,
    build_dataset,
    by_analysis,
    chunk_variables,
    coerce_outputs,
    validate_dataset,
)

__all__ = [
    "COORDINATES",
    "VARIABLES",
    "ChunkVariables",
    "MergeError",
    "MergeStats",
    "Part",
    "VariableSpec",
    "build_dataset",
    "by_analysis",
    "chunk_variables",
    "coerce_outputs",
    "compression_options",
    "list_parts",
    "merge_parts",
    "open_ensemble",
    "open_parts",
    "validate_dataset",
    "write_part",
]
