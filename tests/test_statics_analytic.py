"""Equilibria and eigenpulsations of the seed bar against their closed forms,
on every sample of 1000-sample sweeps over clearance and mass."""

from __future__ import annotations

import numpy as np
import pytest

from mcchain.scene import Equilibrium, compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.statics import assemble, solve_equilibrium
from mcchain.status import Status
from mcchain.testing.closed_forms import bar_pulsation, clearance_bar_pulsations

CLOSED_FORM_RTOL = 1e-10
"""Issue #2: relative error of every sample against the closed forms."""
NEWTON_QUADRATIC_CONSTANT = 10.0
"""Newton step norms (≈ the error of each iterate) obey δ_{k+1} ≤ C δ_k² once δ_k < 1e-2."""

HALF_LENGTH = 0.5
GRAVITY = 9.81
INERTIA = 2.0 * (2 * HALF_LENGTH) ** 2 / 12.0  # homogeneous bar of mass 2 kg, length 1 m


def bar_scene(clearance: float | None, tip_force: float = 0.0, count: int = 1000) -> str:
    """The seed bar (the scene-format example) with a sweep over mass (and clearance if any)."""
    joint = (
        "" if clearance is None else f"clearance = {clearance}\neccentricity = -1.5707963267948966"
    )
    vary = '"body.bar.mass" = { normal = [2.0, 0.02] }'
    if clearance is not None:
        vary += '\n"joint.O.clearance" = { uniform = [1e-4, 1e-3] }'
    force = ""
    if tip_force:
        force = f"""
[[force]]
name = "tip"
body = "bar"
point = [{HALF_LENGTH}, 0.0]
value = [{tip_force}, 0.0]
"""
    return f"""
[scene]
name = "bar"
gravity = [0.0, -{GRAVITY}]

[[body]]
name = "bar"
mass = 2.0
inertia = {INERTIA!r}
position = [0.0, -{HALF_LENGTH}]
angle = -1.5707963267948966

[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-{HALF_LENGTH}, 0.0]]
{joint}
{force}
[sample]
count = {count}
seed = 11
design = "sobol"
[sample.vary]
{vary}

[equilibrium]
[modes]
"""


def run(text: str) -> tuple[object, dict[str, np.ndarray]]:
    scene = load_scene_text(text)
    model = compile_model(scene)
    return model, solve_chunk(model, scene)


def sampled(model, path: str) -> np.ndarray:
    return model.parameters[:, model.param_paths.index(path)]


def test_statics__seed_bar_pulsation_matches_closed_form():
    model, out = run(bar_scene(clearance=None))
    mass = sampled(model, "body.bar.mass")
    expected = np.array([bar_pulsation(m, INERTIA, HALF_LENGTH, GRAVITY) for m in mass])
    assert np.all(out["status"] == 0)
    assert out["omega"].shape == (1000, 1)
    np.testing.assert_allclose(out["omega"][:, 0], expected, rtol=CLOSED_FORM_RTOL, atol=0)
    assert out["stable"].all()


def test_statics__clearance_bar_quartic_on_every_sample():
    model, out = run(bar_scene(clearance=1e-3))
    mass = sampled(model, "body.bar.mass")
    clearance = sampled(model, "joint.O.clearance")
    expected = np.array(
        [
            clearance_bar_pulsations(m, INERTIA, HALF_LENGTH, GRAVITY, c)
            for m, c in zip(mass, clearance, strict=True)
        ]
    )
    assert np.all(out["status"] == 0)
    np.testing.assert_allclose(out["omega"], expected, rtol=CLOSED_FORM_RTOL, atol=0)
    # the journal rests at the bottom of its bearing: |d| = c straight down
    q = out["q_eq"].reshape(1000, 3)
    journal_y = q[:, 1] + HALF_LENGTH  # the pin end of the hanging bar
    np.testing.assert_allclose(journal_y, -clearance, rtol=CLOSED_FORM_RTOL)


@pytest.mark.parametrize("tip_force", [5.0, -3.0, 40.0])
def test_statics__tip_load_equilibrium(tip_force):
    model, out = run(bar_scene(clearance=1e-3, tip_force=tip_force))
    assert np.all(out["status"] == 0)
    mass = sampled(model, "body.bar.mass")
    clearance = sampled(model, "joint.O.clearance")
    q = out["q_eq"].reshape(-1, 3)
    # angle φ from the downward vertical: tan φ = 2P/(m g)
    phi = q[:, 2] + np.pi / 2
    np.testing.assert_allclose(np.tan(phi), 2 * tip_force / (mass * GRAVITY), rtol=CLOSED_FORM_RTOL)
    # d is parallel to the resultant external force and |d| = c
    resultant = np.stack([np.full_like(mass, tip_force), -mass * GRAVITY], axis=1)
    journal = q[:, :2] + HALF_LENGTH * np.stack([-np.cos(q[:, 2]), -np.sin(q[:, 2])], axis=1)
    d = journal  # the bearing centre is the origin
    cross = d[:, 0] * resultant[:, 1] - d[:, 1] * resultant[:, 0]
    norms = np.linalg.norm(d, axis=1) * np.linalg.norm(resultant, axis=1)
    assert np.max(np.abs(cross) / norms) <= CLOSED_FORM_RTOL
    assert np.all(np.sum(d * resultant, axis=1) > 0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), clearance, rtol=CLOSED_FORM_RTOL)
    # the joint force on the bar balances the loads
    np.testing.assert_allclose(
        out["joint_force_eq"][:, 0, :], -resultant, rtol=CLOSED_FORM_RTOL, atol=0
    )


@pytest.mark.slow  # iteration histories of many samples
@pytest.mark.parametrize(
    ("clearance", "max_iterations"), [(None, 4), (1e-2, 6), (1e-3, 6), (1e-4, 12)]
)
def test_equilibrium__newton_converges_quadratically(clearance, max_iterations):
    # from the hanging bar to φ = 27° under a 5 N tip load: a few damped steps, then Newton's
    # quadratic phase; the clearance's curvature 1/c sets the quadratic constant.
    text = bar_scene(clearance=clearance, tip_force=5.0, count=1)
    text = text[: text.index("[sample]")] + "[equilibrium]\n"
    model = compile_model(load_scene_text(text))
    assembled = assemble(model)
    result = solve_equilibrium(model, assembled.q, assembled.status, Equilibrium(tolerance=1e-12))
    assert result.status[0] == 0
    iterations = int(result.iterations[0])
    assert iterations <= max_iterations
    residual, steps = result.history[0, : iterations + 1, 0], result.history[0, :iterations, 1]
    assert residual[-1] <= 1e-12
    curvature = 1.0 if clearance is None else 2 * HALF_LENGTH / clearance
    assert steps[-1] <= NEWTON_QUADRATIC_CONSTANT * curvature * steps[-2] ** 2


def test_equilibrium__already_at_rest_takes_no_iteration():
    scene = load_scene_text(bar_scene(clearance=None, count=4))
    model = compile_model(scene)
    assembled = assemble(model)
    result = solve_equilibrium(model, assembled.q, assembled.status)
    np.testing.assert_array_equal(result.iterations, 0)
    # the hanging bar satisfies the joint exactly: assembly keeps it bit for bit
    np.testing.assert_array_equal(assembled.q, np.broadcast_to(model.q0, assembled.q.shape))


def test_modes__inverted_bar_is_unstable():
    text = bar_scene(clearance=None, count=4).replace(
        "position = [0.0, -0.5]\nangle = -1.5707963267948966",
        "position = [0.0, 0.5]\nangle = 1.5707963267948966",
    )
    _, out = run(text)
    assert np.all(out["status"] == Status.UNSTABLE_EQUILIBRIUM)
    assert not out["stable"].any()
    mass = 2.0
    expected = -bar_pulsation(mass, INERTIA, HALF_LENGTH, GRAVITY)
    assert out["omega"][:, 0] == pytest.approx(expected, rel=0.05)
    assert np.all(out["omega"][:, 0] < 0)


def test_statics__scale_inertia_carries_the_inertia_with_the_sampled_mass():
    """With ``scale_inertia`` J = J_written m / m_written, and each clearance-bar sample
    matches the quartic with its own (m, J); without it J stays as written."""
    text = bar_scene(clearance=1e-3, count=200)
    scaled = text.replace(f"inertia = {INERTIA!r}", f"inertia = {INERTIA!r}\nscale_inertia = true")
    model, out = run(scaled)
    mass = sampled(model, "body.bar.mass")
    clearance = sampled(model, "joint.O.clearance")
    np.testing.assert_allclose(model.body_inertia[:, 0], INERTIA * mass / 2.0, rtol=1e-15)
    expected = np.array(
        [
            clearance_bar_pulsations(m, INERTIA * m / 2.0, HALF_LENGTH, GRAVITY, c)
            for m, c in zip(mass, clearance, strict=True)
        ]
    )
    np.testing.assert_allclose(out["omega"], expected, rtol=CLOSED_FORM_RTOL, atol=0)
    assert np.ptp(model.body_inertia) > 0.01 * INERTIA  # the masses scatter by ~1 %
    written = compile_model(load_scene_text(text))
    assert np.all(written.body_inertia == INERTIA)
