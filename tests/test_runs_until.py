"""``[sample] until = "decided"``: one run that adds batches until its requirements are decided.

The clearance bar (equilibrium and modes, cheap), clearance uniform on [0.1, 1] mm: the
rolling mode's pulsation exceeds the limit exactly when the clearance is below c*, so the
failure probability is known. The run must stop at the first look where the sequential
interval decides, hold the samples of one run of that count bit for bit, and stop at
``max_count`` when it cannot decide.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from test_runs_extend import assert_same_values

from mcchain.cli import main
from mcchain.decision.sequential import confidence_sequence
from mcchain.decision.summary import export_requirements
from mcchain.runner import plan, runs
from mcchain.runner.summary import run_summary
from mcchain.testing.closed_forms import G, clearance_bar_pulsations
from mcchain.testing.scenes import hanging_clearance_bar_text

pytestmark = pytest.mark.slow  # real solvers

C_LOW, C_HIGH = 1e-4, 1e-3


def rolling_limit(p_fail: float) -> float:
    """The rolling pulsation (rad/s) exceeded with probability ``p_fail`` (nominal mass)."""
    c_star = C_LOW + p_fail * (C_HIGH - C_LOW)
    return float(clearance_bar_pulsations(2.0, 1.0 / 6.0, 0.5, G, c_star)[1])


def scene_text(
    p_fail: float, target: float, until: str = 'until = "decided"\nmax_count = 2048'
) -> str:
    return (
        hanging_clearance_bar_text("until-bar")
        + f"""[equilibrium]
[modes]
shapes = false
[[requirement]]
name = "rolling"
output = "omega"
select = {{ mode = 1 }}
max = {rolling_limit(p_fail)!r}
target = {target!r}
[sample]
count = 64
seed = 5
{until}
[sample.vary]
"joint.O.clearance" = {{ uniform = [{C_LOW!r}, {C_HIGH!r}] }}
"""
    )


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def test_until__stops_at_the_first_decided_look_with_the_samples_of_one_run(tmp_path: Path) -> None:
    scene = write(tmp_path, "until.toml", scene_text(0.05, 0.01))
    result = plan.start_run(scene, run_dir=tmp_path / "until", progress=False)
    record = result.record
    until = record["until"]
    looks = until["looks"]
    final = record["samples"]
    assert [look["samples"] for look in looks] == list(range(64, final + 1, 64))
    verdicts = [look["requirements"]["rolling"]["verdict"] for look in looks]
    assert verdicts[-1] == "fail" and set(verdicts[:-1]) <= {"undecided"}
    assert until["stopped"] == f"decided after {final} samples" and final < 2048
    assert record["chunks"] == len(looks) and record["restarts"] == list(range(64, final, 64))
    with runs.open_run(result.folder) as ds:
        met = ds["requirement_met"].values[:, 0]
        settings = json.loads(ds.attrs["settings"])
        assert settings["samples"] == final and ds.attrs["sample_count"] == final
        assert settings["sequential"]["batch"] == 64
        grown = ds.load()
    # The last look's interval is the running intersection of the confidence sequence.
    counts = np.arange(64, final + 1, 64)
    k = np.array([(met[:n] == 0).sum() for n in counts])
    lower, upper = confidence_sequence(k, counts, 0.95, 0.01)
    assert looks[-1]["requirements"]["rolling"]["p_lower"] == lower.max() > 0.01
    assert looks[-1]["requirements"]["rolling"]["p_upper"] == upper.min()
    # The export reports that interval and its verdict, and says which interval it is.
    csv_path, _, txt_path, *_ = export_requirements(result.folder)
    with open(csv_path, encoding="utf-8") as f:
        (row,) = list(csv.DictReader(f))
    assert float(row["p_lower"]) == pytest.approx(lower.max(), rel=1e-12)
    assert float(row["p_upper"]) == pytest.approx(upper.min(), rel=1e-12)
    assert row["verdict"] == "fail" and int(row["samples"]) == final
    assert "intervals: sequential" in txt_path.read_text(encoding="utf-8")
    # One run of the final count, no until: the same samples bit for bit.
    plain = write(tmp_path, "plain.toml", scene_text(0.05, 0.01, until=""))
    reference = plan.start_run(plain, samples=final, run_dir=tmp_path / "plain", progress=False)
    with runs.open_run(reference.folder) as ds:
        assert_same_values(grown, ds.load())


def test_until__stops_at_max_count_when_it_cannot_decide(tmp_path: Path) -> None:
    text = scene_text(0.01, 0.01, until='until = "decided"\nmax_count = 200')
    result = plan.start_run(write(tmp_path, "s.toml", text), run_dir=tmp_path / "r", progress=False)
    until = result.record["until"]
    assert [look["samples"] for look in until["looks"]] == [64, 128, 192, 200]
    assert until["stopped"] == "max_count 200 reached; undecided: rolling"
    assert result.record["samples"] == 200
    assert any("max_count 200 reached" in line for line in run_summary(result.record))
    # Extended by hand afterwards, it still reports its confidence sequence (valid at any
    # count), continued over every look it was judged at: 64, 128, 192, 200 and 256.
    extended = plan.extend_run(result.folder, 56, progress=False).record
    assert extended["samples"] == 256 and extended["restarts"] == [64, 128, 192, 200]
    csv_path, *_ = export_requirements(result.folder)
    with open(csv_path, encoding="utf-8") as f:
        (row,) = list(csv.DictReader(f))
    with runs.open_run(result.folder) as ds:
        failed = ds["requirement_met"].values[:, 0] == 0
    looks = np.array([64, 128, 192, 200, 256])
    k = np.array([failed[:n].sum() for n in looks])
    lower, upper = confidence_sequence(k, looks, 0.95, 0.01)
    assert float(row["p_upper"]) == pytest.approx(upper.min(), rel=1e-12)
    assert float(row["p_lower"]) == pytest.approx(lower.max(), rel=1e-12)


def test_until__needs_a_requirement(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = scene_text(0.05, 0.01)
    start = text.index("[[requirement]]")
    text = text[:start] + text[text.index("[sample]") :]
    scene = write(tmp_path, "s.toml", text)
    assert main(["run", str(scene), "--run-dir", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sample.until" in err and "[[requirement]]" in err
    assert not (tmp_path / "r").exists()


def test_until__an_interrupted_run_resumes_where_it_stopped(tmp_path: Path) -> None:
    scene = write(tmp_path, "s.toml", scene_text(0.05, 0.01))
    calls: list[int] = []

    def failing_solve(model, scene):  # type: ignore[no-untyped-def]
        from mcchain.solvers import solve_chunk

        if model.nsample == 64:  # a batch (warming the kernels solves 2 samples)
            calls.append(model.nsample)
        if len(calls) == 2:  # the second batch fails
            raise RuntimeError("power cut")
        return solve_chunk(model, scene)

    folder = tmp_path / "r"
    with pytest.raises(RuntimeError, match="power cut"):
        plan.start_run(scene, run_dir=folder, solve=failing_solve, progress=False)
    record = runs.read_record(folder)
    assert record["status"] == "FAILED" and record["samples"] == 128
    assert [look["samples"] for look in record["until"]["looks"]] == [64]
    resumed = plan.resume_run(folder, progress=False).record
    reference = plan.start_run(scene, run_dir=tmp_path / "ref", progress=False).record
    assert resumed["samples"] == reference["samples"] >= 128
    assert resumed["until"]["looks"] == reference["until"]["looks"]
    with runs.open_run(folder) as a, runs.open_run(tmp_path / "ref") as b:
        assert_same_values(a.load(), b.load())
