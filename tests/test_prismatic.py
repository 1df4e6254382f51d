"""The prismatic (sliding) joint: a slider-crank against its closed form and Newton–Euler
reactions, statics and modes against closed forms and a dense reference, every integrator,
and the scene's checks.

Derivatives of the prismatic rows (B, γ, the constraint Hessian) are checked with every other
joint kind in ``test_kernels_derivatives.py`` (random chains with prismatic joints); the lane
kernels' acceleration and outputs against a dense KKT solve in ``test_simulate_methods.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_cli_commands import assert_usage_error, in_process

from mcchain.kernels.joints import constraint_gamma, constraint_jacobian
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble, solve_equilibrium, solve_modes
from mcchain.testing import dense
from mcchain.testing.factory import write_scene
from mcchain.testing.scenes import SLIDER_CRANK, TELESCOPE_TEXT, slider_crank_text

G = 9.81
OMEGA = 100.0 * np.pi  # one crank turn in 20 ms
PHI0 = 0.7


def closed_form(t: np.ndarray) -> dict[str, np.ndarray]:
    """The slider-crank of :func:`slider_crank_text` at crank angle φ = φ0 + ω t: the rod
    pin B at height e above the guide, x_B(φ) = r cos φ + √(l² − (e − r sin φ)²), the rod
    angle β (sin β = (e − r sin φ)/l) and their first and second time derivatives."""
    r, l, e = SLIDER_CRANK["crank"], SLIDER_CRANK["rod"], SLIDER_CRANK["pin_height"]
    phi = PHI0 + OMEGA * t
    sb = (e - r * np.sin(phi)) / l
    cb = np.sqrt(1.0 - sb**2)
    beta = np.arctan2(sb, cb)
    beta_d = -r * OMEGA * np.cos(phi) / (l * cb)
    beta_dd = (r * OMEGA**2 * np.sin(phi) / l + beta_d**2 * sb) / cb
    x = r * np.cos(phi) + l * cb
    x_d = -r * OMEGA * np.sin(phi) - l * sb * beta_d
    x_dd = -r * OMEGA**2 * np.cos(phi) - l * (cb * beta_d**2 + sb * beta_dd)
    return dict(phi=phi, beta=beta, beta_d=beta_d, beta_dd=beta_dd, x=x, x_d=x_d, x_dd=x_dd)


def newton_euler_reactions(t: np.ndarray) -> dict[str, np.ndarray]:
    """Joint forces (on b by a), the guide's couple and the driver torque from Newton–Euler
    on each body with the closed-form motion: 9 linear equations per instant."""
    d = SLIDER_CRANK
    r, l, e, g = d["crank"], d["rod"], d["pin_height"], d["guide_point"]
    k = closed_form(t)
    out = {name: [] for name in ("O", "A", "B", "P", "M", "T")}
    for i in range(t.size):
        phi, beta, bd, bdd = k["phi"][i], k["beta"][i], k["beta_d"][i], k["beta_dd"][i]
        u_c, u_r = np.array([np.cos(phi), np.sin(phi)]), np.array([np.cos(beta), np.sin(beta)])
        pin_a = r * u_c
        com_c = pin_a / 2
        com_r = pin_a + l / 2 * u_r
        com_s = np.array([k["x"][i], 0.0])  # below the pin B, on the guide
        pin_b = com_s + np.array([0.0, e])
        guide = com_s + np.array([g, 0.0])
        acc_c = -(OMEGA**2) * com_c
        acc_r = -(OMEGA**2) * pin_a + l / 2 * (bdd * np.array([-u_r[1], u_r[0]]) - bd**2 * u_r)
        acc_s = np.array([k["x_dd"][i], 0.0])
        # unknowns: F_O (2), F_A (2), F_B (2), f (normal, along +y), M, T
        A = np.zeros((9, 9))
        rhs = np.zeros(9)
        weight = np.array([0.0, -G])
        # crank: F_O − F_A + m g = m a;  (O − c) × F_O − (A − c) × F_A + T = 0
        A[0:2, 0:2], A[0:2, 2:4] = np.eye(2), -np.eye(2)
        rhs[0:2] = d["m_crank"] * (acc_c - weight)
        lever_o, lever_a = -com_c, pin_a - com_c
        A[2, 0:2] = [-lever_o[1], lever_o[0]]
        A[2, 2:4] = [lever_a[1], -lever_a[0]]
        A[2, 8] = 1.0
        # rod: F_A − F_B + m g = m a;  (A − c) × F_A − (B − c) × F_B = J β̈
        A[3:5, 2:4], A[3:5, 4:6] = np.eye(2), -np.eye(2)
        rhs[3:5] = d["m_rod"] * (acc_r - weight)
        lever_ra, lever_rb = pin_a - com_r, pin_b - com_r
        A[5, 2:4] = [-lever_ra[1], lever_ra[0]]
        A[5, 4:6] = [lever_rb[1], -lever_rb[0]]
        rhs[5] = d["J_rod"] * bdd
        # slider: F_B + f ŷ + m g = m a;  (B − c) × F_B + (G − c) × f ŷ + M = 0
        A[6:8, 4:6] = np.eye(2)
        A[7, 6] = 1.0
        rhs[6:8] = d["m_slider"] * (acc_s - weight)
        lever_sb, lever_sg = pin_b - com_s, guide - com_s
        A[8, 4:6] = [-lever_sb[1], lever_sb[0]]
        A[8, 6] = lever_sg[0]
        A[8, 7] = 1.0
        x = np.linalg.solve(A, rhs)
        out["O"].append(x[0:2])
        out["A"].append(x[2:4])
        out["B"].append(x[4:6])
        out["P"].append([0.0, x[6]])
        out["M"].append(x[7])
        out["T"].append(x[8])
    return {name: np.array(v) for name, v in out.items()}


@pytest.fixture(scope="module")
def cycle():
    """One crank turn of the slider-crank, rk4, float64 histories."""
    model = compile_model(load_scene_text(slider_crank_text(OMEGA, PHI0)))
    sim = dict(t_end=0.02, dt=1e-5, output_dt=1e-4, method="rk4")
    return model, _simulate(model, sim)


def _simulate(model, sim):
    """Integrate from the assembled start (the scene gives only the dimensions)."""
    start = assemble(model)
    return simulate(model, sim, q_start=start.q, v_start=start.v, history_dtype=np.float64)


def test_slider_crank__kinematics_match_the_closed_form_along_a_cycle(cycle):
    model, out = cycle
    t = out["time"]
    k = closed_form(t)
    q, v = out["q"].reshape(1, t.size, -1), out["v"].reshape(1, t.size, -1)
    assert not out["status"].any()
    pin_height = SLIDER_CRANK["pin_height"]
    # the slider's centre is below the pin B by e, on the guide (y = 0), not turning
    np.testing.assert_allclose(q[0, :, 6], k["x"], rtol=0, atol=1e-10)
    np.testing.assert_allclose(v[0, :, 6], k["x_d"], rtol=0, atol=1e-10 * OMEGA)
    assert np.abs(q[0, :, 7:9]).max() <= 1e-12 and np.abs(v[0, :, 7:9]).max() <= 1e-9
    np.testing.assert_allclose(q[0, :, 5], k["beta"], rtol=0, atol=1e-10)
    assert pin_height > 0
    # accelerations: B q̈ = γ (B square: the mechanism is fully driven) at the computed states
    km = model.kernel_model()
    B, gamma = np.zeros((model.ncon, model.ndof)), np.zeros(model.ncon)
    for i in range(0, t.size, 20):
        constraint_jacobian(km, 0, q[0, i], B)
        constraint_gamma(km, 0, q[0, i], v[0, i], t[i], gamma)
        qdd = np.linalg.solve(B, gamma)
        scale = OMEGA**2 * SLIDER_CRANK["crank"]
        assert abs(qdd[6] - k["x_dd"][i]) <= 1e-9 * scale
        assert abs(qdd[5] - k["beta_dd"][i]) <= 1e-9 * OMEGA**2


def test_slider_crank__reactions_match_newton_euler(cycle):
    model, out = cycle
    reference = newton_euler_reactions(out["time"])
    forces = out["joint_force"][0].reshape(-1, model.njoint, 2)
    for k, name in enumerate(model.joint_names):
        scale = np.abs(reference[name]).max()
        error = np.abs(forces[:, k] - reference[name]).max()
        assert error <= 1e-8 * scale, (name, error, scale)
    moment = out["joint_moment"][0]
    assert np.isnan(moment[:, :3]).all()
    assert np.abs(moment[:, 3] - reference["M"]).max() <= 1e-8 * np.abs(reference["M"]).max()
    torque = out["driver_torque"][0, :, 0]
    assert np.abs(torque - reference["T"]).max() <= 1e-8 * np.abs(reference["T"]).max()
    assert np.isnan(out["contact_force"][0, :, 3]).all()


@pytest.mark.parametrize(
    ("method", "extra", "tol"),
    [("rk45", dict(rtol=1e-10, atol=1e-12), 1e-8), ("generalized-alpha", {}, 2e-5)],
)
def test_slider_crank__other_integrators_agree(cycle, method, extra, tol):
    model, out = cycle
    sim = dict(t_end=0.02, dt=1e-5, output_dt=1e-4, method=method, **extra)
    other = _simulate(model, sim)
    assert not other["status"].any()
    x = other["q"][0, :, 2, 0]  # the slider's x
    assert np.abs(x - out["q"][0, :, 2, 0]).max() <= tol * SLIDER_CRANK["crank"]
    assert np.abs(other["joint_moment"][0, :, 3] - out["joint_moment"][0, :, 3]).max() <= (
        max(1e3 * tol, 1e-6) * np.abs(out["joint_moment"][0, :, 3]).max()
    )


INCLINE = """
[scene]
name = "incline"
[[body]]
name = "block"
mass = 2.0
inertia = 0.01
[[joint]]
name = "P"
type = "prismatic"
bodies = ["ground", "block"]
points = [[0.0, 0.0], [0.0, 0.0]]
axis = [0.8, 0.6]
[[spring]]
name = "S"
bodies = ["ground", "block"]
points = [[0.0, 0.0], [0.0, 0.0]]
stiffness = 500.0
rest_length = 0.0
[equilibrium]
[modes]
"""


def test_incline__equilibrium_reaction_and_mode_are_the_closed_forms():
    """A block on a 36.87° guide held by a spring to the guide's origin: it sits m g sin α / k
    down the guide, the guide pushes with m g cos α along its normal, ω = √(k/m)."""
    scene = load_scene_text(INCLINE)
    model = compile_model(scene)
    out = solve_chunk(model, scene)
    sin_a, cos_a = 0.6, 0.8
    shift = 2.0 * G * sin_a / 500.0
    np.testing.assert_allclose(out["q_eq"][0, 0], [-shift * cos_a, -shift * sin_a, 0.0], atol=1e-13)
    normal = 2.0 * G * cos_a * np.array([-sin_a, cos_a])
    np.testing.assert_allclose(out["joint_force_eq"][0, 0], normal, rtol=1e-12)
    assert abs(out["joint_moment_eq"][0, 0]) <= 1e-12
    np.testing.assert_allclose(out["omega"][0], [np.sqrt(500.0 / 2.0)], rtol=1e-12)


def test_telescope__modes_match_a_dense_reference_at_the_equilibrium():
    model = compile_model(load_scene_text(TELESCOPE_TEXT))
    assembled = assemble(model)
    equilibrium = solve_equilibrium(model, assembled.q)
    modes = solve_modes(model, equilibrium)
    reference = dense.statics(model, 0, assembled.q[0])
    np.testing.assert_allclose(equilibrium.q[0], reference.q, atol=1e-12)
    expected = dense.modes(model, 0, reference.q, reference.lam)
    np.testing.assert_allclose(modes.omega[0], expected, rtol=1e-10)
    assert modes.omega.shape == (1, 2) and (modes.omega > 0).all()


def test_telescope__energy_is_conserved_without_damping():
    text = TELESCOPE_TEXT.replace("damping = 0.3", "damping = 0.0")
    model = compile_model(load_scene_text(text))
    sim = dict(t_end=1.0, dt=1e-4, output_dt=1e-2, method="rk4")
    out = _simulate(model, sim)
    assert not out["status"].any()
    energy = out["energy"][0]
    assert np.ptp(energy) <= 1e-9 * np.abs(energy).max()
    assert np.ptp(out["q"][0, :, 0, 2]) > 0.1  # it really swings


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            ("axis = [1.0, 0.0]\n", ""),
            "joint.P.axis: a prismatic joint needs its sliding direction",
        ),
        (("axis = [1.0, 0.0]", "axis = [0.0, 0.0]"), "joint.P.axis: must not be [0, 0]"),
        (
            ("axis = [1.0, 0.0]", "axis = [1.0, 0.0]\nclearance = 1e-4"),
            "joint.P.clearance: a prismatic joint is ideal",
        ),
        (
            ('name = "B"\n', 'name = "B"\naxis = [1.0, 0.0]\n'),
            'joint.B.axis: only a prismatic joint has one (type = "prismatic")',
        ),
        (('type = "prismatic"', 'type = "slider"'), "joint.P.type"),
    ],
)
def test_cli__bad_prismatic_joints_are_one_line(tmp_path, monkeypatch, capsys, edit, message):
    text = slider_crank_text()
    assert edit[0] in text
    path = write_scene(tmp_path, text.replace(edit[0], edit[1], 1))
    ran = in_process(monkeypatch, capsys)("validate", path, cwd=tmp_path)
    assert_usage_error(ran, message)


def test_cli__validate_lists_the_prismatic_joint(tmp_path, monkeypatch, capsys):
    path = write_scene(tmp_path, slider_crank_text())
    ran = in_process(monkeypatch, capsys)("validate", path, cwd=tmp_path)
    assert ran.returncode == 0
    assert "P: ground (bearing) - slider (journal), prismatic, axis [1, 0]" in ran.stdout
    assert "degrees of freedom: 0" in ran.stdout
