"""The loop kernels take float64 histories only (mcchain.solvers.history_rows): float32 ones
are written a block of samples at a time into float64 rows and stored. Stored float32, a
run's histories are its float64 histories rounded, and nothing else changes."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from mcchain.solvers.history_rows import ROWS_BLOCK
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.status import ASSEMBLY_FAILED
from mcchain.testing.scenes import scene_model

HISTORIES = ("q", "v", "joint_force", "contact_force", "driver_torque", "constraint_error",
             "energy")  # fmt: skip


@pytest.mark.parametrize("method", ["rk4-loop", "generalized-alpha", "radau"])
def test_loop_histories__float32_are_the_float64_ones_rounded(method):
    """Two blocks of rows and a part of one, on 2 threads, with a sample failed on entry
    (its rows NaN): each float32 history is its float64 one rounded, bit for bit, and every
    other variable is the same."""
    name, kernels = ("rk4", "loop") if method == "rk4-loop" else (method, "auto")
    model = scene_model("double_pendulum", nsample=2 * ROWS_BLOCK + 5)
    start = assemble(model)
    status = start.status.copy()
    status[ROWS_BLOCK + 1] |= ASSEMBLY_FAILED
    settings = {"t_end": 0.05, "dt": 1e-3, "output_dt": 1e-2, "method": name,
                "kernels": kernels}  # fmt: skip
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        runs = {
            dtype: simulate(
                model, settings, start.q, start.v, status=status.copy(), history_dtype=dtype
            )
            for dtype in (np.float64, np.float32)
        }
    finally:
        numba.set_num_threads(threads)
    wide, narrow = runs[np.float64], runs[np.float32]
    assert set(wide) == set(narrow)
    for key in HISTORIES:
        assert narrow[key].dtype == np.float32, key
        assert narrow[key].tobytes() == wide[key].astype(np.float32).tobytes(), key
    assert np.isnan(narrow["q"][ROWS_BLOCK + 1]).all() and np.isfinite(narrow["q"][0]).all()
    for key, value in wide.items():
        if key not in HISTORIES:
            assert np.asarray(narrow[key]).tobytes() == np.asarray(value).tobytes(), key
