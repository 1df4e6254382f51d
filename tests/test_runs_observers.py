"""The pipeline's protocol (mcchain.runner.steps): observers called at fixed points, in order,
only for the hooks they override, on the run's thread; a run grown by ``more_samples``
equals a run of the final count; a solve step changes what is stored and what observers
see. On the fake scene and solver of test_runs_support (no kernels)."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr
from test_runs_support import fake_loader, fake_solve, write_fake_scene

from mcchain.compiled.ready import Kernels
from mcchain.runner.job import Job, prepare_job
from mcchain.runner.pipeline import Plan, RunResult, run_pipeline
from mcchain.runner.runs import ENSEMBLE, create_run
from mcchain.runner.steps import Observer, RunState, SolvedChunk

CHUNK = 8
"""Samples per chunk: the counts below end mid-chunk, so the chunking restarts show."""


class Recorder(Observer):
    """Notes every hook call; asks once to grow the run to ``grow_to``."""

    def __init__(self, grow_to: int | None = None) -> None:
        self.calls: list[tuple[Any, ...]] = []
        self.grow_to = grow_to

    def on_start(self, run: RunState) -> None:
        self.calls.append(("on_start", list(run.todo)))

    def on_chunk_done(self, run: RunState, chunk: SolvedChunk) -> None:
        iterations = int(np.sum(chunk.outputs["iterations"]))
        self.calls.append(("chunk", chunk.start, chunk.stop, threading.get_ident(), iterations))

    def more_samples(self, run: RunState) -> int | None:
        self.calls.append(("more", run.nsample))
        if self.grow_to is not None and run.nsample < self.grow_to:
            return self.grow_to
        return None

    def on_chunks_done(self, run: RunState) -> None:
        self.calls.append(("chunks_done", run.nsample))

    def on_merged(self, run: RunState) -> None:
        self.calls.append(("merged", (run.folder / ENSEMBLE).exists(), run.record["status"]))


class Silent(Observer):
    """Overrides no hook: the pipeline has nothing to call."""


def _job(tmp_path: Path, nsample: int, model_samples: int) -> Job:
    scene = write_fake_scene(tmp_path / "s.toml", count=model_samples, storage={})
    job = prepare_job(scene, samples=model_samples, chunk_size=CHUNK, loader=fake_loader)
    return job.resized(nsample)  # a model of model_samples, the first nsample run first


def _run(
    tmp_path: Path, name: str, job: Job, observers: list[Observer], steps: Any = ()
) -> RunResult:
    folder, record = create_run(job, tmp_path / "s.toml", ["test"], run_dir=tmp_path / name)
    kernels = Kernels()
    kernels.after_checks(job.kernels, job.nsample)
    plan = Plan(
        job, folder, record, record["versions"], observers, kernels,
        solve=fake_solve, solve_steps=steps,
    )  # fmt: skip
    return run_pipeline(plan)


def test_pipeline__hooks_in_order_and_a_grown_run_equals_one_of_its_final_count(tmp_path):
    recorder = Recorder(grow_to=30)
    grown = _run(tmp_path, "grown", _job(tmp_path, 20, 30), [recorder, Silent()])
    me = threading.get_ident()
    chunks = [c[1:3] for c in recorder.calls if c[0] == "chunk"]
    assert recorder.calls[0] == ("on_start", [(0, 8), (8, 16), (16, 20)])
    assert chunks == [(0, 8), (8, 16), (16, 20), (20, 28), (28, 30)]  # restarted at 20
    assert [c[0] for c in recorder.calls] == [
        "on_start", "chunk", "chunk", "chunk", "more", "chunk", "chunk", "more",
        "chunks_done", "merged",
    ]  # fmt: skip
    assert [c for c in recorder.calls if c[0] == "more"] == [("more", 20), ("more", 30)]
    assert all(c[3] == me for c in recorder.calls if c[0] == "chunk")
    assert recorder.calls[-2:] == [("chunks_done", 30), ("merged", True, "RUNNING")]
    record = grown.record
    assert (record["samples"], record["restarts"], record["chunks"], record["status"]) == (
        30, [20], 5, "COMPLETED",
    )  # fmt: skip
    whole = _run(tmp_path, "whole", _job(tmp_path, 30, 30), [])
    with (
        xr.open_dataset(grown.folder / ENSEMBLE) as a,
        xr.open_dataset(whole.folder / ENSEMBLE) as b,
    ):
        xr.testing.assert_identical(a, b)


def step_add_100_iterations(model: Any, scene: Any, outputs: dict[str, Any]) -> dict[str, Any]:
    """A solve step (module level: it pickles for Dask)."""
    return {**outputs, "iterations": outputs["iterations"] + 100}


def test_pipeline__a_solve_step_changes_what_is_stored_and_what_observers_see(tmp_path):
    plain, stepped = Recorder(), Recorder()
    a = _run(tmp_path, "plain", _job(tmp_path, 20, 20), [plain])
    b = _run(tmp_path, "stepped", _job(tmp_path, 20, 20), [stepped], [step_add_100_iterations])
    seen = [c[4] for c in plain.calls if c[0] == "chunk"]
    assert [c[4] for c in stepped.calls if c[0] == "chunk"] == [
        s + 100 * n for s, n in zip(seen, (8, 8, 4), strict=True)
    ]
    with xr.open_dataset(a.folder / ENSEMBLE) as x, xr.open_dataset(b.folder / ENSEMBLE) as y:
        np.testing.assert_array_equal(y["iterations"].values, x["iterations"].values + 100)
        np.testing.assert_array_equal(y["q_eq"].values, x["q_eq"].values)


def test_pipeline__a_failing_hook_fails_the_run_and_keeps_its_chunks(tmp_path):
    class Broken(Observer):
        def on_chunk_done(self, run: RunState, chunk: SolvedChunk) -> None:
            if chunk.start == 8:
                raise RuntimeError("observer broke")

    recorder = Recorder()
    with pytest.raises(RuntimeError, match="observer broke"):
        _run(tmp_path, "broken", _job(tmp_path, 20, 20), [Broken(), recorder])
    record = json.loads((tmp_path / "broken" / "run.json").read_text())
    assert record["status"] == "FAILED" and record["error"] == "observer broke"
    assert recorder.calls[-1] == ("chunks_done", 20)  # told the computing is over
    parts = sorted(p.name for p in (tmp_path / "broken" / "parts").glob("part-*.nc"))
    assert parts == ["part-000000000000-000000000008.nc", "part-000000000008-000000000016.nc"]
