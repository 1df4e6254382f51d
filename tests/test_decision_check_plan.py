"""``mcchain check``: which samples it re-solves, the tightened verdict and the flip bound,
against a solver whose error is known exactly.

The solver is a stand-in for the kernels (the scene, its sampling and the run machinery are
real): the peak joint force of sample i is 100 m_i (1 + e s_i) N with e = 1e4 rtol (1 % at
rtol 1e-6, 0.1 % ten times tighter) and s_i = sin(1e7 m_i), so every value at every
tolerance is known in closed form; optionally the samples with m > ``FAIL_ABOVE`` diverge at
the run's tolerance and solve ten times tighter (a failure the integrator caused).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr

from mcchain.decision.check import (
    BAND,
    CHECK_COLUMNS,
    check_run,
    near_limit,
    relative_changes,
    spread_count,
    spread_indices,
)
from mcchain.decision.stats import one_sided_bounds, success_run_count, verdict
from mcchain.runner import plan, runs
from mcchain.scene.study import Requirement
from mcchain.status import DIVERGED
from mcchain.testing.factory import bar_scene_dict, toml_text

LIMIT = 250.0  # N: fails where m > 2.5 kg, P(fail) = 0.25
COUNT = 400
RTOL = 1e-6


def peak(m: np.ndarray, rtol: float) -> np.ndarray:
    return 100.0 * m * (1.0 + 1e4 * rtol * np.sin(1e7 * m))


def make_solver(fail_above: float | None) -> Any:
    def solve(model: Any, scene: Any) -> dict[str, np.ndarray]:
        m = np.asarray(model.parameters)[:, 0]
        rtol = float(scene.simulate.rtol)
        value = peak(m, rtol)
        status = np.zeros(m.size, dtype=np.uint32)
        if fail_above is not None and rtol >= RTOL:
            status[m > fail_above] = DIVERGED
            value = np.where(m > fail_above, np.nan, value)
        return {"status": status, "peak_joint_force": value[:, None]}

    return solve


def scene_text(retry_failed: bool = False) -> str:
    doc = bar_scene_dict(
        sample={"count": COUNT, "seed": 5, "vary": {"body.bar.mass": {"uniform": [1.0, 3.0]}}},
        equilibrium=False,
        modes=False,
        # retry_failed = false: the run keeps its failures, for the check to re-solve them
        simulate={
            "t_end": 0.01,
            "dt": 1e-3,
            "method": "rk45",
            "rtol": RTOL,
            "atol": 1e-8,
            "retry_failed": retry_failed,
        },
    )
    doc["requirement"] = [
        {
            "name": "pin",
            "output": "peak_joint_force",
            "select": {"joint": "O"},
            "max": LIMIT,
            "target": 0.3,
        }
    ]
    return toml_text(doc)


def make_run(tmp_path: Path, fail_above: float | None = None, retry: bool = False) -> Path:
    scene = tmp_path / "bar.toml"
    scene.write_text(scene_text(retry))
    return plan.start_run(
        scene, run_dir=tmp_path / "run", progress=False, solve=make_solver(fail_above)
    ).folder


def masses(folder: Path) -> np.ndarray:
    with runs.open_run(folder) as ds:
        return np.asarray(ds["parameters"].values[:, 0])


def rows_of(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames or ()) == CHECK_COLUMNS
        return list(reader)


def test_check__band_near_the_limit_and_the_flip_bound(tmp_path: Path) -> None:
    folder = make_run(tmp_path)
    m = masses(folder)
    before, after = peak(m, RTOL), peak(m, RTOL / 10)
    requirement = Requirement(name="pin", output="peak_joint_force", max=LIMIT, target=0.3)
    spread = spread_indices(COUNT, 16)
    scale = float(np.max(relative_changes(before[spread], after[spread], requirement)))
    near = near_limit(before, requirement, scale)
    near[spread] = False
    expected = np.union1d(spread, np.flatnonzero(near))
    assert 16 < expected.size < COUNT  # a band, not the whole run

    result = check_run(folder, 10, samples=16, solve=make_solver(None))
    (row,) = rows_of(result.csv)
    with xr.open_dataset(result.values) as tight:
        np.testing.assert_array_equal(tight["sample"].values, expected)
        np.testing.assert_allclose(
            tight["peak_joint_force"].values[:, 0], after[expected], rtol=0, atol=0
        )
    assert int(row["samples"]) == expected.size and int(row["near"]) == expected.size - 16
    flips = (before <= LIMIT) != (after <= LIMIT)
    # every flip of the whole run lies in the band: none was left unseen
    assert int(row["flips"]) == int(flips.sum()) == int(flips[expected].sum()) > 0
    merged = before.copy()
    merged[expected] = after[expected]
    k = int(np.sum(merged > LIMIT))
    assert row["verdict_tightened"] == verdict(*one_sided_bounds(k, COUNT, 0.95), 0.3)
    assert row["verdict"] == verdict(
        *one_sided_bounds(int(np.sum(before > LIMIT)), COUNT, 0.95), 0.3
    )
    assert float(row["flip_bound"]) == pytest.approx(1 - 0.05 ** (1 / 16), rel=1e-12)
    text = "\n".join(result.lines())
    assert f"the {COUNT - expected.size} samples not re-solved flip with probability <= " in text
    assert f"{BAND:g}x the largest of the 16 spread samples'" in text
    # the bound is not small against the interval: one advice line, which tolerance and why
    advice = [line for line in result.lines() if line.startswith("advice:")]
    assert len(advice) == 1 and "rtol 1e-07, atol 1e-09" in advice[0], advice


def test_check__default_count_bounds_by_a_tenth_of_the_interval(tmp_path: Path) -> None:
    folder = make_run(tmp_path)
    before = peak(masses(folder), RTOL)
    k = int(np.sum(before > LIMIT))
    low, high = one_sided_bounds(k, COUNT, 0.95)
    assert spread_count([high - low], [0.95], COUNT) == min(
        success_run_count(0.1 * (high - low), 0.95), COUNT
    )
    assert success_run_count(0.09, 0.95) < 64 == spread_count([0.9], [0.95], 10_000)
    assert spread_count([0.0], [0.95], 500) == 500  # a zero-width interval: all
    chosen = spread_count([high - low], [0.95], COUNT)
    result = check_run(folder, 10, solve=make_solver(None))
    (row,) = rows_of(result.csv)
    assert int(row["samples"]) >= chosen and result.spread == chosen
    assert float(row["flip_bound"]) <= 0.1 * (high - low)  # small: no advice
    assert not any(line.startswith("advice:") for line in result.lines())
    everything = check_run(folder, 10, samples=COUNT, solve=make_solver(None))
    (row,) = rows_of(everything.csv)
    assert int(row["samples"]) == COUNT and float(row["flip_bound"]) == 0.0
    assert "every sample re-solved: no flip left unseen" in "\n".join(everything.lines())


def test_check__tighten_1_changes_nothing(tmp_path: Path) -> None:
    folder = make_run(tmp_path)
    result = check_run(folder, 1, samples=8, solve=make_solver(None))
    (row,) = rows_of(result.csv)
    assert (row["samples"], row["near"], row["flips"]) == ("8", "0", "0")
    assert float(row["abs_diff_max"]) == 0.0 and row["verdict"] == row["verdict_tightened"]


def test_check__failed_samples_are_re_solved(tmp_path: Path) -> None:
    """Samples with m > 2.9 diverge at the run's tolerance (undefined: failed). The check
    re-solves every one of them (only a re-solve tells whether they fail); a spread sample
    that changes state (a change of no size) makes every sample near: all re-solved."""
    folder = make_run(tmp_path, fail_above=2.9)
    m = masses(folder)
    failed = m > 2.9
    assert failed.sum() > 5
    result = check_run(folder, 10, samples=16, solve=make_solver(2.9))
    (row,) = rows_of(result.csv)
    with xr.open_dataset(result.values) as tight:
        solved = tight["sample"].values
    assert not failed[spread_indices(COUNT, 16)].any()
    assert set(np.flatnonzero(failed)) <= set(solved.tolist()) and solved.size < COUNT
    after = peak(m, RTOL / 10)
    # undefined samples fail; re-solved they are beyond the limit anyway: no flip from them
    before = np.where(failed, np.nan, peak(m, RTOL))
    flips = (before <= LIMIT) != (after <= LIMIT)
    assert int(row["flips"]) == int(flips[solved].sum())
    check = result.checks[0]
    assert check.run.undefined == int(failed.sum()) and check.tightened.undefined == 0

    result = check_run(folder, 10, samples=200, solve=make_solver(2.9))
    (row,) = rows_of(result.csv)
    assert failed[spread_indices(COUNT, 200)].any()
    assert int(row["samples"]) == COUNT and float(row["flip_bound"]) == 0.0
    assert int(row["flips"]) == int(flips.sum())


def test_near_limit__band_undefined_and_infinite_scale() -> None:
    r = Requirement(name="r", output="omega", min=1.0, max=2.0)
    x = np.array([0.5, 0.98, 1.5, 2.03, 3.0, math.nan, math.inf])
    # scale 0.01: a band of 3 % of max(|x|, |limit|) around each limit
    assert near_limit(x, r, 0.01).tolist() == [False, True, False, True, False, True, False]
    assert near_limit(x, r, 0.0).tolist() == [False] * 5 + [True, False]
    assert near_limit(x, r, math.inf).all()
    changes = relative_changes(
        np.array([1.0, 2.0, math.nan, math.nan, math.inf, math.inf, 4.0]),
        np.array([1.1, 2.0, math.nan, 1.0, math.inf, 1.0, math.nan]),
        r,
    )
    assert changes[0] == pytest.approx(0.1 / 1.0) and changes[1] == 0.0
    assert changes[2] == 0.0 and changes[4] == 0.0  # both undefined / both never
    assert np.isinf(changes[[3, 5, 6]]).all()  # a change of state


def test_check__cli_defaults_and_one_line_refusals(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``mcchain check RUN`` needs no flag (F = 10, the spread count of
    :func:`spread_count`); bad flags are one line, exit 2, nothing written."""
    import mcchain.runner.executors
    from mcchain.cli import main

    folder = make_run(tmp_path)
    for argv, message in [
        (["check", str(folder), "--samples", "0"], "--samples: must be >= 1"),
        (["check", str(folder), "--tighten", "nan"], "--tighten: must be a number >= 1"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, err
    assert not (folder / "check").exists() and not (folder / "export").exists()
    monkeypatch.setattr(mcchain.runner.executors, "default_solve", lambda: make_solver(None))
    assert main(["check", str(folder)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("check: rtol 1e-06 -> 1e-07, atol 1e-08 -> 1e-09 (10x tighter)")
    assert out[-1] == str(folder / "export" / "check.csv")
    assert (folder / "check" / "tighten-10.nc").is_file()


def test_requirement_tolerance__tighter_only_where_the_scene_writes_none(tmp_path: Path) -> None:
    """A requirement on an output of the time integration, an adaptive method and no
    rtol/atol written: the defaults ten times tighter, said in a note and stored in the
    settings; anything written, a fixed-step method or a requirement on statics: as is."""
    from mcchain.decision.tolerance import requirement_tolerance
    from mcchain.runner.job import prepare_job
    from mcchain.scene import load_scene_text
    from mcchain.scene.models import Simulate

    def scene(simulate: dict[str, Any], output: str = "peak_joint_force") -> str:
        doc = bar_scene_dict(sample={"count": 4}, equilibrium=False, simulate=simulate)
        select = {"joint": "O"} if output == "peak_joint_force" else {"mode": 0}
        doc["requirement"] = [{"name": "r", "output": output, "select": select, "max": 1e9}]
        return toml_text(doc)

    base = {"t_end": 0.01, "dt": 1e-3, "method": "rk45"}
    path = tmp_path / "auto.toml"
    path.write_text(scene(base))
    job = prepare_job(path)
    defaults = (Simulate.model_fields["rtol"].default, Simulate.model_fields["atol"].default)
    assert (job.scene.simulate.rtol, job.scene.simulate.atol) == (1e-9, 1e-11)
    assert defaults == (1e-8, 1e-10)
    assert job.settings["scene"]["simulate"]["rtol"] == 1e-9
    assert any("integrates at rtol 1e-09, atol 1e-11" in note for note in job.notes)
    for simulate, output in [
        ({**base, "rtol": 1e-7}, "peak_joint_force"),  # written: kept, atol too
        ({**base, "atol": 1e-9}, "peak_joint_force"),
        ({**base, "method": "rk4"}, "peak_joint_force"),  # fixed step: its dt is written
        (base, "omega"),  # a requirement on the modes only
    ]:
        loaded = load_scene_text(scene(simulate, output))
        same, note = requirement_tolerance(loaded)
        assert same is loaded and note is None


def test_check__a_retried_sample_is_tightened_from_what_solved_it(tmp_path: Path) -> None:
    """With ``retry_failed``, the samples with m > 2.9 diverge at RTOL and the run solves
    them at RTOL / 10 (``solved_by`` 1). The check tightens each sample from the settings
    that solved it: F = 10 re-solves those at RTOL / 100, the others at RTOL / 10; F = 1
    gives back the run's own values, the retried ones included."""
    from mcchain.solvers.retry import SOLVED_BY, TIGHTENED_10

    folder = make_run(tmp_path, fail_above=2.9, retry=True)
    m = masses(folder)
    failed = m > 2.9
    with runs.open_run(folder) as ds:
        np.testing.assert_array_equal(ds[SOLVED_BY].values, np.where(failed, TIGHTENED_10, 0))
        run_values = ds["peak_joint_force"].values[:, 0]
    np.testing.assert_array_equal(run_values, np.where(failed, peak(m, RTOL / 10), peak(m, RTOL)))
    same = check_run(folder, 1, samples=COUNT, solve=make_solver(2.9))
    with xr.open_dataset(same.values) as tight:
        np.testing.assert_array_equal(tight["peak_joint_force"].values[:, 0], run_values)
    (row,) = rows_of(same.csv)
    assert (row["flips"], float(row["abs_diff_max"])) == ("0", 0.0)
    result = check_run(folder, 10, samples=COUNT, solve=make_solver(2.9))
    with xr.open_dataset(result.values) as tight:
        values = tight["peak_joint_force"].values[:, 0]
    expected = np.where(failed, peak(m, RTOL / 100), peak(m, RTOL / 10))
    np.testing.assert_array_equal(values, expected)
    assert result.checks[0].run.undefined == 0 and result.checks[0].tightened.undefined == 0
