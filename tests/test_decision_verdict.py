"""Failed instances, never-events, units and ``mcchain verdict``.

* a Dataset whose diverged samples store the sentinel -1 in ``impact_count`` and whose
  never-separating samples store NaN in ``first_separation_time`` (the issue's slider-crank,
  in miniature): the summaries count the failure bits, not the values, and read "never" as
  never — also where the stored ``requirement_met`` was written by the old rule;
* ``mcchain verdict``: its exit codes (0 all pass, 1 one fails, 4 one undecided) on the pinned
  bar, whose P(fail) is known, and its one-line refusals (exit 2);
* the units every printed limit, quantile and bound carries.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from test_cli_commands import Ran, assert_usage_error

from mcchain.decision.requirements import dataset_requirement_met, defined_mask
from mcchain.decision.stats import one_sided_bounds
from mcchain.decision.summary import summarize, summary_lines
from mcchain.decision.verdict import EXIT_FAIL, EXIT_PASS, EXIT_UNDECIDED, exit_code
from mcchain.ensemble.units import format_quantity, output_units
from mcchain.status import CONTACT_LOST, DIVERGED
from mcchain.testing.closed_forms import bar_pulsation
from mcchain.testing.factory import bar_scene_dict, toml_text

REQUIREMENTS = [
    {"name": "impacts", "output": "impact_count", "select": {"joint": "B"}, "max": 1000},
    {"name": "separation", "output": "first_separation_time", "select": {"joint": "B"},
     "min": 0.001},
    {"name": "force-kn", "output": "peak_contact_force", "select": {"joint": "B"}, "max": 5.0},
]  # fmt: skip


def slider_crank_like(n: int = 256, diverged: int = 102, never: int = 154) -> xr.Dataset:
    """``diverged`` samples flagged with impact_count -1 and NaN values, then ``never``
    samples that never separate (NaN time, status ok: one with the contact_lost warning),
    then the rest separating at 0.5 ms; peak forces 2.7-5.0 kN."""
    assert diverged + never <= n
    status = np.zeros(n, dtype=np.uint32)
    status[:diverged] = DIVERGED
    status[diverged % n] |= CONTACT_LOST  # a warning bit: still defined (past the diverged)
    impacts = np.zeros((n, 1), dtype=np.int32)
    impacts[:diverged] = -1
    first = np.full((n, 1), 0.0005)
    first[: diverged + never] = np.nan
    force = np.linspace(2700.0, 5000.0, n)[:, None]
    force[:diverged] = np.nan
    settings = {"scene": {"sample": {"design": "random"}, "requirement": REQUIREMENTS}}
    stale = np.ones((n, len(REQUIREMENTS)), dtype=np.int8)  # as the old rule stored it
    return xr.Dataset(
        {
            "status": (("sample",), status),
            "impact_count": (("sample", "joint"), impacts, {"units": "1"}),
            "first_separation_time": (("sample", "joint"), first, {"units": "s"}),
            "peak_contact_force": (("sample", "joint"), force, {"units": "N"}),
            "requirement_met": (("sample", "requirement"), stale),
        },
        coords={
            "sample": np.arange(n),
            "joint": ["B"],
            "requirement": [r["name"] for r in REQUIREMENTS],
        },
        attrs={"settings": json.dumps(settings)},
    )


def test_dataset__failure_bits_decide_and_never_is_never() -> None:
    ds = slider_crank_like()
    defined = defined_mask(ds)
    assert int((~defined).sum()) == 102 and bool(defined[102])  # contact_lost is a warning
    impacts, separation, force = summarize(ds)
    # impact_count -1 on a diverged sample never passes impact_count <= 1000
    assert (impacts.failures, impacts.undefined, impacts.decision) == (102, 102, "fail")
    assert (impacts.p_lower, impacts.p_upper) == one_sided_bounds(102, 256, 0.95)
    # the 154 that never separate meet "not before 1 ms"; the diverged ones fail
    assert (separation.failures, separation.undefined) == (102, 102)
    met = dataset_requirement_met(ds, separation_requirement := _requirement(ds, 1))
    assert met[:102].sum() == 0 and met[102:256].all()
    assert separation_requirement.output == "first_separation_time"
    # a limit in kN on a force in N: every sample fails, with a warning naming it
    assert force.failures == 256
    text = "\n".join(summary_lines([impacts, separation, force], [], "random"))
    assert "warning: requirement force-kn: every one of the 256 samples fails it" in text
    assert "peak_contact_force[joint=B] <= 5 N" in text
    lowest = format_quantity(float(np.linspace(2700.0, 5000.0, 256)[102]), "N")
    assert f"range over {lowest} to 5000 N (5 kN); 102 undefined" in text
    assert "first_separation_time[joint=B] >= 0.001 s (1 ms)" in text
    assert "all 3 verdicts hold at once with probability >= 1 - 3 x 0.05 = 0.85" in text


def test_dataset__no_failure_bit_and_all_failed() -> None:
    clean = summarize(slider_crank_like(diverged=0, never=0))
    assert [s.failures for s in clean] == [0, 256, 256]  # separates at 0.5 ms: fails min 1 ms
    assert [s.undefined for s in clean] == [0, 0, 0]
    everything = summarize(slider_crank_like(diverged=256, never=0))
    assert all(s.failures == s.undefined == 256 for s in everything)
    text = "\n".join(summary_lines(everything, [], "random"))
    assert "no sample has a value to compare (all 256 undefined" in text


def _requirement(ds: xr.Dataset, i: int) -> object:
    from mcchain.decision.requirements import stored_requirements

    return stored_requirements(ds)[i]


def test_units__readable_multiples_and_mixed_units() -> None:
    assert format_quantity(5000.0, "N") == "5000 N (5 kN)"
    assert format_quantity(5.0, "N") == "5 N"
    assert format_quantity(2.4e-5, "m") == "2.4e-05 m (0.024 mm)"
    assert format_quantity(0.001, "s") == "0.001 s (1 ms)"
    assert format_quantity(-2.5e-4, "s") == "-0.00025 s (-250 µs)"
    assert format_quantity(12.0, "N m") == "12 N m"
    assert format_quantity(1000.0, "") == "1000"
    assert format_quantity(math.nan, "N") == "NaN" and format_quantity(math.inf, "s") == "inf s"
    assert output_units("peak_contact_force") == "N"
    assert output_units("omega") == "rad s-1"
    assert output_units("impact_count") == ""
    assert output_units("q_eq", {"body": "bar", "dof": "theta"}) == "rad"
    assert output_units("q_eq", {"body": "bar", "dof": 0}) == "m"
    assert output_units("made_up", attrs={"units": "m"}) == "m"


# -- mcchain verdict -------------------------------------------------------------------------
M, A, J_LOW, J_HIGH = 2.0, 0.5, 0.05, 0.5


def pinned_bar_text(count: int, limits: dict[str, tuple[float, float]]) -> str:
    """The pinned bar of tests/test_decision_closed_form.py, one requirement per entry of
    ``limits``: name -> (max on omega[mode=0], target)."""
    doc = bar_scene_dict(
        mass=M,
        sample={
            "count": count,
            "seed": 11,
            "vary": {"body.bar.inertia": {"uniform": [J_LOW, J_HIGH]}},
        },
        equilibrium=False,
    )
    doc["requirement"] = [
        {"name": name, "output": "omega", "select": {"mode": 0}, "max": limit, "target": target}
        for name, (limit, target) in limits.items()
    ]
    return toml_text(doc)


P_MAX = float(bar_pulsation(M, J_LOW, A))  # the largest pulsation: nothing exceeds it
P_MEDIAN = float(bar_pulsation(M, (J_LOW + J_HIGH) / 2, A))  # P(fail) = 1/2


@pytest.mark.parametrize(
    ("limits", "code", "word"),
    [
        ({"wide": (P_MAX, 0.05)}, EXIT_PASS, "PASS"),  # 0 of 100: upper 0.0295 <= 0.05
        ({"wide": (P_MAX, 0.05), "tight": (P_MAX, 0.01)}, EXIT_UNDECIDED, "UNDECIDED"),
        ({"wide": (P_MAX, 0.05), "tight": (P_MAX, 0.01), "half": (P_MEDIAN, 0.1)}, EXIT_FAIL,
         "FAIL"),
    ],
)  # fmt: skip
def test_verdict__exit_codes(
    mcchain: Callable[..., Ran],
    tmp_path: Path,
    limits: dict[str, tuple[float, float]],
    code: int,
    word: str,
) -> None:
    (tmp_path / "bar.toml").write_text(pinned_bar_text(100, limits))
    ran = mcchain("run", "bar.toml", "--run-dir", "run", "--quiet", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    ran = mcchain("verdict", "run", cwd=tmp_path)
    assert ran.returncode == code, ran.stdout + ran.stderr
    lines = ran.stdout.splitlines()
    assert lines[0].split()[:3] == ["requirement", "limit", "samples"]
    rows = {line.split()[0]: line for line in lines[1 : 1 + len(limits)]}
    assert set(rows) == set(limits)
    assert rows["wide"].rstrip().endswith("PASS")
    upper = one_sided_bounds(0, 100, 0.95)[1]  # 1 - 0.05^(1/100) = 0.0295
    assert "rad/s" in rows["wide"] and f"[0, {upper:.4g}] at 95 %" in rows["wide"]
    assert any(line.rstrip().endswith(word) for line in rows.values())
    if len(limits) > 1:
        assert f"all {len(limits)} verdicts hold at once" in ran.stdout
    assert ran.stderr == ""


def test_verdict__bad_runs_one_line_exit_2(mcchain: Callable[..., Ran], tmp_path: Path) -> None:
    assert_usage_error(mcchain("verdict", "nope", cwd=tmp_path), "nope: no such run folder")
    doc = bar_scene_dict(sample={"count": 4}, equilibrium=False)
    (tmp_path / "plain.toml").write_text(toml_text(doc))
    assert (
        mcchain("run", "plain.toml", "--run-dir", "plain", "--quiet", cwd=tmp_path).returncode == 0
    )
    assert_usage_error(
        mcchain("verdict", "plain", cwd=tmp_path), "verdict: plain has no [[requirement]]"
    )
    (tmp_path / "empty").mkdir()
    assert_usage_error(mcchain("verdict", "empty", cwd=tmp_path), "not a run folder")
    run_json = tmp_path / "plain" / "run.json"
    record = json.loads(run_json.read_text())
    run_json.write_text(json.dumps({**record, "status": "INTERRUPTED"}))
    assert_usage_error(mcchain("verdict", "plain", cwd=tmp_path), "verdict: plain is not completed")
    assert_usage_error(mcchain("verdict", cwd=tmp_path), "the following arguments are required")


def test_exit_code__any_fail_wins_then_undecided() -> None:
    assert exit_code(["pass", "pass"]) == 0
    assert exit_code(["pass", "undecided"]) == 4
    assert exit_code(["pass", "empty"]) == 4
    assert exit_code(["undecided", "fail", "pass"]) == 1
    assert exit_code([]) == 0
