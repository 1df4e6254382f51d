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
(:mod:`mcchain.compiled.first_run`), and :func:`start_background` starts a detached process that
compiles them all for the next runs, one such process at a time (a lock in
``MCCHAIN_CACHE_DIR/compile``, with its log and its record ``background.json``), and once
per cache: only in an interactive terminal outside CI and batch schedulers, unless switched
off (:func:`why_not_background`). Its failure is shown by the next run
(:func:`background_failure_note`); a run started while it compiles waits for it where that
is sooner (:func:`mcchain.compiled.first_run.choose`, :func:`background_remaining`).
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
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
    module = [sys.executable, "-m", "mcchain.compiled.ahead", *first]
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


def _compile_check_and_modes(scene_path: Path, seed: int | None) -> None:
    """What a cold compiled run's own process compiles beside the helper: the scene check
    (assembly) and the eigen step."""
    scene, model = _helper_model(scene_path, seed)
    _compile_check(scene, model)
    compile_modes(model, scene)


def _compile_check(scene: Any, model: Model) -> None:
    """The scene check a run makes before anything is written (:func:`mcchain.runner.job.
    default_loader`): assembly of the samples and of the scene as written."""
    from mcchain.runner.job import written_state
    from mcchain.solvers.statics import check_scene, initial_state_warnings

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


# -- in the background, for the next runs -----------------------------------------------------

BACKGROUND = "--background"
"""The helper's first argument when it compiles for the next runs (:func:`start_background`)."""


def background_files() -> tuple[Path, Path]:
    """The lock file a background compile holds while it runs, and its log."""
    from mcchain.compiled.caches import mcchain_cache

    folder = mcchain_cache("compile")
    return folder / "background.lock", folder / "background.log"


def background_record_path() -> Path:
    """The record of this cache's background compile (:func:`read_background`)."""
    return background_files()[0].with_name("background.json")


BATCH_VARIABLES = (
    "CI", "CONTINUOUS_INTEGRATION", "GITHUB_ACTIONS", "GITLAB_CI", "BUILDKITE", "JENKINS_URL",
    "TF_BUILD", "TEAMCITY_VERSION", "SLURM_JOB_ID", "PBS_JOBID", "LSB_JOBID", "JOB_ID",
    "FLUX_JOB_ID", "COBALT_JOBID",
)  # fmt: skip
"""Environment variables set by CI services and batch schedulers (GitHub, GitLab, Buildkite,
Jenkins, Azure, TeamCity; SLURM, PBS/Torque, LSF, SGE, Flux, Cobalt): a background compile
is not started under them, since the end of a job kills it or it outlives the allocation."""

BACKGROUND_DEFAULT_S = 30.0
"""Expected length of a background compile before one was measured in this cache (a statics
sweep's kernels on two busy cores: 20-35 s)."""


def why_not_background(
    *,
    opted_out: str | None = None,
    environ: Mapping[str, str] | None = None,
    interactive: bool | None = None,
) -> str | None:
    """Why no background compile may start for this run, or None if one may: it starts only
    in an interactive terminal (stdin and stderr), outside CI and batch schedulers
    (:data:`BATCH_VARIABLES`), where neither ``MCCHAIN_COMPILE_AHEAD=0``, nor ``opted_out``
    (what switched it off: ``--no-background-compile`` or the user's config file) say no,
    and only once per cache (a finished or failed one is not started again)."""
    env = os.environ if environ is None else environ
    if env.get(ENV_SWITCH, "1") == "0":
        return f"{ENV_SWITCH}=0"
    if opted_out:
        return f"switched off by {opted_out}"
    for name in BATCH_VARIABLES:
        if env.get(name):
            return f"not started under {name}"
    if interactive is None:
        interactive = all(_isatty(stream) for stream in (sys.stdin, sys.stderr))
    if not interactive:
        return "not started outside an interactive terminal"
    record = read_background()
    if record is not None and record.get("state") in ("done", "failed", "ended"):
        return f"one ran already in this cache ({record['state']}: {background_files()[1]})"
    return None


def _isatty(stream: Any) -> bool:
    try:
        return bool(stream is not None and stream.isatty())
    except (OSError, ValueError):
        return False


def read_background() -> dict[str, Any] | None:
    """The record of this cache's background compile, or None: ``state`` ("running",
    "done", "failed", or "ended" where a running one's process is gone), ``started`` (epoch
    seconds), ``seconds`` (its length, once done), ``error`` (its last line, if failed),
    ``reported`` (the failure was shown by a run)."""
    try:
        record = json.loads(background_record_path().read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict):
        return None
    if record.get("state") == "running" and not background_running():
        record["state"] = "ended"
        record.setdefault("error", "it ended before it finished (killed?)")
    return record


def _write_background(record: Mapping[str, Any]) -> None:
    from mcchain.ensemble.io import write_text_atomic

    with contextlib.suppress(OSError):
        write_text_atomic(background_record_path(), json.dumps(dict(record)) + "\n")


def background_failure_note() -> str | None:
    """One line on a background compile of this cache that failed (or was killed), shown
    once: by the first run after it."""
    record = read_background()
    if record is None or record.get("state") not in ("failed", "ended"):
        return None
    if record.get("reported"):
        return None
    _write_background({**record, "reported": True})
    return (
        f"the background compile of {record.get('scene', '?')} failed ({record.get('error')}; "
        f"log: {background_files()[1]}): `mcchain cache warm SCENE` compiles in the foreground"
    )


def background_remaining(now: Callable[[], float] = time.time) -> float | None:
    """Seconds a running background compile should still take, from when it started and
    the length of the last finished one in this cache (else :data:`BACKGROUND_DEFAULT_S`);
    None where none runs."""
    record = read_background()
    if record is None or record.get("state") != "running":
        return None
    expected = float(record.get("expected") or BACKGROUND_DEFAULT_S)
    return max(0.0, expected - (now() - float(record.get("started", now()))))


def background_running() -> bool:
    """Whether a background compile (:func:`start_background`) holds its lock now (False
    where the lock cannot be read: NFS or Lustre without locks)."""
    from mcchain.runner.runs import file_locked

    try:
        return file_locked(background_files()[0])
    except OSError:
        return False


def wait_background() -> None:
    """Wait until no background compile runs (for benchmarks, tests, and a run that waits
    for it: :func:`mcchain.compiled.first_run.choose`)."""
    import fcntl

    with contextlib.suppress(OSError):
        fd = os.open(background_files()[0], os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_SH)
        finally:
            os.close(fd)


def background_note(
    scene_path: Path, seed: int | None, samples: int | None, opted_out: str | None = None
) -> str:
    """What compiles an interpreted run's kernels meanwhile, for its note: a background
    process (:func:`start_background`) where :func:`why_not_background` allows one, else
    nothing, and why."""
    reason = why_not_background(opted_out=opted_out)
    if reason is not None:
        return (
            f"nothing compiles them meanwhile ({reason}; `mcchain cache warm {scene_path}` "
            "compiles them)"
        )
    return start_background(scene_path, seed, samples)


def start_background(scene_path: Path, seed: int | None, samples: int | None) -> str:
    """Start a process that compiles every kernel of the scene into the caches, for the
    next runs, while this run goes on with its kernels interpreted
    (:mod:`mcchain.compiled.first_run`). It is detached: it outlives the run (which may end first),
    and an interrupt of the run does not reach it. One at a time: a second one started
    meanwhile finds the lock held and exits. It never fails the run: a lock that cannot be
    taken for any reason (NFS or Lustre without locks: ENOLCK, ENOSYS) means "not started".

    Returns:
        What the run's note says of it: that it started (with its log), that one is
        already running, that it could not start, or that ``MCCHAIN_COMPILE_AHEAD=0``
        turned it off.
    """
    import fcntl

    if os.environ.get(ENV_SWITCH, "1") == "0":
        return f"nothing compiles them meanwhile ({ENV_SWITCH}=0)"
    lock, log_path = background_files()
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o600)
    except OSError as exc:
        return f"nothing compiles them meanwhile (its lock {lock}: {exc.strerror})"
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return f"a process compiles them already (log: {log_path})"
        except OSError as exc:
            return f"nothing compiles them meanwhile (its lock {lock}: {exc.strerror})"
        previous = read_background() or {}
        expected = previous.get("seconds") if previous.get("state") == "done" else None
        _write_background(
            {"state": "running", "scene": str(scene_path), "started": time.time(),
             "expected": expected or previous.get("expected")}
        )  # fmt: skip
        args = _command(Path(scene_path).resolve(), seed, samples, BACKGROUND)
        try:
            with open(log_path, "wb") as log_file:  # one compile's log, not a growing one
                # The process inherits the locked file: the lock is its own from the start
                # (no moment without it), until it exits.
                process = subprocess.Popen(
                    args, stdin=subprocess.DEVNULL, stdout=log_file, stderr=subprocess.STDOUT,
                    start_new_session=True, pass_fds=(fd,),
                )  # fmt: skip
        except OSError as exc:
            _write_background({"state": "failed", "scene": str(scene_path), "error": str(exc)})
            return f"nothing compiles them meanwhile (it could not start: {exc.strerror})"
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
    record = {**(read_background() or {}), "state": "running", "scene": str(scene_path)}
    print(f"{time.strftime('%H:%M:%S')} pid {os.getpid()} {scene_path}: compiling", flush=True)
    try:
        if _cores() >= 2:
            command = _command(scene_path, seed, samples)
            helper = subprocess.Popen(command, stdin=subprocess.DEVNULL)
            _compile_check_and_modes(scene_path, seed)
            if helper.wait() != 0:
                raise RuntimeError(f"its helper process exited with {helper.returncode}")
        compile_for(scene_path, seed, samples, whole=True)
    except BaseException as exc:
        error = f"{type(exc).__name__}: {exc}".splitlines()[0]
        _write_background({**record, "state": "failed", "error": error})
        print(f"{time.strftime('%H:%M:%S')} pid {os.getpid()} failed: {error}", flush=True)
        raise
    seconds = time.perf_counter() - t0
    _write_background({**record, "state": "done", "seconds": seconds})
    print(f"{time.strftime('%H:%M:%S')} pid {os.getpid()} done in {seconds:.1f} s")


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
