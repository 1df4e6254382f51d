"""``report/index.html`` as a reader gets it: one file that carries its figures, the answer
first with units, provenance, model-form notes, and the same page in a real browser
(headless Chromium: its DOM, a screenshot and a printout).

The runs are the pinned bar of :mod:`test_decision_closed_form` (statics, exact P(fail) 2 %),
once with a fixed count and once with ``until = "decided"``; the model-form notes are
checked on a hand-made ensemble whose shares and peak times are known exactly.
"""

from __future__ import annotations

import base64
import io
import json
import math
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from PIL import Image
from test_decision_closed_form import pinned_bar_text, run_pinned_bar

from mcchain.decision.summary import allocations, interval_name, summarize
from mcchain.ensemble.units import (
    in_reading_unit,
    interval_with_units,
    reading_unit,
    with_units,
)
from mcchain.runner.runs import open_run
from mcchain.scene.study import Requirement
from mcchain.testing import browser
from mcchain.viz import report_modelform, report_outputs
from mcchain.viz.report import Report
from mcchain.viz.report_page import index_html

SAMPLES = 600
C0 = (31, 119, 180)  # matplotlib's first colour: the figures' curves and points
VERDICT_BORDERS = {(0x2C, 0x8A, 0x2C), (0xC0, 0x20, 0x20), (0xC0, 0x80, 0x00)}


# -- units ----------------------------------------------------------------------------------------
def test_reading_unit__the_documented_rules() -> None:
    assert reading_unit("m", 2.4e-4) == ("mm", 1e3)
    assert reading_unit("m", 5e-5) == ("mm", 1e3)  # clearances read in mm
    assert reading_unit("m", 5e-7) == ("nm", 1e9)
    assert reading_unit("m", 0.2) == ("m", 1.0)
    assert reading_unit("N", 5000.0) == ("kN", 1e-3)
    assert reading_unit("N", 2e6) == ("MN", 1e-6)
    assert reading_unit("N", 999.0) == ("N", 1.0)
    assert reading_unit("N m", 1500.0) == ("kN m", 1e-3)
    assert reading_unit("rad s-1", 62.8) == ("Hz", 1.0 / (2.0 * math.pi))
    assert reading_unit("s", 1.2e-3) == ("ms", 1e3)
    assert reading_unit("s", 2.0) == ("s", 1.0)
    assert reading_unit("Pa", 2.07e11) == ("GPa", 1e-9)
    assert reading_unit("1", 3.0) == ("", 1.0)
    assert reading_unit("kg m2", 0.1) == ("kg m²", 1.0)
    assert reading_unit("m", math.nan) == ("m", 1.0)  # no size: SI


def test_with_units__reading_value_with_si_beside() -> None:
    assert with_units(5000.0, "N") == "5 kN (5000 N)"
    assert with_units(2.39912e-05, "m", magnitude=4e-4) == "0.02399 mm (2.39912e-05 m)"
    assert with_units(2.39912e-05, "m") == "0.02399 mm (2.39912e-05 m)"
    assert with_units(2 * math.pi * 10.0, "rad s-1") == "10 Hz (62.8319 rad/s)"
    assert with_units(12.0, "N") == "12 N"  # already in its reading unit: once
    assert with_units(0.9, "1") == "0.9"
    assert with_units(math.nan, "N") == "NaN"
    assert in_reading_unit(5000.0, "N") == "5 kN" and in_reading_unit(0.9, "1") == "0.9"
    assert interval_with_units(16302.9, 13304.7, 19014.3, "N") == (
        "16.3 [13.3, 19.01] kN (16302.9 [13304.7, 19014.3] N)"
    )
    assert interval_with_units(38517.1, 34426.5, math.nan, "N") == (
        "38.52 [34.43, —] kN (38517.1 [34426.5, —] N)"
    )


# -- the page of a run ----------------------------------------------------------------------------
class Page(HTMLParser):
    """What a reader (and a mail client) meets in a page: text by section, headings, images,
    inline SVGs, links, scripts and external resources."""

    def __init__(self) -> None:
        super().__init__()
        self.title = ""
        self.headings: list[str] = []
        self.images: list[str] = []
        self.svgs = 0
        self.links: list[str] = []
        self.external: list[str] = []
        self.scripts = 0
        self.answers: list[str] = []
        self.text: list[str] = []
        self._in: list[str] = []
        self._answer = -1

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.images.append(a.get("src") or "")
            return
        self._in.append(tag)
        if tag == "svg":
            self.svgs += 1
        if tag == "script":
            self.scripts += 1
        if tag in ("link", "iframe", "object", "embed"):
            self.external.append(tag)
        if tag == "a":
            self.links.append(a.get("href") or "")
        if tag == "p" and "answer" in (a.get("class") or ""):
            self.answers.append("")
            self._answer = len(self._in)

    def handle_endtag(self, tag: str) -> None:
        while self._in and self._in.pop() != tag:
            pass
        if len(self._in) < self._answer:
            self._answer = -1

    def handle_data(self, data: str) -> None:
        if not self._in or not data.strip():
            return
        if self._in[-1] == "title":
            self.title = data.strip()
        if self._in[-1] in ("h1", "h2", "h3"):
            self.headings.append(data.strip())
        if self._answer > 0:
            self.answers[-1] += data
        if "svg" not in self._in and "style" not in self._in:
            self.text.append(data.strip())


def parse(path: Path) -> Page:
    page = Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


@pytest.fixture(scope="module")
def reported_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return run_pinned_bar(tmp_path_factory.mktemp("page"), SAMPLES, ["report"])


@pytest.fixture(scope="module")
def until_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The pinned bar (P(fail) 2 %, target 1 %) in batches of 500 until decided."""
    folder = tmp_path_factory.mktemp("until")
    text = pinned_bar_text(500).replace("count = 500", 'count = 500\nuntil = "decided"')
    assert 'until = "decided"' in text
    (folder / "bar.toml").write_text(text.replace("[sample]", "[sample]\nmax_count = 20000"))
    from mcchain.cli import main

    runs = folder / "runs"
    assert main(["run", str(folder / "bar.toml"), "--out", str(runs), "--quiet"]) == 0
    (run,) = runs.iterdir()
    assert main(["report", str(run)]) == 0
    return run


def test_page__carries_every_figure_and_needs_nothing_else(reported_run: Path) -> None:
    """Mailed alone it loses nothing: every image is a PNG data URI that decodes, the
    decision figures are inline SVG, no script, stylesheet link or frame, links only to
    its own sections."""
    page = parse(reported_run / "report" / "index.html")
    assert page.scripts == 0 and page.external == []
    assert page.images, "no PNG figure"
    for src in page.images:
        assert src.startswith("data:image/png;base64,"), src[:40]
        with Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1]))) as img:
            assert img.format == "PNG" and img.size[0] > 300
    assert page.svgs == 2  # requirements.svg, status_counts.svg
    assert page.links and all(href.startswith("#") for href in page.links)


def test_page__titled_after_the_scene_and_its_question(reported_run: Path) -> None:
    page = parse(reported_run / "report" / "index.html")
    ds = open_run(reported_run)
    limit = in_reading_unit(summarize(ds)[0].limit, "rad s-1")
    expected = f"{ds.attrs['scene_name']}: omega[mode=0] ≤ {limit} in 99 % of instances?"
    assert page.title == expected and page.headings[0] == expected
    assert reported_run.name not in page.title


def test_page__the_answer_comes_first_in_one_sentence_with_units(reported_run: Path) -> None:
    page = parse(reported_run / "report" / "index.html")
    assert page.headings[1] == "Answer"
    (answer,) = page.answers
    ds = open_run(reported_run)
    (s,) = summarize(ds)
    assert s.decision == "fail"  # 2 % against a target of 1 %, 600 samples
    assert answer.startswith("pulsation: FAIL.")
    limit = with_units(s.limit, "rad s-1")
    assert f"omega[mode=0] ≤ {limit} fails in {s.failures} of {SAMPLES} samples" in answer
    name = interval_name(s)  # the decision layer's name, quoted, never written here
    assert name == "95 % bounds (each one-sided; together a 90 % interval)"
    p = f"P(fail) = {100 * s.p_fail:.3g} % ({name}: {100 * s.p_lower:.3g} %–"
    assert p + f"{100 * s.p_upper:.3g} %), beyond the target 1 %." in answer
    (row,) = allocations(ds)  # J cut from below: large J lowers p
    low = with_units(row.low, "kg m2", magnitude=0.5)
    assert row.side == "lower"
    if row.meets_target:
        assert f"Binding parameter: inertia bar ≥ {low} keeps" in answer
        assert f"({row.samples_kept} of {SAMPLES} samples kept)" in answer
    else:  # 600 samples: the bound over every cut tried stays just above the target
        assert f"the nearest is inertia bar (its best range, inertia bar ≥ {low}, keeps " in answer
        assert f"{row.samples_kept} samples and P(fail) ≤ {100 * row.p_upper:.3g} %)" in answer


def test_page__provenance_from_run_json_and_the_settings(reported_run: Path) -> None:
    record = json.loads((reported_run / "run.json").read_text())
    text = " ".join(parse(reported_run / "report" / "index.html").text)
    assert record["git"]["commit"] in text
    assert record["host"]["name"] in text and record["start"] in text
    assert f"mcchain {record['versions']['mcchain']}" in text
    assert f"random, {SAMPLES} samples, seed 11" in text
    assert "[modes]" in text
    assert "The run printed no warning and no note." in text
    assert "mcchain check" in text  # no check.csv: how to run it


def test_page__every_warning_the_run_printed_and_the_check(
    reported_run: Path, tmp_path: Path
) -> None:
    run = Path(shutil.copytree(reported_run, tmp_path / "run"))
    record = json.loads((run / "run.json").read_text())
    record["warnings"] = ["body bar: the written position moved by 1.5 mm to assemble"]
    record["notes"] = ["kernels: loop kernels for a short run"]
    (run / "run.json").write_text(json.dumps(record))
    (run / "export").mkdir(exist_ok=True)
    (run / "export" / "check.csv").write_text(
        "requirement,samples,flips,abs_diff_median\npulsation,64,0,1.234567e-09\n"
    )
    html = index_html(run, open_run(run), run / "report", Report())
    page = Page()
    page.feed(html)
    text = " ".join(page.text)
    assert "The run printed 1 warning: see Provenance" in text
    assert "warning: body bar: the written position moved by 1.5 mm to assemble" in text
    assert "note: kernels: loop kernels for a short run" in text
    assert "pulsation 64 0 1.235e-09" in text  # the check's row, numbers to 4 digits


def test_page__an_until_run_names_its_sequential_interval(until_run: Path) -> None:
    page = parse(until_run / "report" / "index.html")
    text = " ".join(page.text)
    (s,) = summarize(open_run(until_run))
    assert s.sequential and interval_name(s).startswith("95 % sequential bounds")
    assert f"({interval_name(s)}: " in page.answers[0]
    assert "Clopper" not in text  # neither in the answer nor in the tables
    assert "until decided: batches of 500" in text


def test_outputs_table__any_per_sample_variable_with_its_own_units() -> None:
    """A variable the registry does not know (a scene's ``[[output]]``) is shown from its own
    attributes; −1 of an integer output is "not applicable"; histories are not outputs."""
    n = 101
    gap = np.linspace(0.0, 5e-5, n)  # m, below 0.1 m: read in mm
    gap_attrs = {"units": "m", "long_name": "largest pin gap"}
    ds = xr.Dataset(
        {
            "pin_gap": (("sample", "joint"), np.column_stack([gap, np.full(n, np.nan)]), gap_attrs),
            "impact_count": (("sample", "joint"), np.tile([[3, -1]], (n, 1)).astype(np.int32)),
            "energy": (("sample", "time"), np.ones((n, 2))),
            "status": (("sample",), np.zeros(n, dtype=np.uint32)),
        },
        coords={"sample": np.arange(n), "joint": ["B", "C"], "time": [0.0, 1.0]},
    )
    assert report_outputs.per_sample_outputs(ds) == ["pin_gap", "impact_count"]
    page = Page()
    page.feed(report_outputs.outputs_table(ds))
    text = " ".join(page.text)
    median = with_units(2.5e-5, "m", magnitude=5e-5)
    assert median == "0.025 mm (2.5e-05 m)"
    assert f"pin_gap[B] largest pin gap m {median}" in text
    assert "pin_gap[C]" not in text and "impact_count[C]" not in text  # no value left
    assert "impact_count[B]" in text and f"3 of {n}" not in text and f"{n} of {n}" in text


# -- model form -----------------------------------------------------------------------------------
def _contact_ensemble() -> xr.Dataset:
    """Two samples, one joint B with a contact law, stored every 1 ms to t = 0.1 s.

    Sample 0: link to 0.05 s, then contact to the end; its force peaks at t = 2 ms (a
    start-up peak) at 100 N, whose continuous peak is 125 N. Sample 1: link to 0.04 s,
    free flight to 0.06 s, contact after; its force peaks at t = 60 ms at 80 N (= its
    continuous peak)."""
    time = np.round(np.arange(101) * 1e-3, 12)
    mode = np.zeros((2, 101, 1), dtype=np.int8)
    mode[0, 50:, 0] = 1
    mode[1, 40:60, 0] = 2
    mode[1, 60:, 0] = 1
    force = np.full((2, 101, 1), 10.0, dtype=np.float32)
    force[0, 2, 0], force[1, 60, 0] = 100.0, 80.0
    return xr.Dataset(
        {
            "contact_mode": (("sample", "time", "joint"), mode),
            "contact_force": (("sample", "time", "joint"), force, {"units": "N"}),
            "peak_contact_force": (("sample", "joint"), [[125.0], [80.0]], {"units": "N"}),
            "free_flight_time": (("sample", "joint"), [[0.0], [0.02]], {"units": "s"}),
            "first_separation_time": (("sample", "joint"), [[np.nan], [0.0395]]),
            "impact_count": (("sample", "joint"), np.array([[0], [1]], dtype=np.int32)),
        },
        coords={"sample": [0, 1], "time": time, "joint": ["B"]},
    )


def test_modelform__shares_of_samples_and_time_on_each_model() -> None:
    ds = _contact_ensemble()
    note = re.sub(r"<[^>]+>", "", report_modelform.joint_note(ds, 0, "auto"))
    # stored points (101 per sample): link (50 + 40)/202, contact (51 + 41)/202, free 20/202
    assert "2 of 2 samples were in contact and 1 flew free" in note
    assert f"on the link {100 * 90 / 202:.3g} %, in contact {100 * 92 / 202:.3g} %" in note
    assert f"free {100 * 20 / 202:.3g} % (stored points)" in note
    assert "free flight 10 % (continuous)" in note  # mean(0, 0.02) / 0.1 s
    assert "1 samples left the link, first at 39.5 ms (0.0395 s); 1 had impacts." in note


def test_modelform__a_peak_in_the_first_5_percent_is_a_start_up_peak() -> None:
    ds = _contact_ensemble()
    requirement = Requirement(
        name="force", output="peak_contact_force", select={"joint": "B"}, max=90.0
    )
    found = report_modelform.peak_times(ds, requirement)
    assert not isinstance(found, str)
    np.testing.assert_allclose(found.time, [0.002, 0.060])
    assert found.window == pytest.approx(0.005)
    np.testing.assert_allclose(found.stored_ratio, [0.8, 1.0])
    np.testing.assert_array_equal(found.mode, [0, 1])  # link at 2 ms, contact at 60 ms
    failed = np.array([True, False])  # 125 N > 90 N
    note = re.sub(r"<[^>]+>", "", report_modelform.peak_note(ds, requirement, failed))
    assert "(t ≤ 5 ms (0.005 s), the first 5 % of the run) in 1 of 2 samples" in note
    assert "and 1 of the 1 failing ones" in note
    assert "Most failures come from a start-up peak" in note
    assert "on the link model in 1 samples (1 failing), under the contact law in 1" in note
    assert "90 % of the continuous peak in the median sample (lowest 80 %)" in note
    omega = Requirement(name="w", output="omega", select={"mode": 0}, max=1.0)
    assert report_modelform.peak_times(ds, omega) == (
        "omega is not the peak of a stored history: no time to locate"
    )


# -- in a real browser ----------------------------------------------------------------------------
needs_chromium = pytest.mark.skipif(
    browser.chromium() is None,
    reason="chromium is not installed (Debian: apt-get install chromium; .ci/run installs it)",
)


@needs_chromium
def test_browser__dom_as_chromium_parsed_it(reported_run: Path) -> None:
    dom = browser.dump_dom(reported_run / "report" / "index.html")
    sections = [m.group(1) for m in re.finditer(r'<section id="([a-z-]+)"', dom)]
    assert sections[:2] == ["answer", "requirements"] and sections[-1] == "provenance"
    assert len(re.findall(r"<svg\b", dom)) == 2  # inline SVG parsed as SVG elements
    assert len(re.findall(r"<text\b", dom)) > 20  # their text stays text
    assert dom.count('src="data:image/png;base64,') >= 1 and "<script" not in dom
    assert re.search(r'<p class="answer fail"><b class="fail">pulsation: FAIL\.</b>', dom)


@needs_chromium
def test_browser__screenshot_shows_the_answer_and_the_figures(
    reported_run: Path, tmp_path: Path
) -> None:
    png = browser.screenshot(reported_run / "report" / "index.html", tmp_path / "page.png")
    with Image.open(png) as img:
        assert img.size == (1280, 2000)
        pixels = np.asarray(img.convert("RGB"))
    flat = pixels.reshape(-1, 3)
    white = (flat == 255).all(axis=1).mean()
    assert 0.5 < white < 0.97, f"{white:.1%} white"  # not blank, not a wall of colour
    colours = {tuple(int(c) for c in p) for p in np.unique(flat, axis=0)}
    assert colours & VERDICT_BORDERS, "the answer's verdict border is not drawn"
    curve = (np.abs(flat.astype(int) - C0).sum(axis=1) <= 6).sum()
    assert curve > 200, f"only {curve} pixels of the figures' blue: figures not rendered"


@needs_chromium
def test_browser__prints_to_pdf_pages(reported_run: Path, tmp_path: Path) -> None:
    pdf = browser.print_pdf(reported_run / "report" / "index.html", tmp_path / "page.pdf")
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF")
    pages = len(re.findall(rb"/Type\s*/Page[^s]", data))
    assert pages >= 2, pages
