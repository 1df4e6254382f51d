"""``[[requirement]]``: the scene keys, the evaluation of a requirement on an ensemble and
the tolerance allocation, on data whose answer is known in closed form."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_cli_commands import Ran, assert_scene_refused

from mcchain.decision.allocation import allocate, upper_bound
from mcchain.decision.requirements import requirement_met
from mcchain.testing.factory import bar_scene_dict, clearance_bar_text, toml_text

PENDULUM = toml_text(
    bar_scene_dict(
        sample={"count": 8, "vary": {"body.bar.inertia": {"uniform": [0.05, 0.5]}}},
        equilibrium=False,
    )
)
REQ = '\n[[requirement]]\nname = "p0"\noutput = "omega"\nselect = {{ mode = 0 }}\n{extra}\n'

BAD_REQUIREMENTS = {
    "no limit": (REQ.format(extra=""), "requirement.p0: give `min`, `max` or both"),
    "min above max": (REQ.format(extra="min = 5.0\nmax = 4.0"), "min 5.0 must be below max 4.0"),
    "target 1": (REQ.format(extra="max = 4.0\ntarget = 1.0"), "requirement.p0.target"),
    "target 0": (REQ.format(extra="max = 4.0\ntarget = 0"), "requirement.p0.target"),
    "confidence": (REQ.format(extra="max = 4.0\nconfidence = 1.5"), "requirement.p0.confidence"),
    "name": (REQ.replace('"p0"', '"Pin Force"').format(extra="max = 1.0"), "requirement[0].name"),
    "duplicate": (
        REQ.format(extra="max = 4.0") + REQ.format(extra="max = 5.0"),
        "requirement[1].name: duplicate requirement name 'p0'",
    ),
    "unknown key": (REQ.format(extra="max = 4.0\nlimit = 3"), "requirement.p0.limit"),
    "output not produced": (
        REQ.replace('"omega"', '"peak_contact_force"').format(extra="max = 4.0"),
        "requirement.p0.output: 'peak_contact_force' is not a per-sample variable this scene "
        "produces (it produces: q_eq, joint_force_eq, iterations, stable, omega,",
    ),
    "time history": (
        REQ.replace('"omega"', '"joint_force"').format(extra="max = 4.0"),
        "requirement.p0.output: 'joint_force' is not a per-sample variable",
    ),
    "unknown dim": (
        REQ.replace("mode = 0", 'joint = "O"').format(extra="max = 4.0"),
        "requirement.p0.select.joint: omega has no dim 'joint' (dims: mode)",
    ),
    "dim not selected": (
        REQ.replace("select = {{ mode = 0 }}", "").format(extra="max = 4.0"),
        "requirement.p0.select: omega has dim 'mode': select one entry, e.g. { mode = 0 }",
    ),
    "select a number": (
        REQ.replace("mode = 0", "mode = 1.5").format(extra="max = 4.0"),
        "requirement.p0.select.mode: expected a label (a string) or a 0-based index",
    ),
    "index out of range": (
        REQ.replace("mode = 0", "mode = 3").format(extra="max = 4.0"),
        "requirement.p0.select.mode: index 3 outside 0..0 of dim mode",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_REQUIREMENTS))
def test_requirement__bad_keys_one_line_exit_2_nothing_written(
    mcchain: Callable[..., Ran], tmp_path: Path, case: str
) -> None:
    extra, fragment = BAD_REQUIREMENTS[case]
    assert_scene_refused(mcchain, tmp_path, PENDULUM + extra, fragment)


def test_requirement__unknown_label_and_joint_without_contact_law(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    text = clearance_bar_text()
    bad_label = (
        '\n[[requirement]]\nname = "f"\noutput = "joint_force_eq"\n'
        'select = { joint = "B", xy = "y" }\nmax = 1.0\n'
    )
    assert_scene_refused(
        mcchain,
        tmp_path,
        text + bad_label,
        "requirement.f.select.joint: unknown joint 'B' (known: O)",
    )


def test_requirement_met__limits_and_nan() -> None:
    values = np.array([1.0, 2.0, 3.0, math.nan, 5.0])
    both = SimpleNamespace(min=2.0, max=3.0)
    assert requirement_met(values, both).tolist() == [0.0, 1.0, 1.0, 0.0, 0.0]
    upper = SimpleNamespace(min=None, max=3.0)
    assert requirement_met(values, upper).tolist() == [1.0, 1.0, 1.0, 0.0, 0.0]
    lower = SimpleNamespace(min=2.0, max=None)
    assert requirement_met(values, lower).tolist() == [0.0, 1.0, 1.0, 0.0, 1.0]


def test_allocate__failures_at_high_values_cut_from_above() -> None:
    """x on a grid of 10,000 values, failing where x > 0.9: the widest passing range keeps
    x <= bound; its p_upper is the simultaneous bound of its counts, and one more kept
    value (a failure) would not pass."""
    x = np.linspace(0.0, 1.0, 10_000)
    failed = x > 0.9
    result = allocate(x, failed, target=0.01, confidence=0.95, support=(0.0, 1.0))
    assert result.side == "upper" and result.passes
    kept = x <= result.bound
    assert (result.low, result.high) == (0.0, result.bound)
    assert result.samples_kept == kept.sum()
    assert result.failures == int(failed[kept].sum()) > 0  # it keeps some failures
    assert result.p_upper == pytest.approx(
        min(upper_bound(result.failures, result.samples_kept, 0.95, 0.01, 3), 0.01)
    )
    assert result.p_upper <= 0.01
    more = int(kept.sum()) + 1
    assert upper_bound(int(failed[:more].sum()), more, 0.95, 0.01, 3) > 0.01


def test_allocate__failures_at_low_values_cut_from_below_and_both_ends() -> None:
    x = np.linspace(0.0, 1.0, 10_000)
    result = allocate(x, x < 0.2, target=0.01, confidence=0.95, support=(0.0, 1.0))
    assert result.side == "lower" and 0.19 < result.bound < 0.21 and result.high == 1.0
    # failures at both ends (20 % each): only the two-sided chain reaches the target
    both = allocate(x, (x < 0.2) | (x > 0.8), target=0.01, confidence=0.95)
    assert both.side == "both" and both.passes and math.isnan(both.bound)
    assert 0.19 < both.low < 0.21 and 0.79 < both.high < 0.81
    # passing only in [0.1, 0.4], off centre: no chain of the three isolates it; the best
    # range and its bound are given
    none = allocate(x, (x < 0.1) | (x > 0.4), target=0.01, confidence=0.95)
    assert not none.passes and math.isnan(none.bound) and none.p_upper > 0.01
    # the best: x <= 0.4, a quarter of it failing (the kept set of lowest bound)
    assert (none.side, none.low) == ("upper", -math.inf) and 0.399 < none.high < 0.4
    assert none.failures == 1000 and 0.25 < none.p_upper < 0.35


def test_requirement_met__stored_per_sample_chunk_independent(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    """The pinned bar (p² = m g a/(J + m a²), a = 0.5): requirement_met is the closed
    form's verdict sample by sample, with the limits as attributes, and the file is
    byte-identical whatever the chunk size."""
    import mcchain as mc
    from mcchain.testing.closed_forms import bar_pulsation

    text = PENDULUM.replace("count = 8", "count = 50") + REQ.format(
        extra="max = 3.4\ntarget = 0.05"
    )
    (tmp_path / "bar.toml").write_text(text)
    runs = []
    for chunk in ("7", "50"):
        ran = mcchain("run", "bar.toml", "--out", "runs", "--chunk-size", chunk, cwd=tmp_path)
        assert ran.returncode == 0, ran.stderr
        runs.append(tmp_path / ran.stdout.strip().splitlines()[-1])
    files = [(run / "ensemble.nc").read_bytes() for run in runs]
    assert files[0] == files[1]
    ds = mc.open_run(runs[0])
    met = ds["requirement_met"]
    assert met.dims == ("sample", "requirement")
    assert list(met["requirement"].values) == ["p0"]
    # one requirement: netCDF reads a one-element attribute back as a scalar
    assert np.atleast_1d(met.attrs["max"]).tolist() == [3.4]
    assert math.isnan(np.atleast_1d(met.attrs["min"])[0])
    assert np.atleast_1d(met.attrs["target"]).tolist() == [0.05]
    J = ds["parameters"].values[:, 0]
    exact = bar_pulsation(2.0, J, 0.5) <= 3.4
    assert met.values[:, 0].tolist() == exact.astype(int).tolist()


def _requirement(**kw: object) -> object:
    from mcchain.scene.study import Requirement

    return Requirement.model_validate({"name": "r", "output": "omega", **kw})


def test_summary__undefined_counted_apart_and_undecided_sample_count() -> None:
    from mcchain.decision.stats import samples_to_decide
    from mcchain.decision.summary import requirement_lines, summarize_requirement

    requirement = _requirement(max=1.0, target=0.01)
    values = np.r_[np.zeros(296), [2.0, 2.0, math.nan, math.nan]]  # 4 failures, 2 undefined
    met = requirement_met(values, requirement)
    s = summarize_requirement(requirement, values, met, "random")
    assert (s.samples, s.failures, s.undefined) == (300, 4, 2)
    assert s.verdict == "undecided"
    assert s.samples_needed == samples_to_decide(4, 300, 0.01, 0.95) > 300
    # the 99 % quantile is x_(297) of 300 with the NaN samples at +inf, beyond the limit
    assert s.quantile == 2.0 and math.isnan(s.quantile_upper)
    text = "\n".join(requirement_lines(s, "random"))
    assert f"about {int(s.samples_needed)} samples" in text
    assert "368 needed" in text


def test_summary__both_limits_quantile_on_the_side_failing_more() -> None:
    from mcchain.decision.summary import summarize_requirement

    requirement = _requirement(min=-1.0, max=1.0, target=0.05)
    values = np.r_[np.linspace(-0.9, 0.9, 88), np.full(10, -2.0), np.full(2, 2.0)]
    s = summarize_requirement(requirement, values, requirement_met(values, requirement), "lhs")
    assert s.side == "min" and s.level == 0.05 and s.failures == 12
    assert s.quantile == np.sort(values)[math.ceil(100 * 0.05) - 1]
    assert s.verdict == "fail (approximate)"


def test_summary__no_failure_gives_the_success_run_figures() -> None:
    from mcchain.decision.summary import requirement_lines, summarize_requirement

    requirement = _requirement(max=1.0, target=0.01)
    values = np.zeros(100)
    s = summarize_requirement(requirement, values, requirement_met(values, requirement), "random")
    text = "\n".join(requirement_lines(s, "random"))
    assert "n = ln(1 - C)/ln(1 - p) = 298.073" in text
    assert "the two-sided interval above needs 368" in text
    assert "about 368 samples (268 more)" in text
