"""codegen: the fixed-step lanes drop from B M⁻¹F the pairs of terms uniform gravity cancels
(``Emitter.cancel_gravity``); the adaptive lanes keep them."""

from __future__ import annotations

import re

import numpy as np
import pytest

from mcchain.codegen import emitter, generate
from mcchain.codegen.emitter import _cancelling
from mcchain.codegen.native import NativeModule
from mcchain.codegen.topology import Topology
from mcchain.solvers.simulate import simulate
from mcchain.testing.scenes import DOUBLE_PENDULUM, model_of, straight_chain_text

GRAVITY = {0: "p_gx", 1: "p_gy", 2: 0.0, 3: "p_gx", 4: "p_gy", 5: 0.0}
"""Free accelerations of two bodies under gravity alone."""

ROUNDING_RTOL = 1e-12
"""Two roundings of the same run apart over 200 steps: far below the method's error."""


@pytest.mark.parametrize(
    ("row", "gone"),
    [
        # a clearance joint between bodies 0 and 1: its x and y terms cancel in pairs
        ({3: "ex1", 4: "ey1", 5: "(a + b)", 0: "(-ex1)", 1: "(-ey1)", 2: "(c)"}, {0, 1, 3, 4}),
        # a revolute joint between them: ±1
        ({3: 1.0, 5: "(-pb1y)", 0: -1.0, 2: "pa1y"}, {0, 3}),
        # a joint to the ground: nothing to cancel
        ({0: 1.0, 2: "(-pb0y)"}, set()),
        # the same coefficient twice is no pair; nor are x against y
        ({3: "ex1", 0: "ex1"}, set()),
        ({3: "ex1", 1: "(-ex1)"}, set()),
    ],
)
def test_cancelling__only_opposite_coefficients_under_the_same_gravity(row, gone):
    assert _cancelling(row, GRAVITY) == gone


def test_cancelling__a_loaded_body_keeps_its_terms():
    loaded = {**GRAVITY, 3: "a0_3", 4: "a0_4"}  # body 1 carries a load or a spring
    assert _cancelling({3: "ex1", 4: "ey1", 0: "(-ex1)", 1: "(-ey1)"}, loaded) == set()


def _clearance_model(nsample: int):
    return model_of(straight_chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4}), nsample=nsample)


def test_generate__fixed_step_lanes_drop_the_cancelling_gravity_terms():
    topo = Topology.from_model(_clearance_model(1))
    term = re.compile(r"\(-ex1\w*\) \* p_gx")  # body 0's term in the clearance row
    assert term.search(generate.generate_source(topo, "rk45"))  # kept, and its bits
    for variant in ("rk4", "rk4-projection"):
        assert not term.search(generate.generate_source(topo, variant))


def test_rk4_lanes__without_the_cancelling_terms_the_same_run_within_rounding(monkeypatch):
    """The clearance double pendulum by rk4 lanes, its text as generated and with the terms
    written out: the same values within rounding (the terms are zero in exact arithmetic)."""
    model = _clearance_model(16)
    topo = Topology.from_model(model)
    monkeypatch.setattr(emitter, "_cancelling", lambda row, a0: set())
    written = generate.generate_source(topo, "rk4")
    monkeypatch.undo()
    assert written != generate.generate_source(topo, "rk4")  # the premise
    sim = dict(t_end=0.02, dt=1e-4, output_dt=1e-3, method="rk4", kernels="lanes")
    mine = simulate(model, sim, history_dtype=np.float64)
    module = NativeModule(written, "gravity_written_out")
    monkeypatch.setattr(generate, "lane_kernels", lambda *args: module)
    reference = simulate(model, sim, history_dtype=np.float64)
    assert (mine["status"] == 0).all() and (reference["status"] == 0).all()
    for name in ("q", "v", "joint_force", "contact_force", "energy"):
        a, b = mine[name], reference[name]
        assert np.array_equal(np.isnan(a), np.isnan(b)), name  # the ideal joint's NaN
        atol = ROUNDING_RTOL * np.nanmax(np.abs(b))
        np.testing.assert_allclose(a, b, rtol=0, atol=atol, equal_nan=True)
