"""Compile ahead (mcchain.compiled.ahead): on a cold cache a second process compiles the
analyses while the scene check compiles assembly; it changes no value."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_runs_support import REPO

from mcchain import open_run
from mcchain.compiled import ahead
from mcchain.compiled.ahead import CompileAhead
from mcchain.compiled.ready import compile_notice
from mcchain.runner import plan
from mcchain.testing.scenes import swinging_bar_text

SWEEP = REPO / "configs" / "clearance-sweep.toml"


def test_start__no_helper_when_assembly_is_cached_on_one_core_or_switched_off(monkeypatch):
    """Warm: nothing. Cold on one core or switched off: no process (the notice still comes
    at the start); waiting and stopping are no-ops."""
    monkeypatch.setattr(ahead, "assembly_is_cached", lambda: True)
    assert CompileAhead.start(SWEEP, 0) is None
    monkeypatch.setattr(ahead, "assembly_is_cached", lambda: False)
    monkeypatch.setattr(ahead, "available_cores", lambda: 1)
    alone = CompileAhead.start(SWEEP, 0)
    assert alone is not None and alone.process is None
    alone.wait()
    alone.stop()
    monkeypatch.setattr(ahead, "available_cores", lambda: 2)
    monkeypatch.setenv(ahead.ENV_SWITCH, "0")
    off = CompileAhead.start(SWEEP, 0)
    assert off is not None and off.process is None


@pytest.mark.parametrize("config", ["clearance-sweep", "clearance-sweep-sobol", "clearance-bar"])
def test_compile_for__solves_without_assembling(monkeypatch, config):
    """The helper compiles everything but assembly: it never calls it (a random design, a
    Saltelli design, which needs a count that is a multiple of d + 2, and no [sample])."""
    import mcchain.solvers as solvers

    def no_assembly(*args, **kwargs):
        raise AssertionError("the helper assembled")

    monkeypatch.setattr(solvers, "assemble", no_assembly)
    ahead.compile_for(REPO / "configs" / f"{config}.toml", 0)


def test_compile_for__resolves_auto_kernels_for_the_runs_count(monkeypatch, tmp_path):
    """The helper solves two samples but compiles the path the run will take: ``[simulate]
    kernels = "auto"`` is resolved for the run's ``--samples``, as the run resolves it."""
    import mcchain.solvers as solvers
    from mcchain.testing.factory import write_scene
    from mcchain.testing.scenes import straight_chain_text

    taken = []
    monkeypatch.setattr(
        solvers, "solve_chunk", lambda model, scene, **kw: taken.append(scene.simulate.kernels)
    )
    text = straight_chain_text([0.3] * 60, [1.0] * 60)  # 180 coordinates
    path = write_scene(tmp_path, text + "[simulate]\nt_end = 0.05\ndt = 1e-4\n", "chain60.toml")
    ahead.compile_for(path, 0, 4)
    ahead.compile_for(path, 0, 2000)
    ahead.compile_for(path, 0)  # the scene's count: 1
    assert taken == ["loop", "lanes", "loop"]


def test_the_split__helper_without_the_eigen_step_run_process_with_it(monkeypatch):
    """The helper solves without the eigen step (``with_modes=False``: no ``stable`` or
    ``omega``); the run's process compiles it meanwhile, as ``solve_chunk`` calls it, and
    only for scenes that have one."""
    import mcchain.solvers.statics as statics
    from mcchain.scene import compile_model, load_scene
    from mcchain.solvers import solve_chunk

    scene = load_scene(SWEEP)
    model = compile_model(scene, nsample=3)
    out = solve_chunk(model, scene, with_modes=False)
    assert "q_eq" in out and not {"stable", "omega", "mode_shape"} & set(out)
    assert {"stable", "omega", "mode_shape"} <= set(solve_chunk(model, scene))
    calls = []
    monkeypatch.setattr(
        statics, "solve_modes", lambda m, eq, **kw: calls.append((m.nsample, eq.q.shape, kw))
    )
    ahead.compile_modes(model, scene)
    assert calls == [(1, (1, model.ndof), {"shapes": True, "damped": True})]
    fourbar = load_scene(REPO / "configs" / "fourbar-clearance.toml")  # [simulate] only
    ahead.compile_modes(compile_model(fourbar, nsample=1), fourbar)
    assert len(calls) == 1


def test_compile_notice__announced_prints_only_the_time_since_the_announcement():
    stream = io.StringIO()
    with compile_notice(stream=stream, announced_at=0.0):
        pass
    (line,) = stream.getvalue().splitlines()
    assert line.startswith("kernels ready in ")


def test_cold_run__a_scene_its_keys_refuse_gets_its_one_line_alone(monkeypatch, tmp_path, capsys):
    """On a cold cache the compile notice comes at the start of a run, but a scene refused
    by its keys (no compiled kernel needed to tell) is refused before it: the one line
    alone on stderr, no helper process started, nothing written."""
    from mcchain.compiled.ready import Kernels
    from mcchain.errors import SceneError

    started: list[Path] = []
    monkeypatch.setattr(ahead, "assembly_is_cached", lambda: False)

    def start(cls: type[CompileAhead], scene_path: Path, *args: object) -> CompileAhead:
        started.append(scene_path)
        return cls(None)  # cold, no helper process: the notice still comes

    monkeypatch.setattr(CompileAhead, "start", classmethod(start))
    bad = tmp_path / "bad.toml"
    bad.write_text(BAR.replace("t_end = 0.1", "t_end = 0.1\ndtt = 1e-4"), encoding="utf-8")
    with pytest.raises(SceneError, match=r"^simulate\.dtt: "):
        Kernels.for_run(bad, None, None, compiled=True)
    assert started == [] and capsys.readouterr().err == ""
    good = tmp_path / "good.toml"
    good.write_text(BAR, encoding="utf-8")
    Kernels.for_run(good, None, None, compiled=True)
    assert started == [good]
    assert capsys.readouterr().err.startswith("compiling the kernels of this scene's analyses")
    assert sorted(tmp_path.iterdir()) == [bad, good]


BAR = (
    swinging_bar_text(count=8)
    + """[sample.vary]
"joint.O.clearance" = { uniform = [1e-4, 1e-3] }
[simulate]
t_end = 0.1
dt = 5e-4
output_dt = 5e-3
method = "rk4"
"""
)
"""The swinging clearance bar, 8 clearances, RK4 over 0.1 s: a scene whose kernel set
(assembly, the RK4 kernels) compiles cold in about half the CPU of the sweep's (assembly,
equilibrium, modes): 33 s against 61 s."""


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scene", "variables"),
    [
        pytest.param(BAR, ("q", "v", "joint_force", "energy", "status"), id="swinging-bar"),
        pytest.param(  # the statics: the helper without the eigen step, the run with it
            SWEEP.read_text(),
            ("q_eq", "omega", "mode_shape", "joint_force_eq", "status"),
            id="clearance-sweep",
            marks=pytest.mark.long,
        ),
    ],
)
def test_cold_run__with_the_helper_gives_the_values_of_a_warm_run(
    tmp_path: Path, scene: str, variables: tuple[str, ...]
) -> None:
    """A run on empty caches (a fresh process) with the helper, then the same run in this
    process from the warm cache: identical values."""
    path = tmp_path / "scene.toml"
    path.write_text(scene)
    env = {
        **os.environ,
        "PYTHONPATH": str(REPO),
        "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
        "MCCHAIN_CACHE_DIR": str(tmp_path / "mcchain"),
        ahead.ENV_SWITCH: "1",
    }
    command = ["mcchain.cli", "run", str(path), "--samples", "8", "--quiet"]
    proc = subprocess.run(
        [sys.executable, "-m", *command, "--run-dir", str(tmp_path / "cold")],
        env=env,
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert proc.returncode == 0, proc.stderr
    two_cores = len(os.sched_getaffinity(0)) >= 2
    assert ("(in two processes)" in proc.stderr) == two_cores
    assert "kernels ready in " in proc.stderr
    warm = plan.start_run(path, samples=8, run_dir=tmp_path / "warm", progress=False)
    with open_run(tmp_path / "cold") as cold, open_run(warm.folder) as ref:
        assert int((cold.status == 0).sum()) == 8  # every sample solved
        for name in variables:
            np.testing.assert_array_equal(cold[name].values, ref[name].values)
