"""``report/index.html``: one plain page a designer can send (no server, no script).

Sections: the scene and its sampled parameters, the status counts, each requirement's
verdict with its interval, quantile and tolerance allocation, the numerical check
(``RUN/export/check.csv``, written by ``mcchain check``), and every figure of the report
with a line saying what it shows. Images are referenced by file name: the page and its PNG
files travel together as the ``report`` folder.
"""

from __future__ import annotations

import csv
import html
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.decision.summary import (
    AllocationRow,
    RequirementSummary,
    allocations,
    design_of,
    summarize,
    summary_lines,
)
from mcchain.ensemble.io import write_text_atomic

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.viz.report import Report

INDEX = "index.html"
CHECK_CSV = Path("export") / "check.csv"
"""Where ``mcchain check RUN`` leaves its table (relative to the run folder)."""

CAPTIONS = {
    "requirements.png": "Per requirement: the exceedance curve of the output (share of "
    "samples beyond x, log scale) with its confidence band, the limit (dashed) and the target "
    "(dotted); then P(fail) against each sampled parameter in equal-count bins with "
    "Clopper–Pearson intervals and the allocated bound (green; the kept side unshaded).",
    "omega_histogram.png": "Histogram of each eigenpulsation, in rad/s and Hz.",
    "modes_along_cycle.png": "Natural frequencies along one turn of the driver, against the "
    "drive's harmonics.",
    "scatter_peak_contact_force.png": "Peak contact force of each clearance joint against "
    "each sampled parameter, with binned medians.",
    "scatter_impact_count.png": "Impacts at each joint with a contact law against each "
    "sampled parameter.",
    "journal_orbit.png": "The journal's orbit in its clearance circle for the samples with "
    "the largest peaks: on the link, free, in contact.",
    "reaction_envelopes.png": "Joint reactions over time: median and 5–95 % band over the samples.",
    "contact_loss.png": "Share of samples that lost contact by time t, and the time of loss "
    "against each sampled parameter.",
    "status_counts.png": "How many samples carry each status flag.",
    "sobol.png": "Sobol' sensitivity indices of the results to the sampled parameters.",
}
"""What each figure shows, one line each (``scatter_<result>.png`` has a pattern)."""

STYLE = """
body { font-family: sans-serif; max-width: 72em; margin: 1em auto; padding: 0 1em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
.pass { color: #176117; font-weight: bold; } .fail { color: #a01010; font-weight: bold; }
.undecided { color: #8a5a00; font-weight: bold; }
figure { margin: 1em 0; } img { max-width: 100%; border: 1px solid #ddd; }
pre { background: #f6f6f6; padding: 0.5em; overflow-x: auto; }
"""


def caption(name: str) -> str:
    """The line under a figure."""
    if name in CAPTIONS:
        return CAPTIONS[name]
    if name.startswith("scatter_"):
        result = name.removeprefix("scatter_").removesuffix(".png")
        return (
            f"{result} against each sampled parameter: binned median, 5–95 % band and Spearman's ρ."
        )
    return name


def _e(value: Any) -> str:
    return html.escape(str(value))


def _num(x: Any, digits: int = 4) -> str:
    if isinstance(x, float | np.floating):
        return "NaN" if math.isnan(float(x)) else f"{float(x):.{digits}g}"
    return _e(x)


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _scene_section(ds: xr.Dataset) -> str:
    settings = json.loads(str(ds.attrs.get("settings", "{}")))
    scene = settings.get("scene") or {}
    sample = scene.get("sample") or {}
    analyses = [a for a in ("equilibrium", "modes", "simulate") if scene.get(a) is not None]
    facts = [
        ["scene", _e(ds.attrs.get("scene_name", "?"))],
        ["samples", _e(ds.sizes.get("sample", 0))],
        ["seed", _e(ds.attrs.get("seed", "none"))],
        ["design", _e(sample.get("design", "none") if sample else "none (one instance)")],
        ["analyses", _e(", ".join(analyses) or "none")],
        ["mcchain", _e(ds.attrs.get("mcchain_version", "?"))],
    ]
    parts = ["<h2>Scene</h2>", _table(["", "value"], facts)]
    vary = sample.get("vary") or {}
    units = {}
    if "param" in ds.dims and "param_units" in ds.coords:
        units = dict(
            zip(
                [str(p) for p in ds["param"].values],
                [str(u) for u in ds["param_units"].values],
                strict=True,
            )
        )
    if vary:
        rows = []
        for path, dist in vary.items():
            kind = next((k for k, v in dist.items() if v is not None), "?")
            rows.append([_e(path), _e(f"{kind} {dist.get(kind)}"), _e(units.get(path, ""))])
        parts += ["<h3>Sampled parameters</h3>", _table(["path", "distribution", "units"], rows)]
    else:
        parts.append("<p>No sampled parameters.</p>")
    text = str(ds.attrs.get("scene", ""))
    if text:
        parts.append(f"<details><summary>scene file</summary><pre>{_e(text)}</pre></details>")
    return "\n".join(parts)


def _status_section(ds: xr.Dataset) -> str:
    from mcchain.status import counts

    found = counts(np.asarray(ds["status"].values))
    rows = [[_e(k), _e(v)] for k, v in found.items() if v or k == "ok"]
    return "<h2>Status counts</h2>\n" + _table(["status", "samples"], rows)


def _requirement_section(
    summaries: list[RequirementSummary], rows: list[AllocationRow], design: str | None
) -> str:
    if not summaries:
        return "<h2>Requirements</h2>\n<p>The scene has no [[requirement]].</p>"
    table = []
    for s in summaries:
        table.append(
            [
                _e(s.name),
                _e(s.output) + (" ≤ " if s.side == "max" else " ≥ ") + _num(s.limit, 6),
                f'<span class="{s.decision}">{_e(s.verdict)}</span>',
                f"{s.failures} / {s.samples} ({s.undefined} undefined)",
                f"{_num(s.p_fail)} [{_num(s.p_lower)}, {_num(s.p_upper)}]",
                f"{_num(s.target)} at {_num(100 * s.confidence, 3)} %",
                f"{_num(s.quantile, 6)} [{_num(s.quantile_lower, 6)}, {_num(s.quantile_upper, 6)}]",
            ]
        )
    parts = [
        "<h2>Requirements</h2>",
        _table(
            [
                "requirement",
                "limit",
                "verdict",
                "failures / samples",
                "P(fail) [interval]",
                "target at confidence",
                "quantile at the target [interval]",
            ],
            table,
        ),
    ]
    if rows:
        alloc = []
        for r in rows:
            op = "≤" if r.side == "upper" else "≥"
            bound = "none reaches the target" if math.isnan(r.bound) else f"{op} {_num(r.bound, 6)}"
            alloc.append(
                [_e(r.requirement), _e(r.parameter), bound, _e(r.samples_kept), _num(r.p_upper)]
            )
        parts += [
            "<h3>Tolerance allocation</h3>",
            "<p>For each requirement and each sampled parameter alone (the others as "
            "sampled): the widest one-sided range whose upper bound of P(fail) meets the "
            "target. The bound comes from a search over cuts; a run sampled inside it "
            "confirms it at the stated confidence.</p>",
            _table(["requirement", "parameter", "range", "samples kept", "p_upper"], alloc),
        ]
    text = "\n".join(summary_lines(summaries, rows, design))
    parts.append(f"<h3>In words</h3>\n<pre>{_e(text)}</pre>")
    return "\n".join(parts)


def _check_section(folder: Path) -> str:
    path = folder / CHECK_CSV
    if not path.is_file():
        return (
            "<h2>Numerical check</h2>\n<p>Not run: the statistical intervals above do not "
            "include the integrator's error. Run <code>mcchain check "
            f"{_e(folder)} --tighten 10</code> (a subset re-run with 10× tighter tolerances) "
            "and <code>mcchain report</code> again to see how many verdicts flip.</p>"
        )
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader, [])
        rows = [[_e(c) for c in row] for row in reader]
    return (
        "<h2>Numerical check</h2>\n<p>From <code>export/check.csv</code> (<code>mcchain "
        "check</code>): the requirements re-evaluated on a subset re-run with tighter "
        "tolerances, beside the statistical intervals above.</p>\n" + _table(header, rows)
    )


def _figures_section(report: Report, out: Path) -> str:
    parts = ["<h2>Figures</h2>"]
    # the decision first, then the figures in the order the report drew them
    pngs = [p for p in report.written if p.suffix == ".png" and p.parent.resolve() == out.resolve()]
    pngs.sort(key=lambda p: p.name != "requirements.png")
    for path in pngs:
        parts.append(
            f'<figure><img src="{_e(path.name)}" alt="{_e(path.name)}">'
            f"<figcaption><b>{_e(path.name)}</b>: {_e(caption(path.name))}</figcaption></figure>"
        )
    if report.skipped:
        items = "".join(f"<li>{_e(k)}: {_e(v)}</li>" for k, v in report.skipped.items())
        parts.append(f"<details><summary>figures not drawn</summary><ul>{items}</ul></details>")
    return "\n".join(parts)


def index_html(folder: Path, ds: xr.Dataset, out: Path, report: Report) -> str:
    """The page's text."""
    design = design_of(ds)
    summaries = summarize(ds)
    rows = allocations(ds)
    title = f"mcchain run {folder.name}"
    body = [
        f"<h1>{_e(title)}</h1>",
        _scene_section(ds),
        _status_section(ds),
        _requirement_section(summaries, rows, design),
        _check_section(folder),
        _figures_section(report, out),
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{_e(title)}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n"
        + "\n".join(body)
        + "\n</body>\n</html>\n"
    )


def write_index(folder: Path, ds: xr.Dataset, out: Path, report: Report) -> Path:
    """Write ``out/index.html`` for the run ``folder``; returns its path."""
    path = Path(out) / INDEX
    write_text_atomic(path, index_html(Path(folder), ds, Path(out), report))
    return path
