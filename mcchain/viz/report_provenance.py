"""Provenance of the report page: what made the numbers, and what the run said while making
them.

From ``run.json`` (the run's log): mcchain's version, the git commit (and whether the tree
had changes), the date, the host, threads and scheduler, the kernel compiler, every warning
and note the run printed. From the ensemble's resolved settings: the analyses with their
method and tolerances, the design, count and seed (and, for ``until = "decided"``, the
batches and looks). From ``RUN/export/check.csv`` (``mcchain check``): the numerical check,
or how to run it. The scene file itself, folded.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain.ensemble.describe import stored_settings
from mcchain.ensemble.units import with_units
from mcchain.viz.page import esc, facts, table

if TYPE_CHECKING:
    import xarray as xr

CHECK_CSV = Path("export") / "check.csv"
"""Where ``mcchain check RUN`` leaves its table (relative to the run folder)."""
SIMULATE_KEYS = (
    ("method", ""),
    ("t_end", "s"),
    ("dt", "s"),
    ("output_dt", "s"),
    ("start", ""),
    ("perturb", ""),
    ("rtol", ""),
    ("atol", ""),
    ("baumgarte", "1/s"),
    ("rho_inf", ""),
    ("max_newton", ""),
    ("constraint_tolerance", "m"),
    ("retry_failed", ""),
    ("kernels", ""),
)
"""``[simulate]`` settings the page lists (key, CF units; "" for a number or a name)."""
ONLY_FOR_METHODS = {
    "rho_inf": ("generalized-alpha",),
    "max_newton": ("generalized-alpha", "radau"),
}
"""Settings that only some methods read: the page lists them for those methods alone."""


def read_record(folder: Path) -> dict[str, Any]:
    """``run.json`` of the run (``{}`` when it is missing or unreadable: the page says so)."""
    from mcchain.errors import RunError
    from mcchain.runner.runs import read_record as run_record

    try:
        found = run_record(folder)
    except RunError:
        return {}
    return found if isinstance(found, dict) else {}


def _setting(value: Any, units: str) -> str:
    """One setting as the scene writes it (TOML's true/false, lists and tables as JSON)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | tuple | dict):
        return esc(json.dumps(value)) + (f" {esc(units)}" if units else "")
    if not isinstance(value, int | float) or not units:
        return esc(value)
    return esc(with_units(float(value), units))


def _method(scene: dict[str, Any]) -> list[tuple[str, str]]:
    rows = []
    for section in ("equilibrium", "modes"):
        if scene.get(section) is not None:
            given = {k: v for k, v in (scene[section] or {}).items() if v is not None}
            rows.append((f"[{section}]", esc(json.dumps(given)) if given else "defaults"))
    simulate = scene.get("simulate")
    if simulate:
        method = simulate.get("method")
        items = [
            f"{key} = {_setting(simulate[key], units)}"
            for key, units in SIMULATE_KEYS
            if simulate.get(key) not in (None, {})
            and method in ONLY_FOR_METHODS.get(key, (method,))
        ]
        rows.append(("[simulate]", "; ".join(items)))
    return rows


def _design(ds: xr.Dataset, settings: dict[str, Any], record: dict[str, Any]) -> str:
    scene = settings.get("scene") or {}
    sample = scene.get("sample")
    n = ds.sizes.get("sample", 0)
    if not sample:
        return f"no [sample]: {n} identical instance(s)"
    text = f"{esc(sample.get('design', 'random'))}, {n} samples, seed {esc(settings.get('seed'))}"
    sequential = settings.get("sequential")
    if isinstance(sequential, dict) and sequential.get("extended_from"):
        text += (
            f"; extended from {esc(sequential['extended_from'])} samples: verdicts by the "
            "confidence sequence"
        )
    elif isinstance(sequential, dict):
        until = record.get("until") or {}
        looks = len(until.get("looks") or [])
        text += (
            f"; until decided: batches of {esc(sequential.get('batch'))}, at most "
            f"{esc(sequential.get('max_count'))}, {looks} looks"
            + (f", {esc(until['stopped'])}" if until.get("stopped") else "")
        )
    return text


def provenance_section(folder: Path, ds: xr.Dataset) -> str:
    """The page's provenance section (HTML)."""
    record = read_record(folder)
    settings = stored_settings(ds)
    scene = settings.get("scene") or {}
    git = record.get("git") or {}
    host = record.get("host") or {}
    commit = git.get("commit") or "unknown (not a git checkout)"
    if git.get("dirty"):
        commit += " (with uncommitted changes)"
    sessions = record.get("sessions") or []
    compilers = sorted(
        {str(s.get("kernel_compiler")) for s in sessions if s.get("kernel_compiler")}
    )
    rows: list[tuple[str, str]] = [
        (
            "mcchain",
            esc(ds.attrs.get("mcchain_version") or record.get("versions", {}).get("mcchain")),
        ),
        ("git commit", f"<code>{esc(commit)}</code>"),
        ("run", f"{esc(record.get('start', '?'))} → {esc(record.get('end', '?'))}"),
        (
            "host",
            esc(
                f"{host.get('name', '?')}: {host.get('cpu', '?')}, {record.get('threads', '?')} "
                f"threads, {record.get('scheduler', '?')}"
            ),
        ),
        ("kernels", esc(", ".join(compilers) or ds.attrs.get("kernel_compiler", "?"))),
        ("design", _design(ds, settings, record)),
        *_method(scene),
        ("run folder", f"<code>{esc(Path(folder).resolve())}</code>"),
    ]
    if not record:
        rows.append(("run.json", "missing or unreadable: date, commit and host unknown"))
    said = [("warning", w) for w in record.get("warnings") or []]
    said += [("note", n) for n in record.get("notes") or []]
    retried = (record.get("retries") or {}).get("line")  # failed samples solved again
    said += [("note", retried)] if retried else []
    if said:
        printed = "".join(f'<li class="{kind}">{kind}: {esc(line)}</li>' for kind, line in said)
        printed = f"<ul>{printed}</ul>"
    else:
        printed = "<p>The run printed no warning and no note.</p>"
    parts = [
        '<section id="provenance"><h2>Provenance</h2>',
        facts(rows),
        "<h3>What the run printed</h3>",
        printed,
        check_section(folder),
    ]
    text = str(ds.attrs.get("scene", ""))
    if text:
        parts.append(f"<details><summary>scene file</summary><pre>{esc(text)}</pre></details>")
    return "\n".join(parts) + "</section>"


def check_section(folder: Path) -> str:
    """The numerical check (``export/check.csv``), or how to run it."""
    path = Path(folder) / CHECK_CSV
    if not path.is_file():
        return (
            "<h3>Numerical check</h3>\n<p>Not run: the statistical intervals do not include "
            "the integrator's error. Run <code>mcchain check "
            f"{esc(folder)} --tighten 10</code> (a subset re-run with 10× tighter tolerances) "
            "and <code>mcchain report</code> again to see how many verdicts flip.</p>"
        )
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader, [])
        rows = [[esc(_short(c)) for c in row] for row in reader]
    return (
        "<h3>Numerical check</h3>\n<p>From <code>export/check.csv</code> (<code>mcchain "
        "check</code>): the requirements re-evaluated on a subset re-run with tighter "
        "tolerances (verdict flips, and how far the outputs moved, in the output's SI "
        "units), beside the statistical intervals.</p>\n" + table(header, rows)
    )


def _short(cell: str) -> str:
    """A CSV number to 4 significant digits (text left as it is)."""
    try:
        value = float(cell)
    except ValueError:
        return cell
    return cell if value.is_integer() and "." not in cell else f"{value:.4g}"
