"""``[[output]]`` in the solvers: what the kernels are given, and the equilibrium's values.

* the plan the kernels take: :mod:`mcchain.solvers.output_plan`.
* :func:`simulate_outputs`: a time history with outputs; with a ``relative_to = "ideal"``
  one, the mechanism and its ideal copy integrated together (:mod:`mcchain.solvers.ideal`),
  the arrays then cut back to the mechanism's own.
* :func:`equilibrium_outputs`: the outputs ``at = "equilibrium"``, from the equilibrium
  (and, relative to the ideal mechanism, from that one's equilibrium of the same sample).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mcchain.model import Model
from mcchain.solvers.output_plan import OutputPlan, output_plan


def check_ideal(scene: Any, model: Model) -> None:
    """A scene with a ``relative_to = "ideal"`` output: its ideal mechanism (every clearance
    joint ideal) must assemble with independent constraints too (a mechanism that closes
    only thanks to its play has none); else one :class:`SceneError` line naming the output."""
    from mcchain.errors import SceneError
    from mcchain.solvers.ideal import ideal_model
    from mcchain.solvers.statics import check_scene

    relative = [o for o in scene.output if o.relative_to == "ideal"]
    if not relative:
        return
    try:
        check_scene(ideal_model(model.select(0, 1)))
    except SceneError as exc:
        raise SceneError(
            f"output.{relative[0].name}.relative_to: the ideal mechanism (every clearance "
            f"joint ideal) cannot be built: {exc}"
        ) from None


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
    are cut back to the mechanism's own; with ``rk45`` and one ideal mechanism for every
    sample, that one is integrated once and read from tables instead
    (:func:`mcchain.solvers.ideal.tabulated_plan`)."""
    from mcchain.solvers.ideal import (
        ideal_model,
        main_part,
        shared_ideal,
        tabulated_plan,
        with_ideal_copy,
    )
    from mcchain.solvers.simulate import simulate
    from mcchain.solvers.start import start_state
    from mcchain.status import FAILURE_BITS

    plan = output_plan(outputs, model, float(sim.t_end))
    if not plan.relative:
        history = simulate(model, sim, q_start, v_start, status=status, outputs=plan, **kwargs)
        return _with_values(history, plan)
    assert reference_start is not None
    ideal = ideal_model(model)
    q, v, status = start_state(model, sim, q_start, v_start, status)
    qi, vi, status = start_state(ideal, sim, *reference_start, status)
    tabulated = None
    if sim.method == "rk45" and shared_ideal(ideal, qi, vi, status):
        first = int(np.flatnonzero((status & FAILURE_BITS) == 0)[0])
        one = slice(first, first + 1)
        tabulated = tabulated_plan(ideal.take(one), qi[one], vi[one], sim, plan)
    if tabulated is not None:  # one ideal for every sample: integrated once, read from tables
        history = simulate(
            model, sim.model_copy(update={"perturb": {}}), q, v, status=status,
            outputs=tabulated, **kwargs,
        )  # fmt: skip
        return _with_values(history, plan)
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
