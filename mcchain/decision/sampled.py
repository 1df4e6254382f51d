"""What a stored ensemble sampled: its design, and each parameter's values, distribution,
units and range (for the verdicts, the allocation, the what-if tolerances and ``mcchain
confirm``)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mcchain.ensemble.per_sample import StoredEnsemble
    from mcchain.scene.study import Distribution


@dataclass(frozen=True)
class SampledParameter:
    """One column of ``parameters``.

    Attributes:
        path: the ``[sample.vary]`` path.
        values: (nsample,) the sampled values.
        distribution: its distribution as the scene wrote it (None for a run that predates
            stored settings).
        units: CF units (``param_units``).
    """

    path: str
    values: np.ndarray
    distribution: Distribution | None
    units: str

    @property
    def support(self) -> tuple[float, float]:
        """The range the distribution can give (±inf where unbounded)."""
        bounds = self.distribution.bounds() if self.distribution is not None else None
        return (-math.inf, math.inf) if bounds is None else (float(bounds[0]), float(bounds[1]))


def sampled_parameters(ds: StoredEnsemble) -> list[SampledParameter]:
    """Every sampled parameter of a stored ensemble ([] without ``parameters``)."""
    if "parameters" not in ds.data_vars or "param" not in ds.dims:
        return []
    from mcchain.parameters import param_units
    from mcchain.scene.study import Distribution

    values = np.asarray(ds["parameters"].transpose("sample", "param").values, dtype=np.float64)
    paths = [str(p) for p in ds["param"].values]
    settings = json.loads(str(ds.attrs.get("settings", "{}")))
    vary = ((settings.get("scene") or {}).get("sample") or {}).get("vary") or {}
    units = (
        [str(u) for u in ds["param_units"].values]
        if "param_units" in ds.coords
        else [param_units(p) for p in paths]
    )
    out = []
    for j, path in enumerate(paths):
        data = vary.get(path)
        dist = Distribution.model_validate(data) if data is not None else None
        out.append(SampledParameter(path, values[:, j], dist, units[j]))
    return out


EXACT_DESIGNS = ("random",)
"""Designs whose samples are independent draws: the binomial interval is exact."""


def design_of(ds: StoredEnsemble) -> str | None:
    """The sampling design of a stored ensemble (``[sample] design``), None without
    ``[sample]``."""
    settings = json.loads(str(ds.attrs.get("settings", "{}")))
    sample = (settings.get("scene") or {}).get("sample")
    return None if not sample else str(sample.get("design", "random"))
