"""``mcchain check RUN --tighten F``: samples re-solved with a tighter integration, with the
real kernels (the choice of samples, the tightened verdict and the flip bound are tested
against a solver with a known error in tests/test_decision_check_plan.py).

On a short slider-crank with an impacting piston pin (rk45): at F = 1 the re-solved samples
are the run's own, bit for bit; at F = 10 their values are those of a whole run made with
rtol and atol ten times smaller, and the flips and spreads are counted from them. The run's
ensemble is never changed.
"""

from __future__ import annotations

import csv
import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from mcchain.cli import main
from mcchain.decision.check import CHECK_COLUMNS, check_run, spread_indices
from mcchain.runner import plan, runs
from mcchain.testing.scenes import config_text, with_lines

pytestmark = pytest.mark.slow  # real solvers

REPO = Path(__file__).resolve().parents[1]
LIMIT = 4500.0  # N: about half the samples' peak pin force is above it


def scene_text(rtol: float = 1e-7, atol: float = 1e-10, requirement: bool = True) -> str:
    """configs/slider-crank-flores.toml cut to 6 ms, 24 samples, with a pin-force limit."""
    keys = {"t_end": "0.006", "count": "24", "rtol": repr(rtol), "atol": repr(atol)}
    replaced = {key: f"{key} = {value}" for key, value in keys.items()}
    lines = with_lines(config_text("slider-crank-flores.toml"), replaced).splitlines()
    if requirement:
        lines += [
            "[[requirement]]",
            'name = "pin-force"',
            'output = "peak_contact_force"',
            'select = { joint = "B" }',
            f"max = {LIMIT!r}",
        ]
    # float64 histories, as test_radau's runs of this mechanism: its rk45 lane module
    # compiles once for both (the checks read per-sample values)
    lines += ["[storage]", 'history_dtype = "float64"']
    return "\n".join(lines) + "\n"


def run_of(folder: Path, name: str, text: str) -> Path:
    scene = folder / f"{name}.toml"
    scene.write_text(text, encoding="utf-8")
    return plan.start_run(scene, run_dir=folder / name, progress=False).folder


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames or ()) == CHECK_COLUMNS
        return list(reader)


def test_spread_indices__even_over_the_run() -> None:
    assert list(spread_indices(100, 5)) == [0, 25, 50, 74, 99]
    assert list(spread_indices(4, 64)) == [0, 1, 2, 3]
    assert list(spread_indices(10, 1)) == [0]


def test_check__tighten_1_reproduces_and_10_equals_a_tighter_run(tmp_path: Path) -> None:
    folder = run_of(tmp_path, "run", scene_text())
    before = digest(folder / "ensemble.nc")

    same = check_run(folder, 1, samples=8)
    (row,) = read_rows(same.csv)
    assert row["requirement"] == "pin-force" and row["samples"] == "8" and row["flips"] == "0"
    assert float(row["abs_diff_max"]) == 0.0 and float(row["rel_diff_max"]) == 0.0

    result = check_run(folder, 10, samples=8)
    assert result.changed == "rtol 1e-07 -> 1e-08, atol 1e-10 -> 1e-11"
    spread = spread_indices(24, 8)
    tight_run = run_of(tmp_path, "tight", scene_text(rtol=1e-8, atol=1e-11))
    with (
        runs.open_run(folder) as ds,
        runs.open_run(tight_run) as ref,
        xr.open_dataset(result.values) as tight,
    ):
        index = tight["sample"].values  # the spread samples, then those near the limit
        assert set(spread) <= set(index.tolist())
        base = ds["peak_contact_force"].sel(joint="B").values[index]
        expected = ref["peak_contact_force"].sel(joint="B").values[index]
        np.testing.assert_array_equal(tight["peak_contact_force"].sel(joint="B").values, expected)
    (row,) = read_rows(result.csv)
    assert int(row["samples"]) == index.size and int(row["near"]) == index.size - 8
    diff = np.abs(expected - base)
    assert int(row["flips"]) == int(np.sum((base <= LIMIT) != (expected <= LIMIT)))
    assert float(row["abs_diff_median"]) == np.median(diff)
    assert float(row["abs_diff_max"]) == np.max(diff) > 0
    assert float(row["rel_diff_max"]) == np.max(diff / np.abs(base))
    assert float(row["tighten"]) == 10.0
    assert digest(folder / "ensemble.nc") == before  # the run is untouched


def test_check__without_requirements_a_row_per_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = run_of(tmp_path, "run", scene_text(requirement=False))
    assert main(["check", str(folder), "--tighten", "10", "--samples", "4"]) == 0
    out = capsys.readouterr().out
    assert "10x tighter" in out and "peak_contact_force" in out
    rows = {r["requirement"]: r for r in read_rows(folder / "export" / "check.csv")}
    assert {"peak_contact_force", "max_penetration", "impact_count"} <= set(rows)
    assert all(math.isnan(float(r["flips"])) and r["samples"] == "4" for r in rows.values())


def test_check__refusals_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    static = tmp_path / "static.toml"
    static.write_text(
        (REPO / "configs" / "clearance-sweep.toml").read_text(encoding="utf-8"), encoding="utf-8"
    )
    folder = plan.start_run(static, samples=4, run_dir=tmp_path / "static", progress=False).folder
    capsys.readouterr()  # the run's own lines (a cold cache's compile notice): not the check's
    for argv, message in [
        (["check", str(folder), "--tighten", "10"], "no [simulate]"),
        (["check", str(folder), "--tighten", "0.5"], "--tighten: must be a number >= 1"),
        (["check", str(tmp_path / "nope"), "--tighten", "10"], "no such run folder"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err, err
    assert not (folder / "check").exists() and not (folder / "export").exists()


def test_tightened_scene__dt_for_fixed_steps_tolerances_for_adaptive() -> None:
    from test_runs_extend import scene_text as rk4_text

    from mcchain.decision.check import tightened_scene
    from mcchain.scene import load_scene_text

    fixed, said = tightened_scene(load_scene_text(rk4_text("random")), 10)
    assert fixed.simulate.dt == 1e-5 and said == "dt 0.0001 -> 1e-05 s"
    assert fixed.simulate.output_dt == 1e-3 and fixed.simulate.t_end == 0.02
    adaptive, said = tightened_scene(load_scene_text(scene_text()), 10)
    assert (adaptive.simulate.rtol, adaptive.simulate.atol) == (1e-8, 1e-11)
    assert adaptive.simulate.dt == 1e-7  # the first step of rk45 is left as written
