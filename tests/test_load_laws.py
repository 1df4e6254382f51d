"""Load laws: a harmonic force or couple, value × sin(2π f t + φ), in every path.

References: the forced undamped oscillator (a slider on a spring, started at rest) and a
rotor turned by a harmonic couple, both in closed form; the kernels' F(q, q̇, t) against the
dense reference; one line per bad load table.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_cli_commands import Ran, assert_scene_refused

from mcchain.kernels.forces import applied_forces
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing import dense
from mcchain.testing.scenes import model_of

MASS, STIFFNESS, FORCE, FREQUENCY = 2.0, 800.0, 3.0, 3.0  # kg, N/m, N, Hz
INERTIA, TORQUE, PHASE = 0.05, 0.4, 0.6  # kg m², N m, rad
METHODS = [
    ("rk4", "lanes"), ("rk4", "loop"), ("rk45", "lanes"), ("radau", "lanes"),
    ("generalized-alpha", "lanes"),
]  # fmt: skip
ATOL = {"rk4": 1e-12, "rk45": 1e-10, "radau": 1e-10, "generalized-alpha": 2e-6}
"""Of positions in m or rad over 1 s (h = 1e-4; generalized-α is second order)."""

OSCILLATOR = f"""
[scene]
name = "forced-oscillator"
gravity = [0.0, 0.0]
[[body]]
name = "slider"
mass = {MASS}
inertia = 1.0
[[joint]]
name = "P"
type = "prismatic"
bodies = ["ground", "slider"]
points = [[0.0, 0.0], [0.0, 0.0]]
axis = [1.0, 0.0]
[[spring]]
bodies = ["ground", "slider"]
points = [[0.0, 0.0], [0.0, 0.0]]
stiffness = {STIFFNESS}
rest_length = 0.0
[[force]]
name = "shaker"
body = "slider"
value = [{FORCE}, 0.0]
law = "harmonic"
frequency = {FREQUENCY}
"""

ROTOR = f"""
[scene]
name = "rotor"
gravity = [0.0, -9.81]
[[body]]
name = "rotor"
mass = 1.0
inertia = {INERTIA}
[[joint]]
name = "O"
bodies = ["ground", "rotor"]
points = [[0.0, 0.0], [0.0, 0.0]]
[[force]]
name = "couple"
body = "rotor"
torque = {TORQUE}
law = "harmonic"
frequency = {FREQUENCY}
phase = {PHASE}
"""


def oscillator_closed_form(t: np.ndarray) -> np.ndarray:
    """x(t) of m ẍ + k x = F sin Ω t from rest at 0."""
    w0, w = math.sqrt(STIFFNESS / MASS), 2.0 * math.pi * FREQUENCY
    return FORCE / (MASS * (w0 * w0 - w * w)) * (np.sin(w * t) - (w / w0) * np.sin(w0 * t))


def rotor_closed_form(t: np.ndarray) -> np.ndarray:
    """θ(t) of J θ̈ = τ sin(Ω t + φ) from rest at 0."""
    w = 2.0 * math.pi * FREQUENCY
    a = TORQUE / INERTIA
    return a * math.cos(PHASE) / w * t - a / (w * w) * (np.sin(w * t + PHASE) - math.sin(PHASE))


def _run(text: str, method: str, kernels: str) -> dict[str, np.ndarray]:
    model = model_of(text)
    start = assemble(model)
    settings = dict(
        t_end=1.0, dt=1e-4, output_dt=1e-2, method=method, kernels=kernels, rtol=1e-11,
        atol=1e-13,
    )  # fmt: skip
    out = simulate(model, settings, start.q, start.v, np.float64)
    assert out["status"][0] == 0
    return out


@functools.cache
def _loads_run(method: str, kernels: str) -> dict[str, np.ndarray]:
    """The three loaded mechanisms (:func:`loads_text`) in one run: one lane module per
    method for the three laws (each scene alone compiled its own, about 1-1.5 s each)."""
    return _run(loads_text(), method, kernels)


@pytest.mark.parametrize(("method", "kernels"), METHODS)
def test_harmonic_force__forced_oscillator_matches_the_closed_form(method, kernels):
    out = _loads_run(method, kernels)
    x = out["q"][0, :, 0, 0]  # the slider, body 0
    np.testing.assert_allclose(x, oscillator_closed_form(out["time"]), rtol=0, atol=ATOL[method])


@pytest.mark.parametrize(("method", "kernels"), METHODS)
def test_harmonic_couple__rotor_matches_the_closed_form(method, kernels):
    out = _loads_run(method, kernels)
    theta = out["q"][0, :, 1, 2]  # the rotor, body 1
    np.testing.assert_allclose(theta, rotor_closed_form(out["time"]), rtol=0, atol=ATOL[method])


@pytest.mark.parametrize("t", [0.0, 0.0417, 0.73])
def test_harmonic_load__kernel_forces_match_the_dense_reference(t):
    model = model_of(OSCILLATOR.replace('name = "shaker"', 'name = "shaker"\npoint = [0.1, 0.2]'))
    km = model.kernel_model()
    rng = np.random.default_rng(4)
    q, v = rng.normal(size=model.ndof), rng.normal(size=model.ndof)
    F = np.empty(model.ndof)
    applied_forces(km, 0, q, v, t, F)
    np.testing.assert_allclose(F, dense.applied_forces(model, 0, q, v, t), rtol=1e-14, atol=1e-13)
    factor = math.sin(2.0 * math.pi * FREQUENCY * t)
    assert F[0] == pytest.approx(FORCE * factor - STIFFNESS * q[0] - 0.0, abs=1e-12)


# -- bad load tables --------------------------------------------------------------------------
LOAD_CASES = {
    "harmonic without frequency": (
        ROTOR.replace(f"frequency = {FREQUENCY}\n", ""),
        'force.couple.frequency: required for law "harmonic"',
    ),
    "phase on a constant load": (
        ROTOR.replace('law = "harmonic"\n', "").replace(f"frequency = {FREQUENCY}\n", ""),
        'force.couple.phase: only a load of law "harmonic" has one',
    ),
    "unknown load law": (ROTOR.replace('law = "harmonic"', 'law = "ramp"'), "force.couple.law"),
    "table without factors": (
        ROTOR.replace('law = "harmonic"', 'law = "table"\ntimes = [0.0, 1.0]')
        .replace(f"frequency = {FREQUENCY}\n", "")
        .replace(f"phase = {PHASE}\n", ""),
        'force.couple.factors: required for law "table"',
    ),
    "table factors of another length": (
        ROTOR.replace('law = "harmonic"', 'law = "table"\ntimes = [0.0, 1.0]\nfactors = [1.0]')
        .replace(f"frequency = {FREQUENCY}\n", "")
        .replace(f"phase = {PHASE}\n", ""),
        "force.couple.factors: 1 values for 2 times (one value per time)",
    ),
}


@pytest.mark.parametrize("case", sorted(LOAD_CASES))
def test_cli_run__bad_load_law_is_one_line_exit_2_no_folder(
    mcchain: Callable[..., Ran], tmp_path: Path, case: str
) -> None:
    text, fragment = LOAD_CASES[case]
    assert text != ROTOR
    assert_scene_refused(mcchain, tmp_path, text, fragment)


# -- table law ---------------------------------------------------------------------------------
FACTOR = (1.0, 0.5, -0.3, 0.2)  # g(t) = 1 + 0.5 t − 0.3 t² + 0.2 t³


def rotor_table_text() -> str:
    """The rotor under its couple times a table of g(t), a cubic at 9 knots on [0, 1.2] s:
    the not-a-knot spline through them is g itself."""
    times = np.linspace(0.0, 1.2, 9)
    factors = np.polyval(FACTOR[::-1], times)
    law = f'law = "table"\ntimes = {[float(t) for t in times]}\n'
    law += f"factors = {[float(g) for g in factors]}\n"
    text = ROTOR.replace('law = "harmonic"\n', law)
    return text.replace(f"frequency = {FREQUENCY}\n", "").replace(f"phase = {PHASE}\n", "")


def loads_text() -> str:
    """The forced oscillator, the rotor under its harmonic couple and a second rotor under
    the tabled couple (:func:`rotor_table_text`), three mechanisms on the ground that do not
    touch, in one scene (bodies 0, 1, 2): each moves as it does alone. Gravity acts on
    all three (the oscillator's alone has none): it loads the slider's prismatic joint
    across its axis and the rotors' pins at their centres of mass, and moves none."""
    table = rotor_table_text().split("[[body]]", 1)[1]
    table = table.replace('name = "rotor"', 'name = "table-rotor"')
    table = table.replace('name = "O"', 'name = "T"').replace('"rotor"]', '"table-rotor"]')
    table = table.replace('body = "rotor"', 'body = "table-rotor"')
    table = table.replace('name = "couple"', 'name = "table-couple"')
    text = OSCILLATOR.replace("gravity = [0.0, 0.0]", "gravity = [0.0, -9.81]")
    return text + "[[body]]" + ROTOR.split("[[body]]", 1)[1] + "[[body]]" + table


@pytest.mark.parametrize(("method", "kernels"), METHODS)
def test_table_load__rotor_under_a_tabled_couple_matches_the_closed_form(method, kernels):
    """J θ̈ = τ g(t) from rest: θ = (τ/J) (t²/2 + g1 t³/6 + g2 t⁴/12 + g3 t⁵/20)."""
    out = _loads_run(method, kernels)
    t = out["time"]
    g0, g1, g2, g3 = FACTOR
    theta = TORQUE / INERTIA * (g0 * t**2 / 2 + g1 * t**3 / 6 + g2 * t**4 / 12 + g3 * t**5 / 20)
    np.testing.assert_allclose(out["q"][0, :, 2, 2], theta, rtol=0, atol=ATOL[method])


def test_table_load__kernel_factor_is_the_spline_through_the_table():
    model = model_of(rotor_table_text())
    km = model.kernel_model()
    q = np.zeros(model.ndof)
    F = np.empty(model.ndof)
    for t in (0.0, 0.15, 0.6, 1.2):
        applied_forces(km, 0, q, q, t, F)
        assert F[2] == pytest.approx(TORQUE * np.polyval(FACTOR[::-1], t), rel=1e-13)
        np.testing.assert_allclose(F, dense.applied_forces(model, 0, q, q, t), rtol=1e-14)


@pytest.mark.parametrize("text", ["harmonic", "table"])
def test_varying_load__stiffness_matches_central_differences(text):
    """−∂F/∂q at time t of a load off the centre of mass (its lever turns with the body),
    harmonic or tabled, against central differences of the kernels' F(q, 0, t)."""
    from mcchain.kernels.forces import applied_stiffness_add

    scene = OSCILLATOR if text == "harmonic" else rotor_table_text()
    scene = scene.replace('body = "slider"\nvalue', 'body = "slider"\npoint = [0.1, 0.2]\nvalue')
    scene = scene.replace(
        "torque = 0.4\n", "torque = 0.4\nvalue = [2.0, -1.0]\npoint = [0.3, 0.1]\n"
    )
    model = model_of(scene)
    km = model.kernel_model()
    rng = np.random.default_rng(2)
    q, rest, t = rng.normal(size=model.ndof), np.zeros(model.ndof), 0.37
    F = np.empty(model.ndof)

    def force(x: np.ndarray) -> np.ndarray:
        applied_forces(km, 0, x, rest, t, F)
        return F.copy()

    h = 1e-6
    fd = -np.column_stack(
        [(force(q + h * e) - force(q - h * e)) / (2 * h) for e in np.eye(model.ndof)]
    )
    K = np.zeros((model.ndof, model.ndof))
    applied_stiffness_add(km, 0, q, t, K)
    np.testing.assert_allclose(K, fd, rtol=0, atol=1e-7 * max(1.0, np.abs(K).max()))
