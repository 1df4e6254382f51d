"""``report/index.html``: one self-contained page a designer can put in a design review, and
the ``mcchain report`` command that writes it with the figures.

The page carries its figures (inline SVG or PNG data URIs: :mod:`mcchain.viz.page`), needs
no script, no server and no network, and prints (print CSS: A4, no navigation, figures
never split). It reads top to bottom as a review does:

1. **Answer** — one sentence per requirement (:mod:`mcchain.viz.report_answer`);
2. **Requirements** — the numbers behind it, the tolerance allocation, ``requirements`` figure;
3. **Model form** — which joint model the results rest on, start-up peaks
   (:mod:`mcchain.viz.report_modelform`);
4. **Ensemble** — sampled parameters (in reading units), every per-sample output
   (:mod:`mcchain.viz.report_outputs`), status counts, every other figure with a line on
   what it shows;
5. **Provenance** — version, commit, date, host, method and tolerances, design and count,
   what the run printed, the numerical check, the scene file
   (:mod:`mcchain.viz.report_provenance`).

The page is titled after the scene and its question, not after the run folder.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.decision.requirements import requirement_values, stored_requirements
from mcchain.decision.summary import allocations, met_of, summarize
from mcchain.ensemble.describe import stored_settings
from mcchain.ensemble.io import write_text_atomic
from mcchain.ensemble.units import pretty_units, with_units
from mcchain.viz.figures import VECTOR_FIGURES
from mcchain.viz.page import embedded, esc, table
from mcchain.viz.report import Report, make_report
from mcchain.viz.report_answer import Units, answer_section, percent, requirement_tables
from mcchain.viz.report_modelform import modelform_section
from mcchain.viz.report_outputs import outputs_table
from mcchain.viz.report_provenance import provenance_section, read_record

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.decision.summary import RequirementSummary

INDEX = "index.html"
DECISION_FIGURES = ("requirements",)
"""Figures shown with the requirements (the others follow with the ensemble)."""

CAPTIONS = {
    "requirements": "Per requirement: the exceedance curve of the output (share of samples "
    "beyond x, log scale) with its confidence band, the limit (dashed) and the target "
    "(dotted); then P(fail) against each sampled parameter in equal-count bins on a log axis: "
    "bins with failures between their exact one-sided bounds at the requirement's confidence, "
    "bins without a failure as their upper bound (▽), and the allocated bound (green; the kept "
    "side unshaded).",
    "omega_histogram": "Histogram of each eigenpulsation, in rad/s and Hz.",
    "modes_along_cycle": "Natural frequencies along one turn of the driver, against the "
    "drive's harmonics.",
    "scatter_peak_contact_force": "Peak contact force of each clearance joint against "
    "each sampled parameter, with binned medians.",
    "scatter_impact_count": "Impacts at each joint with a contact law against each sampled "
    "parameter.",
    "journal_orbit": "The journal's orbit in its clearance circle for the samples with the "
    "largest peaks: on the link, free, in contact.",
    "reaction_envelopes": "Joint reactions over time: median and 5–95 % band over the "
    "samples at the stored points, with the continuous per-sample peaks.",
    "contact_loss": "Share of samples that lost contact by time t, and the time of loss "
    "against each sampled parameter.",
    "status_counts": "How many samples carry each status flag.",
    "sobol": "Sobol' sensitivity indices of the results to the sampled parameters.",
}
"""What each figure shows, one line each (``scatter_<result>`` has a pattern)."""

STYLE = """
body { font-family: system-ui, sans-serif; max-width: 75em; margin: 1em auto; padding: 0 1em;
       color: #111; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; }
.sub { color: #555; margin-top: 0; }
nav { font-size: 0.9em; margin: 0.5em 0 1em; } nav a { margin-right: 1em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.92em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: left; vertical-align: top; }
table.facts th { text-align: left; background: #f4f4f4; } table.facts td { text-align: left; }
.pass { color: #176117; } .fail { color: #a01010; } .undecided { color: #8a5a00; }
p.answer { color: #111; font-size: 1.1em; border-left: 6px solid #888; padding: 0.4em 0.8em;
           background: #f7f7f7; }
p.answer.pass { border-color: #2c8a2c; } p.answer.fail { border-color: #c02020; }
p.answer.undecided { border-color: #c08000; }
.warn, li.warning { color: #8a3a00; }
.banner { background: #fff4e0; border: 1px solid #e0b060; padding: 0.4em 0.8em; }
figure { margin: 1em 0; break-inside: avoid; page-break-inside: avoid; }
img, .svg svg { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #333; }
pre { background: #f6f6f6; padding: 0.5em; overflow-x: auto; font-size: 0.85em; }
code { font-size: 0.92em; } td small { color: #444; }
@media print {
  @page { size: A4; margin: 14mm; }
  body { max-width: none; margin: 0; padding: 0; font-size: 9.5pt; }
  nav { display: none; }
  h2, h3 { break-after: avoid; page-break-after: avoid; }
  table, p.answer { break-inside: avoid; page-break-inside: avoid; }
  p.answer { background: none; }
  img, .svg svg { border: none; }
  a { color: inherit; text-decoration: none; }
}
"""


def caption(stem: str) -> str:
    """The line under a figure (by file stem)."""
    if stem in CAPTIONS:
        return CAPTIONS[stem]
    if stem.startswith("scatter_"):
        result = stem.removeprefix("scatter_")
        return (
            f"{result} against each sampled parameter: binned median, 5–95 % band and Spearman's ρ."
        )
    return stem


def question(ds: xr.Dataset, summaries: list[RequirementSummary]) -> str:
    """The page's title: the scene and the question its requirements ask (or what the
    ensemble holds)."""
    scene = str(ds.attrs.get("scene_name") or "mcchain run")
    if not summaries:
        analyses = [a for a in ("equilibrium", "modes", "simulate") if a in _analyses(ds)]
        return f"{scene}: {ds.sizes.get('sample', 0)} samples ({', '.join(analyses) or 'none'})"
    units = Units(ds)
    asked = []
    for s in summaries:
        asked.append(
            f"{units.limits(s, reading_only=True)} in {percent(1.0 - s.target)} of instances?"
        )
    return f"{scene}: " + "; ".join(asked)


def _analyses(ds: xr.Dataset) -> list[str]:
    scene = stored_settings(ds).get("scene") or {}
    return [a for a in ("equilibrium", "modes", "simulate") if scene.get(a) is not None]


def _distribution(units: Units, path: str, dist: dict[str, Any]) -> str:
    kind = next((k for k, v in dist.items() if v is not None), "?")
    values = dist.get(kind)
    _, cf, size = units.param(path)
    numbers = values if isinstance(values, list) else [values]
    if kind in ("uniform", "truncnormal", "choice", "normal") and all(
        isinstance(v, int | float) for v in numbers
    ):
        shown = [with_units(float(v), cf, magnitude=size) for v in numbers if v is not None]
        return f"{kind} [{', '.join(shown)}]"
    return f"{kind} {values}"


def ensemble_section(ds: xr.Dataset) -> str:
    """Sampled parameters (in reading units) and status counts."""
    from mcchain.status import counts

    scene = stored_settings(ds).get("scene") or {}
    vary = (scene.get("sample") or {}).get("vary") or {}
    units = Units(ds)
    parts = ['<section id="ensemble"><h2>Ensemble</h2>']
    if vary:
        rows = []
        for path, dist in vary.items():
            if path not in units.paths:
                continue
            name, cf, _ = units.param(path)
            rows.append(
                [
                    f"{esc(name)}<br><code>{esc(path)}</code>",
                    esc(_distribution(units, path, dist)),
                    esc(pretty_units(cf) or "– (dimensionless)"),
                ]
            )
        parts += [
            "<h3>Sampled parameters</h3>",
            table(["parameter", "distribution", "SI units"], rows),
        ]
    else:
        parts.append("<p>No sampled parameters.</p>")
    parts.append(outputs_table(ds))
    if "status" in ds.data_vars:
        found = counts(np.asarray(ds["status"].values))
        rows = [[esc(k), esc(v)] for k, v in found.items() if v or k == "ok"]
        parts += ["<h3>Status counts</h3>", table(["status", "samples"], rows)]
    return "\n".join(parts) + "</section>"


def _figure(path: Path) -> str:
    return (
        f'<figure id="fig-{esc(path.stem)}">{embedded(path)}'
        f"<figcaption><b>{esc(path.stem)}</b>: {esc(caption(path.stem))}</figcaption></figure>"
    )


def figures(
    report: Report, out: Path, stems: tuple[str, ...] | None, exclude: tuple[str, ...] = ()
) -> str:
    """The figures of ``report`` written into ``out`` (those named in ``stems``, or all
    but ``exclude``), each carried inside the page: the SVG of :data:`VECTOR_FIGURES`, else
    the PNG."""
    written = {p.name: p for p in report.written if p.parent.resolve() == out.resolve()}
    parts = []
    for path in report.written:
        if path.suffix != ".png" or path.name not in written:
            continue
        if (stems is not None and path.stem not in stems) or path.stem in exclude:
            continue
        vector = path.with_suffix(".svg")
        shown = vector if path.stem in VECTOR_FIGURES and vector.name in written else path
        parts.append(_figure(shown))
    return "\n".join(parts)


def _banner(record: dict[str, Any]) -> str:
    warnings = record.get("warnings") or []
    if not warnings:
        return ""
    return (
        f'<p class="banner">The run printed {len(warnings)} warning'
        f'{"s" if len(warnings) > 1 else ""}: see <a href="#provenance">Provenance</a>.</p>'
    )


def index_html(
    folder: Path,
    ds: xr.Dataset,
    out: Path,
    report: Report,
    models: list[str | None] | None = None,
) -> str:
    """The page's text (see the module docstring); ``models``: each joint's model
    (:func:`mcchain.viz.contact.joint_models`, default from the data)."""
    summaries = summarize(ds)
    rows = allocations(ds)
    record = read_record(folder)
    title = question(ds, summaries)
    requirements = []
    for requirement in stored_requirements(ds):
        values = requirement_values(ds, requirement)
        requirements.append((requirement, met_of(ds, requirement, values) == 0))
    from mcchain.viz.contact import joint_models

    evidence = requirement_tables(summaries, rows, ds)
    if evidence:
        evidence = evidence.removesuffix("</section>") + figures(report, out, DECISION_FIGURES)
        evidence += "</section>"
    others = figures(report, out, None, exclude=DECISION_FIGURES)
    skipped = ""
    if report.skipped:
        items = "".join(f"<li>{esc(k)}: {esc(v)}</li>" for k, v in report.skipped.items())
        skipped = f"<details><summary>figures not drawn</summary><ul>{items}</ul></details>"
    sections = [
        answer_section(summaries, rows, ds),
        # the what-if section (tolerance choices and their P(fail)) goes here
        evidence,
        modelform_section(ds, models or joint_models(ds), requirements),
        ensemble_section(ds),
        f'<section id="figures"><h2>Figures</h2>{others}{skipped}</section>'
        if others or skipped
        else "",
        provenance_section(folder, ds),
    ]
    nav = " ".join(
        f'<a href="#{key}">{label}</a>'
        for key, label in (
            ("answer", "Answer"),
            ("requirements", "Requirements"),
            ("model-form", "Model form"),
            ("ensemble", "Ensemble"),
            ("figures", "Figures"),
            ("provenance", "Provenance"),
        )
        if f'id="{key}"' in "".join(sections)
    )
    when = str(record.get("end") or record.get("start") or "")[:10]
    sub = (
        f"mcchain {esc(ds.attrs.get('mcchain_version', '?'))} · run "
        f"<code>{esc(Path(folder).name)}</code>" + (f" · {esc(when)}" if when else "")
    )
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f"<title>{esc(title)}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n"
        f'<header><h1>{esc(title)}</h1><p class="sub">{sub}</p>{_banner(record)}'
        f"<nav>{nav}</nav></header>\n"
        + "\n".join(s for s in sections if s)
        + "\n</body>\n</html>\n"
    )


def write_index(
    folder: Path,
    ds: xr.Dataset,
    out: Path,
    report: Report,
    models: list[str | None] | None = None,
) -> Path:
    """Write ``out/index.html`` for the run ``folder``; returns its path."""
    path = Path(out) / INDEX
    write_text_atomic(path, index_html(Path(folder), ds, Path(out), report, models))
    return path


def write_report(run: str | Path, out: str | Path | None = None) -> Report:
    """``mcchain report``: every figure of a run folder (path or id under ``runs/``) into
    ``out`` (default ``RUN/report``) and the page that carries them; the design comes from
    the ensemble's own settings."""
    from mcchain.ensemble.describe import stored_model
    from mcchain.ensemble.histories import not_stored_reason, without_histories
    from mcchain.ensemble.queries import run_design
    from mcchain.errors import McchainError
    from mcchain.runner.runs import open_run, resolve_run, writable_folder

    folder = resolve_run(run)
    ds = open_run(folder)
    target = Path(out) if out else folder / "report"
    writable_folder(target, "--out")
    try:
        model = stored_model(ds)
    except McchainError as err:  # an ensemble without a usable scene: draw what needs none
        import logging

        logging.getLogger(__name__).info("report: the run's model cannot be rebuilt (%s)", err)
        model = None
    report = make_report(ds, target, design=run_design(folder, ds), model=model)
    from mcchain.viz.contact import joint_models

    models = joint_models(ds, model)
    if not_stored_reason(ds) is not None:  # a light run: the page reads per-sample variables
        ds = without_histories(ds)
    report.written.append(write_index(folder, ds, target, report, models))
    return report
