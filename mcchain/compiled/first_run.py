"""A first run on a cold cache: the kernels run interpreted while they compile for the next.

A statics sweep's kernels take about 35 s of one core to compile (about 20 s on two, with
:mod:`mcchain.compiled.ahead`), where the Quick start's 10,000 samples then solve in 0.15 s.
Interpreted as plain Python (:func:`mcchain.kernels.config.interpret_kernels`), the same
kernels solve those samples in about 4-5 s, with the compiled kernels' bits: the same IEEE
operations in the same order, libm's ``hypot`` in both (tested on every shipped scene, and
a run's ``ensemble.nc`` holds the same bytes either way, but for its attribute
``kernel_compiler``). So on a cold cache a small statics run is interpreted, and a detached
process compiles the kernels into the cache meanwhile where it may (in an interactive
terminal, outside CI and batch schedulers, not switched off:
:func:`mcchain.compiled.background.background_note`): the next run loads them. Which way a run
went is in ``run.json`` (its notes, ``kernels_interpreted`` and ``kernel_compiler`` in its
session) and in the ensemble's attribute ``kernel_compiler``.

:func:`choose` decides, before any kernel module is imported, and only in a process that
does nothing but this run (``mcchain run SCENE`` from the console script, never a process
that called :func:`mcchain.cli.main`). The run is interpreted when all of these hold:

* the scene has no ``[simulate]`` (the generated lane kernels may fuse a multiply and an
  add, which Python does not: their bits would differ) and at most
  :data:`~mcchain.kernels.config.INTERPRET_MAX_COORDINATES` coordinates;
* numba's cache lacks a statics kernel (:func:`mcchain.compiled.caches.kernels_cached`);
* a probe, a few samples solved interpreted, projects the run's kernels within
  :data:`BUDGET_S`. The cost per sample spans four orders of magnitude (0.2 ms for a bar,
  6 s for a 16-bar chain): no formula in the size predicts it, so it is measured.

Where the probe says no (or fails), the process replaces itself by the same command with
the kernels compiled (:func:`run_compiled`), before anything is written; the probe cost
well under a second of a cold run compiling for 20 s or more. Should the interpreted
kernels raise during the run where numba gives inf or NaN (a Python float divided by zero
on a degenerate instance), the run goes on with the compiled kernels from its last
finished chunk (``mcchain run --resume``), so no instance stops the batch.

``MCCHAIN_INTERPRET_COLD``: ``0`` never interprets; ``1`` interprets whenever the scene
and the cache allow, without the probe (tests); unset, the probe decides.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

ENV_SWITCH = "MCCHAIN_INTERPRET_COLD"
"""``0``: never interpret; ``1``: interpret without the probe; unset: the probe decides."""

BUDGET_S = 10.0
"""Largest projected time of a run's kernels interpreted: half of the cold compile it saves
on two cores (about 20 s; 35 s on one), since the background compile shares the machine."""

PROBE_SAMPLES = 32
"""Samples the probe solves at most (random ones: their cost per sample varies with the
Newton iterations each needs)."""

PROBE_S = 0.3
"""About the longest the probe takes, when one sample is quicker."""

STATICS_KERNELS = [
    "assembly.assemble_batch",
    "statics.equilibrium_batch",
    "statics.joint_forces_batch",
    "statics.modes_batch",
]
"""The kernels a statics run calls first; any missing from numba's cache means a compile."""


@dataclass(frozen=True)
class FirstRun:
    """A run chosen to go interpreted (:func:`choose`)."""

    seconds_per_sample: float | None
    """Measured by the probe (None: ``MCCHAIN_INTERPRET_COLD=1``, no probe)."""

    def note(self, nsample: int, background: str) -> str:
        """The run's ``note:`` line; ``background``: what compiles the kernels meanwhile."""
        seconds = (self.seconds_per_sample or 0.0) * nsample
        about = f", about {seconds:.1f} s" if seconds >= 0.1 else ""
        samples = f"{nsample:,} samples" if nsample != 1 else "1 sample"
        return (
            f"the kernels are not compiled yet: this run's {samples} run them interpreted "
            f"(the same values{about}); {background}"
        )


def choose(
    scene_path: str | Path,
    samples: int | None,
    seed: int | None,
    now: Callable[[], float] = time.time,
) -> FirstRun | None:
    """Whether this run goes interpreted (see the module's docstring): a :class:`FirstRun`
    if so, None to go on compiled as usual. Where the probe says no, or where a background
    compile already running should end sooner than the run interpreted would (from when it
    started and the length of the last one: :func:`mcchain.compiled.background.
    background_remaining`, on the clock ``now``), the process is replaced by the same
    command with compiled kernels (:func:`run_compiled`, after waiting for that compile),
    and this does not return."""
    switch = os.environ.get(ENV_SWITCH)
    if switch == "0":
        return None
    from mcchain.compiled.caches import kernels_cached
    from mcchain.kernels.config import INTERPRET_MAX_COORDINATES
    from mcchain.scene import load_scene

    try:
        scene = load_scene(scene_path)
    except Exception:  # the run reports it, as without this
        return None
    if scene.simulate is not None or 3 * len(scene.body) > INTERPRET_MAX_COORDINATES:
        return None
    if scene.equilibrium is None and scene.modes is None:
        return None  # assembly only: its compile is the scene check's, a few seconds
    kernels = STATICS_KERNELS
    if scene.modes is not None and scene.modes.along is not None:
        kernels = [*kernels, "statics.dynamic_multipliers_batch"]
    if kernels_cached(kernels) is not False:
        return None
    from mcchain.kernels.config import interpret_kernels

    if not interpret_kernels():
        return None
    if switch == "1":
        return FirstRun(None)
    count = samples if samples is not None else (scene.sample.count if scene.sample else 1)
    try:
        per_sample = _probe(scene, seed)
    except Exception:  # interpreted, a degenerate instance may raise: compile
        run_compiled()
    if per_sample * count > BUDGET_S:
        run_compiled()
    from mcchain.compiled.background import background_remaining, wait_background

    remaining = background_remaining(now)
    if remaining is not None and remaining < per_sample * count:
        wait_background()
        run_compiled()  # the kernels are in the cache now (or, if it failed, compile here)
    return FirstRun(per_sample)


def _probe(scene: Any, seed: int | None) -> float:
    """Seconds per sample of the scene's analyses interpreted, on up to
    :data:`PROBE_SAMPLES` random samples of its design's ranges (no quasi-random design:
    drawing one imports scipy.stats): one sample, then as many more in one block as fit
    in :data:`PROBE_S` by the first one's time. A run solves its samples in chunks of
    hundreds, so the block's time per sample is the one to project (a call alone costs
    about 1 ms interpreted, more than a small mechanism's sample)."""
    import numpy as np

    from mcchain.scene import compile_model
    from mcchain.solvers import solve_chunk

    sample = scene.sample
    if sample is not None:
        sample = sample.model_copy(update={"design": "random", "count": PROBE_SAMPLES})
    probe_scene = scene.model_copy(update={"sample": sample})
    model = compile_model(probe_scene, seed=seed)
    with np.errstate(all="ignore"):
        t0 = time.perf_counter()
        solve_chunk(model.select(0, 1), probe_scene)
        first = time.perf_counter() - t0
        block = min(model.nsample - 1, int(PROBE_S / first))
        if block < 1:
            return first
        t0 = time.perf_counter()
        solve_chunk(model.select(1, 1 + block), probe_scene)
        return (time.perf_counter() - t0) / block


def run_compiled(resume: Path | None = None, reason: BaseException | None = None) -> NoReturn:
    """Replace this process by ``mcchain`` with the same arguments and compiled kernels,
    or (``resume``) by ``mcchain run --resume`` of that run folder, with the arguments that
    go with a resume. ``reason``: what the interpreted kernels raised (said in a note)."""
    if reason is not None:
        print(
            f"note: the interpreted kernels raised ({type(reason).__name__}: {reason}); the run "
            "goes on with the compiled kernels",
            file=sys.stderr,
        )
    args = sys.argv[1:]
    if resume is not None:
        from mcchain.cli.parser import resume_arguments

        kept = resume_arguments(args)
        args = ["run", "--resume", str(resume), *kept]
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    env = {**os.environ, ENV_SWITCH: "0"}
    os.execve(sys.executable, [sys.executable, "-m", "mcchain.cli", *args], env)
