"""``[[requirement]]``: the scene keys, the evaluation of a requirement on an ensemble and
the tolerance allocation, on data whose answer is known in closed form."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

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
    "confidence below a half": (
        REQ.format(extra="max = 4.0\nconfidence = 0.4"),
        "requirement.p0.confidence",
    ),
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
    # ties at a limit meet it
    assert requirement_met(np.array([2.0, 3.0]), both).tolist() == [1.0, 1.0]


def test_requirement_met__a_failure_bit_fails_whatever_the_value() -> None:
    """impact_count is -1 on a diverged sample (the value meaning "no contact law"): the
    failure bit, not the value, decides; a warning bit (contact_lost) does not."""
    from mcchain.decision.requirements import decision_values, defined_samples
    from mcchain.status import CONTACT_LOST, DIVERGED, FAILURE_BITS, Status

    impacts = np.array([-1, 3, 0, 1200, 7], dtype=np.int32)
    status = np.array([DIVERGED, 0, CONTACT_LOST, 0, DIVERGED | CONTACT_LOST], dtype=np.uint32)
    defined = defined_samples(status)
    assert defined.tolist() == [False, True, True, True, False]
    at_most = SimpleNamespace(min=None, max=1000.0, output="impact_count")
    assert requirement_met(impacts, at_most, defined).tolist() == [0.0, 1.0, 1.0, 0.0, 0.0]
    assert requirement_met(impacts, at_most).tolist() == [1.0, 1.0, 1.0, 0.0, 1.0]  # no status
    assert np.isnan(decision_values(impacts, defined, "impact_count")[[0, 4]]).all()
    for flag in Status:  # every failure bit alone fails, no warning bit does
        alone = defined_samples(np.array([flag.value], dtype=np.uint32))
        assert bool(alone[0]) == (not flag.value & FAILURE_BITS)


def test_requirement_met__an_event_that_never_happened_is_never() -> None:
    """first_separation_time NaN on a sample without a failure bit: never separated, +inf:
    it meets "not before 1 ms" and fails "before 20 ms"; with a failure bit it fails both."""
    from mcchain.decision.requirements import decision_values, is_event_time
    from mcchain.status import DIVERGED

    assert is_event_time("first_separation_time") and is_event_time("contact_lost_time")
    assert not is_event_time("free_flight_time") and not is_event_time("peak_contact_force")
    assert not is_event_time("no_such_output") and not is_event_time(None)
    t = np.array([math.nan, 0.0005, 0.002, math.nan, 0.001])
    defined = np.array([True, True, True, False, True])
    late = SimpleNamespace(min=0.001, max=None, output="first_separation_time")
    early = SimpleNamespace(min=None, max=0.02, output="first_separation_time")
    window = SimpleNamespace(min=0.001, max=0.02, output="first_separation_time")
    assert requirement_met(t, late, defined).tolist() == [1.0, 0.0, 1.0, 0.0, 1.0]
    assert requirement_met(t, early, defined).tolist() == [0.0, 1.0, 1.0, 0.0, 1.0]
    assert requirement_met(t, window, defined).tolist() == [0.0, 0.0, 1.0, 0.0, 1.0]
    values = decision_values(t, defined, "first_separation_time")
    assert values[0] == math.inf and math.isnan(values[3])
    # the same NaN on an output that is no event time stays undefined
    peak = SimpleNamespace(min=0.001, max=None, output="peak_contact_force")
    assert requirement_met(t, peak, defined).tolist() == [0.0, 0.0, 1.0, 0.0, 1.0]
    status = np.array([0, 0, 0, DIVERGED, 0], dtype=np.uint32)
    from mcchain.decision.requirements import chunk_requirement_met, resolve_selection

    req = _requirement(output="first_separation_time", select={"joint": "B"}, min=0.001)
    sel = resolve_selection(req, ("sample", "joint"), {"joint": ["A", "B"]})
    outputs = {"first_separation_time": np.c_[np.zeros(5), t], "status": status}
    met = chunk_requirement_met(outputs, [req], [sel])
    assert met.dtype == np.int8 and met[:, 0].tolist() == [1, 0, 1, 0, 1]


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
        min(upper_bound(result.failures, result.samples_kept, 0.95, 3), 0.01)
    )
    assert result.p_upper <= 0.01
    more = int(kept.sum()) + 1
    assert upper_bound(int(failed[:more].sum()), more, 0.95, 3) > 0.01


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


def _requirement(**kw: object) -> Any:
    from mcchain.scene.study import Requirement

    return Requirement.model_validate({"name": "r", "output": "omega", **kw})


def _one_sided(confidence: float = 0.95) -> object:
    from mcchain.decision.stats import one_sided_bounds

    return lambda k, n: one_sided_bounds(k, n, confidence)


def test_summary__undefined_counted_apart_and_undecided_sample_count() -> None:
    from mcchain.decision.stats import one_sided_bounds, samples_to_decide
    from mcchain.decision.summary import requirement_lines, summarize_requirement

    requirement = _requirement(max=1.0, target=0.01)
    values = np.r_[np.zeros(296), [2.0, 2.0, math.nan, math.nan]]  # 4 failures, 2 undefined
    met = requirement_met(values, requirement)
    s = summarize_requirement(requirement, values, met, "random", units="rad/s")
    assert (s.samples, s.failures, s.undefined) == (300, 4, 2)
    assert (s.p_lower, s.p_upper) == one_sided_bounds(4, 300, 0.95)
    assert s.verdict == "undecided"
    assert s.samples_needed == samples_to_decide(4, 300, 0.01, 0.95, interval=_one_sided()) > 300
    # the 99 % quantile is x_(297) of 300 with the NaN samples at +inf, beyond the limit
    assert s.quantile == 2.0 and s.quantile_upper == math.inf
    text = "\n".join(requirement_lines(s, "random"))
    assert f"about {int(s.samples_needed)} samples" in text
    assert "omega <= 1 rad/s" in text
    assert "95 % bounds (each one-sided; together a 90 % interval)" in text


def test_summary__both_limits_quantile_on_the_side_failing_more() -> None:
    from mcchain.decision.summary import limit_text, summarize_requirement

    requirement = _requirement(min=-1.0, max=1.0, target=0.05)
    values = np.r_[np.linspace(-0.9, 0.9, 88), np.full(10, -2.0), np.full(2, 2.0)]
    s = summarize_requirement(requirement, values, requirement_met(values, requirement), "lhs")
    assert s.side == "min" and s.level == 0.05 and s.failures == 12
    assert s.quantile == np.sort(values)[5 - 1]  # x_(5): 100 x 0.05 = 5 exactly
    assert s.verdict == "fail (approximate)"
    assert limit_text(s) == "-1 <= omega <= 1"  # both limits shown


def test_summary__quantile_point_is_x7_of_100_at_target_007() -> None:
    from mcchain.decision.summary import summarize_requirement

    requirement = _requirement(min=50.0, target=0.07)
    values = np.arange(1.0, 101.0)
    s = summarize_requirement(requirement, values, requirement_met(values, requirement), "random")
    assert s.side == "min" and s.quantile == 7.0
    upper = _requirement(max=500.0, target=0.07)
    s = summarize_requirement(upper, values, requirement_met(values, upper), "random")
    assert s.side == "max" and s.quantile == 93.0


def test_summary__no_failure_gives_the_success_run_figure() -> None:
    from mcchain.decision.summary import requirement_lines, summarize_requirement

    requirement = _requirement(max=1.0, target=0.01)
    values = np.zeros(100)
    s = summarize_requirement(requirement, values, requirement_met(values, requirement), "random")
    text = "\n".join(requirement_lines(s, "random"))
    assert "ceil(ln(1 - C)/ln(1 - p)) = 299 failure-free samples" in text
    assert "about 299 samples (199 more)" in text
    passed = np.zeros(299)
    s = summarize_requirement(requirement, passed, requirement_met(passed, requirement), "random")
    assert s.verdict == "pass" and s.samples_needed == 299


def test_summary__every_sample_failing_warns_with_units_and_range() -> None:
    """The kN-vs-N mistake: max = 5.0 on a force in N."""
    from mcchain.decision.summary import all_fail_warning, requirement_lines, summarize_requirement

    requirement = _requirement(
        output="peak_contact_force", select={"joint": "B"}, max=5.0, target=0.01
    )
    values = np.r_[np.linspace(2719.55, 5016.37, 10), math.nan]
    met = requirement_met(values, requirement)
    s = summarize_requirement(requirement, values, met, "random", units="N")
    warning = all_fail_warning(s)
    assert warning is not None and warning.startswith("warning: requirement r: every one of")
    for part in ("<= 5 N", "2719.55 N (2.72 kN)", "5016.37 N (5.016 kN)", "1 undefined"):
        assert part in warning
    assert warning in requirement_lines(s, "random")
    # all undefined: says so; one passing sample: no warning
    nan = np.full(4, math.nan)
    s = summarize_requirement(requirement, nan, requirement_met(nan, requirement), "random")
    assert "all 4 undefined" in (all_fail_warning(s) or "")
    ok = np.r_[values, 4.0]
    s = summarize_requirement(requirement, ok, requirement_met(ok, requirement), "random")
    assert all_fail_warning(s) is None


def test_summary__empty_running_intersection_is_no_verdict() -> None:
    """An until run whose first look is all failures and whose later looks have none: the
    confidence sequence's running intersection empties; that is reported as such."""
    from mcchain.decision.sequential import sequential_bounds
    from mcchain.decision.summary import requirement_lines, summarize_requirement

    requirement = _requirement(max=1.0, target=0.01)
    values = np.r_[np.full(100, 2.0), np.zeros(20_000)]
    met = requirement_met(values, requirement)
    lo, hi = sequential_bounds(met == 0, 100, 0.95, 0.01)
    assert lo > hi
    s = summarize_requirement(
        requirement, values, met, "random", sequential={"batch": 100, "method": "m"}
    )
    assert s.decision == "empty" and (s.p_lower, s.p_upper) == (lo, hi)
    text = "\n".join(requirement_lines(s, "random"))
    assert "NO VERDICT: the running intersection of the sequential interval is empty" in text


def test_summary__until_counts_from_the_sequential_interval() -> None:
    """In an until run, the samples needed and the zero-failure figure come from the
    confidence sequence that decides (whole batches), not from Clopper–Pearson."""
    from mcchain.decision.sequential import confidence_sequence
    from mcchain.decision.summary import requirement_lines, summarize_requirement

    requirement = _requirement(max=1.0, target=0.01)
    values = np.zeros(256)
    met = requirement_met(values, requirement)
    s = summarize_requirement(
        requirement, values, met, "random", sequential={"batch": 256, "method": "m"}
    )
    assert s.sequential and s.decision == "undecided"
    # (1 - p)^n = b/((b + n)/(1 - C)) at the bound: 0.0145 after 300 samples, 0.0094 after 512
    assert s.success_run % 256 == 0 and s.success_run == s.samples_needed == 512
    assert confidence_sequence(0, s.success_run, 0.95, 0.01)[1] <= 0.01
    assert confidence_sequence(0, s.success_run - 256, 0.95, 0.01)[1] > 0.01
    text = "\n".join(requirement_lines(s, "random"))
    assert f"{int(s.success_run)} failure-free samples pass at 95 %" in text
    assert "sequential bounds (each one-sided, valid at every look)" in text
    # a caller that does not pass the sequential settings (the report) still says so
    from mcchain.decision.summary import summary_lines

    words = "\n".join(summary_lines([s], [], "random"))
    assert "intervals: sequential" in words and "Clopper" not in words


def test_family_line__bonferroni_beside_several_requirements() -> None:
    from mcchain.decision.summary import family_line, summarize_requirement

    values = np.zeros(400)
    r1, r2 = _requirement(max=1.0), _requirement(max=1.0, name="s", confidence=0.99)
    s1 = summarize_requirement(r1, values, requirement_met(values, r1), "random")
    s2 = summarize_requirement(r2, values, requirement_met(values, r2), "random")
    assert family_line([s1]) is None
    assert "probability >= 1 - 2 x 0.05 = 0.9 (Bonferroni" in (family_line([s1, s1]) or "")
    assert "1 - sum(1 - C) = 0.94" in (family_line([s1, s2]) or "")
