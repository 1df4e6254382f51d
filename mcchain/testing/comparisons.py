"""Which fast result is held to which reference, and how closely: one table for both the
tests' assertions and the benchmarks' error axes.

Time histories are compared with ``radau`` at rtol 1e-12 (:data:`REFERENCE`), itself held to
minimal coordinates (sympy Lagrangians) to 1e-9 m by the tests. The tolerances are what an
explicit method at its finest swept step (rk4, dt = 1e-5 s) must reach.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mcchain.model import Model
from mcchain.status import CONTACT_LOST

REFERENCE: dict[str, Any] = dict(method="radau", rtol=1e-12, atol=1e-13)
"""The reference integration's settings."""


@dataclass(frozen=True)
class HistoryComparison:
    """A time history of one named scene against :data:`REFERENCE`.

    Attributes:
        name: label in test ids and benchmark tables.
        scene: key of :data:`mcchain.testing.scenes.SCENES`.
        t_end: simulated time, s.
        output_dt: output interval, s (a whole multiple of every step the benchmarks sweep).
        position_tol: max |x, y − reference| over the history, m.
        force_tol: max joint force error relative to the reference's peak joint force.
    """

    name: str
    scene: str
    t_end: float
    output_dt: float = 0.01
    position_tol: float = 1e-8
    force_tol: float = 1e-6

    def settings(self, **overrides: Any) -> dict[str, Any]:
        """``[simulate]`` settings of this comparison, with ``overrides``."""
        return {"t_end": self.t_end, "dt": self.output_dt, "output_dt": self.output_dt, **overrides}

    def reference(self, model: Model) -> dict[str, np.ndarray]:
        """The reference history of ``model`` (float64)."""
        return simulate_float64(model, self.settings(**REFERENCE))


HISTORIES = (
    HistoryComparison("clearance bar", "clearance_bar", t_end=0.3),
    HistoryComparison("double pendulum, clearance", "double_pendulum", t_end=0.2),
    HistoryComparison("four-bar, clearance", "fourbar", t_end=0.1),
)
"""The histories every method is measured on (tests: rk4 at dt 1e-5 within the tolerances;
benchmark: error against cost over steps and tolerances)."""


def simulate_float64(model: Model, settings: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
    """``simulate`` with float64 histories (the tests' and benchmarks' comparisons)."""
    from mcchain.solvers.simulate import simulate

    return simulate(model, settings, history_dtype=np.float64, **kwargs)


def simulate_scene(text: str, **settings: Any) -> dict[str, Any]:
    """The time history of a scene given as TOML text from its assembled state, its
    ``[simulate]`` keys updated with ``settings``, float64 histories."""
    from mcchain.scene import compile_model, load_scene_text
    from mcchain.solvers.simulate import simulate
    from mcchain.solvers.statics import assemble

    scene = load_scene_text(text)
    if scene.simulate is None:
        raise ValueError("simulate_scene: the scene has no [simulate] section")
    model = compile_model(scene)
    start = assemble(model)
    return simulate(
        model, scene.simulate.model_copy(update=settings), q_start=start.q, v_start=start.v,
        status=start.status, history_dtype=np.float64,
    )  # fmt: skip


def history_errors(result: dict[str, Any], reference: dict[str, Any]) -> tuple[float, float]:
    """(max position error in m over x, y, relative joint force error) of sample 0; inf where
    the result is not finite."""
    q, q_ref = result["q"][0][..., :2], reference["q"][0][..., :2]
    if not np.all(np.isfinite(q)):
        return np.inf, np.inf
    position = float(np.abs(q - q_ref).max())
    force, force_ref = result["joint_force"][0], reference["joint_force"][0]
    relative = float(np.abs(force - force_ref).max() / np.abs(force_ref).max())
    return position, relative


def failed(status: np.ndarray) -> np.ndarray:
    """Status bits other than the contact-loss warning (the comparisons' scenes may lose
    contact; the link model is what they compare)."""
    return np.asarray(status) & ~np.uint32(CONTACT_LOST)
