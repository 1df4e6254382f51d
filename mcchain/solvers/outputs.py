"""``[[output]]`` in the solvers: what the kernels are given, and the equilibrium's values.

* :func:`output_plan`: the time outputs of a scene as the arrays every kernel takes
  (:func:`mcchain.kernels.outputs.outputs_feed`): per output its kind, component, item,
  the ideal copy's item, reduction and whether the state gives its rate (``spec``), and per
  sample its point, window and threshold (``data``); ``cycles`` become each sample's
  window from its driver's speed.
* :func:`simulate_outputs`: a time history with outputs; with a ``relative_to = "ideal"``
  one, the mechanism and its ideal copy integrated together (:mod:`mcchain.solvers.ideal`),
  the arrays then cut back to the mechanism's own.
* :func:`equilibrium_outputs`: the outputs ``at = "equilibrium"``, from the equilibrium
  (and, relative to the ideal mechanism, from that one's equilibrium of the same sample).
"""

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


def simulate_outputs(
    model: Model,
    outputs: Sequence[Any],
    sim: Any,
    q_start: np.ndarray,
    v_start: np.ndarray,
    reference_start: tuple[np.ndarray, np.ndarray] | None,
    status: np.ndarray,
    **kwargs: Any,
) -> dict[str, np.ndarray]:
    """:func:`mcchain.solvers.simulate.simulate` of ``model`` with its time outputs
    (returned by name, sample first). With a ``relative_to = "ideal"`` output the model is
    integrated with its ideal copy (``reference_start``: the copy's start state, assembled or
    at its equilibrium, before ``[simulate] perturb``, which both receive), and the arrays
    are cut back to the mechanism's own."""
    from mcchain.solvers.ideal import ideal_model, main_part, with_ideal_copy
    from mcchain.solvers.simulate import simulate
    from mcchain.solvers.start import start_state

    plan = output_plan(outputs, model, float(sim.t_end))
    if not plan.relative:
        history = simulate(model, sim, q_start, v_start, status=status, outputs=plan, **kwargs)
        return _with_values(history, plan)
    assert reference_start is not None
    ideal = ideal_model(model)
    q, v, status = start_state(model, sim, q_start, v_start, status)
    qi, vi, status = start_state(ideal, sim, *reference_start, status)
    both = with_ideal_copy(model, ideal)
    history = simulate(
        both,
        sim.model_copy(update={"perturb": {}}),
        np.concatenate([q, qi], axis=1),
        np.concatenate([v, vi], axis=1),
        status=status,
        outputs=plan,
        **kwargs,
    )
    return _with_values(main_part(both, history), plan)


def _with_values(history: dict[str, np.ndarray], plan: OutputPlan) -> dict[str, np.ndarray]:
    values = history.pop("output_values")
    for k, name in enumerate(plan.names):
        history[name] = np.ascontiguousarray(values[:, k])
    return history


def equilibrium_outputs(
    outputs: Sequence[Any],
    model: Model,
    q: np.ndarray,
    lam: np.ndarray,
    ideal: tuple[Model, np.ndarray, np.ndarray] | None,
) -> dict[str, np.ndarray]:
    """The outputs ``at = "equilibrium"``: each quantity at the equilibrium (q, λ) of every
    sample (velocities and accelerations 0), minus the ideal mechanism's at its own
    equilibrium ``ideal`` = (model, q, λ) for ``relative_to = "ideal"``. NaN where an
    equilibrium failed."""
    static = [o for o in outputs if o.at is not None]
    out: dict[str, np.ndarray] = {}
    for output in static:
        if output.relative_to != "ideal":
            out[output.name] = _static_values(output, model, q, lam)
            continue
        assert ideal is not None
        # the component of the difference: for the magnitude, |r − r_ideal|
        parts = ("x", "y") if output.component == "magnitude" else (output.component,)
        differences = []
        for part in parts:
            single = output.model_copy(update={"component": part, "relative_to": None})
            own = _static_values(single, model, q, lam)
            differences.append(own - _static_values(single, *ideal))
        out[output.name] = np.hypot(*differences) if len(differences) == 2 else differences[0]
    return out


def _static_values(output: Any, model: Model, q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """One output's quantity (no reference) at each sample's equilibrium (q, λ)."""
    from mcchain.kernels.outputs import equilibrium_values

    timed = output.model_copy(update={"at": None, "reduce": "max"})
    plan = output_plan([timed], model, 1.0)
    values = np.full(model.nsample, np.nan)
    equilibrium_values(model.kernel_model(), plan.spec, plan.data, q, lam, values)
    return values
