"""``mcchain validate`` from the command line runs its kernels interpreted (no numba):
the same lines and the same bits as the compiled kernels, and a fallback to the compiled
kernels where the interpreted check raises."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import in_process
from test_runs_support import REPO

from mcchain.scene import compile_model, load_scene
from mcchain.solvers import solve_chunk

CONFIGS = sorted((REPO / "configs").glob("*.toml"))


def _python(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    environ = {**os.environ, "PYTHONPATH": str(REPO), **(env or {})}
    return subprocess.run(
        [sys.executable, *args], env=environ, capture_output=True, text=True, timeout=600
    )


VALIDATE_EACH = """
import contextlib, io, json, sys
from mcchain import cli
from mcchain.cli import commands
commands._may_interpret = True  # as console_main sets it for validate
printed = {}
for config in sys.argv[1:]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(["validate", config])
    printed[config] = (code, out.getvalue(), err.getvalue())
print(json.dumps({"numba": "numba" in sys.modules, "printed": printed}))
"""
"""``mcchain validate CONFIG`` for every config in turn, in one fresh process that may
interpret (as :func:`mcchain.cli.console_main` lets it): each command's exit code and
output, and whether numba was imported by any of them."""


@pytest.fixture(scope="module")
def validated_interpreted() -> dict[str, tuple[int, str, str]]:
    """What ``mcchain validate`` prints for each shipped config, interpreted: one process
    for all (a process costs about 0.6 s of CPU to start; the command line's own choice to
    interpret is :func:`test_validate__imports_no_numba_from_the_command_line`'s)."""
    proc = _python("-c", VALIDATE_EACH, *map(str, CONFIGS))
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.splitlines()[-1])
    assert result["numba"] is False  # every config ran interpreted
    return {path: tuple(printed) for path, printed in result["printed"].items()}


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_validate__interpreted_prints_what_the_compiled_kernels_print(
    config: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture,
    validated_interpreted: dict[str, tuple[int, str, str]],
) -> None:
    code, stdout, stderr = validated_interpreted[str(config)]
    compiled = in_process(monkeypatch, capsys)("validate", config, cwd=tmp_path)
    assert (code, compiled.returncode) == (0, 0), stderr
    assert stdout == compiled.stdout
    assert stderr == compiled.stderr == ""


def test_validate__imports_no_numba_from_the_command_line(
    validated_interpreted: dict[str, tuple[int, str, str]],
) -> None:
    """``mcchain validate`` as a process of its own interprets: no numba imported, and it
    prints what the check of the same config printed in the shared process above."""
    proc = _python("-X", "importtime", "-m", "mcchain.cli", "validate", str(CONFIGS[0]))
    assert proc.returncode == 0
    assert proc.stdout == validated_interpreted[str(CONFIGS[0])][1]
    imported = [line.rsplit("|", 1)[-1].strip() for line in proc.stderr.splitlines()]
    assert "numpy" in imported
    assert not [name for name in imported if name.split(".")[0] in ("numba", "llvmlite")]


def test_validate__a_large_scene_is_checked_compiled(tmp_path: Path) -> None:
    """Over ``INTERPRET_MAX_COORDINATES`` (34 bars: 102 coordinates) the interpreted check
    would be slower than loading numba (it grows with the cube of the size)."""
    from mcchain.kernels.config import INTERPRET_MAX_COORDINATES
    from mcchain.testing.factory import write_scene
    from mcchain.testing.scenes import straight_chain_text

    n = INTERPRET_MAX_COORDINATES // 3 + 1
    scene = write_scene(tmp_path, straight_chain_text([0.3] * n, [1.0] * n), "chain.toml")
    proc = _python("-X", "importtime", "-m", "mcchain.cli", "validate", str(scene))
    assert proc.returncode == 0, proc.stderr
    imported = [line.rsplit("|", 1)[-1].strip() for line in proc.stderr.splitlines()]
    assert "numba" in imported
    assert f"coordinates: {3 * n}" in proc.stdout


def test_kernels__interpreted_give_the_compiled_bits_on_every_shipped_scene(
    tmp_path: Path,
) -> None:
    """Assembly, equilibrium, modes (and modes along a driver) of every config, 8 samples
    each, interpreted against compiled: bit for bit. Both call libm's hypot
    (``config.hypot``); with Python's own ``math.hypot`` 3 of 64 four-bar samples differed
    by 1 ulp in q."""
    _assert_same_bits([str(path) for path in CONFIGS], tmp_path)


def test_kernels__interpreted_give_the_compiled_bits_on_random_chains(tmp_path: Path) -> None:
    """What the interpreted first run (mcchain.compiled.first_run) relies on, on mechanisms nobody
    wrote by hand: random chains of 1-5 bars mixing clearance, ideal and prismatic joints,
    springs and applied forces, 8 random samples each of their masses and clearances."""
    from mcchain.testing.factory import chain_scene_text, write_scene

    mixes = [
        dict(nbody=1, clearance_joints=(0,)),
        dict(nbody=2, clearance_joints=(1,), springs=1),
        dict(nbody=3, clearance_joints=(0, 2), forces=2),
        dict(nbody=3, prismatic_joints=(1,), springs=1),
        dict(nbody=4, clearance_joints=(1, 3), springs=2, forces=1),
        dict(nbody=5, clearance_joints=(0, 2, 4), spread=1.0),
    ]
    paths = []
    for seed, mix in enumerate(mixes):
        text = chain_scene_text(**mix, seed=seed, sample=8)  # type: ignore[arg-type]
        paths.append(str(write_scene(tmp_path, text, f"chain{seed}.toml")))
    _assert_same_bits(paths, tmp_path)


def _assert_same_bits(paths: list[str], tmp_path: Path) -> None:
    """Each scene's statics solved interpreted in a fresh process (no numba), then compiled
    here: the same arrays, bit for bit (NaN where NaN)."""
    code = (
        "import sys, warnings, numpy as np\n"
        "from mcchain.kernels.config import interpret_kernels\n"
        "assert interpret_kernels()\n"
        "from mcchain.scene import compile_model, load_scene\n"
        "from mcchain.solvers import solve_chunk\n"
        "warnings.simplefilter('ignore')\n"
        "for k, path in enumerate(sys.argv[2:]):\n"
        "    scene = load_scene(path).model_copy(update={'simulate': None})\n"
        "    model = compile_model(scene, nsample=8 if scene.sample else None)\n"
        "    with np.errstate(all='ignore'):\n"
        "        np.savez(f'{sys.argv[1]}/{k}.npz', **solve_chunk(model, scene))\n"
        "print('numba' in sys.modules)\n"
    )
    proc = _python("-c", code, str(tmp_path), *paths)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "False"
    for k, path in enumerate(paths):
        scene = load_scene(path).model_copy(update={"simulate": None})
        model = compile_model(scene, nsample=8 if scene.sample else None)
        compiled = solve_chunk(model, scene)
        interpreted = np.load(tmp_path / f"{k}.npz")
        assert sorted(interpreted.files) == sorted(compiled), path
        for name, value in compiled.items():
            if value.dtype.kind == "f":  # the bits: -0.0 and 0.0 differ, NaN equals NaN
                value = np.where(np.isnan(value), np.nan, value).view(np.uint64)
                other = np.where(np.isnan(interpreted[name]), np.nan, interpreted[name])
                np.testing.assert_array_equal(
                    other.view(np.uint64), value, err_msg=f"{path}: {name}"
                )
            else:
                np.testing.assert_array_equal(interpreted[name], value, err_msg=f"{path}: {name}")


def test_validate__falls_back_to_the_compiled_kernels_where_the_interpreted_check_raises(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    """A degenerate instance can raise in plain Python where numba gives inf or NaN: the
    check then runs again, compiled, in a fresh process, and prints what it prints."""
    config = REPO / "configs" / "clearance-bar.toml"
    code = (
        "import sys\n"
        "from mcchain import cli\n"
        "from mcchain.cli import commands\n"
        "commands._may_interpret = True  # as console_main sets it for validate\n"
        "def degenerate(path):\n"
        "    raise ZeroDivisionError('float division by zero')\n"
        "commands._validation_lines = degenerate\n"
        "sys.stdout.flush()\n"
        "sys.exit(cli.main(['validate', sys.argv[1]]))\n"
    )
    proc = _python("-c", code, str(config))
    compiled = in_process(monkeypatch, capsys)("validate", config, cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout == compiled.stdout, proc.stderr
