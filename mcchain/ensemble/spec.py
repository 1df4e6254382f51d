"""The declaration of one ensemble variable (:class:`VariableSpec`): the registry's
(:mod:`mcchain.ensemble.registry`) and a scene's own ``[[output]]``s'
(:mod:`mcchain.ensemble.outputs`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mcchain.status import STATUS_DTYPE


@dataclass(frozen=True)
class VariableSpec:
    """Declaration of one ensemble variable.

    Attributes:
        name: netCDF variable name (a contract with users: never renamed).
        dims: dimension names, ``sample`` first.
        units: CF units string.
        long_name: CF long_name.
        dtype: dtype rule, one of :data:`DTYPE_RULES`.
        analysis: producing analysis, one of :data:`ANALYSES`.
        attrs: further CF attributes (flag masks, comments).
        event_time: the time of an event, NaN on a sample where the event never happened:
            a requirement reads that NaN as "never" (+inf) when the sample has no failure
            bit (:func:`mcchain.decision.requirements.decision_values`).
    """

    name: str
    dims: tuple[str, ...]
    units: str
    long_name: str
    dtype: str
    analysis: str
    attrs: Mapping[str, Any] = field(default_factory=dict)
    event_time: bool = False

    def storage_dtype(self, history_dtype: str = "float32") -> np.dtype:
        """The numpy dtype the variable is stored with."""
        if self.dtype == "history":
            return np.dtype(history_dtype)
        if self.dtype == "uint32":
            return np.dtype(STATUS_DTYPE)
        return np.dtype(self.dtype)

    def attributes(self) -> dict[str, Any]:
        """CF attributes: ``units``, ``long_name`` and the extras."""
        return {"units": self.units, "long_name": self.long_name, **self.attrs}
