"""What a warm run loads besides its compute: numba's kernels from its cache without the
target context's registries (numba's implementations of everything it can compile, and
scipy.linalg, which they import), the same bits as a process that installed them; a compile
after such loads still finds every implementation; a light load that raises falls back to
numba's own.

The run checks start a fresh interpreter (what a run imported is what ``sys.modules`` holds
there); its ensemble is compared byte for byte with the same run in this process, whose
target context numba refreshed.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mcchain.runner import plan
from mcchain.testing.scenes import config_text, with_lines

REPO = Path(__file__).resolve().parents[1]

REGISTRIES = "['numba.np.arraymath', 'numba.np.linalg', 'scipy.linalg']"
"""Modules only numba's target-context refresh imports in a warm run (printed as those of
them a fresh interpreter holds)."""


def requirement_scene(tmp_path: Path) -> Path:
    """configs/slider-crank-requirement.toml, 4 samples, 3 ms, no histories: the statics
    check, the ideal reference's knots (``relative_to = "ideal"``), the rk45 lanes, the
    verdict."""
    lines = {"count": "count = 4", "t_end": "t_end = 0.003", "window": "window = [0.002, 0.003]"}
    text = with_lines(config_text("slider-crank-requirement.toml"), lines)
    path = tmp_path / "requirement.toml"
    path.write_text(text + '\n[storage]\nhistories = "none"\n', "utf-8")
    return path


@pytest.mark.slow  # a fresh interpreter loads the kernels (2-5 s)
def test_warm_run__loads_numbas_kernels_without_its_registries_with_the_same_bits(
    tmp_path: Path,
) -> None:
    """The run in a fresh interpreter (its kernels cached by the same run here first)
    imports none of :data:`REGISTRIES` and writes the ensemble this process writes; a
    kernel compiled afterwards in that interpreter (``np.linalg.norm``: an implementation
    of the registries) compiles and gives numpy's value."""
    scene = requirement_scene(tmp_path)
    here = plan.start_run(scene, run_dir=tmp_path / "here", progress=False)
    code = f"""
import sys
from pathlib import Path
import numpy as np
from mcchain.runner import plan
plan.start_run(Path({str(scene)!r}), run_dir=Path({str(tmp_path / "fresh")!r}), progress=False)
print([m for m in {REGISTRIES} if m in sys.modules])
from mcchain.kernels.config import njit
norm = njit(lambda x: np.linalg.norm(x))
print(repr(norm(np.array([3.0, 4.0, 12.0]))))
"""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    *_, loaded, norm = out.stdout.splitlines()
    assert loaded == "[]"
    assert norm == "13.0"
    ensemble = here.folder / "ensemble.nc"
    assert ensemble.read_bytes() == (tmp_path / "fresh" / "ensemble.nc").read_bytes()


class _Cache:
    """A numba cache whose light load raises (what a load needing a registry would do)."""

    def __init__(self) -> None:
        self.own_loads = 0

    @contextlib.contextmanager
    def _guard_against_spurious_io_errors(self) -> Any:
        yield

    def _load_overload(self, signature: Any, target_context: Any) -> Any:
        raise KeyError("an implementation the registries hold")

    def load_overload(self, signature: Any, target_context: Any) -> Any:
        self.own_loads += 1
        return ("numba's own load", signature)


def test_load_cached__numbas_own_load_where_the_light_one_raises() -> None:
    from numba.core.registry import cpu_target

    from mcchain.kernels.config import load_cached

    cache = _Cache()
    assert load_cached(cache, "sig", cpu_target.target_context) == ("numba's own load", "sig")
    assert cache.own_loads == 1


def test_njit__cached_kernels_load_lightly_others_as_numba_does() -> None:
    """A ``cache=True`` kernel's cache loads through :func:`load_cached`; a kernel without a
    cache keeps numba's (nothing to load)."""
    from mcchain.kernels.config import JIT, load_cached, njit
    from mcchain.kernels.linalg import null_space

    assert null_space._cache.load_overload.func is load_cached
    assert null_space._cache.load_overload.args == (null_space._cache,)
    plain = njit(**{**JIT, "cache": False})(lambda x: x + 1.0)
    assert not hasattr(plain._cache.load_overload, "func")
    assert plain(np.float64(1.0)) == 2.0


def test_verdict_lines__the_summarys_modules_imported_beside_the_compute() -> None:
    """In a fresh interpreter: the first chunk done starts their import on a thread of its
    own, which has ended, the modules imported, once the computing is over."""
    code = """
import sys
from mcchain.runner.observers import VerdictLines
verdict = VerdictLines()
print(["mcchain.decision.summary" in sys.modules, "scipy.special" in sys.modules])
verdict.on_chunk_done(None, None)
started = verdict._imports
verdict.on_chunk_done(None, None)
verdict.on_chunks_done(None)
print(["mcchain.decision.summary" in sys.modules, "scipy.special" in sys.modules])
print([verdict._imports is started, started.is_alive()])
"""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.splitlines() == ["[False, False]", "[True, True]", "[True, False]"]
