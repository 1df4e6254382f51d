"""``mcchain confirm RUN --requirement NAME``: a new run inside the allocated range, on the
pinned bar (J ~ U[0.05, 0.5] kg m², p > LIMIT fails with P = 2 % exactly), and its
refusals (one line, exit 2, nothing written)."""

from __future__ import annotations

import json
import tomllib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import Ran, assert_usage_error
from test_decision_closed_form import J_HIGH, LIMIT, A, M, pinned_bar_text, run_pinned_bar

from mcchain.testing.closed_forms import pinned_bar_inertia_at

EXIT = {"pass": 0, "fail": 1, "undecided": 4}


@pytest.fixture(scope="module")
def screened(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 4,000-sample run of the pinned bar (seed 11) and its exported allocation."""
    return run_pinned_bar(tmp_path_factory.mktemp("screen"), 4000, ["export", "--requirements"])


def _new_runs(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_dir())


def test_confirm__the_allocated_range_on_fresh_samples(
    mcchain: Callable[..., Ran], screened: Path, tmp_path: Path
) -> None:
    import mcchain as mc

    with open(screened / "export" / "allocation.csv", newline="") as f:
        (row,) = list(__import__("csv").DictReader(f))
    assert row["side"] == "lower" and row["meets_target"] == "True"
    bound = float(row["bound"])
    ran = mcchain(
        "confirm", str(screened), "--requirement", "pulsation", "--out", str(tmp_path / "runs"),
        "--quiet", cwd=tmp_path,
    )  # fmt: skip
    (new,) = _new_runs(tmp_path / "runs")
    assert ran.stdout.strip().splitlines()[-1] == str(new)
    assert f"confirm pulsation inside body.bar.inertia >= {bound:.6g} kg m2" in ran.stdout
    scene = tomllib.loads((new / "scene.toml").read_text())
    assert scene["sample"]["vary"]["body.bar.inertia"] == {"uniform": [bound, J_HIGH]}
    record = json.loads((new / "run.json").read_text())
    assert record["seed"] == 12  # the screening run's 11 + 1
    assert record["confirm"]["ranges"] == {"body.bar.inertia": [bound, J_HIGH]}
    with mc.open_run(new) as ds:  # closed before the next run writes (HDF5 is one-threaded)
        J = ds["parameters"].values[:, 0]
    assert np.all((J >= bound) & (J <= J_HIGH))
    # the verdict on fresh samples; the exit code says it
    j_star = float(pinned_bar_inertia_at(LIMIT, M, A))
    assert (j_star - bound) / (J_HIGH - bound) <= 0.01  # the range is right in truth
    decision = next(w for w in ("PASS", "FAIL", "UNDECIDED") if f": {w}" in ran.stdout)
    assert ran.returncode == EXIT[decision.lower()]
    assert decision != "FAIL"


def test_confirm__a_range_given_with_count_and_seed(
    mcchain: Callable[..., Ran], screened: Path, tmp_path: Path
) -> None:
    ran = mcchain(
        "confirm", str(screened), "--requirement", "pulsation", "--range",
        "body.bar.inertia=0.3:", "--samples", "400", "--seed", "5", "--run-dir",
        str(tmp_path / "c"), "--quiet", cwd=tmp_path,
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr  # no failure above J = 0.3 kg m2: 400 samples pass
    assert "400 fresh samples (given), seed 5" in ran.stdout
    scene = tomllib.loads((tmp_path / "c" / "scene.toml").read_text())
    assert scene["sample"]["vary"]["body.bar.inertia"] == {"uniform": [0.3, J_HIGH]}


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--requirement", "nope"], "--requirement: no requirement 'nope' in the run"),
        (["--requirement", "pulsation", "--parameter", "body.bar.mass"], "--parameter: 'body."),
        (["--requirement", "pulsation", "--box"], "--box: a box needs two or more"),
        (["--requirement", "pulsation", "--range", "body.bar.inertia"], "--range: expected"),
        (["--requirement", "pulsation", "--range", "x=1:2"], "--range: 'x' is not a sampled"),
        (["--requirement", "pulsation", "--range", "body.bar.inertia=0.4:0.3"], "LOW must"),
        (["--requirement", "pulsation", "--range", "body.bar.inertia=1:2"], "cuts nothing"),
        (["--requirement", "pulsation", "--box", "--range", "a=1:2"], "--range: cannot be"),
        (["--requirement", "pulsation", "--samples", "0"], "--samples"),
    ],
)
def test_confirm__bad_input_one_line_exit_2_nothing_written(
    mcchain: Callable[..., Ran], screened: Path, tmp_path: Path, args: list[str], fragment: str
) -> None:
    before = sorted(p.name for p in (screened / "export").iterdir())
    ran = mcchain("confirm", str(screened), *args, "--out", str(tmp_path / "runs"), cwd=tmp_path)
    assert_usage_error(ran, fragment)
    assert not (tmp_path / "runs").exists()
    assert sorted(p.name for p in (screened / "export").iterdir()) == before


def test_confirm__refused_when_no_range_meets_the_target(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    (tmp_path / "bar.toml").write_text(pinned_bar_text(50))
    ran = mcchain("run", "bar.toml", "--out", "runs", "--quiet", cwd=tmp_path)
    run = ran.stdout.strip().splitlines()[-1]
    bad = mcchain("confirm", run, "--requirement", "pulsation", "--out", "more", cwd=tmp_path)
    assert_usage_error(bad, "no allocated range of pulsation meets its target", "best:")
    assert not (tmp_path / "more").exists()
    missing = mcchain("confirm", "nowhere", "--requirement", "pulsation", cwd=tmp_path)
    assert_usage_error(missing, "nowhere: no such run folder")


def _passing_failures_scipy_stats(n: np.ndarray, target: float, confidence: float) -> np.ndarray:
    """passing_failures as first written, on scipy.stats (the reference of the planning)."""
    from scipy import stats

    n = np.asarray(n, dtype=np.int64)
    lo, hi = np.full(n.shape, -1), n.copy()
    while np.any(hi - lo > 1):
        mid = (lo + hi) // 2
        with np.errstate(invalid="ignore"):
            ok = stats.beta.ppf(confidence, mid + 1, np.maximum(n - mid, 1)) <= target
        ok &= mid >= 0
        lo = np.where(ok & (hi - lo > 1), mid, lo)
        hi = np.where(~ok & (hi - lo > 1), mid, hi)
    return lo


def test_confirm_planning__the_counts_scipy_stats_gives_without_importing_it() -> None:
    """The confirming run's count (default_count) and the failures each count may show
    (passing_failures) on scipy.special alone: the integers scipy.stats gives, over the
    planning's counts (the success-run figure to 2^24) and its edges: no failure inside,
    a rate at or above the target (no count passes), counts too small to pass even with
    no failure (−1)."""
    from scipy import stats

    from mcchain.decision.confirm import default_count, passing_failures
    from mcchain.decision.stats import success_run_count

    for target, confidence in ((0.01, 0.95), (0.001, 0.99), (0.05, 0.9), (0.2, 0.5)):
        success = success_run_count(target, confidence)
        counts = np.unique(np.geomspace(1, 1 << 24, 400).astype(np.int64))
        got = passing_failures(counts, target, confidence)
        np.testing.assert_array_equal(
            got, _passing_failures_scipy_stats(counts, target, confidence)
        )
        assert got[counts < success].max() == -1 and got[counts >= success].min() >= 0
        for failures, kept in ((0, 50), (1, 4000), (3, 3000), (7, 2000), (5, 5), (1, 10**6)):
            count, why = default_count(failures, kept, target, confidence)
            rate = failures / kept
            if failures == 0 or rate >= target:
                assert count == success, why
                continue
            plan = np.unique(np.geomspace(success, 1 << 24, 400).astype(np.int64))
            power = stats.binom.cdf(_passing_failures_scipy_stats(plan, target, confidence),
                                    plan, rate)  # fmt: skip
            enough = np.flatnonzero(power >= 0.9)
            assert count == (int(plan[enough[0]]) if enough.size else int(plan[-1])), why
