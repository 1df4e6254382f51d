"""The integration tolerance of a requirement run whose scene writes none.

A verdict is only as good as the values it counts: a peak force off by 20 % near the limit
flips samples, and the default tolerances (``rtol`` 1e-8, ``atol`` 1e-10) are chosen for
histories, not for counting samples at a limit. On the slider-crank with clearance
0.010–0.027 mm (256 samples, the issue's case; docs/scenes.md), ``mcchain check`` of a run at
the defaults flipped 1 sample of 256 against an interval 0.027 wide (more than the tenth of
the width the check calls small), and at rtol 1e-9, atol 1e-11 none: that run passes its
own check. So a requirement run gets the defaults divided by :data:`FACTOR` (10) — the
check's own tightening, one step ahead — when all of these hold:

* ``[simulate]`` uses an adaptive method (``rk45``, ``radau``; a fixed-step method always
  writes its ``dt``, which is kept);
* the scene writes neither ``rtol`` nor ``atol`` (writing either keeps both as written);
* a ``[[requirement]]`` reads an output of the time integration (a requirement on ``omega``
  alone does not pay for a tighter integration).

Cost: rk45 takes about 10^(1/5) = 1.6 times the steps per tenfold tightening (order 5); on
that scene 1.50x the steps of the default (4,671 against 3,124 per sample). The choice is a
``note:`` line of the run and is stored in the ensemble's settings; ``mcchain check`` says
when it is not enough.
"""

from __future__ import annotations

from typing import Any

FACTOR = 10.0
"""How much tighter than the defaults a requirement run integrates."""

ADAPTIVE_METHODS = ("rk45", "radau")
"""Methods whose accuracy is set by rtol/atol."""


def reads_time_integration(output: str) -> bool:
    """Whether a requirement on ``output`` reads a value of the time integration (an output
    the registry does not know, e.g. a user's ``[[output]]``, is taken to)."""
    from mcchain.ensemble.registry import VARIABLES

    spec = VARIABLES.get(output)
    return spec is None or spec.analysis == "simulate"


def requirement_tolerance(scene: Any) -> tuple[Any, str | None]:
    """The scene with ``[simulate] rtol, atol`` chosen for a requirement run (see the module
    docstring), and a line saying so; the scene unchanged and None when the rule does not
    apply."""
    sim = getattr(scene, "simulate", None)
    requirements = getattr(scene, "requirement", None) or ()
    if sim is None or not requirements or getattr(sim, "method", None) not in ADAPTIVE_METHODS:
        return scene, None
    written = getattr(sim, "model_fields_set", None)
    if written is None or {"rtol", "atol"} & set(written):
        return scene, None  # written by the user (or not a scene model: left alone)
    if not any(reads_time_integration(r.output) for r in requirements):
        return scene, None
    fields = type(sim).model_fields
    rtol = float(f"{fields['rtol'].default / FACTOR:.15g}")
    atol = float(f"{fields['atol'].default / FACTOR:.15g}")
    simulate = sim.model_copy(update={"rtol": rtol, "atol": atol})
    note = (
        f"[simulate] writes no rtol/atol: this requirement run integrates at rtol {rtol:g}, "
        f"atol {atol:g} ({FACTOR:g}x tighter than the defaults, about 1.6x the steps) so that "
        "`mcchain check` passes; write rtol/atol to choose them"
    )
    return scene.model_copy(update={"simulate": simulate}), note
