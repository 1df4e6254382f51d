"""The time outputs of a scene as the arrays every kernel takes
(:func:`mcchain.kernels.outputs.outputs_feed`): per output its kind, component, item, the
ideal copy's item, reduction and whether the state gives its rate (``spec``), and per
sample its point, window and threshold (``data``); ``cycles`` become each sample's window
from its driver's speed (:func:`mcchain.scene.outputs.output_window`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mcchain.codes import (
    OUTPUT_COMPONENTS,
    OUTPUT_KINDS,
    OUTPUT_REDUCTIONS,
    OUTPUT_WITH_RATE,
)
from mcchain.model import Model
from mcchain.scene.outputs import output_window

SPEC_COLUMNS = ("kind", "component", "item", "ref", "reduce", "rate")
"""The columns of :attr:`OutputPlan.spec`."""
DATA_COLUMNS = ("sx", "sy", "w0", "w1", "threshold")
"""The columns of :attr:`OutputPlan.data`."""


@dataclass(frozen=True)
class OutputPlan:
    """The time outputs of a scene for the kernels.

    Attributes:
        names: (nout,) the outputs' names.
        spec: (nout, 6) int64, :data:`SPEC_COLUMNS`.
        data: (nsample or 1, nout, 5) float64, :data:`DATA_COLUMNS` (m, m, s, s, the
            quantity's units).
        relative: whether an output subtracts the ideal mechanism's (the model then needs
            its ideal copy, and ``ref`` indexes the copy's items in it).
    """

    names: tuple[str, ...]
    spec: np.ndarray
    data: np.ndarray
    relative: bool

    @property
    def signature(self) -> tuple[tuple[int, ...], ...]:
        """The structure the lane kernels' text depends on (not the per-sample data)."""
        return tuple(tuple(int(x) for x in row) for row in self.spec)

    def take(self, index: slice | np.ndarray) -> OutputPlan:
        """The plan of the samples ``index`` picks (per-sample data indexed)."""
        if self.data.shape[0] == 1:
            return self
        return OutputPlan(self.names, self.spec, self.data[index], self.relative)


def empty_plan(nsample: int) -> OutputPlan:
    """No outputs (the kernels' arrays of size 0: one compiled signature)."""
    return OutputPlan((), np.zeros((0, 6), np.int64), np.zeros((1, 0, 5)), False)


def _item(model: Model, output: Any) -> tuple[int, int]:
    """The output's item index in ``model`` and the same item of its ideal copy (or −1)."""
    if output.body is not None:
        index, kind = model.body_names.index(output.body), 0
    elif output.joint is not None:
        index, kind = model.joint_names.index(output.joint), 1
    else:
        index, kind = model.driver_names.index(output.driver), 2
    ref = -1
    if output.relative_to == "ideal":
        counts = (model.nbody, model.njoint, model.ndriver)
        ref = counts[kind] + index  # the copy's items follow the mechanism's
    return index, ref


def output_plan(outputs: Sequence[Any], model: Model, t_end: float) -> OutputPlan:
    """The plan of the outputs that reduce a history (``at`` ones left out) for ``model``
    (the mechanism alone: ``ref`` counts its items as :func:`mcchain.solvers.ideal.
    with_ideal_copy` appends the copy's)."""
    timed = [o for o in outputs if o.at is None]
    nout = len(timed)
    spec = np.zeros((nout, 6), dtype=np.int64)
    windows = [output_window(o, model, t_end) for o in timed]
    nrow = max([w.shape[0] for w in windows] + [1])
    data = np.zeros((nrow, nout, 5))
    for k, output in enumerate(timed):
        index, ref = _item(model, output)
        kind = OUTPUT_KINDS[output.of]
        component = OUTPUT_COMPONENTS[output.component] if output.component else -1
        rate = 1 if kind in OUTPUT_WITH_RATE else 0
        spec[k] = (kind, component, index, ref, OUTPUT_REDUCTIONS[output.reduce], rate)
        point = output.point if output.point is not None else (0.0, 0.0)
        data[:, k, 0:2] = point
        data[:, k, 2:4] = windows[k]
        data[:, k, 4] = output.threshold if output.threshold is not None else 0.0
    relative = any(o.relative_to == "ideal" for o in timed)
    return OutputPlan(tuple(o.name for o in timed), spec, data, relative)
