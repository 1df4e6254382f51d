"""A module of the repository as it was at an earlier commit, for before/after benchmarks."""

from __future__ import annotations

import subprocess
import sys
import types
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def module_at(commit: str, path: str) -> types.ModuleType:
    """The module ``path`` (e.g. ``mcchain/decision/subset.py``) at ``commit``, read with
    ``git show`` and executed as a module of its own (its imports are today's)."""
    source = subprocess.run(
        ["git", "show", f"{commit}:{path}"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout
    name = f"{Path(path).stem}_at_{commit}"
    module = types.ModuleType(name)
    sys.modules[name] = module  # dataclasses look their module up
    exec(compile(source, f"{commit}:{path}", "exec"), module.__dict__)
    return module
