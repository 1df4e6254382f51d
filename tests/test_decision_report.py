"""What a run with requirements gives a reader: ``requirements.png`` (its bins against the
closed form, zero-failure bins as upper bounds), ``mcchain show --failed`` and the export's
refusals (the page: ``test_viz_report_page.py``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import Ran, assert_usage_error
from test_decision_closed_form import J_HIGH, J_LOW, LIMIT, A, M, pinned_bar_text, run_pinned_bar

from mcchain.testing.closed_forms import bar_pulsation, pinned_bar_exceedance
from mcchain.viz.report_requirements import binned_failure, exceedance

SAMPLES = 600


@pytest.fixture(scope="module")
def reported_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return run_pinned_bar(tmp_path_factory.mktemp("reported"), SAMPLES, ["report"])


def test_requirements_png__drawn(reported_run: Path) -> None:
    png = reported_run / "report" / "requirements.png"
    assert png.stat().st_size > 10_000


def test_requirements_png__zero_failure_bins_are_upper_bounds_on_a_log_axis(
    reported_run: Path,
) -> None:
    """P(fail) by parameter on a log axis: a bin without a failure is drawn as its one-sided
    upper bound 1 − (1 − C)^(1/n), not as a point at 0; the bound is the success-run figure
    turned around (299 failure-free samples show P(fail) <= 1 % at 95 %: 298.07 rounded up)."""
    from mcchain.runner.runs import open_run
    from mcchain.viz.report_requirements import requirements_figure

    x = np.arange(600.0)
    _, _, _, hi, _, count = binned_failure(x, np.zeros(600, dtype=bool), 0.95)
    np.testing.assert_allclose(hi, 1.0 - 0.05 ** (1.0 / count))  # the closed form at k = 0
    _, _, _, hi, _, _ = binned_failure(np.arange(299.0), np.zeros(299, dtype=bool), 0.95)
    assert hi[0] > 0.01  # 12 bins of ~25: each bound is far above the 1 % of 299 together
    fig = requirements_figure(open_run(reported_run))
    assert not isinstance(fig, str)
    exceedance_ax, inertia_ax = fig.axes[:2]
    assert exceedance_ax.get_yscale() == inertia_ax.get_yscale() == "log"
    (bounds,) = [line for line in inertia_ax.get_lines() if line.get_marker() == "v"]
    # 600 samples in 12 equal-count bins of 50; failures (J < 0.059) only in the first
    np.testing.assert_allclose(bounds.get_ydata(), 1.0 - 0.05 ** (1.0 / 50))
    assert len(bounds.get_ydata()) == 11
    assert inertia_ax.get_xlabel() == "inertia bar [kg m²]"
    assert exceedance_ax.get_xlabel() == "omega[mode=0] [Hz]"


def test_exceedance__shares_and_nan_beyond() -> None:
    values = np.array([1.0, 2.0, 3.0, math.nan])
    x, share, lo, hi = exceedance(values, "max", 0.95)
    assert share[x == 1.0][0] == 3 / 4  # 2, 3 and the NaN are beyond 1
    assert share[x == 3.0][0] == 1 / 4  # only the NaN
    assert np.all(lo <= share) and np.all(share <= hi)
    x, share, _, _ = exceedance(values, "min", 0.95)
    assert share[x == 1.0][0] == 1 / 4


def test_binned_failure__pinned_bar_bins_against_exact() -> None:
    """Closed-form samples: each bin's interval holds the exact conditional P(fail) of its
    J range in most bins (coverage is per bin, so not all)."""
    rng = np.random.default_rng(5)
    J = rng.uniform(J_LOW, J_HIGH, 24_000)
    failed = bar_pulsation(M, J, A) > LIMIT
    _, p, lo, hi, edges, _ = binned_failure(J, failed, 0.95)
    J_star = J_LOW + float(pinned_bar_exceedance(LIMIT, M, A, J_LOW, J_HIGH)) * (J_HIGH - J_LOW)
    exact = np.clip((J_star - edges[:-1]) / (edges[1:] - edges[:-1]), 0.0, 1.0)
    assert np.sum((lo <= exact) & (exact <= hi)) >= len(exact) - 1
    assert p[0] > 0 and np.all(p[1:] == 0)


def test_show__failed_picks_the_farthest_failures(
    mcchain: Callable[..., Ran], reported_run: Path, tmp_path: Path
) -> None:
    import mcchain as mc

    ran = mcchain(
        "show", str(reported_run), "--failed", "pulsation", "--limit", "2",
        "--save", str(tmp_path / "f.rrd"), cwd=tmp_path,
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    shown = [int(s) for s in ran.stdout.splitlines()[0].removeprefix("samples ").split(",")]
    J = mc.open_run(reported_run)["parameters"].values[:, 0]
    assert shown == list(np.argsort(J)[:2])  # smallest J: largest p, farthest past the limit
    bad = mcchain("show", str(reported_run), "--failed", "other", cwd=tmp_path)
    assert_usage_error(bad, "--failed: no requirement 'other' in the run (requirements: pulsation)")


def test_export__requirements_refused_without_requirements(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    text = pinned_bar_text(8)
    text = text[: text.index("[[requirement]]")]
    (tmp_path / "bar.toml").write_text(text)
    ran = mcchain("run", "bar.toml", "--out", "runs", cwd=tmp_path)
    run = ran.stdout.strip().splitlines()[-1]
    assert_usage_error(
        mcchain("export", run, "--requirements", cwd=tmp_path),
        "the run has no [[requirement]]",
    )
