"""``mcchain validate`` from the command line runs its kernels interpreted (no numba):
the same lines as the compiled kernels, bit for bit the same numbers, and a fallback to
the compiled kernels where the interpreted check raises."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import in_process
from test_runs_support import REPO

from mcchain.scene import compile_model, load_scene
from mcchain.solvers.statics import assemble, solve_equilibrium

CONFIGS = sorted((REPO / "configs").glob("*.toml"))


def _python(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    environ = {**os.environ, "PYTHONPATH": str(REPO), **(env or {})}
    return subprocess.run(
        [sys.executable, *args], env=environ, capture_output=True, text=True, timeout=600
    )


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_validate__interpreted_prints_what_the_compiled_kernels_print(
    config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    interpreted = _python("-m", "mcchain.cli", "validate", str(config))
    compiled = in_process(monkeypatch, capsys)("validate", config, cwd=tmp_path)
    assert (interpreted.returncode, compiled.returncode) == (0, 0), interpreted.stderr
    assert interpreted.stdout == compiled.stdout
    assert interpreted.stderr == compiled.stderr == ""


def test_validate__imports_no_numba_from_the_command_line() -> None:
    proc = _python("-X", "importtime", "-m", "mcchain.cli", "validate", str(CONFIGS[0]))
    assert proc.returncode == 0
    imported = [line.rsplit("|", 1)[-1].strip() for line in proc.stderr.splitlines()]
    assert "numpy" in imported
    assert not [name for name in imported if name.split(".")[0] in ("numba", "llvmlite")]


def test_kernels__interpreted_and_compiled_give_the_same_bits(tmp_path: Path) -> None:
    """Assembly and equilibrium of sampled instances: the interpreted kernels do the same
    IEEE operations in the same order as the compiled ones (no fast-math, no FMA)."""
    scenes = ["clearance-sweep", "fourbar-clearance-statics", "slider-crank-flores"]
    code = (
        "import sys, numpy as np\n"
        "from mcchain.kernels.config import interpret_kernels\n"
        "assert interpret_kernels()\n"
        "from mcchain.scene import compile_model, load_scene\n"
        "from mcchain.solvers.statics import assemble, solve_equilibrium\n"
        "for k, path in enumerate(sys.argv[2:]):\n"
        "    model = compile_model(load_scene(path), nsample=4)\n"
        "    a = assemble(model)\n"
        "    e = solve_equilibrium(model, a.q, a.status)\n"
        "    np.savez(f'{sys.argv[1]}/{k}.npz', q=a.q, status=a.status, q_eq=e.q, lam=e.lam)\n"
        "print('numba' in sys.modules)\n"
    )
    paths = [str(REPO / "configs" / f"{name}.toml") for name in scenes]
    proc = _python("-c", code, str(tmp_path), *paths)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "False"
    for k, path in enumerate(paths):
        model = compile_model(load_scene(path), nsample=4)
        a = assemble(model)
        e = solve_equilibrium(model, a.q, a.status)
        saved = np.load(tmp_path / f"{k}.npz")
        np.testing.assert_array_equal(saved["q"], a.q)
        np.testing.assert_array_equal(saved["status"], a.status)
        np.testing.assert_array_equal(saved["q_eq"], e.q)
        np.testing.assert_array_equal(saved["lam"], e.lam)


def test_validate__falls_back_to_the_compiled_kernels_where_the_interpreted_check_raises(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    """A degenerate instance can raise in plain Python where numba gives inf or NaN: the
    check then runs again, compiled, in a fresh process, and prints what it prints."""
    config = REPO / "configs" / "clearance-bar.toml"
    code = (
        "import sys\n"
        "from mcchain import cli\n"
        "from mcchain.kernels.config import interpret_kernels\n"
        "assert interpret_kernels()\n"
        "def degenerate(path):\n"
        "    raise ZeroDivisionError('float division by zero')\n"
        "cli._validation_lines = degenerate\n"
        "sys.stdout.flush()\n"
        "sys.exit(cli.main(['validate', sys.argv[1]]))\n"
    )
    proc = _python("-c", code, str(config))
    compiled = in_process(monkeypatch, capsys)("validate", config, cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout == compiled.stdout, proc.stderr
