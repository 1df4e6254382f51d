"""Driver laws: a harmonic drive θ0 + ω t + A (sin(2π f t + φ) − sin φ) in every path.

References: the closed form of a bar turned about its pin (angle and driver torque), central
differences of the kernels' Φ in t (Φ_t = −ν, Φ_tt = −γ), the loop kernels against the lanes,
and one line per bad driver table.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_cli_commands import Ran, assert_scene_refused

from mcchain.kernels.joints import constraint_gamma, constraint_residual, constraint_velocity_rhs
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing import dense
from mcchain.testing.scenes import fourbar_text, model_of

HALF, MASS, GRAVITY = 0.5, 2.0, 9.81
INERTIA = MASS * (2 * HALF) ** 2 / 12.0
THETA0, OMEGA, AMPLITUDE, FREQUENCY, PHASE = -1.2, 0.7, 0.4, 1.5, 0.3
ANGLE_ATOL = {"rk4": 1e-13, "rk45": 2e-12, "radau": 2e-12, "generalized-alpha": 1e-14}
"""Observed 8.9e-15, 7.4e-13, 4.4e-13, 2.2e-16 (rtol 1e-11 for the adaptive methods; the
harmonic swing run beside the tabled one, :func:`two_swings_text`: alone 8.9e-15, 5.2e-13,
3.0e-13, 5.6e-16, the adaptive steps chosen on both swings' errors)."""
TORQUE_RTOL = {"rk4": 1e-12, "rk45": 1e-10, "radau": 1e-10, "generalized-alpha": 1e-6}
"""Observed 4.0e-14, 2.1e-12, 2.5e-12 and 2.3e-7 (generalized-α's accelerations are
second-order accurate: its torque error is O(h²), h = 1e-4)."""


def swing_text(amplitude: float = AMPLITUDE, count: int | None = None) -> str:
    """A bar pinned at its end to the ground, turned by a harmonic driver; with ``count``,
    the amplitude is sampled."""
    sample = ""
    if count is not None:
        sample = (
            f'[sample]\ncount = {count}\n[sample.vary]\n"driver.bar.amplitude" = '
            "{ uniform = [0.1, 0.6] }\n"
        )
    return f"""
[scene]
name = "swing"
gravity = [0.0, -{GRAVITY}]
[[body]]
name = "bar"
mass = {MASS}
inertia = {INERTIA!r}
angle = {THETA0}
[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-{HALF}, 0.0]]
[[driver]]
body = "bar"
law = "harmonic"
omega = {OMEGA}
amplitude = {amplitude}
frequency = {FREQUENCY}
phase = {PHASE}
{sample}"""


def swing_with_law(law: str) -> str:
    """:func:`swing_text` with its driver's law lines (law, omega, amplitude, frequency,
    phase) replaced by ``law``."""
    text = swing_text()
    start = text.index('law = "harmonic"')
    end = text.index(f"phase = {PHASE}\n") + len(f"phase = {PHASE}\n")
    return text[:start] + law + text[end:]


def swing_closed_form(t: np.ndarray, amplitude: float = AMPLITUDE) -> tuple[np.ndarray, ...]:
    """θ(t) and the driver torque τ = (J + m l²) θ̈ + m g l cos θ of the pinned bar."""
    w = 2.0 * math.pi * FREQUENCY
    theta = THETA0 + OMEGA * t + amplitude * (np.sin(w * t + PHASE) - math.sin(PHASE))
    acc = -amplitude * w * w * np.sin(w * t + PHASE)
    torque = (INERTIA + MASS * HALF * HALF) * acc + MASS * GRAVITY * HALF * np.cos(theta)
    return theta, torque


@functools.cache
def _two_swings_run(method: str, kernels: str) -> tuple[Any, dict[str, np.ndarray]]:
    """The start and the run of :func:`two_swings_text` (the harmonic swing, body 0 and
    driver 0; the tabled one, body 1 and driver 1): one lane module per method for both
    laws (each scene alone compiled its own, about 1 s each)."""
    model = model_of(two_swings_text())
    start = assemble(model)
    settings = dict(
        t_end=1.0, dt=1e-4, output_dt=1e-2, method=method, kernels=kernels, rtol=1e-11,
        atol=1e-12,
    )  # fmt: skip
    out = simulate(model, settings, start.q, start.v, np.float64)
    assert out["status"][0] == 0
    return start, out


@pytest.mark.parametrize(
    ("method", "kernels"),
    [("rk4", "lanes"), ("rk4", "loop"), ("rk45", "lanes"), ("radau", "lanes"),
     ("generalized-alpha", "lanes")],
)  # fmt: skip
def test_harmonic_driver__bar_follows_the_law_with_the_closed_form_torque(method, kernels):
    start, out = _two_swings_run(method, kernels)
    rate0 = OMEGA + AMPLITUDE * 2.0 * math.pi * FREQUENCY * math.cos(PHASE)
    assert start.v[0, 2] == pytest.approx(rate0, rel=1e-14)  # velocity analysis: ḟ(0)
    theta, torque = swing_closed_form(out["time"])
    np.testing.assert_allclose(out["q"][0, :, 0, 2], theta, rtol=0, atol=ANGLE_ATOL[method])
    got = out["driver_torque"][0, :, 0]
    assert np.abs(got - torque).max() <= TORQUE_RTOL[method] * np.abs(torque).max()


def test_harmonic_driver__a_sampled_amplitude_reaches_every_instance():
    model = model_of(swing_text(count=6))
    start = assemble(model)
    out = simulate(model, dict(t_end=0.5, dt=1e-4, output_dt=1e-2), start.q, start.v, np.float64)
    amplitudes = model.parameters[:, 0]
    assert np.ptp(amplitudes) > 0.1
    for s, amplitude in enumerate(amplitudes):
        theta, torque = swing_closed_form(out["time"], amplitude)
        np.testing.assert_allclose(out["q"][s, :, 0, 2], theta, rtol=0, atol=1e-13)
        np.testing.assert_allclose(out["driver_torque"][s, :, 0], torque, rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize("t", [0.0, 0.137, 0.9])
def test_harmonic_driver__time_derivatives_match_central_differences(t):
    """Φ_t = −ν (central differences of the kernels' Φ(q, t)) and −Φ_tt = γ = dν/dt at q̇ = 0
    (differences of ν), and both equal the dense reference's law."""
    model = model_of(fourbar_text().replace("omega = 20.0", HARMONIC_FOURBAR_DRIVER))
    km = model.kernel_model()
    q = np.ascontiguousarray(assemble(model).q[0])
    m = model.ncon

    def phi(time: float) -> np.ndarray:
        out = np.empty(m)
        constraint_residual(km, 0, q, time, out)
        return out

    def nu(time: float) -> np.ndarray:
        out = np.empty(m)
        constraint_velocity_rhs(km, 0, time, out)
        return out

    h = 1e-5  # truncation h² f‴ / 6 ~ 5e-8 of ν ~ 20 rad/s; round-off ~ 1e-16 / h
    gamma = np.empty(m)
    constraint_gamma(km, 0, q, np.zeros(model.ndof), t, gamma)
    row = model.driver_row[0]
    phi_t = (phi(t + h) - phi(t - h)) / (2 * h)
    nu_t = (nu(t + h) - nu(t - h)) / (2 * h)
    np.testing.assert_allclose(-nu(t)[row], phi_t[row], rtol=1e-8)
    np.testing.assert_allclose(gamma[row], nu_t[row], rtol=1e-6)
    np.testing.assert_allclose(phi(t), dense.constraints(model, 0, q, t), rtol=0, atol=1e-15)
    _, rate, acc = dense.driver_law(model, 0, 0, t)
    assert (nu(t)[row], gamma[row]) == pytest.approx((rate, acc), rel=1e-14)


HARMONIC_FOURBAR_DRIVER = (
    'law = "harmonic"\nomega = 20.0\namplitude = 0.05\nfrequency = 6.0\nphase = 0.4'
)
"""The four-bar's crank at 20 rad/s with a 0.05 rad, 6 Hz speed fluctuation on top."""


def test_harmonic_driver__four_bar_lanes_and_loop_agree():
    text = (
        fourbar_text()
        .replace("clearance = 1e-4\n", "")
        .replace("omega = 20.0", HARMONIC_FOURBAR_DRIVER)
    )
    model = model_of(text)
    start = assemble(model)
    runs = {
        kernels: simulate(
            model,
            dict(t_end=0.3, dt=1e-4, output_dt=1e-3, kernels=kernels),
            start.q,
            start.v,
            np.float64,
        )
        for kernels in ("lanes", "loop")
    }
    lanes, loop = runs["lanes"], runs["loop"]
    assert lanes["status"][0] == loop["status"][0] == 0
    np.testing.assert_allclose(lanes["q"], loop["q"], rtol=0, atol=1e-12)
    scale = np.abs(lanes["driver_torque"]).max()
    np.testing.assert_allclose(lanes["driver_torque"], loop["driver_torque"], atol=1e-10 * scale)
    w = 2.0 * math.pi * 6.0
    t = lanes["time"]
    crank = lanes["q"][0, :, 0, 2]
    expected = crank[0] + 20.0 * t + 0.05 * (np.sin(w * t + 0.4) - math.sin(0.4))
    np.testing.assert_allclose(crank, expected, rtol=0, atol=1e-12)


# -- bad driver tables ------------------------------------------------------------------------
BAR = swing_text()
DRIVER_CASES = {
    "constant without omega": (
        swing_with_law(""),
        'driver.bar.omega: required for law "constant" (θ0 + ω t)',
    ),
    "amplitude on a constant driver": (
        BAR.replace('law = "harmonic"\n', ""),
        'driver.bar.amplitude: only a driver of law "harmonic" has one',
    ),
    "harmonic without frequency": (
        BAR.replace("frequency = 1.5\n", ""),
        'driver.bar.frequency: required for law "harmonic"',
    ),
    "frequency not positive": (BAR.replace("frequency = 1.5", "frequency = 0.0"), "frequency"),
    "unknown law": (BAR.replace('law = "harmonic"', 'law = "cam"'), "driver.bar.law"),
    "table without angles": (
        swing_with_law('law = "table"\ntimes = [0.0, 1.0]\n'),
        'driver.bar.angles: required for law "table"',
    ),
    "table times not increasing": (
        swing_with_law('law = "table"\ntimes = [0.0, 0.5, 0.5]\nangles = [0, 1, 2]\n'),
        "driver.bar.times: must increase, but times[2] = 0.5 follows 0.5",
    ),
    "omega with a table": (
        swing_with_law('law = "table"\nomega = 0.7\ntimes = [0.0, 1.0]\nangles = [0, 1]\n'),
        'driver.bar.omega: a driver of law "table" takes `times` and `angles` only',
    ),
    "table shorter than the run": (
        swing_with_law('law = "table"\ntimes = [0.0, 0.5]\nangles = [0, 1]\n')
        + "[simulate]\nt_end = 1.0\ndt = 1e-3\n",
        "driver.bar.times: the table ends at 0.5 s, before simulate.t_end = 1.0 s",
    ),
    "modes along a harmonic driver": (
        BAR + '[modes]\nalong = { driver = "bar", points = 8 }\n',
        'modes.along: follows drivers of law "constant" only',
    ),
}


@pytest.mark.parametrize("case", sorted(DRIVER_CASES))
def test_cli_run__bad_driver_law_is_one_line_exit_2_no_folder(
    mcchain: Callable[..., Ran], tmp_path: Path, case: str
) -> None:
    text, fragment = DRIVER_CASES[case]
    assert text != BAR
    assert_scene_refused(mcchain, tmp_path, text, fragment)


# -- table law ---------------------------------------------------------------------------------
CUBIC = (THETA0, 0.7, -0.9, 1.3)  # θ(t) = c0 + c1 t + c2 t² + c3 t³


def cubic_swing_text() -> str:
    """The pinned bar turned by a table of θ(t) = a cubic at 11 knots on [0, 1] s: the
    not-a-knot spline through them is that cubic, exactly."""
    times = np.linspace(0.0, 1.0, 11)
    angles = np.polyval(CUBIC[::-1], times)
    return swing_with_law(
        f'law = "table"\ntimes = {[float(t) for t in times]}\n'
        f"angles = {[float(a) for a in angles]}\n"
    )


@pytest.mark.parametrize(
    ("method", "kernels"),
    [("rk4", "lanes"), ("rk4", "loop"), ("rk45", "lanes"), ("radau", "lanes"),
     ("generalized-alpha", "lanes")],
)  # fmt: skip
def two_swings_text() -> str:
    """The harmonic swing (:func:`swing_text`) and, pinned beside it, the swing turned by
    the table (:func:`cubic_swing_text`): two mechanisms that do not touch, in one scene."""
    table = cubic_swing_text().split("[[body]]", 1)[1]
    table = table.replace('name = "bar"', 'name = "table-bar"').replace('"bar"]', '"table-bar"]')
    table = table.replace('name = "O"', 'name = "T"').replace('body = "bar"', 'body = "table-bar"')
    return swing_text() + "[[body]]" + table


@pytest.mark.parametrize(
    ("method", "kernels"),
    [("rk4", "lanes"), ("rk4", "loop"), ("rk45", "lanes"), ("radau", "lanes"),
     ("generalized-alpha", "lanes")],
)  # fmt: skip
def test_table_driver__a_cubic_table_is_followed_with_the_closed_form_torque(method, kernels):
    start, out = _two_swings_run(method, kernels)
    assert start.v[0, 5] == pytest.approx(CUBIC[1], rel=1e-12)  # ḟ(0) = c1, body 1
    t = out["time"]
    theta = np.polyval(CUBIC[::-1], t)
    acc = 2 * CUBIC[2] + 6 * CUBIC[3] * t
    torque = (INERTIA + MASS * HALF * HALF) * acc + MASS * GRAVITY * HALF * np.cos(theta)
    np.testing.assert_allclose(out["q"][0, :, 1, 2], theta, rtol=0, atol=ANGLE_ATOL[method] + 1e-13)
    got = out["driver_torque"][0, :, 1]
    assert np.abs(got - torque).max() <= TORQUE_RTOL[method] * np.abs(torque).max()


def test_table_driver__spline_through_the_points_and_its_derivatives():
    """A table of a smooth motion: the spline passes through every point, and between them
    ḟ and f̈ (the velocity and acceleration rows) agree with central differences of f."""
    times = np.linspace(-0.1, 1.2, 27)
    angles = THETA0 + 2.0 * times + 0.3 * np.sin(7.0 * times)
    model = model_of(
        swing_with_law(
            f'law = "table"\ntimes = {[float(t) for t in times]}\n'
            f"angles = {[float(a) for a in angles]}\n"
        )
    )
    km = model.kernel_model()
    q = np.zeros(model.ndof)
    phi = np.empty(model.ncon)
    row = model.driver_row[0]

    def f(t: float) -> float:
        constraint_residual(km, 0, q, t, phi)
        return -phi[row]  # Φ = θ − f with θ = 0

    for t, a in zip(times, angles, strict=True):
        assert f(t) == pytest.approx(a, abs=1e-13)
    nu, gamma = np.empty(model.ncon), np.empty(model.ncon)
    h = 1e-5
    for t in (0.0, 0.123, 0.77):
        constraint_velocity_rhs(km, 0, t, nu)
        constraint_gamma(km, 0, q, np.zeros(model.ndof), t, gamma)
        assert nu[row] == pytest.approx((f(t + h) - f(t - h)) / (2 * h), rel=1e-8)
        nu_next, nu_prev = np.empty(model.ncon), np.empty(model.ncon)
        constraint_velocity_rhs(km, 0, t + h, nu_next)
        constraint_velocity_rhs(km, 0, t - h, nu_prev)
        # f̈ = dḟ/dt; across a knot f‴ jumps: the difference is off by up to h |Δf‴| / 2
        assert gamma[row] == pytest.approx((nu_next[row] - nu_prev[row]) / (2 * h), abs=1e-4)
        _, rate, acc = dense.driver_law(model, 0, 0, t)
        assert (nu[row], gamma[row]) == pytest.approx((rate, acc), rel=1e-13)
