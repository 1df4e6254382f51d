"""``--extend`` keeps its verdicts valid and its files honest.

On the clearance bar of tests/test_runs_until.py (P(fail) known): a fixed-count run with a
requirement, extended, is judged by its confidence sequence (looks every n0 samples, the
first at n0), never by a Clopper-Pearson interval that optional stopping breaks; it says so
in one line. The files ``export``, ``check`` and ``report`` made before an extension are
moved aside to ``stale/<n>-samples/`` with a note, never left beside the larger ensemble.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from test_runs_until import scene_text

from mcchain.cli import main
from mcchain.decision.sequential import sequential_bounds
from mcchain.decision.summary import export_requirements
from mcchain.decision.until import SETTINGS_KEY
from mcchain.decision.verdict import run_verdict
from mcchain.runner import plan, runs
from mcchain.runner.stale import move_stale
from mcchain.runner.summary import run_summary

pytestmark = pytest.mark.slow  # real solvers


def write(tmp: Path, name: str, text: str) -> Path:
    path = tmp / name
    path.write_text(text, encoding="utf-8")
    return path


def rows(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_extend__a_fixed_count_run_continues_under_its_confidence_sequence(
    tmp_path: Path,
) -> None:
    scene = write(tmp_path, "s.toml", scene_text(0.05, 0.01, until=""))
    first = plan.start_run(scene, run_dir=tmp_path / "r", progress=False)
    assert not any("confidence sequence" in line for line in run_summary(first.record))
    csv_path, *_ = export_requirements(first.folder)
    assert (first.folder / "export" / "requirements.csv").exists()
    with runs.open_run(first.folder) as ds:
        assert SETTINGS_KEY not in json.loads(ds.attrs["settings"])
    result = plan.extend_run(first.folder, 100, progress=False)
    lines = run_summary(result.record)
    (said,) = [line for line in lines if line.startswith("note: --extend:")]
    assert "confidence sequence, looked at every 64 samples" in said
    assert "optional stopping" in said
    # the export made from 64 samples was moved aside, and the summary says so
    stale = result.folder / "stale" / "64-samples"
    assert (stale / "export" / "requirements.csv").exists()
    assert not (result.folder / "export").exists()
    (moved,) = [line for line in lines if "moved to stale/64-samples/" in line]
    assert moved.startswith("note: export/ described the run's first 64 samples")
    assert result.record["stale"] == [{"samples": 64, "moved_to": "stale/64-samples"}]
    assert rows(stale / "export" / "requirements.csv")[0]["samples"] == "64"
    with runs.open_run(result.folder) as ds:
        settings = json.loads(ds.attrs["settings"])
        failed = ds["requirement_met"].values[:, 0] == 0
    assert settings[SETTINGS_KEY]["extended_from"] == 64 and settings[SETTINGS_KEY]["batch"] == 64
    lower, upper = sequential_bounds(failed, 64, 0.95, 0.01)  # looks 64, 128, 164
    csv_path, *_ = export_requirements(result.folder)
    (row,) = rows(csv_path)
    assert int(row["samples"]) == 164
    assert float(row["p_lower"]) == pytest.approx(lower, rel=1e-12)
    assert float(row["p_upper"]) == pytest.approx(upper, rel=1e-12)
    first_lower, first_upper = float(row["p_lower"]), float(row["p_upper"])
    table = run_verdict(result.folder).lines()
    assert any("since the run of 64 was extended" in line for line in table)
    # A second extension keeps the sequence (looks every 64 from the first) and moves the
    # export just written, now of 164 samples, aside too.
    again = plan.extend_run(result.folder, 36, progress=False)
    assert not any(line.startswith("note: --extend:") for line in run_summary(again.record))
    assert (again.folder / "stale" / "164-samples" / "export" / "requirements.csv").exists()
    with runs.open_run(again.folder) as ds:
        failed = ds["requirement_met"].values[:, 0] == 0
        assert json.loads(ds.attrs["settings"])[SETTINGS_KEY]["extended_from"] == 64
        assert json.loads(ds.attrs["settings"])[SETTINGS_KEY]["looks"] == [64, 164]
    (row,) = rows(export_requirements(again.folder)[0])
    lower, upper = sequential_bounds(failed, 64, 0.95, 0.01, [64, 164])  # 64 128 164 192 200
    assert float(row["p_upper"]) == pytest.approx(upper, rel=1e-12)
    assert float(row["p_lower"]) == pytest.approx(lower, rel=1e-12)
    assert float(row["p_upper"]) <= first_upper and float(row["p_lower"]) >= first_lower


def test_extend__an_until_run_keeps_its_sequence_and_its_check_goes_stale(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = write(tmp_path, "s.toml", scene_text(0.05, 0.01))
    first = plan.start_run(scene, run_dir=tmp_path / "r", progress=False)
    n = int(first.record["samples"])
    assert first.record["until"]["stopped"].startswith("decided after")
    (first.folder / "report").mkdir()
    (first.folder / "report" / "index.html").write_text("<p>old</p>", encoding="utf-8")
    (first.folder / "check").mkdir()
    (first.folder / "check" / "tighten-10.nc").write_bytes(b"old")
    assert main(["run", "--extend", str(first.folder), "--samples", "64"]) == 0
    out = capsys.readouterr().out
    assert f"note: check/, report/ described the run's first {n} samples" in out
    assert "--extend: the verdicts" not in out  # an until run was sequential already
    stale = first.folder / "stale" / f"{n}-samples"
    assert (stale / "report" / "index.html").read_text(encoding="utf-8") == "<p>old</p>"
    assert (stale / "check" / "tighten-10.nc").read_bytes() == b"old"
    with runs.open_run(first.folder) as ds:
        settings = json.loads(ds.attrs["settings"])[SETTINGS_KEY]
        failed = ds["requirement_met"].values[:, 0] == 0
    assert settings["batch"] == 64 and "extended_from" not in settings
    (row,) = rows(export_requirements(first.folder)[0])
    assert int(row["samples"]) == n + 64
    assert float(row["p_upper"]) == pytest.approx(sequential_bounds(failed, 64, 0.95, 0.01)[1])


def test_move_stale__never_overwrites(tmp_path: Path) -> None:
    assert move_stale(tmp_path, 10) is None
    for k in range(2):
        (tmp_path / "export").mkdir()
        (tmp_path / "export" / "a.csv").write_text(str(k), encoding="utf-8")
        moved = move_stale(tmp_path, 10)
        assert moved is not None and moved[1] == ["export"]
    assert (tmp_path / "stale" / "10-samples" / "export" / "a.csv").read_text() == "0"
    assert (tmp_path / "stale" / "10-samples-2" / "export" / "a.csv").read_text() == "1"
    assert np.array_equal(
        sorted(p.name for p in (tmp_path / "stale").iterdir()), ["10-samples", "10-samples-2"]
    )


def test_extend__interrupted_then_resumed_still_moves_the_stale_files(tmp_path: Path) -> None:
    scene = write(tmp_path, "s.toml", scene_text(0.05, 0.01, until=""))
    folder = plan.start_run(scene, chunk_size=32, run_dir=tmp_path / "r", progress=False).folder
    export_requirements(folder)
    calls = []

    def failing_solve(model, scene):  # type: ignore[no-untyped-def]
        from mcchain.solvers import solve_chunk

        calls.append(model.nsample)
        if len(calls) == 2:  # the second new chunk fails
            raise RuntimeError("power cut")
        return solve_chunk(model, scene)

    with pytest.raises(RuntimeError, match="power cut"):
        plan.extend_run(folder, 64, solve=failing_solve, progress=False)
    assert (folder / "export" / "requirements.csv").exists()  # the old run is still whole
    result = plan.resume_run(folder, progress=False)
    assert (folder / "stale" / "64-samples" / "export" / "requirements.csv").exists()
    assert any("moved to stale/64-samples/" in line for line in run_summary(result.record))
    with runs.open_run(folder) as ds:
        assert json.loads(ds.attrs["settings"])[SETTINGS_KEY]["extended_from"] == 64
