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


@pytest.mark.parametrize("module", LIGHT)
def test_light_module__imports_only_the_standard_library(module: str) -> None:
    """Imported alone in a fresh interpreter: no third-party module gets loaded."""
    code = (
        "import sys; before = set(sys.modules)\n"
        f"import {module}\n"
        "print(sorted({m.split('.')[0] for m in set(sys.modules) - before}"
        " - set(sys.stdlib_module_names) - {'mcchain'}))"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert proc.stdout.splitlines()[-1] == "[]"
