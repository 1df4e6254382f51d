"""The first run on a cold cache (mcchain.compiled.first_run): a small statics run goes interpreted,
with the compiled run's ``ensemble.nc`` byte for byte, while a background process compiles
the kernels for the next runs (mcchain.compiled.background); the cache is read without numba."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from test_cli_commands import in_process
from test_runs_support import REPO

from mcchain.compiled import ahead, background, first_run
from mcchain.compiled.caches import kernels_cached, numba_index_folder
from mcchain.errors import SceneError
from mcchain.runner import executors, plan
from mcchain.runner.runs import read_record

CONFIGS = REPO / "configs"


def _cold_run(config: Path, tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``mcchain run`` from the command line on empty caches, interpreted without the probe
    and without the background compile (which would take a core for a minute)."""
    env = {
        **os.environ,
        "PYTHONPATH": str(REPO),
        "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
        "MCCHAIN_CACHE_DIR": str(tmp_path / "mcchain"),
        first_run.ENV_SWITCH: "1",
        ahead.ENV_SWITCH: "0",
    }
    command = ["-X", "importtime", "-m", "mcchain.cli", "run", str(config), "--quiet", *args]
    return subprocess.run(
        [sys.executable, *command], env=env, cwd=tmp_path, capture_output=True, text=True,
        timeout=600,
    )  # fmt: skip


@pytest.mark.parametrize(
    ("config", "samples"),
    [("clearance-sweep", "512"), ("fourbar-clearance-statics", "16"), ("paper-bar", None)],
)
def test_cold_run__interpreted_writes_the_compiled_runs_ensemble_byte_for_byte(
    config: str, samples: str | None, tmp_path: Path, monkeypatch, capsys
) -> None:
    """Interpreted in a fresh process, without numba; then compiled in this one: the same
    bytes in every variable (a sweep, a four-bar with a clearance joint, a scene without
    [sample]); the files differ in the attribute that says so, ``kernel_compiler``."""
    count = [] if samples is None else ["--samples", samples]
    cold = _cold_run(CONFIGS / f"{config}.toml", tmp_path, *count, "--run-dir", "cold")
    assert cold.returncode == 0, cold.stderr[-3000:]
    assert "run them interpreted (the same values); nothing compiles them" in cold.stderr
    imported = [line.rsplit("|", 1)[-1].strip() for line in cold.stderr.splitlines()]
    assert not [name for name in imported if name.split(".")[0] in ("numba", "llvmlite")]
    run = in_process(monkeypatch, capsys)
    scene = CONFIGS / f"{config}.toml"
    warm = run("run", scene, *count, "--quiet", "--run-dir", "warm", cwd=tmp_path)
    assert warm.returncode == 0, warm.stderr
    # the same file, but for the attribute that says what ran the kernels
    cold_nc, warm_nc = (tmp_path / name / "ensemble.nc" for name in ("cold", "warm"))
    assert _contents(cold_nc) == _contents(warm_nc, kernel_compiler="interpreted")
    sessions = [read_record(tmp_path / name)["sessions"] for name in ("cold", "warm")]
    assert [s[-1]["kernels_interpreted"] for s in sessions] == [True, False]
    assert [s[-1]["kernel_compiler"] for s in sessions] == ["interpreted", "numba"]


def _contents(path: Path, **replaced: str) -> tuple[Any, ...]:
    """Every global attribute (``replaced`` given other values), dimension, and variable
    (dtype, dimensions, attributes and raw bytes) of a netCDF file."""
    import netCDF4

    with netCDF4.Dataset(path) as nc:
        nc.set_auto_mask(False)
        attrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
        assert all(k in attrs for k in replaced)
        attrs.update(replaced)
        dims = {name: len(dim) for name, dim in nc.dimensions.items()}
        variables = {
            name: (
                str(var.dtype), var.dimensions, {k: str(var.getncattr(k)) for k in var.ncattrs()},
                _raw(np.asarray(var[...])),
            )
            for name, var in nc.variables.items()
        }  # fmt: skip
    return tuple(sorted((k, str(v)) for k, v in attrs.items())), dims, variables


def _raw(values: np.ndarray) -> Any:
    return values.tolist() if values.dtype == object else values.tobytes()


@pytest.fixture(autouse=True)
def _switch_unset(monkeypatch: pytest.MonkeyPatch) -> None:
    """As a user has it (the test suite sets ``MCCHAIN_INTERPRET_COLD=0``)."""
    monkeypatch.delenv(first_run.ENV_SWITCH, raising=False)


def test_numba_index_folder__is_where_numba_indexes_the_kernels() -> None:
    """Worked out without numba, checked against numba's own locator."""
    from mcchain.kernels import assembly

    index = assembly.assemble_batch._cache._cache_file._index_path
    assert Path(os.path.dirname(index)) == numba_index_folder()
    from mcchain.scene import compile_model, load_scene
    from mcchain.solvers import solve_chunk

    scene = load_scene(CONFIGS / "clearance-bar.toml")
    solve_chunk(compile_model(scene), scene)
    assert kernels_cached(first_run.STATICS_KERNELS) is True
    assert kernels_cached([*first_run.STATICS_KERNELS, "statics.no_such_kernel"]) is False


def test_numba_index_folder__each_of_numbas_choices(tmp_path: Path, monkeypatch) -> None:
    """``NUMBA_CACHE_DIR``, and the user-wide folder where the sources' ``__pycache__``
    cannot be written: the folders numba's own locators give for the assembly kernel."""
    import inspect

    from numba.core import caching, config

    import mcchain.compiled.caches
    from mcchain.kernels import assembly

    function = assembly.assemble_batch.py_func
    source = inspect.getfile(function)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba"))
    provided = caching.UserProvidedCacheLocator(function, source).get_cache_path()
    assert numba_index_folder() == Path(provided)
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "home-cache"))
    writable = mcchain.compiled.caches.writable
    monkeypatch.setattr(
        mcchain.compiled.caches,
        "writable",
        lambda folder: "__pycache__" not in str(folder) and writable(folder),
    )
    user_wide = caching.UserWideCacheLocator(function, source).get_cache_path()
    assert numba_index_folder() == Path(user_wide)
    assert Path(user_wide).parent == tmp_path / "home-cache" / "numba"


def test_kernels_cached__an_empty_cache_folder(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    folder = numba_index_folder()
    assert folder is not None and folder.parent == tmp_path / "numba"
    assert folder.name.startswith("kernels_")
    assert kernels_cached(first_run.STATICS_KERNELS) is False


def _choose(monkeypatch, config: str, *, cached=False, per_sample=1e-3, samples=None):
    """:func:`first_run.choose` with the cache state and the probe's result given, and the
    exec recorded instead of made."""
    import mcchain.compiled.caches
    import mcchain.kernels.config

    monkeypatch.setattr(mcchain.compiled.caches, "kernels_cached", lambda names: cached)
    monkeypatch.setattr(mcchain.kernels.config, "interpret_kernels", lambda: True)
    monkeypatch.setattr(first_run, "_probe", lambda scene, seed: per_sample)

    class Exec(Exception):
        pass

    def run_compiled(resume=None, reason=None):
        raise Exec

    monkeypatch.setattr(first_run, "run_compiled", run_compiled)
    try:
        return first_run.choose(CONFIGS / f"{config}.toml", samples, None)
    except Exec:
        return "exec"


def test_choose__a_small_statics_run_on_a_cold_cache(monkeypatch) -> None:
    """clearance-sweep: 10,000 samples; at 1 ms each the projection (10 s) is the budget."""
    chosen = _choose(monkeypatch, "clearance-sweep", per_sample=first_run.BUDGET_S / 10_000)
    assert chosen == first_run.FirstRun(first_run.BUDGET_S / 10_000)
    too_slow = first_run.BUDGET_S / 10_000 * 1.001
    assert _choose(monkeypatch, "clearance-sweep", per_sample=too_slow) == "exec"
    assert _choose(monkeypatch, "clearance-sweep", per_sample=too_slow, samples=9_990) is not None
    assert _choose(monkeypatch, "clearance-sweep", cached=True) is None
    assert _choose(monkeypatch, "clearance-sweep", cached=None) is None  # cannot tell


def test_choose__never_for_a_simulation_a_large_scene_or_when_switched_off(
    monkeypatch, tmp_path: Path
) -> None:
    from mcchain.kernels.config import INTERPRET_MAX_COORDINATES
    from mcchain.testing.factory import write_scene
    from mcchain.testing.scenes import straight_chain_text

    assert _choose(monkeypatch, "fourbar-clearance") is None  # [simulate]
    n = INTERPRET_MAX_COORDINATES // 3 + 1
    chain = straight_chain_text([0.3] * n, [1.0] * n) + "[equilibrium]\n"
    path = write_scene(tmp_path, chain, "chain.toml")
    monkeypatch.setattr(first_run, "_probe", lambda scene, seed: 0.0)
    assert first_run.choose(path, None, None) is None
    monkeypatch.setenv(first_run.ENV_SWITCH, "0")
    assert _choose(monkeypatch, "clearance-sweep") is None
    monkeypatch.setenv(first_run.ENV_SWITCH, "1")
    assert _choose(monkeypatch, "clearance-sweep", per_sample=1.0) == first_run.FirstRun(None)
    bad = write_scene(tmp_path, "[scene]\nname = 3\n", "bad.toml")
    assert first_run.choose(bad, None, None) is None  # the run reports it


def test_choose__a_probe_that_raises_runs_compiled(monkeypatch) -> None:
    _choose(monkeypatch, "clearance-sweep")

    def probe(scene, seed):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(first_run, "_probe", probe)
    with pytest.raises(Exception) as caught:
        first_run.choose(CONFIGS / "clearance-sweep.toml", None, None)
    assert type(caught.value).__name__ == "Exec"


def test_run_compiled__execs_the_command_or_its_resume(monkeypatch, capsys) -> None:
    calls = []
    monkeypatch.setattr(os, "execve", lambda path, args, env: calls.append((path, args, env)))
    argv = ["mcchain", "run", "scene.toml", "--samples", "5", "--threads=2", "--quiet"]
    monkeypatch.setattr(sys, "argv", argv)
    first_run.run_compiled()
    first_run.run_compiled(Path("runs/x"), ZeroDivisionError("float division by zero"))
    (path, args, env), (_, resumed, _) = calls
    assert path == sys.executable and args[:3] == [sys.executable, "-m", "mcchain.cli"]
    assert args[3:] == argv[1:] and env[first_run.ENV_SWITCH] == "0"
    assert resumed[3:] == ["run", "--resume", "runs/x", "--threads", "2", "--quiet"]
    note = capsys.readouterr().err
    assert "interpreted kernels raised (ZeroDivisionError: float division by zero)" in note


def test_start_run__interpreted_kernels_that_raise_hand_the_run_to_its_compiled_resume(
    monkeypatch, tmp_path: Path
) -> None:
    """A chunk raising in the interpreted kernels: the run is resumed compiled from the
    folder it made (the exec is recorded here); a scene error is reported as always."""
    calls = []

    def run_compiled(resume=None, reason=None):
        calls.append((resume, type(reason).__name__))
        raise SystemExit(0)

    monkeypatch.setattr(first_run, "run_compiled", run_compiled)
    monkeypatch.setenv(ahead.ENV_SWITCH, "0")

    def solve(model, scene):
        if model.nsample > 1:
            raise ZeroDivisionError("float division by zero")
        return {}

    chosen = first_run.FirstRun(1e-3)
    with pytest.raises(ZeroDivisionError):  # a custom solve is not the interpreted kernels
        plan.start_run(
            CONFIGS / "clearance-sweep.toml", samples=4, run_dir=tmp_path / "r",
            progress=False, first_run=chosen, solve=solve,
        )  # fmt: skip
    assert calls == []
    monkeypatch.setattr(executors, "execute", lambda *a, **k: 1 / 0)  # after the folder
    with pytest.raises(SystemExit):
        plan.start_run(
            CONFIGS / "clearance-sweep.toml", samples=4, run_dir=tmp_path / "s",
            progress=False, first_run=chosen,
        )  # fmt: skip
    assert [(path.resolve(), name) for path, name in calls] == [
        ((tmp_path / "s").resolve(), "ZeroDivisionError")
    ]
    bad = tmp_path / "bad.toml"
    bad.write_text("[scene]\nname = 3\n")
    with pytest.raises(SceneError):
        plan.start_run(bad, run_dir=tmp_path / "t", progress=False, first_run=chosen)
    assert len(calls) == 1 and not (tmp_path / "t").exists()


def test_background_compile__one_at_a_time_detached_and_logged(monkeypatch, tmp_path: Path) -> None:
    """The process holds the lock from its start (inherited), so that a second start finds it
    held and starts nothing; waiting ends when it is done. The kernels are in this suite's
    cache already: it loads them."""
    import fcntl

    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(REPO))
    monkeypatch.delenv(ahead.ENV_SWITCH, raising=False)
    lock, log = background.background_files()
    assert not background.background_running()
    background.wait_background()  # no lock file yet: nothing to wait for
    started = background.start_background(CONFIGS / "clearance-bar.toml", None, None)
    assert started.startswith("a background process compiles them for the next runs (pid ")
    assert background.background_running()
    second = background.start_background(CONFIGS / "clearance-bar.toml", None, None)
    assert second == f"a process compiles them already (log: {log})"
    background.wait_background()
    assert not background.background_running()
    lines = log.read_text().splitlines()
    assert len(lines) == 2 and lines[0].endswith("clearance-bar.toml: compiling")
    assert " done in " in lines[1]
    fd = os.open(lock, os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)  # another holder: nothing starts
    try:
        assert background.start_background(CONFIGS / "paper-bar.toml", 0, 5) == second
    finally:
        os.close(fd)
    monkeypatch.setenv(ahead.ENV_SWITCH, "0")
    off = background.start_background(CONFIGS / "paper-bar.toml", 0, 5)
    assert off == "nothing compiles them meanwhile (MCCHAIN_COMPILE_AHEAD=0)"


def test_probe__times_one_sample_then_a_block(monkeypatch) -> None:
    """The probe's calls (compiled here, interpreted in a cold run), on a clock that reads
    1 ms more each time: one sample, then a block of the other PROBE_SAMPLES - 1 random
    samples of the design's ranges (300 would fit in 0.3 s); a scene without [sample] has
    one instance, timed alone."""
    import mcchain.solvers
    from mcchain.scene import load_scene

    sizes = []
    solve = mcchain.solvers.solve_chunk

    def counted(model, scene, **kw):
        sizes.append((model.nsample, scene.sample.design if scene.sample else None))
        return solve(model, scene, **kw)

    monkeypatch.setattr(mcchain.solvers, "solve_chunk", counted)
    clock = iter(range(100))  # a clock that reads 1 ms more at every reading

    monkeypatch.setattr(first_run, "time", SimpleNamespace(perf_counter=lambda: next(clock) / 1e3))
    assert first_run._probe(load_scene(CONFIGS / "clearance-sweep.toml"), 3) == 1e-3 / 31
    assert sizes == [(1, "random"), (first_run.PROBE_SAMPLES - 1, "random")]
    sizes.clear()
    assert first_run._probe(load_scene(CONFIGS / "paper-bar.toml"), None) == pytest.approx(1e-3)
    assert sizes == [(1, None)]


# -- when the background compile starts, and what a run does beside it (issue 29) --------------


@pytest.fixture
def own_cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def _write_record(**record) -> None:
    import json

    background.background_record_path().write_text(json.dumps(record))


def test_background__only_interactive_outside_ci_and_schedulers_unless_switched_off(
    own_cache: Path,
) -> None:
    why = background.why_not_background
    assert why(environ={}, interactive=True) is None
    assert why(environ={}, interactive=False) == "not started outside an interactive terminal"
    for name in ("CI", "SLURM_JOB_ID", "PBS_JOBID", "LSB_JOBID", "JOB_ID", "FLUX_JOB_ID"):
        assert why(environ={name: "17"}, interactive=True) == f"not started under {name}"
    assert why(environ={name: ""}, interactive=True) is None  # set but empty: not a job
    off = why(opted_out="--no-background-compile", environ={}, interactive=True)
    assert off == "switched off by --no-background-compile"
    switch = {ahead.ENV_SWITCH: "0"}
    assert why(environ=switch, interactive=True) == f"{ahead.ENV_SWITCH}=0"
    # once per cache: one that finished, failed or was killed is not started again
    for state in ("done", "failed"):
        _write_record(state=state, scene="s.toml", started=0.0)
        reason = why(environ={}, interactive=True)
        assert reason is not None and reason.startswith(f"one ran already in this cache ({state}")


def test_background__a_lock_that_fails_means_not_started(own_cache: Path, monkeypatch) -> None:
    """NFS or Lustre without locks (ENOLCK): the run goes on; before, the run failed."""
    import errno
    import fcntl

    def no_locks(fd, operation):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.delenv(ahead.ENV_SWITCH, raising=False)
    monkeypatch.setattr(fcntl, "flock", no_locks)
    popen = []
    monkeypatch.setattr(background.subprocess, "Popen", lambda *a, **k: popen.append(a))
    lock = background.background_files()[0]
    note = background.start_background(CONFIGS / "clearance-bar.toml", None, None)
    assert note == f"nothing compiles them meanwhile (its lock {lock}: No locks available)"
    assert popen == [] and not background.background_running()


def test_background__its_failure_is_recorded_and_shown_once_by_the_next_run(
    own_cache: Path, monkeypatch, capsys
) -> None:
    def broken(*args, **kwargs):
        raise MemoryError("out of memory")

    monkeypatch.setattr(background, "available_cores", lambda: 1)
    monkeypatch.setattr(background, "compile_for", broken)
    lock = background.background_files()[0]
    fd = os.open(lock, os.O_RDWR | os.O_CREAT)
    import fcntl

    fcntl.flock(fd, fcntl.LOCK_EX)  # as the background process holds it
    try:
        with pytest.raises(MemoryError):
            background.compile_in_background(CONFIGS / "clearance-bar.toml", None, None)
    finally:
        os.close(fd)
    record = background.read_background()
    assert record is not None and record["state"] == "failed"
    assert record["error"] == "MemoryError: out of memory"
    note = background.background_failure_note()
    assert note is not None and note.startswith("the background compile of ")
    assert "failed (MemoryError: out of memory; log: " in note
    assert background.background_failure_note() is None  # shown once
    # one killed before it finished (its lock is free, its record says running)
    _write_record(state="running", scene="s.toml", started=0.0)
    note = background.background_failure_note()
    assert note is not None and "it ended before it finished (killed?)" in note


def test_background__a_run_beside_it_waits_when_that_is_sooner(own_cache: Path, monkeypatch):
    """On a fake clock: a compile started at t = 1000 s, 30 s expected (the last one's
    length); a run at t = 1025 s whose interpreted kernels would take 8 s waits (5 s
    left), then runs compiled; one of 3 s runs interpreted beside it."""
    import fcntl

    import mcchain.compiled.caches
    import mcchain.kernels.config

    monkeypatch.setattr(mcchain.compiled.caches, "kernels_cached", lambda names: False)
    monkeypatch.setattr(mcchain.kernels.config, "interpret_kernels", lambda: True)
    calls = []
    monkeypatch.setattr(background, "wait_background", lambda: calls.append("wait"))

    class Exec(Exception):
        pass

    def run_compiled(resume=None, reason=None):
        calls.append("exec")
        raise Exec

    monkeypatch.setattr(first_run, "run_compiled", run_compiled)
    _write_record(state="running", scene="s.toml", started=1000.0, expected=30.0)
    fd = os.open(background.background_files()[0], os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        assert background.background_remaining(lambda: 1025.0) == 5.0
        scene = CONFIGS / "clearance-sweep.toml"  # 10,000 samples
        monkeypatch.setattr(first_run, "_probe", lambda scene, seed: 8.0 / 10_000)
        with pytest.raises(Exec):
            first_run.choose(scene, None, None, now=lambda: 1025.0)
        assert calls == ["wait", "exec"]
        calls.clear()
        monkeypatch.setattr(first_run, "_probe", lambda scene, seed: 3.0 / 10_000)
        chosen = first_run.choose(scene, None, None, now=lambda: 1025.0)
        assert chosen == first_run.FirstRun(3.0 / 10_000) and calls == []
    finally:
        os.close(fd)
    assert background.background_remaining(lambda: 1020.0) is None  # none runs now


def test_user_config__switches_the_background_compile_off(tmp_path: Path, monkeypatch) -> None:
    from mcchain.cli.user_config import background_compile_off, config_path
    from mcchain.errors import RunError

    monkeypatch.delenv("MCCHAIN_CONFIG", raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    path = tmp_path / "mcchain" / "config.toml"
    assert config_path() == path and background_compile_off() is None
    path.parent.mkdir()
    path.write_text("[run]\nbackground_compile = false\n")
    assert background_compile_off() == f"{path} (run.background_compile = false)"
    path.write_text("[run]\nbackground_compile = true\n")
    assert background_compile_off() is None
    path.write_text('[run]\nbackground_compile = "no"\n')
    with pytest.raises(RunError, match=r"run.background_compile: expected a bool, got 'no'"):
        background_compile_off()
    path.write_text("[run]\nbackground = false\n")
    with pytest.raises(RunError, match=r"run\.background: unknown key"):
        background_compile_off()


def test_run__no_background_compile_flag_and_user_config_reach_the_run(
    monkeypatch, tmp_path: Path, mcchain
) -> None:
    from mcchain.cli import commands

    seen = []

    def start_run(scene, **kwargs):
        seen.append(kwargs["background_off"])
        raise SceneError("stopped here")

    monkeypatch.setattr(commands, "_may_interpret", True)
    monkeypatch.setattr(first_run, "choose", lambda *a: first_run.FirstRun(None))
    monkeypatch.setattr(plan, "start_run", start_run)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    monkeypatch.delenv("MCCHAIN_CONFIG", raising=False)
    scene = CONFIGS / "paper-bar.toml"
    mcchain("run", scene, cwd=tmp_path)
    mcchain("run", scene, "--no-background-compile", cwd=tmp_path)
    (tmp_path / "mcchain").mkdir()
    (tmp_path / "mcchain" / "config.toml").write_text("[run]\nbackground_compile = false\n")
    mcchain("run", scene, cwd=tmp_path)
    config = tmp_path / "mcchain" / "config.toml"
    assert seen == [None, "--no-background-compile", f"{config} (run.background_compile = false)"]
    config.write_text("[run]\nbackground_compile = 0\n")
    refused = mcchain("run", scene, cwd=tmp_path)
    assert refused.returncode == 2 and len(refused.stderr.splitlines()) == 1
    assert "run.background_compile: expected a bool, got 0" in refused.stderr
