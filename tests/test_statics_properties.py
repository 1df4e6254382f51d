"""Statics on random chains against the SciPy reference, rank handling, zero modes, scene
checks and determinism across chunking and threads."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mcchain.errors import SceneError
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.statics import assemble, check_scene, solve_equilibrium, solve_modes
from mcchain.status import Status
from mcchain.testing import dense as reference
from mcchain.testing.factory import chain_scene_text

REFERENCE_RTOL = 1e-8
"""Both sides are exact to round-off; the stiff clearance modes cost conditioning."""
EQUILIBRIUM_ATOL = 1e-9
"""Converged residual (default tolerance 1e-10, scaled) seen by the independent reference."""
FAILED = Status.ASSEMBLY_FAILED | Status.EQUILIBRIUM_NOT_CONVERGED | Status.SINGULAR


@pytest.mark.slow  # statics of random chains against scipy root
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    nbody=st.integers(1, 4),
    clearance=st.sets(st.integers(0, 3)),
    springs=st.integers(0, 2),
    forces=st.integers(0, 2),
    seed=st.integers(0, 2**31 - 1),
)
def test_statics__random_chains_are_verified_equilibria(nbody, clearance, springs, forces, seed):
    """Either flagged, or a true equilibrium (independent residual) whose eigenpulsations
    match SciPy's eigh, with every clearance joint in contact (λ > 0)."""
    clearance = {k for k in clearance if k < nbody}
    text = chain_scene_text(nbody, clearance, seed, springs=springs, forces=forces)
    model = compile_model(load_scene_text(text))
    assembled = assemble(model)
    eq = solve_equilibrium(model, assembled.q, assembled.status)
    modes = solve_modes(model, eq)
    if eq.status[0] & FAILED:
        assert np.all(np.isnan(eq.q[0])) and np.all(np.isnan(modes.omega[0]))
        return
    q, lam = eq.q[0], eq.lam[0]
    residual = reference.equilibrium_residual(model, 0, np.concatenate([q, lam]))
    force_scale = np.max(np.abs(reference.applied_forces(model, 0, q)))
    assert np.max(np.abs(residual[: model.ndof])) <= EQUILIBRIUM_ATOL * force_scale
    assert np.max(np.abs(residual[model.ndof :])) <= EQUILIBRIUM_ATOL
    contact = [lam[model.joint_row[k]] for k in range(model.njoint) if model.joint_kind[k]]
    assert (eq.status[0] & Status.CONTACT_LOST != 0) == any(x <= 0 for x in contact)
    expected = reference.modes(model, 0, q, lam)
    scale = np.max(np.abs(expected))
    np.testing.assert_allclose(modes.omega[0], expected, rtol=REFERENCE_RTOL, atol=1e-6 * scale)


def test_equilibrium__converges_more_often_than_scipy_root():
    """On 60 random loaded chains started from their written configuration, the globalised
    Newton fails at most as often as ``scipy.optimize.root`` (hybr) and at most 5 %."""
    rng = np.random.default_rng(2024)
    kernel_failures = scipy_failures = 0
    trials = 60
    for _ in range(trials):
        nbody = int(rng.integers(1, 5))
        clearance = {k for k in range(nbody) if rng.random() < 0.5}
        text = chain_scene_text(
            nbody, clearance, int(rng.integers(2**31)), springs=int(rng.integers(3)), forces=1
        )
        model = compile_model(load_scene_text(text))
        assembled = assemble(model)
        eq = solve_equilibrium(model, assembled.q, assembled.status)
        kernel_failures += bool(eq.status[0] & FAILED)
        scipy_failures += not reference.statics(model, 0, assembled.q[0]).success
    assert kernel_failures <= scipy_failures
    assert kernel_failures <= 0.05 * trials


def test_modes__zero_modes_are_exact_zeros():
    # no gravity, no springs, no loads: every mode of the chain is a free motion
    text = chain_scene_text(3, {1}, seed=3).replace(
        "gravity = [0.0, -9.81]", "gravity = [0.0, 0.0]"
    )
    assert "gravity = [0.0, 0.0]" in text
    model = compile_model(load_scene_text(text))
    out = solve_chunk(model, load_scene_text(text))
    assert out["omega"].shape == (1, model.nmode)
    assert np.all(out["omega"] == 0.0)
    assert out["stable"].all()


def test_modes__mode_shapes_are_mass_orthonormal_null_vectors():
    text = chain_scene_text(3, {0, 2}, seed=5, springs=1)
    text = text.replace("[modes]", "[modes]\nshapes = true")
    scene = load_scene_text(text)
    model = compile_model(scene)
    assembled = assemble(model)
    eq = solve_equilibrium(model, assembled.q, assembled.status)
    modes = solve_modes(model, eq, shapes=True)
    Z = modes.shapes[0]  # (nmode, ndof)
    M = np.diag(reference.mass_diagonal(model, 0))
    np.testing.assert_allclose(Z @ M @ Z.T, np.eye(model.nmode), atol=1e-10)
    B = reference.constraint_jacobian(model, 0, eq.q[0])
    np.testing.assert_allclose(B @ Z.T, 0.0, atol=1e-10)
    K = reference.stiffness(model, 0, eq.q[0], eq.lam[0])
    p2 = np.sign(modes.omega[0]) * modes.omega[0] ** 2
    np.testing.assert_allclose(np.diag(Z @ K @ Z.T), p2, rtol=1e-6)


def test_check_scene__redundant_joint_is_rejected():
    text = chain_scene_text(2, (), seed=1)
    # a second ideal joint at the same place repeats J1's two rows
    doubled = text + '\n[[joint]]\nname = "J1bis"\nbodies = ["b0", "b1"]\n'
    model = compile_model(load_scene_text(doubled + _same_points(text, "J1")))
    with pytest.raises(SceneError, match=r"redundant constraints: rank of B is 4 < 6"):
        check_scene(model)


def test_check_scene__negative_degrees_of_freedom():
    text = chain_scene_text(1, (), seed=1)
    extra = (
        '\n[[joint]]\nname = "J0b"\nbodies = ["ground", "b0"]\npoints = [[0.1, 0.0], [0.1, 0.0]]\n'
    )
    model = compile_model(load_scene_text(text + extra))
    with pytest.raises(SceneError, match="negative degrees of freedom: 4 constraint rows for 3"):
        check_scene(model)


def test_check_scene__unassemblable_positions():
    # a four-bar whose links cannot close: ground link 1 m, other links 0.1 m each
    text = chain_scene_text(2, (), seed=2)
    extra = (
        '\n[[joint]]\nname = "close"\nbodies = ["ground", "b1"]\n'
        "points = [[5.0, 0.0], [0.0, 0.0]]\n"
    )
    model = compile_model(load_scene_text(text + extra))
    with pytest.raises(SceneError, match="initial positions cannot be assembled"):
        check_scene(model)


def _same_points(text: str, joint: str) -> str:
    """The ``points = ...`` line of ``joint`` in a factory scene."""
    block = text[text.index(f'name = "{joint}"') :]
    line = next(x for x in block.splitlines() if x.startswith("points"))
    return line + "\n"


@pytest.mark.parametrize("chunk", [1, 7, 64])
def test_statics__bit_identical_across_chunks_and_threads(chunk):
    text = chain_scene_text(3, {1, 2}, seed=9, springs=1, forces=1, sample=64)
    scene = load_scene_text(text)
    model = compile_model(scene)
    whole = solve_chunk(model, scene)
    parts = [solve_chunk(model.select(i, min(i + chunk, 64)), scene) for i in range(0, 64, chunk)]
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single = solve_chunk(model, scene)
    finally:
        numba.set_num_threads(previous)
    for name, value in whole.items():
        joined = np.concatenate([p[name] for p in parts])
        np.testing.assert_array_equal(joined, value, err_msg=name)
        np.testing.assert_array_equal(single[name], value, err_msg=name)
