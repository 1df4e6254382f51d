"""Python drivers of the analyses: allocate arrays, call kernels, decode status bits.

:func:`solve_chunk` is the one entry point the run machinery calls for a chunk of samples:
it runs exactly the analyses the scene's sections ask for and returns arrays
keyed by ensemble variable name, sample axis first.
"""

from __future__ import annotations

import numpy as np

from mcchain.model import Model
from mcchain.scene.models import Scene
from mcchain.solvers.statics import (
    Assembled,
    EquilibriumResult,
    assemble,
    solve_equilibrium,
    solve_modes,
    solve_modes_along,
)


def wrap_angles(q: np.ndarray) -> np.ndarray:
    """A copy of configurations (..., 3 nbody) with every angle θ wrapped to (−π, π]: a
    configuration's angle, as stored, has one value (time histories keep theirs continuous)."""
    q = np.array(q, dtype=np.float64, copy=True)
    theta = q[..., 2::3]
    q[..., 2::3] = np.pi - np.mod(np.pi - theta, 2.0 * np.pi)
    return q


def solve_chunk(
    model: Model, scene: Scene, assembled: Assembled | None = None, *, with_modes: bool = True
) -> dict[str, np.ndarray]:
    """Run the scene's analyses on every sample of ``model``.

    1. Assembly of the initial state (always; ``assembled`` given: that state instead, as
       :mod:`mcchain.compiled.ahead` does to compile the rest without assembly).
    2. ``[equilibrium]`` or ``[modes]``: Newton equilibrium, then the eigen step, which
       also decides ``stable``; ``omega``, ``damped_omega``, ``damping_ratio`` and
       ``mode_shape`` (unless ``shapes = false``) are stored only with ``[modes]``.
       ``with_modes=False`` leaves the eigen step out (and its outputs): the compile-ahead
       helper's share, while the run's own process compiles the eigen step.
    3. ``[simulate]``: time integration from the assembled state or the equilibrium.

    Returns:
        Arrays keyed by ensemble variable name, sample axis first, plus ``status`` (uint32,
        every analysis' bits OR-ed) and, with ``[simulate]``, ``time`` and the steps each
        sample took (:data:`mcchain.ensemble.registry.STEPS_TAKEN`, not stored).
    """
    nsample = model.nsample
    out: dict[str, np.ndarray] = {"parameters": np.asarray(model.parameters, dtype=np.float64)}
    if assembled is None:
        assembled = assemble(model)
    status = assembled.status.copy()
    equilibrium = None
    timed = [o for o in scene.output if o.at is None]
    static = [o for o in scene.output if o.at is not None]
    ideal = _Ideal(model, scene) if any(o.relative_to for o in scene.output) else None
    if scene.equilibrium is not None or scene.modes is not None:
        settings = scene.equilibrium
        equilibrium = solve_equilibrium(model, assembled.q, assembled.status, settings)
        if static:
            from mcchain.solvers.outputs import equilibrium_outputs

            reference: tuple[Model, np.ndarray, np.ndarray] | None = None
            if any(o.relative_to for o in static):
                assert ideal is not None
                status |= ideal.equilibrium().status
                reference = (ideal.model, ideal.equilibrium().q, ideal.equilibrium().lam)
            out.update(
                equilibrium_outputs(static, model, equilibrium.q, equilibrium.lam, reference)
            )
        out["q_eq"] = wrap_angles(equilibrium.q).reshape(nsample, model.nbody, 3)
        out["joint_force_eq"] = equilibrium.joint_force
        if model.has_prismatic:
            out["joint_moment_eq"] = equilibrium.joint_moment
        out["iterations"] = equilibrium.iterations
        if with_modes:
            want_shapes = scene.modes is not None and scene.modes.shapes
            damped = scene.modes is not None
            modes = solve_modes(model, equilibrium, shapes=want_shapes, damped=damped)
            status |= modes.status
            out["stable"] = modes.stable
            if scene.modes is not None:
                out["omega"] = modes.omega
                assert modes.damped_omega is not None and modes.damping_ratio is not None
                out["damped_omega"] = modes.damped_omega
                out["damping_ratio"] = modes.damping_ratio
                if modes.shapes is not None:
                    shapes = modes.shapes.reshape(nsample, model.nmode, model.nbody, 3)
                    out["mode_shape"] = shapes
        along = None if scene.modes is None else scene.modes.along
        if along is not None:
            driver = model.driver_names.index(along.driver)
            cycle = solve_modes_along(model, driver, along.points, assembled.q, assembled.v)
            out["omega_cycle"] = cycle.omega
            out["cycle_phase"] = cycle.phase
    if scene.simulate is not None:
        from mcchain.ensemble.registry import STEPS_TAKEN
        from mcchain.solvers.simulate import simulate

        at_equilibrium = scene.simulate.start == "equilibrium"
        if at_equilibrium:
            if equilibrium is None:
                equilibrium = solve_equilibrium(model, assembled.q, assembled.status)
                status |= equilibrium.status
            q_start, v_start = equilibrium.q, np.zeros_like(equilibrium.q)
        else:
            q_start, v_start = assembled.q, assembled.v
        storage = np.dtype(scene.storage.history_dtype)
        # "none" stores no history: the solver computes none (0 times), the store drops them
        histories = scene.storage.histories != "none"
        if timed:
            from mcchain.solvers.outputs import simulate_outputs

            start: tuple[np.ndarray, np.ndarray] | None = None
            if any(o.relative_to for o in timed):
                assert ideal is not None
                start = ideal.start(at_equilibrium)
                status |= ideal.status(at_equilibrium)
            history = simulate_outputs(
                model, timed, scene.simulate, q_start, v_start, start, status,
                history_dtype=storage, diagnostics=True, histories=histories,
            )  # fmt: skip
        else:
            history = simulate(
                model,
                scene.simulate,
                q_start=q_start,
                v_start=v_start,
                history_dtype=storage,
                status=status,
                diagnostics=True,
                histories=histories,
            )
        status |= history.pop("status")
        out[STEPS_TAKEN] = history.pop("steps")
        del history["rejected_steps"], history["evaluations"]
        out.update(history)
    out["status"] = status
    return out


class _Ideal:
    """The ideal mechanism of a chunk (every clearance joint ideal, the same samples:
    :func:`mcchain.solvers.ideal.ideal_model`), its assembled start and equilibrium, each
    computed once when first asked."""

    def __init__(self, model: Model, scene: Scene) -> None:
        from mcchain.solvers.ideal import ideal_model

        self.model = ideal_model(model)
        self.settings = scene.equilibrium
        self._assembled: Assembled | None = None
        self._equilibrium: EquilibriumResult | None = None

    def assembled(self) -> Assembled:
        if self._assembled is None:
            self._assembled = assemble(self.model)
        return self._assembled

    def equilibrium(self) -> EquilibriumResult:
        if self._equilibrium is None:
            start = self.assembled()
            self._equilibrium = solve_equilibrium(self.model, start.q, start.status, self.settings)
        return self._equilibrium

    def start(self, at_equilibrium: bool) -> tuple[np.ndarray, np.ndarray]:
        """The start of its time history: assembled, or at rest at its equilibrium."""
        if at_equilibrium:
            q = self.equilibrium().q
            return q, np.zeros_like(q)
        return self.assembled().q, self.assembled().v

    def status(self, at_equilibrium: bool) -> np.ndarray:
        """The status bits of that start (a failed one fails the sample's outputs)."""
        return self.equilibrium().status if at_equilibrium else self.assembled().status
