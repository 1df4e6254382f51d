"""Bad inputs around runs (not scenes): each is one line naming the argument or key and the
reason, exit code 2, and nothing written — no run folder, no changed ``run.json``."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from test_cli_commands import CLEARANCE_BAR, Ran, assert_usage_error
from test_runs_support import fake_loader, fake_solve, write_fake_scene

from mcchain.runner import plan


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def failed_fake_run(tmp_path: Path) -> Path:
    """A fake run of 30 samples whose second chunk of 10 failed (one part file kept)."""
    calls = 0

    def solve(model: Any, scene: Any) -> Any:
        nonlocal calls
        calls += 1
        if calls == 3:  # warm-up, chunk 0, then chunk 1 fails
            raise FloatingPointError("boom")
        return fake_solve(model, scene)

    scene = write_fake_scene(tmp_path / "s.toml", count=30)
    with pytest.raises(FloatingPointError):
        plan.start_run(scene, out=tmp_path / "runs", chunk_size=10, loader=fake_loader, solve=solve)
    (folder,) = (tmp_path / "runs").iterdir()
    return folder


def test_cli_run__missing_dask_names_the_extra_to_install(
    mcchain: Callable[..., Ran], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A None entry in sys.modules makes `import dask.distributed` raise ImportError.
    monkeypatch.setitem(sys.modules, "dask", None)
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    for address in ("local", "tcp://127.0.0.1:8786"):
        proc = mcchain("run", CLEARANCE_BAR, "--dask", address, "--out", "runs", cwd=tmp_path)
        assert_usage_error(proc, "--dask: needs dask.distributed", "pip install 'mcchain[cluster]'")
    assert list(tmp_path.iterdir()) == []


def test_cli_run__unreachable_scheduler_is_one_line_and_leaves_no_folder(
    mcchain: Callable[..., Ran], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from mcchain.runner import executors

    monkeypatch.setattr(executors, "CONNECT_TIMEOUT", 0.5)  # port 1 refuses at once anyway
    address = "tcp://127.0.0.1:1"
    proc = mcchain("run", CLEARANCE_BAR, "--dask", address, "--out", "runs", cwd=tmp_path)
    assert_usage_error(proc, f"--dask: no Dask scheduler answers at {address}")
    assert list(tmp_path.iterdir()) == []


def test_cli_resume__unreachable_scheduler_leaves_the_run_as_it_was(
    mcchain: Callable[..., Ran], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from mcchain.runner import executors

    monkeypatch.setattr(executors, "CONNECT_TIMEOUT", 0.5)
    folder = failed_fake_run(tmp_path)
    before = snapshot(folder)
    proc = mcchain("run", "--resume", folder, "--dask", "tcp://127.0.0.1:1", cwd=tmp_path)
    assert_usage_error(proc, "--dask: no Dask scheduler answers at tcp://127.0.0.1:1")
    assert snapshot(folder) == before


def completed_fake_run(tmp_path: Path, count: int = 12) -> Path:
    """A completed fake run of ``count`` samples in chunks of 5."""
    scene = write_fake_scene(tmp_path / "s.toml", count=count, steps=4)
    return plan.start_run(
        scene,
        out=tmp_path / "runs",
        chunk_size=5,
        loader=fake_loader,
        solve=fake_solve,
        progress=False,
    ).folder


@pytest.mark.parametrize(
    ("out", "fragment"),
    [
        ("blocker", "--out: blocker is a file, not a folder"),
        ("blocker/report", "--out: cannot create the folder blocker/report (Not a directory)"),
    ],
)
def test_cli_report__unwritable_out_is_one_line_and_writes_nothing(
    mcchain: Callable[..., Ran], tmp_path: Path, out: str, fragment: str
) -> None:
    folder = completed_fake_run(tmp_path)
    (tmp_path / "blocker").write_text("a file")
    before, files = snapshot(folder), sorted(p.name for p in tmp_path.iterdir())
    assert_usage_error(mcchain("report", folder, "--out", out, cwd=tmp_path), fragment)
    assert snapshot(folder) == before and (tmp_path / "blocker").read_text() == "a file"
    assert sorted(p.name for p in tmp_path.iterdir()) == files


def test_cli_report__read_only_out_is_one_line(
    mcchain: Callable[..., Ran], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = completed_fake_run(tmp_path)
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    # The permission as the OS reports it to a non-root user (root may write anyway, so the
    # check is made to see what a user sees, whoever runs the tests).
    access = os.access
    monkeypatch.setattr(
        os,
        "access",
        lambda path, mode, *a, **k: (
            False if Path(path).resolve() == locked.resolve() else access(path, mode, *a, **k)
        ),
    )
    proc = mcchain("report", folder, "--out", "locked", cwd=tmp_path)
    assert_usage_error(proc, "--out: cannot write into locked (permission denied)")
    assert list((tmp_path / "locked").iterdir()) == []
