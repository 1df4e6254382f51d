"""Failed samples solved again before they count as undefined (``[simulate] retry_failed``).

A sample whose time integration fails at the scene's settings (a failure bit of the
integration in ``status``: diverged, singular, a contact step too large; its values NaN) is
solved again, alone, by each attempt of :func:`attempts` in turn until one solves it:

1. ``tightened_10``: the scene's integration 10 times tighter (``rtol`` and ``atol`` / 10 for
   the adaptive methods ``rk45`` and ``radau``, ``dt`` / 10 for the fixed-step ones);
2. ``tightened_100``: 100 times tighter;
3. ``radau``: the implicit Radau IIA(5) at the scene's ``rtol``/``atol`` / 100 (left out when
   the scene already integrates with ``radau``).

What solved each sample is the per-sample variable ``solved_by`` (:data:`SOLVED_BY`, int8,
CF ``flag_values``/``flag_meanings``): 0 ``as_written`` (the scene's own settings, also a
sample that failed for a reason no tolerance changes: an assembly or an equilibrium that
failed), 1-3 the attempt above, 4 ``unsolved`` (every attempt failed: it keeps the flags and
NaN values of the scene's settings). A retried sample's values are exactly those of a fresh
run of that sample at the attempt's settings: the kernels compute every sample alone, so
the ensemble stays identical whatever the chunking, threads or scheduler.

:class:`RetryFailed` is the run's solve step (:data:`mcchain.runner.steps.SolveStep`); it
touches only the failed samples, so a run without failures pays nothing but a scan of
``status``. The integration steps of the attempts are added to the samples'
:data:`~mcchain.ensemble.registry.STEPS_TAKEN` (the run's throughput counts them).
:func:`tightened_simulate` is also what ``mcchain check --tighten F`` tightens by.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mcchain.errors import SceneError
from mcchain.status import (
    ASSEMBLY_FAILED,
    CONTACT_STEP_TOO_LARGE,
    DIVERGED,
    EQUILIBRIUM_NOT_CONVERGED,
    FAILURE_BITS,
    SINGULAR,
)

SOLVED_BY = "solved_by"
"""The per-sample ensemble variable saying what solved each sample."""

AS_WRITTEN, TIGHTENED_10, TIGHTENED_100, RADAU, UNSOLVED = 0, 1, 2, 3, 4
SOLVED_BY_MEANINGS = ("as_written", "tightened_10", "tightened_100", "radau", "unsolved")
"""The CF ``flag_meanings`` of :data:`SOLVED_BY`, by value 0..4."""

RETRIED_BITS = DIVERGED | SINGULAR | CONTACT_STEP_TOO_LARGE
"""Failures of the time integration, which a tighter integration may cure."""
KEPT_BITS = ASSEMBLY_FAILED | EQUILIBRIUM_NOT_CONVERGED
"""Failures before the integration: the same at any integration setting, never retried."""

ADAPTIVE_METHODS = ("rk45", "radau")
"""Methods whose accuracy is set by ``rtol``/``atol`` (the others by ``dt``)."""


def divided(value: float, factor: float) -> float:
    """``value / factor`` to 15 significant digits: 1e-10 / 10 is the 1e-11 a table prints,
    not the 1.0000000000000001e-11 of binary division."""
    return float(f"{value / factor:.15g}")


def tightened_simulate(sim: Any, factor: float) -> tuple[Any, str]:
    """``[simulate]`` ``factor`` times tighter (rtol and atol, or dt), and what changed, in
    words: ``rtol 1e-07 -> 1e-08, atol 1e-10 -> 1e-11`` or ``dt 1e-05 -> 1e-06 s``."""
    if sim.method in ADAPTIVE_METHODS:
        update = {"rtol": divided(sim.rtol, factor), "atol": divided(sim.atol, factor)}
        said = f"rtol {sim.rtol:g} -> {update['rtol']:g}, atol {sim.atol:g} -> {update['atol']:g}"
    else:
        update = {"dt": divided(sim.dt, factor)}
        said = f"dt {sim.dt:g} -> {update['dt']:g} s"
    return sim.model_copy(update=update), said


def by_radau(sim: Any, factor: float) -> tuple[Any, str]:
    """``[simulate]`` integrated by ``radau`` at the scene's rtol/atol / ``factor``."""
    rtol, atol = divided(sim.rtol, factor), divided(sim.atol, factor)
    update = {"method": "radau", "rtol": rtol, "atol": atol}
    return sim.model_copy(update=update), f"radau at rtol {rtol:g}, atol {atol:g}"


def attempts(sim: Any) -> list[tuple[int, Any, str]]:
    """The retries of a scene's ``[simulate]``, in order: (``solved_by`` value, settings,
    the settings in words)."""
    tries = [
        (TIGHTENED_10, *tightened_simulate(sim, 10.0)),
        (TIGHTENED_100, *tightened_simulate(sim, 100.0)),
    ]
    if sim.method != "radau":
        tries.append((RADAU, *by_radau(sim, 100.0)))
    return tries


def attempt_scene(scene: Any, solved_by: int) -> Any:
    """The scene as it solved samples whose ``solved_by`` is ``solved_by`` (0 and 4: the
    scene itself)."""
    for value, sim, _ in attempts(scene.simulate):
        if value == solved_by:
            return scene.model_copy(update={"simulate": sim})
    return scene


def retries_on(scene: Any) -> bool:
    """Whether a run of ``scene`` retries its failed samples (``[simulate] retry_failed``)."""
    sim = getattr(scene, "simulate", None)
    return sim is not None and bool(getattr(sim, "retry_failed", False))


def retryable(status: np.ndarray) -> np.ndarray:
    """(nsample,) bool: the samples whose time integration failed, and nothing before it."""
    status = np.asarray(status)
    return ((status & RETRIED_BITS) != 0) & ((status & KEPT_BITS) == 0)


SolveFn = Callable[[Any, Any], Mapping[str, Any]]


@dataclass(frozen=True)
class RetryFailed:
    """The solve step of ``[simulate] retry_failed = true`` (see the module docstring):
    ``step(model_chunk, scene, outputs) -> outputs`` with the failed samples' values replaced
    by those of the first attempt that solved them, and :data:`SOLVED_BY` added. Picklable
    (a Dask worker runs it). ``solve``: the chunk solver (default
    :func:`mcchain.solvers.solve_chunk`)."""

    solve: SolveFn | None = None

    def __call__(self, model: Any, scene: Any, outputs: dict[str, Any]) -> dict[str, Any]:
        from mcchain.ensemble.registry import AXIS_OUTPUTS, STEPS_TAKEN

        status = np.asarray(outputs["status"])
        solved_by = np.full(status.shape, AS_WRITTEN, dtype=np.int8)
        todo = np.flatnonzero(retryable(status))
        if todo.size:
            solve = self.solve or _solve_chunk()
            per_sample = [k for k in outputs if k not in AXIS_OUTPUTS]
            result = {k: np.array(outputs[k], copy=True) for k in per_sample}
            for value, sim, _ in attempts(scene.simulate):
                try:
                    fresh = solve(model.take(todo), scene.model_copy(update={"simulate": sim}))
                except SceneError:  # settings the grid refuses (a dt within t's rounding)
                    continue
                if STEPS_TAKEN in result and STEPS_TAKEN in fresh:
                    result[STEPS_TAKEN][todo] += np.asarray(fresh[STEPS_TAKEN])
                solved = (np.asarray(fresh["status"]) & FAILURE_BITS) == 0
                done = todo[solved]
                for name in per_sample:
                    if name != STEPS_TAKEN:
                        result[name][done] = np.asarray(fresh[name])[solved]
                solved_by[done] = value
                todo = todo[~solved]
                if not todo.size:
                    break
            solved_by[todo] = UNSOLVED
            outputs = {**outputs, **result}
        outputs[SOLVED_BY] = solved_by
        return outputs


def _solve_chunk() -> SolveFn:
    from mcchain.solvers import solve_chunk

    return solve_chunk  # type: ignore[return-value]


def retry_counts(solved_by: np.ndarray, sim: Any) -> dict[str, Any]:
    """What solved a run's samples (``run.json["retries"]``): the count of each
    :data:`SOLVED_BY_MEANINGS`, the settings of each attempt in words, and the note line
    ``mcchain run`` prints (None when nothing was retried)."""
    values = np.asarray(solved_by)
    counts = {m: int(np.count_nonzero(values == i)) for i, m in enumerate(SOLVED_BY_MEANINGS)}
    said = {SOLVED_BY_MEANINGS[value]: words for value, _, words in attempts(sim)}
    retried = values.size - counts["as_written"]
    line = None
    if retried:
        parts = [
            f"{counts[m]} by {said[m]}" for m in SOLVED_BY_MEANINGS[1:4] if m in said and counts[m]
        ]
        line = (
            f"retried: {retried} of {values.size} samples failed at the scene's tolerance and "
            f"were solved again: {', '.join(parts) or 'none solved'}"
            + (f"; {counts['unsolved']} still fail (flagged, NaN)" if counts["unsolved"] else "")
            + " (solved_by in the ensemble; [simulate] retry_failed = false keeps the failures)"
        )
    return {"counts": counts, "attempts": said, "line": line}
