"""simulate: contact-loss flags, determinism across threads/chunks/lanes, history dtype."""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
import pytest

from mcchain.solvers import simulate as simulate_module
from mcchain.solvers.simulate import METHODS, simulate
from mcchain.status import ASSEMBLY_FAILED, CONTACT_LOST
from mcchain.testing.scenes import scene_model

KEYS = ("q", "v", "joint_force", "contact_force", "driver_torque", "constraint_error", "energy")


def _fourbar(nsample: int):
    """The driven four-bar with clearances spread over [5e-5, 2e-4] m (start re-projected)."""
    model = scene_model("fourbar")
    clearance = np.repeat(model.joint_clearance, nsample, axis=0)
    clearance[:, 2] = np.linspace(5e-5, 2e-4, nsample)
    return dataclasses.replace(model, nsample=nsample, joint_clearance=clearance)


# A zero perturbation of the driven angle re-projects the start onto each sample's clearance.
PROJECT = {"body.crank.angle": 0.0}


def test_contact_lost__flag_and_time_agree_with_the_stored_contact_force():
    model = _fourbar(6)
    out = simulate(
        model, dict(t_end=0.3, dt=1e-5, output_dt=1e-5, perturb=PROJECT), history_dtype=np.float64
    )
    cf = out["contact_force"][:, :, 2]
    lost = out["status"] & CONTACT_LOST != 0
    assert lost.any()
    for s in range(model.nsample):
        negative = np.nonzero(cf[s] <= 0.0)[0]
        assert bool(lost[s]) == bool(len(negative))
        if len(negative):
            assert out["contact_lost_time"][s] == out["time"][negative[0]]
        else:
            assert np.isnan(out["contact_lost_time"][s])


def _bits(out):
    return {k: np.ascontiguousarray(out[k]).view(np.uint8).tobytes() for k in KEYS}


@pytest.mark.parametrize("method", ["rk4", "rk4-projection"])
def test_simulate__bit_identical_across_threads_chunks_and_lanes(method):
    model = _fourbar(70)
    sim = dict(t_end=0.02, dt=1e-5, output_dt=1e-3, method=method, perturb=PROJECT)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = simulate(model, sim, history_dtype=np.float64)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = simulate(model, sim, history_dtype=np.float64, lanes=3)
        parts = [
            simulate(model.select(a, b), sim, history_dtype=np.float64)
            for a, b in ((0, 9), (9, 70))
        ]
    finally:
        numba.set_num_threads(threads)
    joined = {k: np.concatenate([p[k] for p in parts]) for k in KEYS}
    assert _bits(one) == _bits(two) == _bits(joined)
    np.testing.assert_array_equal(one["status"], two["status"])


def test_rk45__bit_identical_across_chunks_and_lanes():
    model = scene_model("parallelogram", nsample=40)
    v_start = model.v0 * np.linspace(0.5, 1.5, 40)[:, None]
    sim = dict(t_end=0.1, dt=1e-3, output_dt=1e-2, method="rk45", rtol=1e-9, atol=1e-12)
    whole = simulate(model, sim, v_start=v_start, history_dtype=np.float64, lanes=3)
    parts = [
        simulate(model.select(a, b), sim, v_start=v_start[a:b], history_dtype=np.float64, lanes=2)
        for a, b in ((0, 13), (13, 40))
    ]
    joined = {k: np.concatenate([p[k] for p in parts]) for k in KEYS}
    assert _bits(whole) == _bits(joined)
    assert not whole["status"].any()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_simulate__history_dtype(dtype):
    model = scene_model("clearance_bar")
    out = simulate(model, dict(t_end=0.01, dt=1e-3), history_dtype=dtype)
    assert all(out[k].dtype == dtype for k in KEYS)
    assert out["q"].shape == (1, 11, 1, 3) and out["joint_force"].shape == (1, 11, 1, 2)
    assert out["time"].shape == (11,) and out["status"].dtype == np.uint32


@pytest.mark.parametrize("lanes", [0, 1000])
def test_simulate__lane_count_outside_the_work_rows_is_refused(lanes):
    from mcchain.codegen.generate import lane_rows
    from mcchain.codegen.topology import Topology

    model = scene_model("clearance_bar")
    rows = lane_rows(Topology.from_model(model), "rk4")
    with pytest.raises(ValueError, match=rf"^lanes: must be in 1\.\.{rows} .* got {lanes}$"):
        simulate(model, dict(t_end=1e-3, dt=1e-4), lanes=lanes)


@pytest.mark.parametrize("method", list(METHODS))
def test_simulate__outputs_from_a_failure_on_are_nan_as_the_method_writes_them(method, monkeypatch):
    """The histories are filled with +inf before the method runs, so an element it leaves
    unwritten fails the test: before a sample's failure time every output is finite, from it
    on NaN; a sample failed on entry is NaN throughout."""
    allocate = simulate_module._allocate

    def sentinel(*args, **kwargs):
        out = allocate(*args, **kwargs)
        for array in out.values():
            array.fill(np.inf)
        return out

    monkeypatch.setattr(simulate_module, "_allocate", sentinel)
    model = scene_model("clearance_bar", nsample=4)
    v_start = np.repeat(model.v0, 4, axis=0)
    v_start[:, 2] += [0.0, 5.0, 40.0, 0.0]  # Φ̇ ≠ 0: the constraint error grows past tolerance
    status = np.array([0, 0, 0, ASSEMBLY_FAILED], np.uint32)
    sim = dict(t_end=0.02, dt=1e-3, output_dt=1e-3, method=method)
    out = simulate(model, sim, v_start=v_start, status=status, history_dtype=np.float64)
    fail = np.fmin(out["diverged_time"], out["singular_time"])
    assert np.isnan(fail[0]) and np.isfinite(fail[2]) and out["status"][3] & ASSEMBLY_FAILED
    for s in range(4):
        first = 0 if s == 3 else int(np.searchsorted(out["time"], fail[s], side="left"))
        for key in KEYS:
            assert np.isfinite(out[key][s, :first]).all(), (key, s)
            assert np.isnan(out[key][s, first:]).all(), (key, s)
