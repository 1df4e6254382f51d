"""Run folders, run.json, resume after SIGKILL, memory, with the fake scene and solver.

These exercise the storage machinery without the solvers (whose own end-to-end tests are in
test_runs_pipeline.py): a fake scene file, a fake model and a deterministic fake solver
with time histories (see test_runs_support.py).
"""

from __future__ import annotations

import filecmp
import json
import os
import signal
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr
from test_runs_support import (
    REPO,
    TESTS,
    fake_loader,
    fake_solve,
    start_paused_child,
    write_fake_scene,
)

from mcchain.compiled.ready import compile_notice
from mcchain.ensemble.io import list_parts
from mcchain.ensemble.registry import validate_dataset
from mcchain.errors import RunError, SceneError
from mcchain.runner import plan, runs
from mcchain.runner.observers import Progress
from mcchain.runner.steps import RunState, SolvedChunk

RUN_JSON_FIELDS = {
    "id",
    "status",
    "scene",
    "scene_file",
    "samples",
    "seed",
    "chunk_size",
    "chunks",
    "storage",
    "start",
    "end",
    "argv",
    "versions",
    "git",
    "host",
    "pid",
    "threads",
    "scheduler",
    "timings",
    "wall_time",
    "status_counts",
    "throughput",
    "merge",
    "sessions",
    "error",
}


def env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{TESTS}"}


def run(scene: Path, out: Path, **kwargs) -> plan.RunResult:  # type: ignore[no-untyped-def]
    kwargs.setdefault("progress", False)
    return plan.start_run(scene, out=out, loader=fake_loader, solve=fake_solve, **kwargs)


def test_start_run__folder_contents_and_run_json(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", name="my scene/1", count=40, steps=6)
    result = run(scene, tmp_path / "runs", chunk_size=16, argv=["mcchain", "run", "s.toml"])
    folder = result.folder
    assert folder.parent == tmp_path / "runs"
    assert folder.name.endswith("-my-scene-1")
    assert sorted(p.name for p in folder.iterdir()) == [  # no .lock once completed
        "ensemble.nc",
        "run.json",
        "run.log",
        "scene.toml",
    ]
    assert (folder / "scene.toml").read_bytes() == scene.read_bytes()
    record = json.loads((folder / "run.json").read_text())
    assert set(record) >= RUN_JSON_FIELDS
    assert record["status"] == "COMPLETED" and record["error"] is None
    assert record["samples"] == 40 and record["seed"] == 3 and record["chunks"] == 3
    assert record["argv"] == ["mcchain", "run", "s.toml"]
    assert record["versions"]["mcchain"] and record["versions"]["numpy"]
    assert record["versions"]["netcdf-c"] and record["versions"]["hdf5"]
    assert set(record["git"]) == {"commit", "dirty"}
    assert record["host"]["name"] and record["host"]["cpu_count"] >= 1
    assert record["threads"] >= 1 and record["scheduler"] == "in-process"
    phases = {"prepare", "warmup", "compute", "kernel", "write", "merge", "total"}
    assert set(record["timings"]) == phases
    assert all(v >= 0 for v in record["timings"].values())
    assert record["wall_time"] == record["timings"]["total"]
    counts = record["status_counts"]
    assert counts["samples"] == 40 and counts["ok"] + counts["equilibrium_not_converged"] <= 40
    assert record["throughput"]["samples_per_s"] > 0
    assert record["throughput"]["steps_per_sample"] == 60
    assert record["throughput"]["instance_steps_per_s"] == pytest.approx(
        60 * record["throughput"]["samples_per_s"]
    )
    assert 0 <= record["throughput"]["outside_kernel_share"] <= 1
    log = (folder / "run.log").read_text()
    assert "chunk 32:40 solved" in log and "merged 3 parts" in log
    with runs.open_run(folder) as ds:
        validate_dataset(ds, "float32")
        assert ds.sizes["sample"] == 40 and ds.sizes["time"] == 6
        assert ds.attrs["scene"] == scene.read_text()
        assert ds.attrs["seed"] == 3
        settings = json.loads(ds.attrs["settings"])
        assert settings["samples"] == 40 and settings["seed"] == 3
        assert "chunk_size" not in settings["scene"]["storage"]
        versions = json.loads(ds.attrs["versions"])
        assert versions["mcchain"] == ds.attrs["mcchain_version"]
        assert not any("time" in k or "host" in k for k in ds.attrs)
        counted = int((ds.status == 0).sum())
        assert counted == counts["ok"]


def test_start_run__identical_file_for_any_chunk_size_and_threads(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", count=37, steps=4)
    files = [
        run(scene, tmp_path / "runs", chunk_size=k, threads=t).folder / "ensemble.nc"
        for k, t in ((37, 2), (5, 1), (16, 2), (1, 1))
    ]
    for other in files[1:]:
        assert filecmp.cmp(files[0], other, shallow=False)


def test_start_run__never_reuses_a_folder(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", count=3)
    folders = [run(scene, tmp_path / "runs").folder for _ in range(3)]
    assert len(set(folders)) == 3
    created = [runs.create_run_folder(tmp_path / "runs", "x") for _ in range(20)]
    assert len(set(created)) == 20  # all in (about) the same second
    assert all(p.is_dir() for p in created)


def test_start_run__existing_run_dir_is_refused_before_anything(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", count=3)
    target = tmp_path / "mine"
    target.mkdir()
    (target / "keep").write_text("x")
    with pytest.raises(RunError, match=r"--run-dir: .* already exists"):
        run(scene, tmp_path / "runs", run_dir=target)
    assert sorted(p.name for p in target.iterdir()) == ["keep"]
    assert not (tmp_path / "runs").exists()
    result = run(scene, tmp_path / "runs", run_dir=tmp_path / "new" / "exact")
    assert result.folder == tmp_path / "new" / "exact"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"samples": 0}, "--samples: must be an integer >= 1"),
        ({"chunk_size": -3}, "--chunk-size: must be an integer >= 1"),
        ({"seed": -1}, "--seed: must be an integer >= 0"),
        ({"threads": 0}, "--threads: must be an integer >= 1"),
        ({"threads": 10_000}, "--threads: at most"),
        ({"dask": "nowhere"}, "--dask: expected 'local' or a scheduler address"),
    ],
)
def test_start_run__bad_arguments_write_nothing(tmp_path: Path, kwargs, message) -> None:  # type: ignore[no-untyped-def]
    scene = write_fake_scene(tmp_path / "s.toml", count=3)
    with pytest.raises(RunError, match=message):
        run(scene, tmp_path / "runs", **kwargs)
    assert not (tmp_path / "runs").exists()


def test_start_run__scene_error_writes_nothing(tmp_path: Path) -> None:
    def loader(path, samples, seed):  # type: ignore[no-untyped-def]
        raise SceneError("body.bar.mass: must be > 0, got -1.0")

    scene = write_fake_scene(tmp_path / "s.toml")
    with pytest.raises(SceneError, match=r"body\.bar\.mass"):
        plan.start_run(scene, out=tmp_path / "runs", loader=loader, solve=fake_solve)
    assert not (tmp_path / "runs").exists()


def test_start_run__failing_solver_marks_the_run_failed(tmp_path: Path) -> None:
    calls = 0

    def solve(model, scene):  # type: ignore[no-untyped-def]
        nonlocal calls
        calls += 1
        if calls == 3:  # warm-up, chunk 0, then chunk 1 fails
            raise FloatingPointError("boom in chunk 1")
        return fake_solve(model, scene)

    scene = write_fake_scene(tmp_path / "s.toml", count=30)
    with pytest.raises(FloatingPointError):
        plan.start_run(scene, out=tmp_path / "runs", chunk_size=10, loader=fake_loader, solve=solve)
    (folder,) = (tmp_path / "runs").iterdir()
    record = runs.read_record(folder)
    assert record["status"] == "FAILED" and record["error"] == "boom in chunk 1"
    assert "Traceback" in (folder / "run.log").read_text()
    assert [p.start for p in list_parts(folder / "parts")] == [0]
    (info,) = runs.list_runs(tmp_path / "runs")
    assert info.state == "FAILED"
    # The failed run completes on resume, computing only the missing chunks.
    result = plan.resume_run(folder, loader=fake_loader, solve=fake_solve, progress=False)
    assert result.record["status"] == "COMPLETED"
    assert result.record["sessions"][-1]["chunks_computed"] == 2
    reference = run(scene, tmp_path / "ref", chunk_size=10).folder
    assert filecmp.cmp(folder / "ensemble.nc", reference / "ensemble.nc", shallow=False)


def test_resume__after_sigkill_equals_an_uninterrupted_run(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", count=64, steps=5)
    target = tmp_path / "runs" / "killed"
    options = json.dumps({"run_dir": str(target), "chunk_size": 8, "progress": False})
    child = start_paused_child(
        ["run", str(scene), options], target / "parts", after_parts=2, env=env()
    )
    child.send_signal(signal.SIGKILL)
    child.wait()

    # Killed: marked unfinished, finished chunks readable, partial ones invisible.
    record = runs.read_record(target)
    assert record["status"] == "RUNNING"
    assert [info.state for info in runs.list_runs(tmp_path / "runs")] == ["INTERRUPTED"]
    (target / "parts" / ".part-000000000056-000000000064.nc.99.tmp").write_bytes(b"\x89HDF")
    done = list_parts(target / "parts")
    assert 2 <= len(done) <= 4 and not (target / "ensemble.nc").exists()
    table = runs.format_runs(runs.list_runs(tmp_path / "runs"))
    assert f"chunks {len(done)}/8" in table and "INTERRUPTED" in table
    with runs.open_run(target) as partial:
        finished = sorted(i for p in done for i in range(p.start, p.stop))
        assert list(partial.sample.values) == finished
        partial_data = partial.load()

    result = plan.resume_run(target, loader=fake_loader, solve=fake_solve, argv=["resume"])
    assert result.record["status"] == "COMPLETED"
    assert len(result.record["sessions"]) == 2
    assert result.record["sessions"][1]["chunks_computed"] == 8 - len(done)
    assert not (target / "parts").exists()

    reference = run(scene, tmp_path / "ref", chunk_size=8).folder
    assert filecmp.cmp(target / "ensemble.nc", reference / "ensemble.nc", shallow=False)
    with runs.open_run(target) as a, runs.open_run(reference) as b:
        xr.testing.assert_identical(a.load(), b.load())
        np.testing.assert_array_equal(a.sample.values, np.arange(64))
        xr.testing.assert_identical(partial_data, b.sel(sample=finished).load())


def test_resume__refuses_completed_running_and_unknown_runs(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", count=4)
    folder = run(scene, tmp_path / "runs").folder
    with pytest.raises(RunError, match="already completed"):
        plan.resume_run(folder, loader=fake_loader, solve=fake_solve)
    with pytest.raises(RunError, match="no such run folder"):
        plan.resume_run(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RunError, match="not a run folder"):
        plan.resume_run(tmp_path / "empty")
    record = runs.read_record(folder)
    record["status"] = "RUNNING"
    runs.write_record(folder, record)
    with runs.run_lock(folder):
        assert runs.is_locked(folder)
        with pytest.raises(RunError, match="being executed by another process"):
            plan.resume_run(folder, loader=fake_loader, solve=fake_solve)
    assert not runs.is_locked(folder)


def test_list_runs__table(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", name="alpha", count=30)
    first = run(scene, tmp_path / "runs").folder
    second = run(scene, tmp_path / "runs", samples=7).folder
    (tmp_path / "runs" / "stray").mkdir()
    found = runs.list_runs(tmp_path / "runs")
    assert [i.id for i in found] == [first.name, second.name]
    assert [i.samples for i in found] == [30, 7]
    assert all(i.state == "COMPLETED" and i.scene == "alpha" for i in found)
    table = runs.format_runs(found).splitlines()
    assert table[0].split() == ["id", "scene", "samples", "status", "wall", "state"]
    ok = found[0].status_counts["ok"]
    assert first.name in table[1] and f"ok={ok}" in table[1] and "COMPLETED" in table[1]
    assert runs.list_runs(tmp_path / "missing") == []


def test_open_run__by_id_under_runs_and_errors(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    scene = write_fake_scene(tmp_path / "s.toml", count=5)
    folder = run(scene, tmp_path / "runs").folder
    monkeypatch.chdir(tmp_path)
    with runs.open_run(folder.name) as ds:
        assert ds.sizes["sample"] == 5
        assert ds.q_eq.chunks is not None  # lazy
    (tmp_path / "runs" / "bare").mkdir()
    with pytest.raises(RunError, match=r"no ensemble\.nc and no finished chunks"):
        runs.open_run("bare")


def test_progress__chunks_rate_and_eta_on_a_terminal_only(
    capsys: pytest.CaptureFixture[str],
) -> None:
    job: Any = None
    todo = [(10, 20), (20, 30), (30, 40)]  # 0:10 was computed before this session
    run = RunState(job, Path("run"), {"chunks": 4}, {}, 40, todo)
    bar = Progress(enabled=True)
    bar.on_start(run)
    for start, stop in todo:
        bar.on_chunk_done(run, SolvedChunk(start, stop, {}))
    bar.on_chunks_done(run)
    err = capsys.readouterr().err
    assert "4/4" in err and "samples/s" in err and "chunk" in err
    quiet = Progress()  # stderr is captured: not a terminal
    quiet.on_start(run)
    quiet.on_chunk_done(run, SolvedChunk(10, 20, {}))
    quiet.on_chunks_done(run)
    assert capsys.readouterr().err == ""


def test_progress__a_run_that_grows_raises_the_bar_s_total(
    capsys: pytest.CaptureFixture[str],
) -> None:
    job: Any = None
    record = {"chunks": 2}
    run = RunState(job, Path("run"), record, {}, 20, [(0, 10), (10, 20)])
    bar = Progress(enabled=True)
    bar.on_start(run)
    for start in (0, 10):
        bar.on_chunk_done(run, SolvedChunk(start, start + 10, {}))
    record["chunks"] = 3  # until added a batch
    bar.on_chunk_done(run, SolvedChunk(20, 30, {}))
    bar.on_chunks_done(run)
    assert "3/3" in capsys.readouterr().err


class _SignallingStream:
    """A text stream that sets an event on its first write (no clock: the test waits on it)."""

    def __init__(self) -> None:
        self.text = ""
        self.written = threading.Event()

    def write(self, text: str) -> int:
        self.text += text
        self.written.set()
        return len(text)

    def flush(self) -> None:
        pass


def test_compile_notice__one_line_naming_the_caches_while_the_kernels_compile() -> None:
    stream = _SignallingStream()
    with compile_notice(after=0.0, stream=stream):
        assert stream.written.wait(60.0)  # the block outlives the delay: the notice comes
    lines = stream.text.splitlines()
    assert "once per installation and topology" in lines[0]
    assert "NUMBA_CACHE_DIR" in lines[0] and "MCCHAIN_CACHE_DIR" in lines[0]
    assert lines[1].startswith("kernels ready in ") and len(lines) == 2
    quiet = _SignallingStream()
    with compile_notice(after=1e9, stream=quiet):  # a warm cache: done before the delay
        pass
    assert quiet.text == ""
