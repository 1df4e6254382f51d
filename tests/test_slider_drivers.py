"""Slider drivers: ``[[driver]] joint = "P"`` prescribes a prismatic joint's displacement
s(t) = s0 + v t (+ A (sin(2π f t + φ) − sin φ)) along its axis, in every path.

References: a block pushed up an incline (the driving force m s̈ + m g sin α in closed form),
a slider pushed along an arm that turns at constant speed (the axis turns: position and force
in closed form), the inverted slider-crank (crank angle from the triangle), the dense KKT
reference at the computed states, and one line per bad slider driver.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import Ran, assert_scene_refused

from mcchain.kernels.joints import constraint_gamma, constraint_residual, constraint_velocity_rhs
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing import dense
from mcchain.testing.scenes import model_of

TILT, MASS, GRAVITY = 0.4, 1.5, 9.81  # rad, kg, m/s²
S0, SPEED, AMPLITUDE, FREQUENCY, PHASE = 0.2, 0.3, 0.05, 2.0, 0.5
METHODS = [
    ("rk4", "lanes"), ("rk4", "loop"), ("rk45", "lanes"), ("radau", "lanes"),
    ("generalized-alpha", "lanes"),
]  # fmt: skip
FORCE_RTOL = {"rk4": 1e-11, "rk45": 1e-9, "radau": 1e-9, "generalized-alpha": 1e-5}
"""Of the driving force against its closed form (generalized-α: O(h²) accelerations)."""

INCLINE = f"""
[scene]
name = "incline"
gravity = [0.0, -{GRAVITY}]
[[body]]
name = "block"
mass = {MASS}
inertia = 0.01
[[joint]]
name = "P"
type = "prismatic"
bodies = ["ground", "block"]
points = [[0.0, 0.0], [0.0, 0.0]]
axis = [{math.cos(TILT)!r}, {math.sin(TILT)!r}]
[[driver]]
joint = "P"
law = "harmonic"
speed = {SPEED}
displacement0 = {S0}
amplitude = {AMPLITUDE}
frequency = {FREQUENCY}
phase = {PHASE}
"""

OMEGA_ARM, ARM_MASS, ARM_INERTIA = 3.0, 2.0, 0.2
ARM = f"""
[scene]
name = "arm"
gravity = [0.0, 0.0]
[[body]]
name = "arm"
mass = {ARM_MASS}
inertia = {ARM_INERTIA}
[[body]]
name = "slider"
mass = {MASS}
inertia = 0.01
position = [{S0}, 0.0]
[[joint]]
name = "O"
bodies = ["ground", "arm"]
points = [[0.0, 0.0], [0.0, 0.0]]
[[joint]]
name = "P"
type = "prismatic"
bodies = ["arm", "slider"]
points = [[0.0, 0.0], [0.0, 0.0]]
axis = [1.0, 0.0]
[[driver]]
body = "arm"
omega = {OMEGA_ARM}
angle0 = 0.0
[[driver]]
joint = "P"
law = "harmonic"
speed = {SPEED}
amplitude = {AMPLITUDE}
frequency = {FREQUENCY}
phase = {PHASE}
"""


def stroke(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s, ṡ, s̈ of the harmonic slider driver."""
    w = 2.0 * math.pi * FREQUENCY
    s = S0 + SPEED * t + AMPLITUDE * (np.sin(w * t + PHASE) - math.sin(PHASE))
    return (
        s,
        SPEED + AMPLITUDE * w * np.cos(w * t + PHASE),
        -AMPLITUDE * w * w * np.sin(w * t + PHASE),
    )


def _run(text: str, method: str, kernels: str, t_end: float = 1.0) -> dict[str, np.ndarray]:
    model = model_of(text)
    start = assemble(model)
    settings = dict(
        t_end=t_end, dt=1e-4, output_dt=1e-2, method=method, kernels=kernels, rtol=1e-11,
        atol=1e-13,
    )  # fmt: skip
    out = simulate(model, settings, start.q, start.v, np.float64)
    assert out["status"][0] == 0
    return out


@pytest.mark.parametrize(("method", "kernels"), METHODS)
def test_slider_driver__block_up_an_incline_with_the_closed_form_force(method, kernels):
    out = _run(INCLINE, method, kernels)
    s, _, acc = stroke(out["time"])
    q = out["q"][0, :, 0]
    np.testing.assert_allclose(q[:, 0], s * math.cos(TILT), rtol=0, atol=1e-12)
    np.testing.assert_allclose(q[:, 1], s * math.sin(TILT), rtol=0, atol=1e-12)
    force = MASS * acc + MASS * GRAVITY * math.sin(TILT)  # along u: F − m g sin α = m s̈
    got = out["driver_force"][0, :, 0]
    assert np.abs(got - force).max() <= FORCE_RTOL[method] * np.abs(force).max()
    assert np.isnan(out["driver_torque"]).all()  # a slider driver's output is a force


@pytest.mark.parametrize(("method", "kernels"), METHODS)
def test_slider_driver__along_a_turning_arm(method, kernels):
    """The axis turns with the arm (θ = ω t): r = s (cos ω t, sin ω t), and along the arm
    F = m (s̈ − s ω²); across it the guide pushes m (2 ṡ ω)."""
    out = _run(ARM, method, kernels, t_end=0.5)
    t = out["time"]
    s, _, acc = stroke(t)
    r = out["q"][0, :, 1, :2]
    np.testing.assert_allclose(r[:, 0], s * np.cos(OMEGA_ARM * t), rtol=0, atol=1e-11)
    np.testing.assert_allclose(r[:, 1], s * np.sin(OMEGA_ARM * t), rtol=0, atol=1e-11)
    force = MASS * (acc - s * OMEGA_ARM**2)
    got = out["driver_force"][0, :, 1]
    assert np.abs(got - force).max() <= FORCE_RTOL[method] * np.abs(force).max()
    assert np.isnan(out["driver_force"][0, :, 0]).all()  # the arm's driver turns it: a torque


@pytest.mark.parametrize("t", [0.0, 0.21, 0.77])
def test_slider_driver__rows_match_the_dense_reference_and_differences(t):
    """Φ, B, γ and ν of the arm's slider row (the axis turns with the arm) against the dense
    reference (complex-step B of the written-out formulation) at a moving state."""
    model = model_of(ARM)
    km = model.kernel_model()
    rng = np.random.default_rng(7)
    q, v = rng.normal(size=model.ndof), rng.normal(size=model.ndof)
    m = model.ncon
    phi, gamma, nu = np.empty(m), np.empty(m), np.empty(m)
    constraint_residual(km, 0, q, t, phi)
    constraint_gamma(km, 0, q, v, t, gamma)
    constraint_velocity_rhs(km, 0, t, nu)
    _, B, gam, phi_ref, phid, _ = dense.equations(model, 0, q, v, t)
    np.testing.assert_allclose(phi, phi_ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(gamma, gam, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(B @ v - nu, phid, rtol=1e-12, atol=1e-13)
    B_cs = dense.complex_step_jacobian(lambda x: dense.constraints(model, 0, x, t), q)
    np.testing.assert_allclose(B, B_cs, rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        dense.constraint_jacobian_formula(model, 0, q), B_cs, rtol=0, atol=1e-14
    )


def test_slider_driver__inverted_slider_crank_kinematics_and_reactions():
    """The slider, pushed along the ground, turns a crank through a rod: the crank angle from
    the triangle r² + x² − 2 r x cos φ = l², and every multiplier equals the dense KKT
    solution at the computed states (generic kernels: the lanes' reactions come from them)."""
    crank, rod = 0.1, 0.25
    text = f"""
[scene]
name = "pushed-crank"
[[body]]
name = "crank"
mass = 0.2
inertia = 0.001
angle = 1.0
[[body]]
name = "rod"
mass = 0.3
inertia = 0.002
angle = -0.3
[[body]]
name = "slider"
mass = 0.5
inertia = 0.001
[[joint]]
name = "O"
bodies = ["ground", "crank"]
points = [[0.0, 0.0], [{-crank / 2}, 0.0]]
[[joint]]
name = "A"
bodies = ["crank", "rod"]
points = [[{crank / 2}, 0.0], [{-rod / 2}, 0.0]]
[[joint]]
name = "B"
bodies = ["rod", "slider"]
points = [[{rod / 2}, 0.0], [0.0, 0.0]]
[[joint]]
name = "P"
type = "prismatic"
bodies = ["ground", "slider"]
points = [[0.0, 0.0], [0.0, 0.0]]
axis = [1.0, 0.0]
[[driver]]
joint = "P"
law = "harmonic"
amplitude = 0.04
frequency = 1.0
"""
    model = model_of(text)
    start = assemble(model)
    out = simulate(model, dict(t_end=1.0, dt=1e-4, output_dt=1e-2), start.q, start.v, np.float64)
    assert out["status"][0] == 0
    x = out["q"][0, :, 2, 0]
    x0 = x[0]
    t = out["time"]
    np.testing.assert_allclose(x, x0 + 0.04 * np.sin(2 * math.pi * t), rtol=0, atol=1e-12)
    cos_phi = (crank**2 + x**2 - rod**2) / (2 * crank * x)
    crank_angle = out["q"][0, :, 0, 2]
    np.testing.assert_allclose(np.cos(crank_angle), cos_phi, rtol=0, atol=1e-11)
    for i in range(0, len(t), 25):
        q, v = out["q"][0, i].reshape(-1), out["v"][0, i].reshape(-1)
        _, lam = dense.kkt_acceleration(model, 0, q, v, t[i])
        driver = lam[model.driver_row[0]]
        assert out["driver_force"][0, i, 0] == pytest.approx(-driver, rel=1e-8, abs=1e-9)


# -- bad slider drivers -----------------------------------------------------------------------
SLIDER_CASES = {
    "body and joint": (
        INCLINE.replace('joint = "P"\nlaw', 'joint = "P"\nbody = "block"\nlaw'),
        "driver[0]: give `body` (a body's angle) or `joint` (a prismatic joint's displacement), "
        "not both",
    ),
    "unknown joint": (INCLINE.replace('joint = "P"\nlaw', 'joint = "Q"\nlaw'), "unknown joint 'Q'"),
    "revolute joint": (
        INCLINE.replace('type = "prismatic"\n', "").replace(
            f"axis = [{math.cos(TILT)!r}, {math.sin(TILT)!r}]\n", ""
        ),
        "driver.P.joint: joint 'P' is revolute; a driver moves a prismatic joint",
    ),
    "omega on a slider": (
        INCLINE.replace("speed = 0.3", "omega = 0.3"),
        "driver.P.omega: a slider driver takes `speed` (m), not `omega`",
    ),
    "speed on a body driver": (
        ARM.replace("omega = 3.0", "omega = 3.0\nspeed = 1.0"),
        "driver.arm.speed: only a driver of a prismatic joint (`joint = ...`) has one",
    ),
    "constant without speed": (
        INCLINE.replace('law = "harmonic"\nspeed = 0.3\n', "")
        .replace("amplitude = 0.05\n", "")
        .replace("frequency = 2.0\n", "")
        .replace("phase = 0.5\n", ""),
        'driver.P.speed: required for law "constant" (s0 + v t)',
    ),
}


@pytest.mark.parametrize("case", sorted(SLIDER_CASES))
def test_cli_run__bad_slider_driver_is_one_line_exit_2_no_folder(
    mcchain: Callable[..., Ran], tmp_path: Path, case: str
) -> None:
    text, fragment = SLIDER_CASES[case]
    assert text not in (INCLINE, ARM)
    assert_scene_refused(mcchain, tmp_path, text, fragment)


def test_slider_driver__a_table_of_displacements_on_the_incline():
    """A cubic stroke s(t) tabled at 6 knots: followed exactly (the spline is the cubic), with
    the driving force m s̈ + m g sin α."""
    stroke_poly = (0.1, 0.2, 0.4, -0.3)
    times = np.linspace(0.0, 0.6, 6)
    table = (
        f'law = "table"\ntimes = {[float(t) for t in times]}\n'
        f"displacements = {[float(x) for x in np.polyval(stroke_poly[::-1], times)]}\n"
    )
    text = INCLINE[: INCLINE.index('law = "harmonic"')] + table
    out = _run(text, "rk4", "lanes", t_end=0.6)
    t = out["time"]
    s = np.polyval(stroke_poly[::-1], t)
    acc = 2 * stroke_poly[2] + 6 * stroke_poly[3] * t
    np.testing.assert_allclose(out["q"][0, :, 0, 0], s * math.cos(TILT), rtol=0, atol=1e-12)
    force = MASS * acc + MASS * GRAVITY * math.sin(TILT)
    np.testing.assert_allclose(out["driver_force"][0, :, 0], force, rtol=1e-11, atol=1e-11)


def test_slider_driver__hessian_matches_central_differences():
    """∂(Bᵀλ)/∂q with the slider row's curvature (the axis turns with the arm), against
    central differences of the kernels' B(q)ᵀλ."""
    from mcchain.kernels.joints import constraint_hessian_add, constraint_jacobian

    model = model_of(ARM)
    km = model.kernel_model()
    rng = np.random.default_rng(11)
    q, lam = rng.normal(size=model.ndof), rng.normal(size=model.ncon)
    B = np.empty((model.ncon, model.ndof))

    def force(x: np.ndarray) -> np.ndarray:
        constraint_jacobian(km, 0, x, B)
        return B.T @ lam

    h = 1e-6
    fd = np.column_stack(
        [(force(q + h * e) - force(q - h * e)) / (2 * h) for e in np.eye(model.ndof)]
    )
    K = np.zeros((model.ndof, model.ndof))
    constraint_hessian_add(km, 0, q, lam, K)
    np.testing.assert_allclose(K, fd, rtol=0, atol=1e-8 * max(1.0, np.abs(K).max()))
    assert np.abs(K).max() > 0.1  # the slider row curves: not a trivially zero Hessian


def test_cli_validate__prints_slider_and_table_drivers(mcchain, tmp_path: Path) -> None:
    from test_driver_laws import cubic_swing_text

    (tmp_path / "arm.toml").write_text(ARM)
    (tmp_path / "cubic.toml").write_text(cubic_swing_text())
    arm = mcchain("validate", "arm.toml", cwd=tmp_path)
    assert arm.returncode == 0, arm.stderr
    assert (
        "  P: joint P along its axis, speed 0.3 m/s, displacement0 0.2 m, amplitude 0.05 m, "
        "frequency 2 Hz, phase 0.5 rad, row 5"
    ) in arm.stdout.splitlines()
    cubic = mcchain("validate", "cubic.toml", cwd=tmp_path)
    assert (
        "  bar: table of 11 points over [0, 1] s, angle0 -1.2 rad (from the table), row 2"
    ) in cubic.stdout.splitlines()


def test_slider_driver__report_and_viewer_show_its_force(mcchain, tmp_path: Path) -> None:
    """A run with a slider driver: the reaction envelopes draw "driver force P" in N (no empty
    torque panel), and ``show`` logs it under driver_force."""
    from test_viz_playback import read_rrd

    import mcchain as package
    from mcchain.ensemble.describe import stored_model
    from mcchain.viz import history, show

    scene = INCLINE + "[simulate]\nt_end = 0.2\ndt = 1e-4\noutput_dt = 1e-2\n"
    # float64 histories, as the incline's other runs: their rk4 lane entry (an entry
    # compiles per type of its arrays: float32 compiled the module once more, 1.4 s cold)
    scene += '[storage]\nhistory_dtype = "float64"\n'
    (tmp_path / "incline.toml").write_text(scene)
    ran = mcchain("run", "incline.toml", "--out", "runs", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    ds = package.open_run(next((tmp_path / "runs").iterdir()))
    fig = history.reaction_envelopes_figure(ds)
    assert not isinstance(fig, str)
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert "driver force P" in titles and not any("torque" in t for t in titles)
    force = next(ax for ax in fig.axes if ax.get_title() == "driver force P")
    assert force.get_ylabel() == "N"
    _, _, acc = stroke(np.asarray(ds["time"].values))
    expected = MASS * acc + MASS * GRAVITY * math.sin(TILT)
    np.testing.assert_allclose(force.lines[0].get_ydata(), expected, rtol=1e-5, atol=1e-5)
    out = tmp_path / "incline.rrd"
    show.show(ds, stored_model(ds), [0], save=out)
    rrd = read_rrd(out)
    assert "/sample/0/driver_force/P" in rrd and "/sample/0/driver_torque/P" not in rrd
