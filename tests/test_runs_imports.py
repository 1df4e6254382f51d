"""The modules ``mcchain runs`` and ``mcchain run`` load before a run starts import only the
standard library (the import circles are tests/test_layering.py's)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "mcchain"

LIGHT = (
    "mcchain.cli",
    "mcchain.runner.runs",
    "mcchain.runner.job",
    "mcchain.runner.plan",
    "mcchain.runner.pipeline",
    "mcchain.runner.steps",
    "mcchain.runner.store",
    "mcchain.runner.observers",
    "mcchain.runner.executors",
    "mcchain.runner.provenance",
    "mcchain.runner.summary",
    "mcchain.compiled.ready",
    "mcchain.viz.live",
)
"""Modules that import only the standard library (and each other) at import time."""


def fresh(code: str) -> list[str]:
    """The lines ``code`` prints in a fresh interpreter running this tree."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return proc.stdout.splitlines()


@pytest.mark.parametrize("module", LIGHT)
def test_light_module__imports_only_the_standard_library(module: str) -> None:
    """Imported alone in a fresh interpreter: no third-party module gets loaded."""
    code = (
        "import sys; before = set(sys.modules)\n"
        f"import {module}\n"
        "print(sorted({m.split('.')[0] for m in set(sys.modules) - before}"
        " - set(sys.stdlib_module_names) - {'mcchain'}))"
    )
    assert fresh(code)[-1] == "[]"


@pytest.mark.slow  # a fresh interpreter loads the kernels (2-5 s)
def test_run__without_dask_imports_no_dask_scheduler(tmp_path: Path) -> None:
    """A run on this machine (no ``--dask``) reads its merged ensemble back for the retry
    counts and the verdict lines without a Dask graph: computing one looked for a scheduler
    and imported distributed, 0.7 s of every run (xarray itself imports dask and dask.array,
    for its type checks)."""
    from mcchain.testing.scenes import config_text, with_lines

    scene = tmp_path / "slider.toml"
    two_samples = with_lines(config_text("slider-crank-requirement.toml"), {"count": "count = 2"})
    scene.write_text(two_samples)
    code = (
        "import sys\n"
        "from mcchain.runner import plan\n"
        f"result = plan.start_run({str(scene)!r}, run_dir={str(tmp_path / 'run')!r},"
        " progress=False)\n"
        "print(result.record['requirements'][0].split(':')[0])\n"
        "print(sorted(m for m in ('distributed',) if m in sys.modules))"
    )
    *_, requirement, imported = fresh(code)
    assert requirement.startswith("requirement ") and imported == "[]"
