"""Must show: a bar pinned off its centre of mass (a = 0.5 m from it, m = 2 kg) with its
inertia J uniform on [0.05, 0.5] kg m², whose p² = m g a/(J + m a²) makes every answer of
``mcchain export --requirements`` exact (:mod:`mcchain.testing.closed_forms`).

What is tested, for the requirement ``omega`` (mode 0) <= LIMIT (exact P(fail) = 2 %):

* the failures counted equal the closed form's, sample by sample (so p_fail is exact for the
  samples drawn), and the exact P(fail) lies inside [p_lower, p_upper];
* coverage: the 40,000 samples of one ``random`` run are independent draws (sample i is a
  pure function of (seed, i)), so 400 disjoint groups of 100 are 400 independent
  experiments; each one-sided 95 % bound holds the true 2 % in at least 95 % of them, less
  three binomial standard errors of the 400-experiment estimate;
* the 99 % quantile of p is the order statistic of the closed-form p of the samples drawn,
  and its one-sided order-statistic bounds contain the exact quantile;
* the allocation of J: cut from below (large J lowers p); the exact conditional failure
  probability P(fail | J >= bound) lies in (target/2, target]: the bound is safe and not
  far beyond the exact b* = (J* − target J_high)/(1 − target), where the estimate's upper
  bound reaches the target. As the sample count grows the bound converges to b*
  (:func:`test_allocation__converges_to_the_exact_bound`, closed-form samples, no
  mechanism).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import Ran

from mcchain.decision.allocation import allocate
from mcchain.decision.stats import one_sided_bounds, one_sided_bounds_arrays
from mcchain.decision.summary import ALLOCATION_COLUMNS, REQUIREMENT_COLUMNS
from mcchain.testing.closed_forms import (
    bar_pulsation,
    pinned_bar_allocation,
    pinned_bar_exceedance,
    pinned_bar_inertia_at,
    pinned_bar_quantile,
)
from mcchain.testing.factory import bar_scene_dict, toml_text

M, A, J_LOW, J_HIGH = 2.0, 0.5, 0.05, 0.5
P_FAIL = 0.02
LIMIT = float(bar_pulsation(M, J_LOW + P_FAIL * (J_HIGH - J_LOW), A))
TARGET = 0.01
SAMPLES = 40_000
GROUP = 100


def pinned_bar_text(count: int, design: str = "random") -> str:
    doc = bar_scene_dict(
        mass=M,
        sample={
            "count": count,
            "seed": 11,
            "design": design,
            "vary": {"body.bar.inertia": {"uniform": [J_LOW, J_HIGH]}},
        },
        equilibrium=False,
    )
    doc["requirement"] = [
        {"name": "pulsation", "output": "omega", "select": {"mode": 0}, "max": LIMIT}
    ]
    return toml_text(doc)


def read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def run_pinned_bar(folder: Path, count: int, then: list[str]) -> Path:
    """``mcchain run`` of the pinned bar (``count`` samples) in this process, then the
    command ``then`` on the run (``["export", "--requirements"]``); returns the run folder,
    with what both printed in ``printed.txt``."""
    import contextlib
    import io

    from mcchain.cli import main

    (folder / "bar.toml").write_text(pinned_bar_text(count))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        runs = str(folder / "runs")
        assert main(["run", str(folder / "bar.toml"), "--out", runs, "--quiet"]) == 0
        run = Path(out.getvalue().strip().splitlines()[-1])
        assert main([then[0], str(run), *then[1:]]) == 0
    (run / "printed.txt").write_text(out.getvalue())
    return run


@pytest.fixture(scope="module")
def pinned_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One run of the pinned bar and its exported requirement files."""
    return run_pinned_bar(tmp_path_factory.mktemp("pinned"), SAMPLES, ["export", "--requirements"])


def test_closed_form__exact_values_are_consistent() -> None:
    assert float(pinned_bar_exceedance(LIMIT, M, A, J_LOW, J_HIGH)) == pytest.approx(P_FAIL)
    assert float(pinned_bar_inertia_at(LIMIT, M, A)) == pytest.approx(J_LOW + P_FAIL * 0.45)
    q = float(pinned_bar_quantile(1 - P_FAIL, M, A, J_LOW, J_HIGH))
    assert q == pytest.approx(LIMIT, rel=1e-12)


def test_requirements_csv__columns_failures_and_interval(pinned_run: Path) -> None:
    import mcchain as mc

    columns, rows = read_csv(pinned_run / "export" / "requirements.csv")
    assert tuple(columns) == REQUIREMENT_COLUMNS
    (row,) = rows
    J = mc.open_run(pinned_run)["parameters"].values[:, 0]
    exact_fail = bar_pulsation(M, J, A) > LIMIT
    assert int(row["samples"]) == SAMPLES
    assert int(row["failures"]) == int(exact_fail.sum())
    assert int(row["undefined"]) == 0
    assert float(row["p_fail"]) == exact_fail.sum() / SAMPLES
    assert float(row["p_lower"]) <= P_FAIL <= float(row["p_upper"])
    assert row["verdict"] == "fail"  # 2 % against a 1 % target, shown with 40,000 samples
    assert float(row["target"]) == TARGET and float(row["confidence"]) == 0.95


def test_requirement_met__coverage_over_independent_groups(pinned_run: Path) -> None:
    """Each bound is one-sided at C: in >= C of the groups the upper bound is above the true
    2 % and, separately, the lower bound below it; the CSV's bounds are those."""
    import mcchain as mc

    met = mc.open_run(pinned_run)["requirement_met"].values[:, 0]
    failures = (met == 0).reshape(-1, GROUP).sum(axis=1)
    lo, hi = one_sided_bounds_arrays(failures, np.full(failures.size, GROUP), 0.95)
    slack = 3 * math.sqrt(0.95 * 0.05 / failures.size)
    assert float(np.mean(P_FAIL <= hi)) >= 0.95 - slack
    assert float(np.mean(lo <= P_FAIL)) >= 0.95 - slack
    _, (row,) = read_csv(pinned_run / "export" / "requirements.csv")
    bounds = one_sided_bounds(int(row["failures"]), SAMPLES, 0.95)
    assert (float(row["p_lower"]), float(row["p_upper"])) == pytest.approx(bounds, rel=1e-15)


def test_requirements_csv__quantile_against_exact(pinned_run: Path) -> None:
    import mcchain as mc

    _, (row,) = read_csv(pinned_run / "export" / "requirements.csv")
    J = mc.open_run(pinned_run)["parameters"].values[:, 0]
    p = np.sort(bar_pulsation(M, J, A))
    level = 1 - TARGET
    assert float(row["quantile"]) == pytest.approx(p[math.ceil(SAMPLES * level) - 1], rel=1e-12)
    exact = float(pinned_bar_quantile(level, M, A, J_LOW, J_HIGH))
    assert float(row["quantile_lower"]) <= exact <= float(row["quantile_upper"])


def test_allocation_csv__bound_against_exact(pinned_run: Path) -> None:
    columns, rows = read_csv(pinned_run / "export" / "allocation.csv")
    assert tuple(columns) == ALLOCATION_COLUMNS
    (row,) = rows
    assert row["parameter"] == "body.bar.inertia" and row["side"] == "lower"
    bound = float(row["bound"])
    exact_bound = pinned_bar_allocation(LIMIT, TARGET, M, A, J_LOW, J_HIGH)
    J_star = float(pinned_bar_inertia_at(LIMIT, M, A))
    conditional = (J_star - bound) / (J_HIGH - bound)  # exact P(fail | J >= bound)
    assert TARGET / 2 < conditional <= TARGET
    assert bound > exact_bound
    assert float(row["p_upper"]) <= TARGET


def test_run__prints_the_answer_and_export_writes_words(pinned_run: Path) -> None:
    printed = (pinned_run / "printed.txt").read_text()
    assert "requirement pulsation (omega[mode=0] <= " in printed
    assert "FAIL: P(fail) > 0.01 shown" in printed
    text = (pinned_run / "export" / "requirements.txt").read_text()
    assert "body.bar.inertia >= " in text
    assert "exact Clopper-Pearson" in text


def test_allocation__converges_to_the_exact_bound() -> None:
    """Closed-form samples (J uniform, p from the formula): the allocated bound's distance to
    b* shrinks as the sample count grows (the upper bound's margin falls like 1/√n)."""
    rng = np.random.default_rng(2)
    exact_bound = pinned_bar_allocation(LIMIT, TARGET, M, A, J_LOW, J_HIGH)
    gaps = []
    for n in (2_000, 20_000, 200_000):
        J = rng.uniform(J_LOW, J_HIGH, size=n)
        result = allocate(J, bar_pulsation(M, J, A) > LIMIT, TARGET, 0.95, (J_LOW, J_HIGH))
        assert result.side == "lower"
        gaps.append(result.bound - exact_bound)
    assert gaps[2] < gaps[1] < gaps[0]
    assert gaps[2] < 0.002 * (J_HIGH - J_LOW)


def test_sobol_design__interval_labelled_approximate(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    (tmp_path / "bar.toml").write_text(pinned_bar_text(256, design="sobol"))
    ran = mcchain("run", "bar.toml", "--out", "runs", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert "APPROXIMATE for design 'sobol'" in ran.stdout
    run = tmp_path / ran.stdout.strip().splitlines()[-1]
    assert mcchain("export", str(run), "--requirements", cwd=tmp_path).returncode == 0
    _, (row,) = read_csv(run / "export" / "requirements.csv")
    assert row["verdict"].endswith(" (approximate)")
