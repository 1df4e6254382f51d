"""The ``mcchain`` command line: errors, validate, runs, show, report."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from test_runs_support import REPO, TESTS, fake_loader, fake_solve, write_fake_scene

from mcchain import cli
from mcchain.runner import plan

CLEARANCE_BAR = REPO / "configs" / "clearance-bar.toml"

REDUNDANT = """
[scene]
name = "redundant"
[[body]]
name = "bar"
mass = 1.0
inertia = 0.1
position = [0.5, 0.0]
angle = 0.0
[[joint]]
name = "A"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]
[[joint]]
name = "B"
bodies = ["ground", "bar"]
points = [[1.0, 0.0], [0.5, 0.0]]
[equilibrium]
"""

NEGATIVE_MASS = """
[scene]
name = "x"
[[body]]
name = "bar"
mass = -1.0
inertia = 0.1
position = [0.0, 0.0]
angle = 0.0
"""


@dataclass(frozen=True)
class Ran:
    """Exit code and output of one ``mcchain`` command line."""

    returncode: int
    stdout: str
    stderr: str


def in_process(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> Callable[..., Ran]:
    """``run(*args, cwd=DIR)``: :func:`mcchain.cli.main` in this process, from ``DIR``, with
    ``sys.argv`` as the console script has it (a run's record keeps it)."""

    def run(*args: str | Path, cwd: Path) -> Ran:
        monkeypatch.chdir(cwd)
        monkeypatch.setattr(sys, "argv", ["mcchain", *map(str, args)])
        capsys.readouterr()
        code = cli.main([str(a) for a in args])
        out, err = capsys.readouterr()
        return Ran(code, out, err)

    return run


def assert_usage_error(proc: Ran | subprocess.CompletedProcess[str], *fragments: str) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("mcchain: error: ")
    for fragment in fragments:
        assert fragment in lines[0]
    assert proc.stdout == ""


def assert_scene_refused(run: Callable[..., Ran], folder: Path, text: str, fragment: str) -> None:
    """``mcchain run`` of the scene ``text`` (written into ``folder``): one line with
    ``fragment``, exit code 2, and nothing written beside the scene file."""
    (folder / "scene.toml").write_text(text)
    assert_usage_error(run("run", "scene.toml", "--out", "runs", cwd=folder), fragment)
    assert sorted(p.name for p in folder.iterdir()) == ["scene.toml"]


def test_cli__console_entry_point_smoke(tmp_path: Path) -> None:
    """One real process: ``python -m mcchain.cli`` exits 2 with the one-line message."""
    env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{TESTS}"}
    proc = subprocess.run(
        [sys.executable, "-m", "mcchain.cli", "run", "missing.toml"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert_usage_error(proc, "missing.toml: no such file")
    assert list(tmp_path.iterdir()) == []


def test_cli_help__says_what_the_tool_is_for_a_user(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``mcchain --help`` opens with what the tool does, in plain text (no docstring markup),
    and points to the scene reference."""
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--help"])
    out = capsys.readouterr().out
    assert exit_info.value.code == 0
    description = " ".join(out.split("\n\n")[1].split())
    assert description.startswith("Monte Carlo studies of planar linkages")
    assert "clearance" in description and "verdicts" in description
    assert "``" not in out and "docs/scenes.md" in out


@pytest.mark.parametrize(
    ("files", "args", "fragments"),
    [
        ({}, ["run", "missing.toml"], ["missing.toml: no such file"]),
        ({"bad.toml": "[scene\nname = 1"}, ["run", "bad.toml"], ["bad.toml: malformed TOML"]),
        ({"neg.toml": NEGATIVE_MASS}, ["run", "neg.toml"], ["body.bar.mass: must be > 0"]),
        ({"red.toml": REDUNDANT}, ["run", "red.toml"], ["negative degrees of freedom"]),
        ({}, ["run", CLEARANCE_BAR, "--samples", "0"], ["--samples: must be >= 1"]),
        ({}, ["run", CLEARANCE_BAR, "--chunk-size", "x"], ["--chunk-size: expected an integer"]),
        ({}, ["run", CLEARANCE_BAR, "--seed", "-4"], ["--seed: must be >= 0"]),
        ({}, ["run", CLEARANCE_BAR, "--threads", "100000"], ["--threads: at most"]),
        ({}, ["run", CLEARANCE_BAR, "--dask", "nowhere"], ["--dask: expected 'local'"]),
        ({}, ["run", CLEARANCE_BAR, "--bogus"], ["unrecognized arguments: --bogus"]),
        ({}, ["run"], ["a SCENE.toml (or --resume RUN) is required"]),
        ({}, ["run", CLEARANCE_BAR, "--resume", "r"], ["--resume: cannot be combined with SCENE"]),
        ({}, ["run", "--resume", "nope"], ["nope: no such run folder"]),
        ({"r": None}, ["run", CLEARANCE_BAR, "--run-dir", "r"], ["--run-dir: r already exists"]),
        ({}, ["frobnicate"], ["invalid choice: 'frobnicate'"]),
        ({}, [], ["required: command"]),
        ({}, ["validate", "missing.toml"], ["missing.toml: no such file"]),
    ],
)
def test_cli__bad_input_is_one_line_exit_2_and_writes_nothing(
    mcchain: Callable[..., Ran],
    tmp_path: Path,
    files: dict[str, str | None],
    args: list[str],
    fragments: list[str],
) -> None:
    for name, text in files.items():
        if text is None:
            (tmp_path / name).mkdir()
        else:
            (tmp_path / name).write_text(text)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert_usage_error(mcchain(*args, cwd=tmp_path), *fragments)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no runs/ folder


def test_cli_validate__prints_bodies_joints_rows_and_dof(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    proc = mcchain("validate", CLEARANCE_BAR, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "scene clearance-bar: 1 bodies, 1 joints, 0 drivers" in out
    assert "  bar: mass 2 kg, inertia 0.166667 kg m2, position [0, -0.501] m" in out
    assert "  O: ground (bearing) - bar (journal), clearance 0.001 m, row 0" in out
    assert "constraint rows: 1\n" in out and "degrees of freedom: 2\n" in out
    assert list(tmp_path.iterdir()) == []


def test_cli_validate__a_sweep_prints_nominal_values_and_sampled_ranges(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    proc = mcchain("validate", REPO / "configs" / "clearance-sweep.toml", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    # the scene file's values, not the first sample's
    assert "  bar: mass 2 kg," in out and "clearance 0.001 m, row 0" in out
    lines = out.splitlines()
    ranges = lines[lines.index("sampled (range over the samples):") + 1 :][:2]
    lo, hi = (float(x) for x in ranges[0].split(": ")[1].split(" … "))
    assert ranges[0].startswith("  joint.O.clearance: ")
    assert 1e-4 <= lo < 1.1e-4 and 9.9e-4 < hi <= 1e-3
    assert ranges[1].startswith("  body.bar.mass: ")


def test_cli_validate__four_bar_rows_and_driver(
    mcchain: Callable[..., Ran], tmp_path: Path
) -> None:
    proc = mcchain("validate", REPO / "configs" / "fourbar-clearance.toml", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert any(line.startswith("drivers:") for line in lines)
    assert any("ideal, rows 0-1" in line for line in lines)
    # joint B's contact law, K from its clearance (1e-4 m), pin radius and steel
    joint_b = next(line for line in lines if line.startswith("  B:"))
    assert "model auto: lankarani-nikravesh law, stiffness 7.65787e+10 N m-1.5" in joint_b
    assert joint_b.endswith("exponent 1.5, restitution 0.9")
    rows = int(next(x for x in lines if x.startswith("constraint rows:")).split(":")[1])
    dof = int(next(x for x in lines if x.startswith("degrees of freedom:")).split(":")[1])
    coords = int(next(x for x in lines if x.startswith("coordinates:")).split(":")[1])
    assert coords - rows == dof


def test_cli_runs__lists_the_runs_of_a_folder(mcchain: Callable[..., Ran], tmp_path: Path) -> None:
    scene = write_fake_scene(tmp_path / "s.toml", name="listed", count=9)
    made = [
        plan.start_run(
            scene, out=tmp_path / "out", loader=fake_loader, solve=fake_solve, progress=False
        ).folder
        for _ in range(2)
    ]
    proc = mcchain("runs", "--out", tmp_path / "out", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].split() == ["id", "scene", "samples", "status", "wall", "state"]
    for folder, line in zip(made, lines[1:], strict=True):
        cells = line.split()
        assert cells[0] == folder.name and cells[1] == "listed" and cells[2] == "9"
        assert cells[-1] == "COMPLETED" and cells[-2].endswith("s")
        assert any(c.startswith("ok=") for c in cells)
    empty = mcchain("runs", "--out", tmp_path / "none", cwd=tmp_path)
    assert empty.returncode == 0 and "no runs" in empty.stdout


def fresh_interpreter(code: str) -> str:
    """What a fresh interpreter prints running ``code`` with this tree's mcchain (what it
    imports is then only what ``code`` needs)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return proc.stdout


def test_cli_runs__does_not_import_numpy_numba_or_xarray() -> None:
    code = (
        "import sys; from mcchain import cli; cli.main(['runs', '--out', '/nonexistent']);"
        "print(sorted(m for m in ('numpy', 'numba', 'xarray', 'netCDF4', 'dask')"
        " if m in sys.modules))"
    )
    assert fresh_interpreter(code).splitlines()[-1] == "[]"


def test_cli_show__parses_and_calls_show_run(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from mcchain.viz import show

    calls: list[tuple[Any, ...]] = []

    def show_run(run: str, samples: list[int], **options: Any) -> list[int]:
        calls.append((run, samples, options))
        return [*samples, 9]

    monkeypatch.setattr(show, "show_run", show_run)
    argv = ["show", "RUN", "--samples", "3,0,3", "--worst", "energy:1", "--save", "x.rrd"]
    assert cli.main(argv) == 0
    assert capsys.readouterr().out == "samples 3,0,9\nx.rrd\n"
    ((run, samples, options),) = calls
    assert run == "RUN" and samples == [3, 0]
    assert options == {
        "worst": "energy:1",
        "status": None,
        "limit": 16,
        "failed": None,
        "save": "x.rrd",
        "serve": False,
        "connect": False,
        "url": None,
        "stdout": False,
        "headless": False,
        "magnify": 100.0,
        "force_scale": None,
    }
    assert cli.main(["show", "RUN", "--samples", "0,a"]) == 2
    assert capsys.readouterr().err == (
        "mcchain: error: --samples: expected comma-separated integers, got '0,a'\n"
    )


def test_cli_report__parses_and_calls_write_report(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from mcchain.viz import report, report_page

    calls: list[tuple[str, str | None]] = []

    def write_report(run: str, out: str | None = None) -> report.Report:
        calls.append((run, out))
        return report.Report([Path("d/a.png")], {"sobol.png": "no design"})

    monkeypatch.setattr(report_page, "write_report", write_report)
    assert cli.main(["report", "RUN", "--out", "d"]) == 0
    assert calls == [("RUN", "d")]
    assert capsys.readouterr().out == "skipped sobol.png: no design\nd/a.png\n"
    assert cli.main(["report"]) == 2
    assert capsys.readouterr().err == (
        "mcchain: error: mcchain report: the following arguments are required: run\n"
    )


def test_console_main__collects_cycles_less_often_in_its_own_process_only() -> None:
    """The ``mcchain`` process sets the collector's youngest generation to
    GC_FIRST_GENERATION before its command runs; importing the package (a library call, the
    tests) leaves Python's thresholds as they were."""
    code = (
        "import gc, mcchain.cli as cli\n"
        "print(gc.get_threshold())\n"
        "cli.main = lambda: print(gc.get_threshold()) or 0\n"
        "cli.console_main()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    imported, in_command = out.stdout.splitlines()
    assert imported == "(700, 10, 10)"
    assert in_command == "(50000, 20, 20)"
