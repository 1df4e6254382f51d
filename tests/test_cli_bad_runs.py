"""Bad inputs around runs (not scenes): each is one line naming the argument or key and the
reason, exit code 2, and nothing written — no run folder, no changed ``run.json``."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from test_cli_commands import CLEARANCE_BAR, Ran, assert_usage_error, in_process


@pytest.fixture
def mcchain(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> Callable[..., Ran]:
    return in_process(monkeypatch, capsys)


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
