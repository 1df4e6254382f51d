"""Compile ahead: on a cold cache, a second process compiles what a chunk needs after assembly.

A first run compiles two sets of numba kernels one after the other: assembly (for the scene
check, before anything is written) and then the analyses and the time integrator (at the
warm-up of the first chunk). Numba compiles on one core. With two cores or more and an empty
cache, :meth:`CompileAhead.start` runs ``python -m mcchain.compile_ahead`` beside the scene
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
(:mod:`mcchain.first_run`), and :func:`start_background` starts a detached process that
compiles them all for the next runs, one such process at a time (a lock in
``MCCHAIN_CACHE_DIR/compile``, with its log).
"""

from __future__ import annotations

import contextlib
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


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def assembly_is_cached() -> bool:
    """True if numba's cache holds the assembly kernel (then the scene check compiles
    nothing, and there is nothing to run beside it), or if that cannot be told."""
    from mcchain.caches import kernels_cached

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
        if os.environ.get(ENV_SWITCH, "1") == "0" or _cores() < 2:
            return cls(None)
        process = subprocess.Popen(
            _command(scene_path, seed, samples), stdin=subprocess.DEVNULL,
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


def _command(scene_path: Path, seed: int | None, samples: int | None, *first: str) -> list[str]:
    """The command line of a helper process (``first``: :data:`BACKGROUND`, or nothing for
    :func:`compile_for`)."""
    seed_arg = str(-1 if seed is None else seed)
    samples_arg = str(-1 if samples is None else samples)
    module = [sys.executable, "-m", "mcchain.compile_ahead", *first]
    return [*module, str(scene_path), seed_arg, samples_arg]


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

    from mcchain.job import resolve_kernels
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


def _compile_check_and_modes(scene_path: Path, seed: int | None) -> None:
    """What a cold compiled run's own process compiles beside the helper: the scene check
    (assembly) and the eigen step."""
    scene, model = _helper_model(scene_path, seed)
    _compile_check(scene, model)
    compile_modes(model, scene)


def _compile_check(scene: Any, model: Model) -> None:
    """The scene check a run makes before anything is written (:func:`mcchain.job.
    default_loader`): assembly of the samples and of the scene as written."""
    from mcchain.job import written_state
    from mcchain.solvers.statics import check_scene, initial_state_warnings

    check_scene(model)
    initial_state_warnings(*written_state(scene))


def _helper_model(scene_path: Path, seed: int | None) -> tuple[Any, Model]:
    """The scene at ``scene_path`` and its first samples for a helper to solve: the
    smallest count its design allows (two; d + 2 for Saltelli's), or its one instance
    without ``[sample]``."""
    from mcchain.parallel import warm_model
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


# -- in the background, for the next runs -----------------------------------------------------

BACKGROUND = "--background"
"""The helper's first argument when it compiles for the next runs (:func:`start_background`)."""


def background_files() -> tuple[Path, Path]:
    """The lock file a background compile holds while it runs, and its log."""
    from mcchain.caches import mcchain_cache

    folder = mcchain_cache("compile")
    return folder / "background.lock", folder / "background.log"


def background_running() -> bool:
    """Whether a background compile (:func:`start_background`) holds its lock now."""
    from mcchain.runs import file_locked

    return file_locked(background_files()[0])


def wait_background() -> None:
    """Wait until no background compile runs (for benchmarks and tests)."""
    import fcntl

    with contextlib.suppress(FileNotFoundError):
        fd = os.open(background_files()[0], os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_SH)
        finally:
            os.close(fd)


def start_background(scene_path: Path, seed: int | None, samples: int | None) -> str:
    """Start a process that compiles every kernel of the scene into the caches, for the
    next runs, while this run goes on with its kernels interpreted
    (:mod:`mcchain.first_run`). It is detached: it outlives the run (which may end first),
    and an interrupt of the run does not reach it. One at a time: a second one started
    meanwhile finds the lock held and exits.

    Returns:
        What the run's note says of it: that it started (with its log), that one is
        already running, or that ``MCCHAIN_COMPILE_AHEAD=0`` turned it off.
    """
    import fcntl

    if os.environ.get(ENV_SWITCH, "1") == "0":
        return f"nothing compiles them meanwhile ({ENV_SWITCH}=0)"
    lock, log_path = background_files()
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return f"a process compiles them already (log: {log_path})"
        args = _command(Path(scene_path).resolve(), seed, samples, BACKGROUND)
        with open(log_path, "ab") as log_file:
            # The process inherits the locked file: the lock is its own from the start (no
            # moment without it), until it exits.
            process = subprocess.Popen(
                args, stdin=subprocess.DEVNULL, stdout=log_file, stderr=subprocess.STDOUT,
                start_new_session=True, pass_fds=(fd,),
            )  # fmt: skip
    finally:
        os.close(fd)
    return (
        f"a background process compiles them for the next runs (pid {process.pid}, log: {log_path})"
    )


def compile_in_background(scene_path: Path, seed: int | None, samples: int | None) -> None:
    """The background process's work (under the lock it inherited): all that the scene's
    run calls (:func:`compile_for` with ``whole``), with a line in the log before and
    after. With two cores or more it shares the work as a cold compiled run does: a helper
    process compiles the analyses (:func:`compile_for`) while this one compiles the scene
    check's assembly and the eigen step; then this one loads them all, compiling what is
    left (the glue of a whole chunk)."""
    t0 = time.perf_counter()
    print(f"{time.strftime('%H:%M:%S')} pid {os.getpid()} {scene_path}: compiling", flush=True)
    if _cores() >= 2:
        helper = subprocess.Popen(_command(scene_path, seed, samples), stdin=subprocess.DEVNULL)
        _compile_check_and_modes(scene_path, seed)
        helper.wait()
    compile_for(scene_path, seed, samples, whole=True)
    print(f"{time.strftime('%H:%M:%S')} pid {os.getpid()} done in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    background = sys.argv[1] == BACKGROUND
    path, seed_arg, samples_arg = sys.argv[2:5] if background else sys.argv[1:4]
    if background:
        with contextlib.suppress(OSError):
            os.nice(5)  # the interpreted run beside it keeps its core
    (compile_in_background if background else compile_for)(
        Path(path),
        None if int(seed_arg) < 0 else int(seed_arg),
        None if int(samples_arg) < 0 else int(samples_arg),
    )
    sys.stdout.flush()
    os._exit(0)  # the kernels are in the cache; the interpreter's teardown would only delay the run
