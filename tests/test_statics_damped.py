"""Damped modes (issue 14): a damped pendulum against its closed form, constrained chains with
dampers against a dense scipy ``eig`` of the full quadratic problem, the undamped case, the
ordering and pairing rules, and the dampers' velocity derivative against differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from mcchain.kernels.forces import applied_forces, damping_matrix_add
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.damped import damped_modes
from mcchain.solvers.statics import assemble, solve_equilibrium, solve_modes
from mcchain.testing import dense as reference
from mcchain.testing.factory import chain_scene_text
from mcchain.testing.scenes import straight_chain_text

CLOSED_FORM_RTOL = 1e-10
"""Issue 14: damped roots against the closed form and the dense reference."""
FD_RTOL = 1e-9
"""F is linear in q̇: a central difference has no truncation error, only round-off."""

HALF_LENGTH = 0.5
GRAVITY = 9.81  # straight_chain_text's
MASS = 2.0
INERTIA = MASS * (2 * HALF_LENGTH) ** 2 / 12.0  # of the nominal mass, as straight_chain_text


def pendulum_scene(damping_range: tuple[float, float], count: int = 400) -> str:
    """The seed bar (1 m, 2 kg) hanging from an ideal pin, with a pure damper (stiffness 0,
    rest length 0: isotropic) from its tip to the ground point where the tip hangs."""
    low, high = damping_range
    bar = straight_chain_text([2 * HALF_LENGTH], [MASS], angle=-math.pi / 2)
    return f"""{bar}
[[spring]]
name = "D"
bodies = ["ground", "b0"]
points = [[0.0, -{2 * HALF_LENGTH}], [{HALF_LENGTH}, 0.0]]
stiffness = 0.0
rest_length = 0.0
damping = 1.0

[sample]
count = {count}
seed = 3
design = "sobol"
[sample.vary]
"spring.D.damping" = {{ uniform = [{low}, {high}] }}
"body.b0.mass" = {{ normal = [{MASS}, 0.02] }}

[modes]
"""


def run(text: str):
    scene = load_scene_text(text)
    model = compile_model(scene)
    return model, solve_chunk(model, scene)


def column(model, path: str) -> np.ndarray:
    return model.parameters[:, model.param_paths.index(path)]


def pendulum_closed_form(model) -> tuple[np.ndarray, np.ndarray]:
    """(p, ζ) of the pendulum: I_O θ̈ + c (2l)² θ̇ + m g l θ = 0, I_O = J + m l²."""
    mass = column(model, "body.b0.mass")
    damping = column(model, "spring.D.damping")
    inertia_o = INERTIA + mass * HALF_LENGTH**2
    p = np.sqrt(mass * GRAVITY * HALF_LENGTH / inertia_o)
    zeta = damping * (2 * HALF_LENGTH) ** 2 / (2.0 * inertia_o * p)
    return p, zeta


def test_damped_modes__pendulum_matches_closed_form_underdamped():
    """s = −ζp ± i p√(1−ζ²) for every sample, ζ from about 0.01 to 0.9."""
    model, out = run(pendulum_scene((0.05, 4.0)))
    p, zeta = pendulum_closed_form(model)
    assert zeta.min() > 0.005 and zeta.max() < 0.95
    np.testing.assert_allclose(out["omega"][:, 0], p, rtol=CLOSED_FORM_RTOL)
    np.testing.assert_allclose(
        out["damped_omega"][:, 0], p * np.sqrt(1.0 - zeta**2), rtol=CLOSED_FORM_RTOL
    )
    np.testing.assert_allclose(out["damping_ratio"][:, 0], zeta, rtol=CLOSED_FORM_RTOL)


def test_damped_modes__pendulum_overdamped_gives_zero_pulsation_and_ratio_above_one():
    """Overdamped (ζ > 1): two real roots s = −ζp ± p√(ζ²−1); stored as damped_omega = 0 and
    ζ = −(s₁ + s₂)/(2√(s₁s₂)) ≥ 1, the closed form's ζ."""
    model, out = run(pendulum_scene((6.0, 20.0), count=64))
    _, zeta = pendulum_closed_form(model)
    assert zeta.min() > 1.05
    assert np.all(out["damped_omega"] == 0.0)
    np.testing.assert_allclose(out["damping_ratio"][:, 0], zeta, rtol=CLOSED_FORM_RTOL)


def test_damped_modes__without_dampers_equal_the_undamped_modes_bit_for_bit():
    text = chain_scene_text(3, {1}, 4, springs=2).replace("damping = ", "# damping = ")
    model, out = run(text)
    assert not np.any(model.spring_damping)
    np.testing.assert_array_equal(out["damped_omega"], out["omega"])
    np.testing.assert_array_equal(out["damping_ratio"], np.zeros_like(out["omega"]))
    assert out["mode_shape"].shape == (1, model.nmode, model.nbody, 3)


def dense_quadratic_roots(model, s: int, q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Roots of (s² Mr + s Cr + Kr) η = 0 on scipy's null space of B, by ``scipy.linalg.eig``
    of the companion form [[0, I], [−Mr⁻¹Kr, −Mr⁻¹Cr]] (no code shared with the kernels: K by
    the complex step of the written-out Bᵀλ − F, C by the complex step of F in q̇)."""
    N = scipy.linalg.null_space(reference.constraint_jacobian_formula(model, s, q))
    M = np.diag(reference.mass_diagonal(model, s))
    K = reference.stiffness(model, s, q, lam)
    C = -reference.complex_step_jacobian(
        lambda v: reference.applied_forces(model, s, q.astype(complex), v), np.zeros(model.ndof)
    )
    Mr, Kr, Cr = N.T @ M @ N, N.T @ K @ N, N.T @ C @ N
    f = Mr.shape[0]
    A = np.block(
        [[np.zeros((f, f)), np.eye(f)], [-np.linalg.solve(Mr, Kr), -np.linalg.solve(Mr, Cr)]]
    )
    return scipy.linalg.eig(A, right=False)


def roots_from_outputs(damped_omega: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """The 2f underdamped roots s = −ζ|s| ± i ω_d, |s| = ω_d/√(1−ζ²), of stored modes."""
    magnitude = damped_omega / np.sqrt(1.0 - ratio**2)
    upper = -ratio * magnitude + 1j * damped_omega
    return np.concatenate([upper, np.conj(upper)])


CHAIN_SAMPLES = """
[sample]
count = 8
seed = 5
[sample.vary]
"body.b1.mass" = { uniform = [1.0, 2.5] }
"""


@pytest.mark.parametrize("seed", [4, 9, 21])
def test_damped_modes__chain_with_dampers_matches_dense_quadratic_eig(seed):
    """A 3-bar chain (one clearance joint) with two ground spring-dampers, every sample,
    about the kernels' equilibrium (same q, same λ)."""
    text = chain_scene_text(3, {1}, seed, springs=2)
    if "damping" not in text:
        text = text.replace("[[spring]]", "[[spring]]\ndamping = 3.0", 1)
    scene = load_scene_text(text + CHAIN_SAMPLES)
    model = compile_model(scene)
    assert np.any(model.spring_damping)
    eq = solve_equilibrium(model, assemble(model).q)
    modes = solve_modes(model, eq, damped=True)
    assert modes.damped_omega is not None and modes.damping_ratio is not None
    for s in range(model.nsample):
        expected = dense_quadratic_roots(model, s, eq.q[s], eq.lam[s])
        assert np.all(expected.imag != 0.0)  # this chain is underdamped in every mode
        actual = roots_from_outputs(modes.damped_omega[s], modes.damping_ratio[s])
        scale = np.abs(expected).max()
        for root in expected:
            assert np.abs(actual - root).min() <= CLOSED_FORM_RTOL * scale, (root, actual)
        # the stored order: ascending |s|
        magnitude = modes.damped_omega[s] / np.sqrt(1.0 - modes.damping_ratio[s] ** 2)
        assert np.all(np.diff(magnitude) >= 0.0)


def one_dof_roots(p: float, zeta: float) -> tuple[float, float]:
    """The two real roots −ζp ± p√(ζ²−1) of an overdamped mode."""
    root = p * np.sqrt(zeta**2 - 1.0)
    return -zeta * p - root, -zeta * p + root


def test_damped_modes__decoupled_overdamped_modes_pair_their_own_roots():
    """Two overdamped modes whose real roots interleave (−0.5, −2 and −0.27, −14.7 for
    p = 1, 2): pairing by eigenvector gives each its own roots, so ζ is exact; mode order
    is ascending |s| = p. In one batch with an all-underdamped sample and a mixed one (the
    batched path, grouped by number of real roots), and with an untouched third mode, which
    keeps ±5i exactly (the deflated path)."""
    assert one_dof_roots(1.0, 1.25)[0] < one_dof_roots(2.0, 3.75)[1]  # interleaved
    omega = np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]])
    zeta = np.array([[1.25, 3.75], [0.3, 3.75], [0.3, 0.2]])
    D = 2.0 * zeta[:, :, None] * omega[:, :, None] * np.eye(2)
    batch = damped_modes(omega, D)
    np.testing.assert_allclose(batch.damping_ratio, zeta, rtol=1e-13)
    expected = np.where(zeta < 1.0, omega * np.sqrt(np.abs(1.0 - zeta**2)), 0.0)
    np.testing.assert_allclose(batch.damped_omega, expected, rtol=1e-13)
    assert np.all(batch.damped_omega[zeta > 1.0] == 0.0)
    for s in range(3):
        alone = damped_modes(omega[s : s + 1], D[s : s + 1])
        np.testing.assert_array_equal(alone.damping_ratio[0], batch.damping_ratio[s])
    third = damped_modes(np.array([[1.0, 2.0, 5.0]]), np.pad(D[:1], ((0, 0), (0, 1), (0, 1))))
    np.testing.assert_array_equal(third.damped_omega, [[0.0, 0.0, 5.0]])
    np.testing.assert_allclose(third.damping_ratio[0, :2], [1.25, 3.75], rtol=1e-13)
    assert third.damping_ratio[0, 2] == 0.0


def test_damped_modes__order_follows_magnitude_when_damping_reorders_modes():
    """Decoupled: mode p = 1 underdamped, mode p = 0.5 damped with ζ = 0.5 and a mode
    p = 0.8: order by |s| (= p for a decoupled mode) is 0.5, 0.8, 1 whatever the input order."""
    omega = np.array([[0.5, 0.8, 1.0]])
    D = np.diag([2 * 0.5 * 0.5, 2 * 0.1 * 0.8, 2 * 0.2 * 1.0])[None]
    result = damped_modes(omega, D)
    zeta = np.array([0.5, 0.1, 0.2])
    np.testing.assert_allclose(result.damping_ratio[0], zeta, rtol=1e-13)
    np.testing.assert_allclose(result.damped_omega[0], omega[0] * np.sqrt(1 - zeta**2), rtol=1e-13)


def test_damped_modes__zero_and_unstable_modes():
    """A damped zero mode (roots 0, −d): damped_omega 0, ζ = +inf; an undamped zero mode:
    0 and ζ = 0; an unstable mode (p² = −4, damped: roots of s² + s − 4, one > 0): 0 and NaN;
    a failed sample (NaN ω): NaN."""
    omega = np.array([[-2.0, 0.0, 0.0, 3.0], [np.nan] * 4])
    D = np.zeros((2, 4, 4))
    D[0, 0, 0] = 1.0
    D[0, 1, 1] = 0.7
    D[0, 3, 3] = 0.6
    result = damped_modes(omega, D)
    np.testing.assert_array_equal(result.damped_omega[0, :3], [0.0, 0.0, 0.0])
    assert np.isnan(result.damping_ratio[0, 0])
    # the zero modes sort by key 0 in input order: the damped one (input 1) first
    np.testing.assert_array_equal(result.damping_ratio[0, 1:3], [np.inf, 0.0])
    np.testing.assert_allclose(result.damping_ratio[0, 3], 0.6 / 6.0, rtol=1e-13)
    assert np.isnan(result.damped_omega[1]).all() and np.isnan(result.damping_ratio[1]).all()


EXTRA_DAMPERS = """
[[spring]]
name = "isotropic"
bodies = ["b1", "b3"]
points = [[0.1, 0.05], [-0.2, 0.0]]
stiffness = 0.0
rest_length = 0.0
damping = 2.5

[[spring]]
name = "along"
bodies = ["ground", "b2"]
points = [[0.3, 0.2], [0.1, -0.03]]
stiffness = 10.0
damping = 4.0
"""


def test_damping_matrix__is_minus_velocity_derivative_of_the_forces():
    """C = −∂F/∂q̇ by central differences (exact: F is linear in q̇), at a random state;
    symmetric and positive semi-definite."""
    text = chain_scene_text(4, {2}, 13, springs=1) + EXTRA_DAMPERS
    model = compile_model(load_scene_text(text))
    km = model.kernel_model()
    rng = np.random.default_rng(1)
    q = model.q0[0] + rng.normal(scale=0.05, size=model.ndof)
    v = rng.normal(scale=2.0, size=model.ndof)
    C = np.zeros((model.ndof, model.ndof))
    damping_matrix_add(km, 0, q, 1.0, C)
    assert C.any()

    def forces(velocity):
        F = np.empty(model.ndof)
        applied_forces(km, 0, q, velocity, 0.0, F)
        return F

    h = 1e-3
    columns = [(forces(v + h * e) - forces(v - h * e)) / (2 * h) for e in np.eye(model.ndof)]
    difference = -np.stack(columns, axis=1)
    assert np.linalg.norm(C - difference) <= FD_RTOL * np.linalg.norm(C)
    assert np.abs(C - C.T).max() <= 1e-15 * np.abs(C).max()  # symmetric to round-off
    assert np.linalg.eigvalsh(C).min() >= -1e-12 * np.abs(C).max()
