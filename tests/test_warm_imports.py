"""A warm run loads what it uses: scipy.optimize (0.2-0.9 s of CPU to import) only where a
root or a peak is located, the radau kernels of the retry ladder only when a retry reaches
them — and then they load on demand and solve as a run that started with them; a radau
solve loads one compiled radau entry and no kernel that has nothing to do.

Each check runs in a fresh interpreter (what a run imported is what ``sys.modules`` holds
there); the values are compared with the same solve in this process.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.peaks import dense_peaks
from mcchain.solvers.radau import EVENT_XTOL, locate_root
from mcchain.testing.scenes import config_text, with_lines

REPO = Path(__file__).resolve().parents[1]

LOADED = "['scipy.optimize', 'mcchain.kernels.radau', 'mcchain.solvers.radau']"
"""The modules a fresh interpreter is asked about (printed as those of them it holds)."""


def fresh(code: str) -> list[str]:
    """The lines ``code`` prints in a fresh interpreter running this tree."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout.splitlines()


def slider_crank(method: str) -> str:
    """configs/slider-crank-flores.toml with ``method``, 2 samples, 0.5 ms."""
    lines = {"count": "count = 2", "t_end": "t_end = 0.0005", "method": f'method = "{method}"'}
    return with_lines(config_text("slider-crank-flores.toml"), lines)


@pytest.mark.slow  # a fresh interpreter loads the kernels (2-5 s)
def test_warm_imports__an_rk45_run_imports_no_radau_nor_scipy_optimize_until_a_retry_does(
    tmp_path: Path,
) -> None:
    """The run (warm-up and chunks, as ``mcchain run``) imports neither; a radau solve after
    it in that process (what the retry ladder's last attempt calls) loads the radau kernels
    then and gives the bits this process gives."""
    scene_path = tmp_path / "rk45.toml"
    scene_path.write_text(slider_crank("rk45"), encoding="utf-8")
    radau_path = tmp_path / "radau.toml"
    radau_path.write_text(slider_crank("radau"), encoding="utf-8")
    saved = tmp_path / "peaks.npy"
    code = f"""
import sys
from pathlib import Path
import numpy as np
from mcchain.runner import plan
from mcchain.scene import compile_model, load_scene
from mcchain.solvers import solve_chunk

plan.start_run(Path({str(scene_path)!r}), run_dir=Path({str(tmp_path / "run")!r}), progress=False)
print([m for m in {LOADED} if m in sys.modules])
scene = load_scene({str(radau_path)!r})
out = solve_chunk(compile_model(scene), scene, with_modes=False)
np.save({str(saved)!r}, out["peak_joint_force"])
print([m for m in {LOADED} if m in sys.modules])
"""
    after_run, after_retry = fresh(code)[-2:]
    assert after_run == "[]"
    assert after_retry == str(["scipy.optimize", "mcchain.kernels.radau", "mcchain.solvers.radau"])
    scene = load_scene_text(slider_crank("radau"))
    here = solve_chunk(compile_model(scene), scene, with_modes=False)["peak_joint_force"]
    assert np.isfinite(here).all()
    np.testing.assert_array_equal(np.load(saved), here)


def test_warm_imports__dense_peaks_imports_scipy_optimize_only_for_a_peak_to_locate() -> None:
    """No column to track (all NaN): nothing imported; a column with a peak between step
    ends: imported, and the peak found is the continuous one."""
    code = """
import sys
import numpy as np
from mcchain.solvers.peaks import dense_peaks
ts = np.linspace(0.0, 1.0, 5)
peaks = np.array([-np.inf])
dense_peaks(lambda t: np.array([t]), ts, lambda t, y: np.array([np.nan]), peaks)
print('scipy.optimize' in sys.modules)
dense_peaks(lambda t: np.array([t]), ts, lambda t, y: np.array([1.0 - (t - 0.3) ** 2]), peaks)
print('scipy.optimize' in sys.modules, repr(float(peaks[0])))
"""
    untracked, tracked = fresh(code)[-2:]
    assert untracked == "False"
    located, peak = tracked.split()
    assert located == "True"
    # the step ends (0, 0.25, 0.5, ...) give 0.9975; the continuous peak is 1 at t = 0.3
    assert float(peak) == pytest.approx(1.0, abs=1e-12)
    peaks = np.array([-np.inf])
    dense_peaks(lambda t: np.array([t]), np.linspace(0.0, 1.0, 5), lambda t, y: y, peaks)
    assert peaks[0] == 1.0  # a monotone quantity: its end, where it is largest


def test_warm_imports__locate_root_is_brentq_at_the_event_tolerance() -> None:
    """The root of t² - 2 on [1, 2]: √2 to the tolerance the events are located with."""
    root = locate_root(lambda t: t * t - 2.0, 1.0, 2.0)
    assert abs(root - np.sqrt(2.0)) <= 2.0 * EVENT_XTOL * np.sqrt(2.0)
    assert locate_root(lambda t: t - 1.0, 1.0, 2.0) == 1.0  # a root at the bracket's end


RADAU_KERNELS = [
    ("mcchain.kernels.clearance", "contact_start"),
    ("mcchain.kernels.clearance", "record_stage0"),
    ("mcchain.kernels.explicit", "finish_contact"),
    ("mcchain.kernels.explicit", "index1_acceleration"),
    ("mcchain.kernels.explicit", "write_outputs"),
    ("mcchain.kernels.forces", "mass_diagonal"),
    ("mcchain.kernels.peaks", "peak_values"),
    ("mcchain.kernels.radau", "radau_kernel"),
]
"""The kernels a radau solve of the slider-crank (no [[output]], no failure) loads from
numba's cache: one stepping entry (start and step), not radau_start and radau_step, each
holding the accelerations' code, and the accelerations the driver evaluates between steps;
not nan_history (no time left unwritten), nor the outputs' kernels (no [[output]])."""


@pytest.mark.slow  # two fresh interpreters load the kernels (2-5 s each)
def test_warm_imports__a_radau_solve_loads_one_radau_entry_and_no_idle_kernel(
    tmp_path: Path,
) -> None:
    """The kernels loaded from numba's cache inside ``run_radau`` (a fresh interpreter, after
    one that filled the cache): :data:`RADAU_KERNELS`, each a cache hit, each once."""
    scene_path = tmp_path / "radau.toml"
    scene_path.write_text(slider_crank("radau"), encoding="utf-8")
    code = f"""
import numba.core.caching as caching
from mcchain.scene import compile_model, load_scene
from mcchain.solvers import radau, solve_chunk

loads, inside = [], [False]
load = caching.Cache._load_overload  # numba's load and mcchain's light one


def recorded(self, sig, target_context):
    found = load(self, sig, target_context)
    if inside[0]:
        loads.append((self._py_func.__module__, self._py_func.__name__, found is not None))
    return found


run_radau = radau.run_radau


def traced(*args):
    inside[0] = True
    try:
        run_radau(*args)
    finally:
        inside[0] = False


caching.Cache._load_overload = recorded
radau.run_radau = traced
scene = load_scene({str(scene_path)!r})
out = solve_chunk(compile_model(scene), scene, with_modes=False)
assert (out["status"] == 0).all(), out["status"]
print(sorted(loads))
"""
    fresh(code)  # fills the cache where it lacks a kernel
    loaded = fresh(code)[-1]
    assert loaded == str(sorted((module, name, True) for module, name in RADAU_KERNELS))
