"""The background compile: a detached process compiles a scene's kernels for the next runs.

A small statics run on a cold cache compiles nothing itself: its kernels run interpreted
(:mod:`mcchain.compiled.first_run`), and :func:`start_background` starts a detached process
(``python -m mcchain.compiled.background``) that compiles them all for the next runs, one
such process at a time (a lock in ``MCCHAIN_CACHE_DIR/compile``, with its log and its record
``background.json``), and once per cache: only in an interactive terminal outside CI and
batch schedulers, unless switched off (:func:`why_not_background`). Its failure is shown by
the next run (:func:`background_failure_note`); a run started while it compiles waits for it
where that is sooner (:func:`mcchain.compiled.first_run.choose`, :func:`background_remaining`).
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
from typing import Any

from mcchain.compiled.ahead import (
    ENV_SWITCH,
    available_cores,
    compile_check_and_modes,
    compile_for,
    helper_arguments,
    helper_command,
)


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
        args = helper_command(Path(scene_path).resolve(), seed, samples, __name__)
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
        if available_cores() >= 2:
            command = helper_command(scene_path, seed, samples)
            helper = subprocess.Popen(command, stdin=subprocess.DEVNULL)
            compile_check_and_modes(scene_path, seed)
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
    with contextlib.suppress(OSError):
        os.nice(5)  # the interpreted run beside it keeps its core
    compile_in_background(*helper_arguments(sys.argv[1:4]))
    sys.stdout.flush()
    os._exit(0)  # the kernels are in the cache; the interpreter's teardown would only delay the run
