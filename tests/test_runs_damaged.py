"""A damaged ``ensemble.nc``: one line that says how to rebuild it, and ``--remerge`` rebuilds
the very file the run wrote first."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from test_cli_commands import assert_usage_error, in_process

import mcchain
from mcchain.errors import RunError

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def completed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, bytes]:
    """A completed 300-sample statics run in 3 chunks, and its ensemble's bytes."""
    from mcchain.runner.plan import start_run

    out = tmp_path_factory.mktemp("runs")
    result = start_run(
        REPO / "configs" / "clearance-sweep.toml", samples=300, chunk_size=100, out=out,
        progress=False,
    )  # fmt: skip
    return result.folder, (result.folder / "ensemble.nc").read_bytes()


@pytest.fixture
def damaged(completed, tmp_path: Path) -> Path:
    """A copy of the completed run whose ensemble.nc is cut in half."""
    folder = tmp_path / completed[0].name
    shutil.copytree(completed[0], folder)
    data = completed[1]
    (folder / "ensemble.nc").write_bytes(data[: len(data) // 2])
    return folder


def test_open_run__a_cut_file_says_how_to_rebuild_it(damaged: Path) -> None:
    with pytest.raises(RunError, match=r"ensemble\.nc: cannot be read .* --remerge$"):
        mcchain.open_run(damaged)


@pytest.mark.parametrize("command", ["report", "show", "verdict"])
def test_commands__one_line_exit_2(damaged, tmp_path, monkeypatch, capsys, command) -> None:
    extra = ["--save", tmp_path / "x.rrd"] if command == "show" else []
    ran = in_process(monkeypatch, capsys)(command, damaged, *extra, cwd=tmp_path)
    assert_usage_error(ran, "ensemble.nc: cannot be read", f"mcchain run --resume {damaged}")
    assert not (damaged / "report").exists() and not (tmp_path / "x.rrd").exists()


def test_resume__a_completed_run_with_a_damaged_file_points_to_remerge(
    damaged, tmp_path, monkeypatch, capsys
) -> None:
    ran = in_process(monkeypatch, capsys)("run", "--resume", damaged, cwd=tmp_path)
    assert_usage_error(ran, "already completed, but", "--remerge")


def test_remerge__rebuilds_the_same_bytes(damaged, completed, tmp_path, monkeypatch, capsys):
    ran = in_process(monkeypatch, capsys)(
        "run", "--resume", damaged, "--remerge", "--quiet", cwd=tmp_path
    )
    assert ran.returncode == 0, ran.stderr
    assert (damaged / "ensemble.nc").read_bytes() == completed[1]
    assert (damaged / "ensemble.damaged.nc").exists()
    mcchain.open_run(damaged).close()


def test_remerge__only_with_resume(tmp_path, monkeypatch, capsys) -> None:
    ran = in_process(monkeypatch, capsys)(
        "run", REPO / "configs" / "clearance-bar.toml", "--remerge", cwd=tmp_path
    )
    assert_usage_error(ran, "--remerge: only with --resume RUN")
