"""The loop kernels (``[simulate] kernels = "loop"``, one compile for every topology) against
the generated lane kernels: the same RK4 steps, checks and outputs, to 1e-12."""

from __future__ import annotations

import numpy as np
import pytest
from test_cli_commands import assert_usage_error, in_process

from mcchain.errors import SceneError
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing import dense
from mcchain.testing.factory import write_scene
from mcchain.testing.scenes import scene_model, straight_chain_text

AGREEMENT = 1e-12
"""Largest difference between the two paths, relative to each output's largest value."""
HISTORIES = ("q", "v", "joint_force", "contact_force", "driver_torque", "energy")

CHAIN = straight_chain_text([0.5, 0.4, 0.3, 0.45, 0.35, 0.25], [1.0, 0.8, 0.6, 0.9, 0.7, 0.5])


def _both(model, **extra):
    start = assemble(model)
    sim = dict(t_end=0.05, dt=1e-5, output_dt=1e-3, method="rk4", **extra)
    return {
        kernels: simulate(
            model, dict(sim, kernels=kernels), q_start=start.q, v_start=start.v,
            history_dtype=np.float64,
        )
        for kernels in ("lanes", "loop")
    }  # fmt: skip


@pytest.mark.parametrize("name", ["chain", "fourbar", "double_pendulum"])
def test_loop__agrees_with_the_lanes(name):
    chain = compile_model(load_scene_text(CHAIN))
    model = chain if name == "chain" else scene_model(name, nsample=3)
    out = _both(model)
    lanes, loop = out["lanes"], out["loop"]
    np.testing.assert_array_equal(lanes["status"], loop["status"])
    np.testing.assert_array_equal(lanes["time"], loop["time"])
    for var in HISTORIES:
        a, b = lanes[var], loop[var]
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=var)
        if np.isfinite(a).any():
            scale = np.nanmax(np.abs(a))
            assert np.nanmax(np.abs(a - b)) <= AGREEMENT * scale, var
    # the constraint error is rounding noise on both paths: compare it to the size
    assert np.nanmax(np.abs(lanes["constraint_error"] - loop["constraint_error"])) <= 1e-12


def test_loop__flags_and_fails_as_the_lanes():
    """A start far off the joints diverges at t = 0 on both paths, with NaN histories."""
    model = scene_model("double_pendulum", nsample=2)
    start = assemble(model)
    q = start.q.copy()
    q[1, 0] += 0.01  # sample 1 starts 1 cm off its joint: past the tolerance
    sim = dict(t_end=0.01, dt=1e-5, output_dt=1e-3, method="rk4")
    runs = [
        simulate(model, dict(sim, kernels=k), q_start=q, v_start=start.v, history_dtype=np.float64)
        for k in ("lanes", "loop")
    ]
    for out in runs:
        assert out["status"][0] == 0 and out["status"][1] != 0
        assert np.isnan(out["q"][1]).all() and out["diverged_time"][1] == 0.0
    np.testing.assert_array_equal(runs[0]["status"], runs[1]["status"])


def test_loop__refuses_a_method_it_does_not_have(tmp_path, monkeypatch, capsys):
    text = CHAIN + '[simulate]\nt_end = 0.01\ndt = 1e-4\nkernels = "loop"\nmethod = "rk45"\n'
    ran = in_process(monkeypatch, capsys)("validate", write_scene(tmp_path, text), cwd=tmp_path)
    assert_usage_error(ran, "simulate.kernels: \"loop\" integrates with rk4, not 'rk45'")


def test_loop__a_contact_law_needs_the_lanes():
    text = scene_text_with_contact()
    with pytest.raises(SceneError, match=r'simulate\.kernels: "loop" has no contact law'):
        load_scene_text(text)


def scene_text_with_contact() -> str:
    from pathlib import Path

    config = Path(__file__).resolve().parents[1] / "configs" / "fourbar-clearance.toml"
    text = config.read_text()
    return text.replace('method = "rk45"', 'method = "rk4"\nkernels = "loop"')


def test_constraint_pattern__rows_touch_their_bodies_and_the_envelope_is_tight():
    """The four-bar: rows O2 (0-1), A (2-3), B (4, clearance), O4 (5-6), the crank's driver
    (7); each row's coordinates, and the first row it shares one with."""
    model = scene_model("fourbar")
    cols, first = model.constraint_pattern()
    crank, coupler, rocker = [0, 1, 2], [3, 4, 5], [6, 7, 8]
    expected = [
        crank,
        crank,
        crank + coupler,
        crank + coupler,
        coupler + rocker,
        rocker,
        rocker,
        [2],
    ]
    for row, want in enumerate(expected):
        assert [c for c in cols[row] if c >= 0] == want, row
    np.testing.assert_array_equal(first, [0, 0, 0, 0, 2, 4, 4, 0])
    # S = B M⁻¹ Bᵀ is zero left of the envelope at any configuration
    q = np.random.default_rng(0).normal(size=model.ndof)
    B = dense.constraint_jacobian_formula(model, 0, q)
    S = B @ np.diag(1.0 / dense.mass_diagonal(model, 0)) @ B.T
    for i, f in enumerate(first):
        assert not S[i, :f].any()
