"""``mcchain run --extend RUN --samples N``: a run continued is the run of the total count.

A real scene (the clearance bar: equilibrium, modes and a short time history, clearance and
mass sampled so that every sample differs) run with 64 samples, extended by 64, must equal
one run of 128 sample for sample, every variable bit for bit, for the ``random`` and the
``sobol`` design; an interrupted extension resumes to the same file; designs that cannot be
continued are refused before anything is written.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from mcchain.cli import main
from mcchain.errors import RunError
from mcchain.runner import plan, runs
from mcchain.runner.runs import plan_chunks
from mcchain.testing.scenes import hanging_clearance_bar_text

pytestmark = pytest.mark.slow  # real solvers


def scene_text(design: str) -> str:
    """The clearance bar with a 20 ms swing, clearance and mass sampled."""
    return (
        hanging_clearance_bar_text("extend-bar", angular_velocity=1.0)
        + f"""[equilibrium]
[modes]
[simulate]
t_end = 0.02
dt = 1e-4
method = "rk4"
output_dt = 1e-3
[sample]
count = 16
seed = 11
design = "{design}"
[sample.vary]
"joint.O.clearance" = {{ uniform = [1e-4, 1e-3] }}
"body.bar.mass" = {{ normal = [2.0, 0.02] }}
"""
    )


def write_scene(folder: Path, design: str) -> Path:
    path = folder / f"{design}.toml"
    path.write_text(scene_text(design), encoding="utf-8")
    return path


def assert_same_values(a: xr.Dataset, b: xr.Dataset) -> None:
    """Every variable and coordinate of ``a`` equals ``b``'s bit for bit (NaN = NaN)."""
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        x, y = a[name].values, b[name].values
        assert x.dtype == y.dtype and x.shape == y.shape, name
        if x.dtype.kind == "f":
            np.testing.assert_array_equal(x.view(np.uint8), y.view(np.uint8), err_msg=name)
        else:
            np.testing.assert_array_equal(x, y, err_msg=name)


def test_plan_chunks__restarts_where_the_run_grew() -> None:
    assert plan_chunks(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert plan_chunks(10, 4, restarts=[6]) == [(0, 4), (4, 6), (6, 10)]
    assert plan_chunks(10, 4, restarts=[6, 0, 10, 12]) == [(0, 4), (4, 6), (6, 10)]


@pytest.mark.parametrize("design", ["random", "sobol"])
def test_extend__64_plus_64_equals_a_run_of_128(tmp_path: Path, design: str) -> None:
    scene = write_scene(tmp_path, design)
    small = plan.start_run(
        scene, samples=64, chunk_size=24, run_dir=tmp_path / "small", progress=False
    ).folder
    whole = plan.start_run(
        scene, samples=128, chunk_size=24, run_dir=tmp_path / "whole", progress=False
    ).folder
    result = plan.extend_run(small, 64, progress=False, argv=["extend"])
    record = result.record
    assert record["status"] == "COMPLETED" and record["samples"] == 128
    assert record["extensions"][0]["from"] == 64 and record["extensions"][0]["to"] == 128
    assert record["restarts"] == [64] and record["chunks"] == 6  # 24 24 16 | 24 24 16
    assert record["sessions"][-1]["samples_computed"] == 64
    assert record["status_counts"]["samples"] == 128
    with runs.open_run(small) as extended, runs.open_run(whole) as reference:
        assert_same_values(extended.load(), reference.load())
        assert extended.attrs["sample_count"] == 128
        settings = json.loads(extended.attrs["settings"])
        assert settings["samples"] == 128
        assert extended.attrs == reference.attrs


def test_extend__an_interrupted_extension_resumes_to_the_same_ensemble(tmp_path: Path) -> None:
    scene = write_scene(tmp_path, "random")
    folder = plan.start_run(
        scene, samples=32, chunk_size=16, run_dir=tmp_path / "run", progress=False
    ).folder
    calls = []

    def failing_solve(model, scene):  # type: ignore[no-untyped-def]
        from mcchain.solvers import solve_chunk

        calls.append(model.nsample)
        if len(calls) == 2:  # the second new chunk fails: the first is kept
            raise RuntimeError("power cut")
        return solve_chunk(model, scene)

    with pytest.raises(RuntimeError, match="power cut"):
        plan.extend_run(folder, 32, solve=failing_solve, progress=False)
    record = runs.read_record(folder)
    assert record["status"] == "FAILED" and record["samples"] == 64
    assert (folder / "ensemble.nc").exists()
    with runs.open_run(folder) as old:  # the completed part is untouched
        assert old.sizes["sample"] == 32
    with pytest.raises(RunError, match="not completed"):
        plan.extend_run(folder, 8)
    plan.resume_run(folder, progress=False)
    reference = plan.start_run(
        scene, samples=64, chunk_size=16, run_dir=tmp_path / "ref", progress=False
    ).folder
    with runs.open_run(folder) as a, runs.open_run(reference) as b:
        assert_same_values(a.load(), b.load())


@pytest.mark.parametrize("design", ["lhs", "saltelli"])
def test_extend__a_design_that_depends_on_the_count_is_refused(
    tmp_path: Path, design: str, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = write_scene(tmp_path, design)
    folder = plan.start_run(scene, samples=16, run_dir=tmp_path / "r", progress=False).folder
    before = sorted(p.name for p in folder.iterdir())
    assert main(["run", "--extend", str(folder), "--samples", "16"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f'design "{design}" cannot be continued' in err
    assert sorted(p.name for p in folder.iterdir()) == before
    assert runs.read_record(folder)["samples"] == 16


def test_extend__arguments_checked_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "--extend", str(tmp_path)]) == 2
    assert "--samples N" in capsys.readouterr().err
    assert main(["run", "--extend", str(tmp_path), "--samples", "4", "--seed", "3"]) == 2
    assert "cannot be combined with --seed" in capsys.readouterr().err
    assert main(["run", "--extend", str(tmp_path / "nope"), "--samples", "4"]) == 2
    assert "no such run folder" in capsys.readouterr().err
