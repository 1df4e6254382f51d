"""codegen: rows of B that fix a body's accelerations alone (a driven crank's pivot and
driver, a slider's guide angle) are taken out of S = B M⁻¹ Bᵀ (``Emitter.eliminate_fixed``):
those accelerations from the rows before the solve, the rows' λ from the body's equations
after it. The same solution in exact arithmetic: the runs agree with the text that keeps
the rows within rounding, reactions and driver torques included. The adaptive stage writes
the coordinates those rows fix in closed form (``Emitter.prescribe``): the crank's angle is
θ0 + ω t and its centre the pivot's to rounding, and the run agrees with the integrated one
to its tolerance."""

from __future__ import annotations

import re

import numpy as np
import pytest

from mcchain.codegen import emitter, generate
from mcchain.codegen.emitter import Emitter, _substitution
from mcchain.codegen.native import NativeModule
from mcchain.codegen.topology import Topology
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing.scenes import (
    DOUBLE_PENDULUM,
    flores_pin_text,
    fourbar_text,
    model_of,
    slider_crank_text,
    straight_chain_text,
)

ROUNDING_RTOL = 1e-11
"""Two roundings of the same fixed-step run apart (a few hundred steps): far below the
method's error."""


def _loose_crank() -> str:
    """The slider-crank with a radial clearance of 0.1 mm at the crank's ground pivot (the
    massless link: a row of the crank's alone, not fixed by substitution), turning at
    10 rad/s (at the default 100π the link's force changes sign: contact lost)."""
    return slider_crank_text(omega=10.0).replace(
        'bodies = ["ground", "crank"]', 'bodies = ["ground", "crank"]\nclearance = 1e-4'
    )


def _fixed(text: str) -> dict[int, list[tuple[int, int]]]:
    """{body: [(row, column), ...]} that the emitter takes out of S."""
    em = Emitter(Topology.from_model(model_of(text, nsample=1)))
    em.bodies()
    em.joints()
    return em.fixed_accelerations()


def test_fixed_accelerations__a_driven_crank_and_a_slider_s_angle():
    # the slider-crank: the crank (body 0) by its driver's row (its angle), then its ground
    # pivot's rows 0, 1 (x, y); the slider (body 2) by its guide's angle row (column 8)
    topo = Topology.from_model(model_of(slider_crank_text(), nsample=1))
    angle_row = topo.joint_row[3] + 1  # joint P: its normal row, then its angle row
    assert _fixed(slider_crank_text()) == {
        0: [(topo.driver_row[0], 2), (0, 0), (1, 1)],
        2: [(angle_row, 8)],
    }
    four = Topology.from_model(model_of(fourbar_text(), nsample=1))
    assert _fixed(fourbar_text()) == {0: [(four.driver_row[0], 2), (0, 0), (1, 1)]}
    # no driver: a pendulum on its ground pivot keeps a degree of freedom
    assert _fixed(straight_chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4})) == {}
    # clearance at the crank's ground pivot: the driver still fixes its angle
    loose = _loose_crank()
    assert _fixed(loose)[0] == [(Topology.from_model(model_of(loose, nsample=1)).driver_row[0], 2)]


def test_fixed_accelerations__not_a_body_in_a_contact_joint_with_friction():
    # the Flores slider-crank: the piston pin's contact joint joins the rod and the slider,
    # frictionless: the slider's angle is fixed; with friction the slider keeps its rows
    assert sorted(_fixed(flores_pin_text())) == [0, 2]
    rough = flores_pin_text().replace("poisson_ratio = 0.3", "poisson_ratio = 0.3\nfriction = 0.1")
    assert "friction = 0.1" in rough  # the premise
    assert sorted(_fixed(rough)) == [0]


def test_fixed_accelerations__a_redundant_row_keeps_the_body_s_rows():
    # a second angle row on the crank (as a driver on a body that cannot turn would give):
    # nothing of it would be left for S, so the crank keeps its rows there
    em = Emitter(Topology.from_model(model_of(slider_crank_text(), nsample=1)))
    em.bodies()
    em.joints()
    em._rows_cache = [*em.rows(), {2: -1.0}]
    assert list(em.fixed_accelerations()) == [2]  # the slider's angle only


@pytest.mark.parametrize(
    ("equations", "unknowns", "plan"),
    [
        # a crank: the driver's row first, then its pivot's two rows
        ({0: {0: 1.0, 2: "w"}, 1: {1: 1.0, 2: "u"}, 7: {2: 1.0}}, {0, 1, 2},
         [(7, 2), (0, 0), (1, 1)]),
        ({0: {0: -1.0}}, {0}, [(0, 0)]),  # −1 pivots too
        ({0: {0: 2.0}}, {0}, []),  # a division: not taken
        ({0: {0: 1.0, 1: 1.0}, 1: {0: 1.0, 1: -1.0}}, {0, 1}, []),  # coupled
        ({0: {0: "a"}}, {0}, []),  # a coefficient that varies
        # a slider: its angle row alone; its normal row keeps x and y open
        ({6: {6: "nx", 7: "ny", 8: "w"}, 7: {8: 1.0}}, {6, 7, 8}, [(7, 8)]),
    ],
)  # fmt: skip
def test_substitution__one_unknown_and_a_unit_pivot_at_each_step(equations, unknowns, plan):
    assert _substitution(equations, unknowns) == plan


def test_generate__the_crank_s_rows_leave_the_factorisation():
    topo = Topology.from_model(model_of(flores_pin_text(), nsample=1))
    text = generate.generate_source(topo, "rk45")
    stage = text[text.index("def group_stage_hertz_dp") :]
    stage = stage[: stage.index("@njit", 10)]
    # eight rows (O 2, A 2, B 1, P 2, driver 1) of which four are factored: not the crank's
    # three nor the slider's angle row
    assert len(set(re.findall(r"\bokp(\d+)__1 =", stage))) == 4
    assert "fqdd2__1 = gam7__2" in stage  # the crank's angular acceleration from its driver
    assert "fqdd8__1 = gam6__2" in stage  # the slider's from its guide


def _both(monkeypatch, model, sim: dict) -> tuple[dict, dict]:
    """The lanes' run of ``model`` with the elimination (as generated) and without it."""
    topo = Topology.from_model(model)
    variant = sim["method"]
    eliminated = generate.generate_source(topo, variant)
    monkeypatch.setattr(emitter.Emitter, "eliminate_fixed", False)
    kept = generate.generate_source(topo, variant)
    monkeypatch.undo()
    assert kept != eliminated  # the premise
    start = assemble(model)
    mine = simulate(model, sim, start.q, start.v, np.float64, status=start.status)
    module = NativeModule(kept, f"prescribed_kept_{variant.replace('-', '_')}")
    monkeypatch.setattr(generate, "lane_kernels", lambda *args: module)
    reference = simulate(model, sim, start.q, start.v, np.float64, status=start.status)
    return mine, reference


@pytest.mark.parametrize(
    ("method", "loose"), [("rk4", False), ("rk4-projection", False), ("rk4", True)]
)
def test_fixed_step_lanes__the_same_run_within_rounding(monkeypatch, method, loose):
    """The driven slider-crank at 50 Hz over 300 steps (and with clearance at the crank's
    pivot: only its angle fixed): positions, velocities, every joint's force (the crank's
    ground pivot's from the crank's equations) and the driver's torque."""
    model = model_of(_loose_crank() if loose else slider_crank_text(), nsample=8)
    sim = dict(t_end=0.03, dt=1e-4, output_dt=1e-3, method=method, kernels="lanes")
    mine, reference = _both(monkeypatch, model, sim)
    assert (mine["status"] == 0).all() and (reference["status"] == 0).all()
    for name in ("q", "v", "joint_force", "driver_torque", "energy", "constraint_error"):
        a, b = np.asarray(mine[name]), np.asarray(reference[name])
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        scale = np.nanmax(np.abs(b)) if name != "constraint_error" else 1e-3  # m: |Φ| ≪ it
        np.testing.assert_allclose(a, b, rtol=0, atol=ROUNDING_RTOL * scale, equal_nan=True)


def test_rk45_lanes__the_flores_pin_within_its_tolerance(monkeypatch):
    """The Flores slider-crank (the piston pin on the contact law after it lets go, 12 ms):
    the adaptive lanes with and without the elimination take steps that round apart, so
    they agree to the run's tolerance, not to rounding; peak forces within 1e-6."""
    model = model_of(flores_pin_text(t_end=0.012), nsample=8)
    sim = dict(t_end=0.012, dt=1e-7, output_dt=1e-4, method="rk45", rtol=1e-9, atol=1e-12,
               kernels="lanes")  # fmt: skip
    mine, reference = _both(monkeypatch, model, sim)
    assert (mine["status"] == 0).all() and (reference["status"] == 0).all()
    np.testing.assert_allclose(mine["q"], reference["q"], rtol=0, atol=1e-9)
    for name in ("peak_joint_force", "peak_driver_torque", "peak_contact_force"):
        np.testing.assert_allclose(mine[name], reference[name], rtol=1e-6)


def _harmonic_crank() -> str:
    """The slider-crank with a harmonic driver (a swing on top of θ0 + ω t)."""
    law = 'law = "harmonic"\namplitude = 0.1\nfrequency = 20.0\nphase = 0.3\n'
    return slider_crank_text().replace('body = "crank"\nomega', f'body = "crank"\n{law}omega')


def test_prescribed_coordinates__the_closed_forms_of_the_fixed_rows():
    # the crank's angle (driver at constant speed), then its centre (ideal pivot to the
    # ground); the slider's angle (its guide's angle row); in the fixed rows' order
    topo = Topology.from_model(model_of(slider_crank_text(), nsample=1))
    angle_row = topo.joint_row[3] + 1
    em = Emitter(topo)
    assert em.prescribed_coordinates() == [
        (0, topo.driver_row[0], 2), (0, 0, 0), (0, 1, 1), (2, angle_row, 8)
    ]  # fmt: skip
    loose = Topology.from_model(model_of(_loose_crank(), nsample=1))
    assert Emitter(loose).prescribed_coordinates()[:1] == [(0, loose.driver_row[0], 2)]
    assert all(b != 0 or c == 2 for b, _, c in Emitter(loose).prescribed_coordinates())
    double = straight_chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4})
    assert Emitter(Topology.from_model(model_of(double, nsample=1))).prescribed_coordinates() == []
    # a harmonic law's swing stays in the rows: nothing of the crank in closed form
    swing = Topology.from_model(model_of(_harmonic_crank(), nsample=1))
    assert swing.harmonic_drivers == (0,)  # the crank's driver, the only one
    assert [b for b, _, _ in Emitter(swing).prescribed_coordinates()] == [2]


def test_rk45_lanes__the_crank_follows_its_closed_form(monkeypatch):
    """The adaptive lanes on the slider-crank (no contact law, 20 ms at 50 Hz): the crank's
    angle is θ0 + ω t and its centre −A(θ) s (the pivot at the origin), with their rates, to
    rounding at every output after the start (the assembled state's); the slider's angle its
    guide's; against the same lanes
    integrating those coordinates (``prescribe`` off), positions within 1e-9 m and the driver's
    torque within 1e-6 of its largest."""
    omega, angle0, half = 100.0 * np.pi, 0.7, 0.025
    model = model_of(slider_crank_text(), nsample=4)
    sim = dict(t_end=0.02, dt=1e-5, output_dt=1e-3, method="rk45", rtol=1e-9, atol=1e-12,
               kernels="lanes")  # fmt: skip
    topo = Topology.from_model(model)
    integrated = generate.generate_source(topo, "rk45")
    monkeypatch.setattr(emitter.Emitter, "prescribe", False)
    assert generate.generate_source(topo, "rk45") != integrated  # the premise
    monkeypatch.undo()
    start = assemble(model)
    mine = simulate(model, sim, start.q, start.v, np.float64, status=start.status)
    assert (mine["status"] == 0).all()
    t = np.asarray(mine["time"])
    q, v = np.asarray(mine["q"]), np.asarray(mine["v"])
    crank, w = q[:, :, 0], v[:, :, 0]  # (sample, time, [x, y, θ])
    theta = np.broadcast_to(angle0 + omega * t, crank[..., 2].shape)
    np.testing.assert_allclose(crank[..., 2], theta, rtol=4e-16)
    np.testing.assert_allclose(w[:, 1:, 2], omega, rtol=1e-15)  # t0: the assembly's v
    np.testing.assert_allclose(w[:, 0, 2], omega, rtol=1e-14)
    np.testing.assert_allclose(crank[..., 0], half * np.cos(theta), rtol=0, atol=1e-17)
    np.testing.assert_allclose(crank[..., 1], half * np.sin(theta), rtol=0, atol=1e-17)
    np.testing.assert_allclose(w[..., 0], -omega * half * np.sin(theta), rtol=0, atol=1e-14)
    np.testing.assert_allclose(w[..., 1], omega * half * np.cos(theta), rtol=0, atol=1e-14)
    assert (q[:, 1:, 2, 2] == 0.0).all() and (v[:, 1:, 2, 2] == 0.0).all()  # the guide's 0
    monkeypatch.setattr(emitter.Emitter, "prescribe", False)
    module = NativeModule(generate.generate_source(topo, "rk45"), "prescribed_integrated_rk45")
    monkeypatch.undo()
    monkeypatch.setattr(generate, "lane_kernels", lambda *args: module)
    reference = simulate(model, sim, start.q, start.v, np.float64, status=start.status)
    np.testing.assert_allclose(q, reference["q"], rtol=0, atol=1e-9)
    torque = np.asarray(reference["driver_torque"])
    np.testing.assert_allclose(mine["driver_torque"], torque, atol=1e-6 * np.abs(torque).max())
