"""What a run with requirements gives a reader: ``requirements.png``, ``report/index.html``
(parsed with html.parser), ``mcchain show --failed`` and the export's refusals."""

from __future__ import annotations

import math
from collections.abc import Callable
from html.parser import HTMLParser
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


class Page(HTMLParser):
    """Headings, table cells, image sources and figure captions of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.headings: list[str] = []
        self.cells: list[str] = []
        self.images: list[str] = []
        self.captions: list[str] = []
        self.scripts = 0
        self._in: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self._in.append(tag)
        if tag == "img":
            self.images.append(dict(attrs)["src"] or "")
            self._in.pop()
        if tag == "script":
            self.scripts += 1

    def handle_endtag(self, tag: str) -> None:
        while self._in and self._in.pop() != tag:
            pass

    def handle_data(self, data: str) -> None:
        if not self._in or not data.strip():
            return
        if self._in[-1] in ("h1", "h2", "h3"):
            self.headings.append(data.strip())
        elif "td" in self._in:
            self.cells.append(data.strip())
        if "figcaption" in self._in:
            self.captions.append(data.strip())


def test_report_page__sections_verdict_and_figures(reported_run: Path) -> None:
    page = Page()
    page.feed((reported_run / "report" / "index.html").read_text(encoding="utf-8"))
    assert page.scripts == 0
    for heading in ("Scene", "Sampled parameters", "Status counts", "Requirements"):
        assert heading in page.headings
    assert {"Tolerance allocation", "Numerical check", "Figures"} <= set(page.headings)
    assert "body.bar.inertia" in page.cells
    assert "pulsation" in page.cells
    assert any(c.startswith("fail") or c.startswith("undecided") for c in page.cells)
    assert "requirements.png" in page.images and "status_counts.png" in page.images
    for image in page.images:
        assert (reported_run / "report" / image).is_file()
    assert any("exceedance curve" in c for c in page.captions)
    text = (reported_run / "report" / "index.html").read_text(encoding="utf-8")
    assert "mcchain check" in text  # no check.csv: how to run the check


def test_report_page__shows_the_check_table_when_present(reported_run: Path) -> None:
    from mcchain.runner.runs import open_run
    from mcchain.viz.report import Report
    from mcchain.viz.report_page import index_html

    check = reported_run / "export" / "check.csv"
    check.parent.mkdir(exist_ok=True)
    check.write_text("requirement,samples,flips\npulsation,64,0\n")
    try:
        page = Page()
        page.feed(
            index_html(reported_run, open_run(reported_run), reported_run / "report", Report())
        )
        assert page.cells[-3:] == ["pulsation", "64", "0"]
    finally:
        check.unlink()


def test_requirements_png__drawn(reported_run: Path) -> None:
    png = reported_run / "report" / "requirements.png"
    assert png.stat().st_size > 10_000


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
    _, p, lo, hi, edges = binned_failure(J, failed, 0.95)
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
