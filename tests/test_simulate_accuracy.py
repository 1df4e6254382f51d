"""simulate: convergence orders, agreement with radau and with minimal coordinates, energy."""

from __future__ import annotations

import numpy as np
import pytest

from mcchain.solvers.simulate import simulate
from mcchain.testing.comparisons import HISTORIES, REFERENCE, failed, history_errors
from mcchain.testing.dense import _body, _param, clearance_angle
from mcchain.testing.minimal import clearance_bar_minimal, double_pendulum_minimal
from mcchain.testing.scenes import scene_model

pytestmark = (
    pytest.mark.slow
)  # convergence orders and references: minutes of integration at tight tolerances

ORDER_SLACK = 0.3  # fitted slope within ±0.3 of the theoretical order
MINIMAL_TOL = 1e-9  # m: radau (index 1, absolute coordinates) vs a minimal-coordinate DOP853
ENERGY_TOL = 1e-9  # relative drift over 2 s, rk4 at dt 1e-5 (issue 3)
RADAU = REFERENCE


def _run(model, **sim):
    return simulate(model, sim, history_dtype=np.float64)


def _order(method: str, steps, t_end=0.2) -> float:
    """Slope of log(error at t_end) against log(dt), errors against radau (rtol 1e-12)."""
    model = scene_model("clearance_bar")
    ref = _run(model, t_end=t_end, dt=t_end / 10, output_dt=t_end / 10, **RADAU)["q"][0, -1]
    errors = []
    for dt in steps:
        q = _run(model, t_end=t_end, dt=dt, output_dt=t_end / 10, method=method)["q"][0, -1]
        errors.append(np.abs(q - ref).max())
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


@pytest.mark.parametrize(
    ("method", "order", "steps"),
    [
        ("rk4", 4, [1e-3, 5e-4, 2.5e-4, 1.25e-4]),
        ("rk4-projection", 4, [1e-3, 5e-4, 2.5e-4, 1.25e-4]),
        ("generalized-alpha", 2, [1e-3, 5e-4, 2.5e-4, 1.25e-4]),
    ],
)
def test_simulate__measured_order_on_the_clearance_bar(method, order, steps):
    assert abs(_order(method, steps) - order) <= ORDER_SLACK


@pytest.mark.parametrize("comparison", HISTORIES, ids=lambda c: c.scene)
def test_rk4__matches_radau(comparison):
    model = scene_model(comparison.scene)
    ref = comparison.reference(model)
    out = _run(model, **comparison.settings(dt=1e-5, method="rk4"))
    assert failed(out["status"])[0] == 0 and failed(ref["status"])[0] == 0
    position, force = history_errors(out, ref)
    assert position <= comparison.position_tol
    assert force <= comparison.force_tol


def _minimal_start(model, q, v, joints):
    """(p, ṗ) of a minimal model from absolute q, v: body angles and clearance angles."""
    pa, pb = _param(model, "joint_point_a", 0), _param(model, "joint_point_b", 0)
    p, pd = [], []
    for kind, index in joints:
        if kind == "body":
            p.append(q[3 * index + 2])
            pd.append(v[3 * index + 2])
        else:
            a, b = int(model.joint_body_a[index]), int(model.joint_body_b[index])
            ra, Aa, va, wa = _body(q, v, a)
            rb, Ab, vb, wb = _body(q, v, b)
            ua, ub = Aa @ pa[index], Ab @ pb[index]
            d = rb + ub - ra - ua
            om = np.array([[0.0, -1.0], [1.0, 0.0]])
            dd = vb + wb * om @ ub - va - wa * om @ ua
            angle, rate = clearance_angle(d, dd)
            p.append(angle)
            pd.append(rate)
    return np.array(p), np.array(pd)


@pytest.mark.parametrize(
    ("name", "builder", "joints"),
    [
        ("clearance_bar", clearance_bar_minimal, [("joint", 0), ("body", 0)]),
        ("double_pendulum", double_pendulum_minimal, [("body", 0), ("joint", 1), ("body", 1)]),
    ],
)
def test_radau__matches_minimal_coordinates(name, builder, joints):
    """The index-1 formulation (incl. the clearance Φ̈ term) against a Lagrangian in (θ, α)."""
    model = scene_model(name)
    out = _run(model, t_end=0.2, dt=0.01, output_dt=0.01, **RADAU)
    p0, pd0 = _minimal_start(model, model.q0[0], model.v0[0], joints)
    q_ref, _ = builder(model).integrate(p0, pd0, out["time"])
    q = out["q"][0].reshape(len(out["time"]), -1)
    assert np.abs(q - q_ref).max() <= MINIMAL_TOL


def test_rk4__conserves_energy_of_the_clearance_bar():
    model = scene_model("clearance_bar")
    out = _run(model, t_end=2.0, dt=1e-5, output_dt=1e-2, method="rk4")
    e = out["energy"][0]
    assert out["status"][0] == 0
    assert np.abs(e - e[0]).max() <= ENERGY_TOL * np.abs(e[0])


@pytest.mark.parametrize(
    ("method", "dt", "q_tol", "torque_tol"),
    [
        ("rk4", 1e-5, 1e-10, 1e-8),  # 4th order at dt 1e-5: ~1e-13 m measured
        ("rk4-projection", 1e-5, 1e-10, 1e-8),
        ("generalized-alpha", 1e-5, 1e-7, 1e-4),  # 2nd order: ~2e-9 m, 2e-6 relative torque
        ("rk45", 1e-3, 1e-9, 1e-6),  # rtol 1e-10: ~2e-11 m
    ],
)
def test_every_method__drives_the_four_bar(method, dt, q_tol, torque_tol):
    model = scene_model("fourbar")
    ref = _run(model, t_end=0.05, dt=1e-3, output_dt=1e-3, **RADAU)
    out = _run(model, t_end=0.05, dt=dt, output_dt=1e-3, method=method, rtol=1e-10, atol=1e-12)
    assert out["status"][0] == 0
    assert np.abs(out["q"] - ref["q"]).max() <= q_tol
    peak = np.abs(ref["driver_torque"]).max()
    assert np.abs(out["driver_torque"] - ref["driver_torque"]).max() <= torque_tol * peak
