"""Compile ahead: on a cold cache, a second process compiles what a chunk needs after assembly.

A first run compiles two sets of numba kernels one after the other: assembly (for the scene
check, before anything is written) and then the analyses and the time integrator (at the
warm-up of the first chunk). Numba compiles on one core. With two cores or more and an empty
cache, :meth:`CompileAhead.start` runs ``python -m mcchain.compiled.ahead`` beside the scene
check: it compiles the equilibrium and the integrator of the scene (it solves two samples
from their written, unassembled state, so it compiles no assembly) into the same caches.
The run's own process, its scene check done, compiles the eigen step meanwhile
(:meth:`CompileAhead.compile_beside`: the two processes then finish at about the same
time), and its warm-up waits for the helper (:meth:`CompileAhead.wait`), then loads the
rest.

It changes no value: the kernels are the same, compiled from the same sources into the same
cache, whichever process compiles them. If the helper fails or cannot share the cache, the
warm-up compiles what is missing itself, as without it. On one core (or with
``MCCHAIN_COMPILE_AHEAD=0``) there is no helper, but a cold run still says at its start that
it compiles, instead of after the scene check's compile.

A small statics run on a cold cache compiles nothing itself: its kernels run interpreted
(:mod:`mcchain.compiled.first_run`) while a process compiles them for the next runs
(:mod:`mcchain.compiled.background`, which calls :func:`compile_for` here). ``mcchain cache
warm`` is :func:`warm`.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mcchain.model import Model

ENV_SWITCH = "MCCHAIN_COMPILE_AHEAD"
"""``0`` turns the helper process off."""


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def assembly_is_cached() -> bool:
    """True if numba's cache holds the assembly kernel (then the scene check compiles
    nothing, and there is nothing to run beside it), or if that cannot be told."""
    from mcchain.compiled.caches import kernels_cached

    return kernels_cached(["assembly.assemble_batch"]) is not False


class CompileAhead:
    """A cold first run: its helper process (see the module's docstring), or None where
    there is no second core or the helper is turned off. Either way the compile notice is
    printed when the run starts (``started``), not after the scene check's silent compile."""

    def __init__(self, process: subprocess.Popen[bytes] | None):
        self.process = process
        self.started = time.perf_counter()

    @classmethod
    def start(
        cls, scene_path: Path, seed: int | None, samples: int | None = None
    ) -> CompileAhead | None:
        """On a cold cache: start the helper for the scene at ``scene_path`` (with the run's
        ``--seed`` and ``--samples``) if a second core is free. None on a warm cache."""
        if assembly_is_cached():
            return None
        if os.environ.get(ENV_SWITCH, "1") == "0" or available_cores() < 2:
            return cls(None)
        process = subprocess.Popen(
            helper_command(scene_path, seed, samples), stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        return cls(process)

    def compile_beside(self, model: Model, scene: Any) -> None:
        """In the run's process, while the helper compiles the rest: the eigen step of the
        scene (on one sample at its written state; the values are discarded)."""
        if self.process is not None:
            compile_modes(model, scene)

    def wait(self) -> None:
        """Wait until the helper has compiled (or failed: the caller compiles then)."""
        if self.process is not None:
            self.process.wait()

    def stop(self) -> None:
        """End the helper if it still runs (the run failed before its warm-up)."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()


def helper_command(
    scene_path: Path, seed: int | None, samples: int | None, module: str = __name__
) -> list[str]:
    """The command line of a helper process: ``python -m module SCENE SEED SAMPLES`` (-1 for
    None); by default this module's, which runs :func:`compile_for`."""
    seed_arg = str(-1 if seed is None else seed)
    samples_arg = str(-1 if samples is None else samples)
    return [sys.executable, "-m", module, str(scene_path), seed_arg, samples_arg]


def helper_arguments(argv: list[str]) -> tuple[Path, int | None, int | None]:
    """The scene, seed and samples of a :func:`helper_command`'s arguments."""
    path, seed_arg, samples_arg = argv
    return (
        Path(path),
        None if int(seed_arg) < 0 else int(seed_arg),
        None if int(samples_arg) < 0 else int(samples_arg),
    )


def compile_for(
    scene_path: Path, seed: int | None, samples: int | None = None, *, whole: bool = False
) -> None:
    """Compile the kernels a chunk of the scene needs after assembly: solve two samples from
    their written state. The kernels' types depend on neither the values nor the count, so
    the helper samples only the smallest count the design allows (not the run's, which may
    fill the memory); ``[simulate] kernels = "auto"`` is resolved for the run's count
    (``samples``, default the scene's), as the run resolves it. ``whole``: all a run calls,
    the scene check and the eigen step too (then it solves from the assembled state)."""
    import numpy as np

    from mcchain.runner.job import resolve_kernels
    from mcchain.solvers import solve_chunk
    from mcchain.solvers.statics import Assembled
    from mcchain.status import STATUS_DTYPE

    scene, model = _helper_model(scene_path, seed)
    sample = scene.sample
    run_count = samples if samples is not None else (sample.count if sample is not None else 1)
    scene, _ = resolve_kernels(scene, model, run_count)
    if whole:
        _compile_check(scene, model)
        solve_chunk(model, scene)
        return
    shape = (model.nsample, model.ndof)
    written = Assembled(
        q=np.array(np.broadcast_to(model.q0, shape), dtype=np.float64, order="C"),
        v=np.array(np.broadcast_to(model.v0, shape), dtype=np.float64, order="C"),
        status=np.zeros(model.nsample, dtype=STATUS_DTYPE),
    )
    solve_chunk(model, scene, assembled=written, with_modes=False)


def compile_check_and_modes(scene_path: Path, seed: int | None) -> None:
    """What a cold compiled run's own process compiles beside the helper: the scene check
    (assembly) and the eigen step."""
    scene, model = _helper_model(scene_path, seed)
    _compile_check(scene, model)
    compile_modes(model, scene)


def _compile_check(scene: Any, model: Model) -> None:
    """The scene check a run makes before anything is written (:func:`mcchain.runner.job.
    default_loader`): assembly of the samples and of the scene as written."""
    from mcchain.solvers.statics import check_scene, initial_state_warnings, written_state

    check_scene(model)
    initial_state_warnings(*written_state(scene))


def _helper_model(scene_path: Path, seed: int | None) -> tuple[Any, Model]:
    """The scene at ``scene_path`` and its first samples for a helper to solve: the
    smallest count its design allows (two; d + 2 for Saltelli's), or its one instance
    without ``[sample]``."""
    from mcchain.runner.executors import warm_model
    from mcchain.scene import compile_model, load_scene

    scene = load_scene(scene_path)
    sample = scene.sample
    count = None
    if sample is not None:
        count = len(sample.vary) + 2 if sample.design == "saltelli" else 2
    return scene, warm_model(compile_model(scene, nsample=count, seed=seed))


def compile_modes(model: Model, scene: Any) -> None:
    """Compile (or load) the kernels of the eigen step that :func:`compile_for` leaves out,
    as :func:`mcchain.solvers.solve_chunk` calls them, on one sample at its written state."""
    if getattr(scene, "equilibrium", None) is None and getattr(scene, "modes", None) is None:
        return
    import numpy as np

    from mcchain.solvers.statics import EquilibriumResult, solve_modes
    from mcchain.status import STATUS_DTYPE

    one = model.select(0, 1)
    at_rest = EquilibriumResult(
        q=np.array(np.broadcast_to(one.q0, (1, one.ndof)), dtype=np.float64, order="C"),
        lam=np.zeros((1, one.ncon)),
        joint_force=np.full((1, one.njoint, 2), np.nan),
        contact_force=np.full((1, one.njoint), np.nan),
        iterations=np.zeros(1, dtype=np.int32),
        history=np.full((1, 1, 2), np.nan),
        status=np.zeros(1, dtype=STATUS_DTYPE),
        joint_moment=np.full((1, one.njoint), np.nan),
    )
    modes = scene.modes
    solve_modes(one, at_rest, shapes=modes is not None and modes.shapes, damped=modes is not None)


def warm(scene_path: str | Path) -> str:
    """Compile (or load) every kernel a run of the scene calls, in this process
    (``mcchain cache warm``): afterwards the scene's runs compile nothing. Returns the line
    ``mcchain cache warm`` prints (what was compiled, what loaded)."""
    from mcchain.codegen import native
    from mcchain.scene import load_scene

    load_scene(scene_path)  # a bad scene: one line, before any compile
    before = dict(native.COUNTS)
    t0 = time.perf_counter()
    compile_for(Path(scene_path), None, None, whole=True)
    compiled = native.COUNTS["compiled"] - before["compiled"]
    loaded = native.COUNTS["loaded"] - before["loaded"]
    return (
        f"{scene_path}: ready in {time.perf_counter() - t0:.1f} s (lane entry points: "
        f"{compiled} compiled, {loaded} loaded from the cache)"
    )


if __name__ == "__main__":
    compile_for(*helper_arguments(sys.argv[1:4]))
    sys.stdout.flush()
    os._exit(0)  # the kernels are in the cache; the interpreter's teardown would only delay the run
