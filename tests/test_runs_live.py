"""``mcchain run ... --rerun SAMPLES``: samples streamed to rerun while the run goes.

The real pipeline on an 8-sample swinging clearance bar (the scene of test_viz_e2e.py with
``t_end = 0.05``: 11 output times) in chunks of 2, so the streamed samples arrive with
different chunks; the .rrd is read back with rerun 0.41's chunk reader (test_viz_playback).
The kernels are those of test_viz_e2e.py (numba's disk cache makes them quick after the first
compile on a machine).
"""

from __future__ import annotations

import contextlib
import filecmp
import io
import json
import os
import subprocess
import sys
import threading
from collections.abc import Mapping
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from test_runs_support import REPO, TESTS, fake_loader, fake_model, fake_solve, write_fake_scene
from test_viz_e2e import SCENE
from test_viz_playback import read_rrd

from mcchain import open_run
from mcchain.cli import main as cli
from mcchain.ensemble.io import list_parts
from mcchain.errors import RunError
from mcchain.runner import plan, runs
from mcchain.runner.executors import run_local
from mcchain.runner.steps import Observer, RunState, SolvedChunk
from mcchain.runner.summary import run_summary
from mcchain.viz import live as viz_live

CLEARANCE_BAR = REPO / "configs" / "clearance-bar.toml"
SWING = SCENE.replace("t_end = 0.1\n", "t_end = 0.05\n")
NTIME = 11  # t = 0, 5 ms, ..., 50 ms
assert SWING != SCENE


def sample_paths(rrd: dict[str, Any]) -> set[str]:
    return {path.split("/")[2] for path in rrd if path.startswith("/sample/")}


def assert_samples_as_stored(rrd: dict[str, Any], run: Path, samples: list[int]) -> None:
    """Forces and contact forces streamed equal the ensemble's, on every output time."""
    with open_run(run) as ds:
        assert ds.sizes["time"] == NTIME
        for s in samples:
            for part in ("mechanism/bodies", "mechanism/forces", "energy", "info"):
                assert f"/sample/{s}/{part}" in rrd, part
            force = rrd[f"/sample/{s}/joint_force/O"]
            np.testing.assert_array_equal(
                force["time"], np.round(ds["time"].values * 1e9).astype(np.int64)
            )
            got = np.array(force["Scalars:scalars"], dtype=np.float64)
            want = ds["joint_force"].sel(sample=s).transpose("time", "joint", "xy").values[:, 0]
            np.testing.assert_array_equal(got, want.astype(np.float64))
            lam = np.array(rrd[f"/sample/{s}/contact_force/O"]["Scalars:scalars"], float)
            np.testing.assert_array_equal(lam[:, 0], ds["contact_force"].sel(sample=s).values[:, 0])
            assert np.isfinite(got).all() and (lam > 0).all()  # a real motion, in contact


@pytest.fixture(scope="module")
def swing(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("swing")
    (folder / "swing.toml").write_text(SWING)
    return folder / "swing.toml"


@pytest.fixture(scope="module")
def plain(swing: Path) -> Path:
    """The run without ``--rerun``."""
    run = swing.parent / "plain"
    assert cli(["run", str(swing), "--run-dir", str(run), "--chunk-size", "2", "--quiet"]) == 0
    return run


@pytest.fixture(scope="module")
def streamed(swing: Path, plain: Path) -> tuple[Path, Path, str]:
    """``mcchain run swing.toml --chunk-size 2 --rerun 0,3 --rerun-save live.rrd``."""
    run, rrd = swing.parent / "streamed", swing.parent / "out" / "live.rrd"
    argv = ["run", str(swing), "--run-dir", str(run), "--chunk-size", "2", "--quiet"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert cli([*argv, "--rerun", "0,3", "--rerun-save", str(rrd)]) == 0
    return run, rrd, out.getvalue()


@pytest.mark.slow  # a real four-bar run streamed to rerun
def test_rerun__streams_samples_0_and_3_only_with_the_ensembles_values(
    streamed: tuple[Path, Path, str],
) -> None:
    run, rrd_path, stdout = streamed
    rrd = read_rrd(rrd_path)
    assert sample_paths(rrd) == {"0", "3"}
    assert len(rrd["/sample/0/joint_force/O"]["time"]) == NTIME
    assert_samples_as_stored(rrd, run, [0, 3])
    from rerun.chunk import RrdReader

    assert RrdReader(rrd_path).blueprints()  # the default layout came with the first chunk
    lines = stdout.splitlines()
    assert lines[-1] == str(run)
    assert f"rerun: samples 0, 3 streamed to {rrd_path}" in lines
    session = runs.read_record(run)["sessions"][-1]["rerun"]
    assert session["samples"] == [0, 3] and session["streamed"] == [0, 3]
    assert session["sink"] == str(rrd_path) and session["error"] is None
    assert not (run / runs.LIVE_RRD).exists()  # --rerun-save: nothing in the folder


@pytest.mark.slow  # a real four-bar run streamed to rerun
def test_rerun__ensemble_is_byte_identical_to_a_run_without_it(
    streamed: tuple[Path, Path, str], plain: Path
) -> None:
    assert filecmp.cmp(streamed[0] / "ensemble.nc", plain / "ensemble.nc", shallow=False)
    assert sorted(p.name for p in streamed[0].iterdir()) == sorted(p.name for p in plain.iterdir())


@pytest.mark.slow  # a real four-bar run streamed to rerun
def test_rerun__resume_streams_what_it_computes_to_the_folder_by_default(
    swing: Path, plain: Path, tmp_path: Path
) -> None:
    """An interrupted run (chunks 2:4 and 6:8 missing) resumed with ``--rerun 0,3,6``: the
    default sink is ``<run>/live.rrd``; sample 0 was computed before and is named."""
    run = tmp_path / "resumed"
    plan.start_run(swing, run_dir=run, chunk_size=2, progress=False, keep_parts=True)
    for part in list_parts(run / "parts"):
        if part.start in (2, 6):
            part.path.unlink()
    (run / "ensemble.nc").unlink()
    record = runs.read_record(run)
    runs.write_record(run, {**record, "status": runs.FAILED})

    result = plan.resume_run(run, progress=False, rerun=viz_live.LiveOptions((0, 3, 6)))
    assert result.record["sessions"][-1]["chunks_computed"] == 2
    rrd = read_rrd(run / runs.LIVE_RRD)
    assert sample_paths(rrd) == {"3", "6"}
    assert_samples_as_stored(rrd, run, [3, 6])
    assert filecmp.cmp(run / "ensemble.nc", plain / "ensemble.nc", shallow=False)
    live = result.record["sessions"][-1]["rerun"]
    assert live["streamed"] == [3, 6] and live["computed_before"] == [0]
    assert any(
        line.startswith("rerun: samples 3, 6 streamed to")
        and "0 computed before this session (replay with mcchain show)" in line
        for line in run_summary(result.record)
    )
    assert "samples 0 were computed before this session" in (run / "run.log").read_text()


@pytest.mark.slow  # a real four-bar run streamed to rerun
def test_rerun__dask_logs_the_chunks_as_they_reach_the_client(
    swing: Path, plain: Path, tmp_path: Path
) -> None:
    from dask.distributed import LocalCluster

    run, rrd_path = tmp_path / "dask", tmp_path / "dask.rrd"
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        plan.start_run(
            swing,
            run_dir=run,
            chunk_size=2,
            dask=cluster.scheduler_address,
            progress=False,
            rerun=viz_live.LiveOptions((7, 2), save=rrd_path),
        )
    assert runs.read_record(run)["scheduler"].startswith("dask ")
    rrd = read_rrd(rrd_path)
    assert sample_paths(rrd) == {"2", "7"}
    assert_samples_as_stored(rrd, run, [2, 7])
    assert filecmp.cmp(run / "ensemble.nc", plain / "ensemble.nc", shallow=False)


# -- errors: one line naming the flag, exit 2, nothing written -----------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--rerun", "0,x"],
            "--rerun: expected comma-separated sample indices like 0,3, got '0,x'",
        ),
        (["--rerun", ","], "--rerun: expected comma-separated sample indices like 0,3, got ','"),
        (["--rerun", "-1"], "--rerun: sample indices are >= 0, got '-1'"),
        (["--rerun", "0,1"], "--rerun: sample 1 is not in the run (1 sample: 0..0)"),
        (
            ["--rerun", "0", "--rerun-save", "a.rrd", "--rerun-spawn"],
            "--rerun-spawn: cannot be combined with --rerun-save (one sink)",
        ),
        (["--rerun-save", "a.rrd"], "--rerun-save: requires --rerun SAMPLES"),
        (["--rerun-spawn"], "--rerun-spawn: requires --rerun SAMPLES"),
        (["--rerun", "0", "--rerun-save", "d"], "--rerun-save: d is a directory"),
    ],
)
def test_rerun__bad_flags_are_one_line_exit_2_and_write_nothing(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    message: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "d").mkdir()
    assert cli(["run", str(CLEARANCE_BAR), *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == f"mcchain: error: {message}\n"
    assert [p.name for p in tmp_path.iterdir()] == ["d"]  # no runs/, no .rrd
    assert list((tmp_path / "d").iterdir()) == []


def test_rerun__bad_sample_on_resume_writes_nothing(tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", count=10, steps=4)
    folder = tmp_path / "run"
    plan.start_run(scene, run_dir=folder, loader=fake_loader, solve=fake_solve, progress=False)
    (folder / "ensemble.nc").unlink()
    before = {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}
    with pytest.raises(RunError, match=r"^--rerun: sample 10 is not in the run \(10 samples"):
        plan.resume_run(
            folder, loader=fake_loader, solve=fake_solve, rerun=viz_live.LiveOptions((10,))
        )
    assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir()} == before


# -- sinks, failures, imports (fake solver) ------------------------------------------------------


def test_rerun__spawn_opens_a_viewer_and_a_second_default_file_never_overwrites(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    opened: list[dict[str, Any]] = []
    chunks: list[tuple[list[int], int, int]] = []

    class Recorder:
        def __init__(self, samples: list[int], **sink: Any) -> None:
            self.samples = list(samples)
            opened.append({"samples": self.samples, **sink})

        def log_chunk(self, ds: Any, model: Any, start: int) -> list[int]:
            ids = ds["sample"].values.tolist()
            chunks.append((ids, start, model.nsample))
            return [s for s in self.samples if s in ids]

        def close(self) -> None:
            opened.append({"closed": True})

    monkeypatch.setattr(viz_live, "LiveStream", Recorder)
    scene = write_fake_scene(tmp_path / "s.toml", count=40, steps=4)
    result = plan.start_run(
        scene,
        run_dir=tmp_path / "run",
        chunk_size=16,
        loader=fake_loader,
        solve=fake_solve,
        progress=False,
        rerun=viz_live.LiveOptions((33, 5), spawn=True),
    )
    assert opened == [{"samples": [33, 5], "save": None, "spawn": True}, {"closed": True}]
    assert chunks == [(list(range(16)), 0, 16), (list(range(32, 40)), 32, 8)]  # not 16:32
    assert "rerun: samples 5, 33 streamed to a spawned viewer" in run_summary(result.record)

    # default file sink: live.rrd is taken (an earlier session), so live-2.rrd
    (tmp_path / "run" / runs.LIVE_RRD).write_bytes(b"earlier session")
    assert viz_live.LiveRun.default_path(tmp_path / "run") == tmp_path / "run" / "live-2.rrd"


def test_rerun__a_failing_stream_is_a_warning_and_the_run_completes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(self: Any, *args: Any) -> list[int]:
        raise OSError("No space left on device\nmore")

    scene = write_fake_scene(tmp_path / "s.toml", count=20, steps=4)
    plain = plan.start_run(
        scene, run_dir=tmp_path / "a", loader=fake_loader, solve=fake_solve, progress=False
    )
    monkeypatch.setattr(viz_live.LiveStream, "log_chunk", broken)
    result = plan.start_run(
        scene,
        run_dir=tmp_path / "b",
        loader=fake_loader,
        solve=fake_solve,
        progress=False,
        rerun=viz_live.LiveOptions((3,)),
    )
    assert result.record["status"] == runs.COMPLETED
    live = result.record["sessions"][-1]["rerun"]
    assert live["error"] == "No space left on device" and live["streamed"] == []
    assert any(
        "stream stopped: No space left on device" in line for line in run_summary(result.record)
    )
    assert (
        "--rerun: the live stream stopped (the run goes on)"
        in (result.folder / "run.log").read_text()
    )
    assert filecmp.cmp(result.folder / "ensemble.nc", plain.folder / "ensemble.nc", shallow=False)


def test_run_local__chunk_hooks_get_each_chunk_on_the_calling_thread_in_order() -> None:
    job: Any = SimpleNamespace(model=fake_model(10, seed=2), scene=None, history_dtype="float32")
    run = RunState(job, Path("run"), {}, {}, 10)
    written: dict[tuple[int, int], Mapping[str, np.ndarray]] = {}
    seen: list[tuple[str, int, int, int]] = []

    def write(chunk: SolvedChunk) -> None:
        written[chunk.start, chunk.stop] = chunk.outputs

    class Seen(Observer):
        def __init__(self, name: str) -> None:
            self.name = name

        def on_chunk_done(self, state: RunState, chunk: SolvedChunk) -> None:
            assert state is run and chunk.outputs["status"].shape == (chunk.stop - chunk.start,)
            seen.append((self.name, chunk.start, chunk.stop, threading.get_ident()))

    chunks = [(0, 4), (4, 8), (8, 10)]
    run_local(
        run, chunks, write, [Seen("a").on_chunk_done, Seen("b").on_chunk_done], solve=fake_solve
    )
    me = threading.get_ident()
    assert seen == [(name, a, b, me) for a, b in chunks for name in "ab"]
    assert set(written) == set(chunks)


def test_rerun__is_imported_only_when_streaming(tmp_path: Path) -> None:
    """One process: a run without ``--rerun`` leaves rerun unimported, then one with it."""
    scene = write_fake_scene(tmp_path / "s.toml", count=8, steps=4)
    code = (
        "import sys; from mcchain.runner import plan; from mcchain.viz.live import LiveOptions\n"
        "from test_runs_support import *\n"
        "for name, live in (('no', None), ('yes', LiveOptions((1,)))):\n"
        "    plan.start_run(sys.argv[1], run_dir=sys.argv[2] + name, loader=fake_loader,"
        " solve=fake_solve, progress=False, rerun=live)\n"
        "    print(name, 'rerun' in sys.modules)\n"
    )
    env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{TESTS}"}
    proc = subprocess.run(
        [sys.executable, "-c", code, str(scene), str(tmp_path / "run-")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == ["no False", "yes True"]
    record = json.loads((tmp_path / "run-yes" / "run.json").read_text())
    assert record["sessions"][0]["rerun"]["streamed"] == [1]
    assert (tmp_path / "run-yes" / runs.LIVE_RRD).is_file()
    assert not (tmp_path / "run-no" / runs.LIVE_RRD).exists()
