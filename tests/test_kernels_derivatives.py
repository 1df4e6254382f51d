"""Every derivative the kernels compute, against central differences and the complex-step
reference, on random chains with mixed ideal, clearance and prismatic joints (hypothesis)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mcchain.kernels.forces import (
    applied_forces,
    applied_stiffness_add,
    damper_stiffness_add,
    kinetic_energy,
    potential_energy,
)
from mcchain.kernels.joints import (
    constraint_gamma,
    constraint_hessian_add,
    constraint_jacobian,
    constraint_residual,
)
from mcchain.scene import compile_model, load_scene_text
from mcchain.testing import dense as reference
from mcchain.testing.factory import chain_scene_text

FD_RTOL = 1e-6
"""Issue #2: derivatives agree with central differences to 1e-6 relative."""
FD_STEP = 1e-6
"""Central-difference step: truncation O(h²) ≈ 1e-12, round-off O(ε/h) ≈ 1e-10."""
COMPLEX_STEP_RTOL = 1e-12
"""Complex-step derivatives are exact to round-off."""
GAMMA_RTOL = 1e-12
"""γ against its complex-step reference, relative to the magnitude of the terms it sums."""


@st.composite
def chains(draw):
    """A random chain (1–6 bars), a random configuration, velocity and multipliers."""
    nbody = draw(st.integers(1, 6))
    clearance = draw(st.sets(st.integers(0, nbody - 1)))
    prismatic = draw(st.sets(st.integers(0, nbody - 1))) - clearance
    seed = draw(st.integers(0, 2**31 - 1))
    text = chain_scene_text(
        nbody,
        clearance,
        seed,
        springs=draw(st.integers(0, 2)),
        forces=draw(st.integers(0, 2)),
        driver=draw(st.booleans()),
        prismatic_joints=prismatic,
    )
    model = compile_model(load_scene_text(text))
    rng = np.random.default_rng(seed)
    # an arbitrary (not assembled) state: derivative identities hold everywhere
    q = model.q0[0] + rng.normal(scale=0.05, size=model.ndof)
    v = rng.normal(scale=2.0, size=model.ndof)
    lam = rng.normal(scale=10.0, size=model.ncon)
    return model, q, v, lam


def _jacobian(km, q, ncon, ndof):
    B = np.empty((ncon, ndof))
    constraint_jacobian(km, 0, q, B)
    return B


def _residual(km, q, ncon, t=0.0):
    phi = np.empty(ncon)
    constraint_residual(km, 0, q, t, phi)
    return phi


def _central(fun, x, h=FD_STEP):
    """Central differences of ``fun`` at ``x``, column by column, Richardson-extrapolated
    from steps h and h/2: (4 D(h/2) − D(h))/3 cancels the h² term, so a clearance joint
    whose |d| is small (derivatives growing like 1/|d|ⁿ) does not put the difference's
    truncation error above FD_RTOL (a random chain measured 6e-6 at h = 1e-6 against the
    complex step, where the kernel agreed with it to 4e-17)."""

    def difference(k, step):
        e = np.zeros_like(x)
        e[k] = step
        return (fun(x + e) - fun(x - e)) / (2 * step)

    cols = [(4 * difference(k, h / 2) - difference(k, h)) / 3 for k in range(x.size)]
    return np.stack(cols, axis=-1)


def _assert_close(actual, expected, rtol):
    scale = max(np.linalg.norm(expected), 1e-12)
    assert np.linalg.norm(actual - expected) <= rtol * scale, (actual, expected)


SETTINGS = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(chains())
def test_constraint_jacobian__matches_differences(chain):
    model, q, _, _ = chain
    km = model.kernel_model()
    B = _jacobian(km, q, model.ncon, model.ndof)
    fd = _central(lambda x: _residual(km, x, model.ncon), q)
    _assert_close(B, fd, FD_RTOL)
    _assert_close(B, reference.constraint_jacobian(model, 0, q), COMPLEX_STEP_RTOL)
    _assert_close(_residual(km, q, model.ncon), reference.constraints(model, 0, q), 1e-14)


@SETTINGS
@given(chains())
def test_constraint_gamma__is_minus_bdot_qdot(chain):
    """γ = −Ḃ q̇, Ḃ q̇ = d/dt [B(q + t q̇)] q̇ at t = 0, by the complex step of the written-out B
    (independent code, exact to round-off). A central difference is no reference here: a
    clearance joint's term (|ḋ|² − (e·ḋ)²)/|d| has derivatives growing like 1/|d|³, and a random
    state can put |d| near zero, where the difference's truncation error dominates."""
    model, q, v, _ = chain
    km = model.kernel_model()
    gamma = np.empty(model.ncon)
    constraint_gamma(km, 0, q, v, 0.0, gamma)
    h = 1e-30
    bdot = np.imag(reference.constraint_jacobian_formula(model, 0, q + 1j * h * v)) / h
    # γ sums terms that may cancel: its round-off scales with the terms, not with the sum
    terms = np.linalg.norm(np.abs(bdot) @ np.abs(v))
    assert np.linalg.norm(gamma + bdot @ v) <= GAMMA_RTOL * max(terms, 1e-12)


@SETTINGS
@given(chains())
def test_stiffness__matches_differences(chain):
    model, q, _, lam = chain
    km = model.kernel_model()
    K = np.zeros((model.ndof, model.ndof))
    constraint_hessian_add(km, 0, q, lam, K)
    applied_stiffness_add(km, 0, q, 0.0, K)
    rest = np.zeros(model.ndof)

    def applied_force(x):
        F = np.empty(model.ndof)
        applied_forces(km, 0, x, rest, 0.0, F)
        return F

    _assert_close(K, _constraint_hessian(model, q, lam) - _central(applied_force, q), FD_RTOL)
    _assert_close(K, K.T, 1e-13)


def _constraint_hessian(model, q, lam):
    """∂(Bᵀλ)/∂q by the complex step of the written-out B: no central difference, whose
    truncation error grows near a clearance joint's |d| → 0 (a random one-bar chain with a
    clearance joint put the difference 7.7e-6 off, relative, with the kernel exact)."""
    h = 1e-30
    cols = []
    for k in range(q.size):
        step = np.zeros(q.size, dtype=complex)
        step[k] = 1j * h
        B = reference.constraint_jacobian_formula(model, 0, q + step)
        cols.append(np.imag(B.T @ lam) / h)
    return np.stack(cols, axis=-1)


@SETTINGS
@given(chains())
def test_damper_stiffness__matches_differences_at_any_velocity(chain):
    """−∂F/∂q of the damping forces at a fixed, non-zero q̇ (not symmetric).

    Differenced on a damping-only copy of the model (no gravity, loads or spring stiffness):
    the round-off of a central difference scales with the force differenced, so differencing
    the whole spring force would bury a small damping stiffness in noise."""
    model, q, v, _ = chain
    km = model.kernel_model()
    K = np.zeros((model.ndof, model.ndof))
    damper_stiffness_add(km, 0, q, v, K)
    if not np.any(model.spring_damping):
        assert not K.any()
        return
    damping_only = replace(
        model,
        gravity=np.zeros_like(model.gravity),
        force_value=np.zeros_like(model.force_value),
        force_torque=np.zeros_like(model.force_torque),
        spring_stiffness=np.zeros_like(model.spring_stiffness),
    ).kernel_model()
    K_damping_only = np.zeros((model.ndof, model.ndof))
    damper_stiffness_add(damping_only, 0, q, v, K_damping_only)
    np.testing.assert_array_equal(K_damping_only, K)  # the stiffness part plays no role

    def minus_damping_forces(x):
        F = np.empty(model.ndof)
        applied_forces(damping_only, 0, x, v, 0.0, F)
        return -F

    _assert_close(K, _central(minus_damping_forces, q), FD_RTOL)


@SETTINGS
@given(chains())
def test_applied_forces__match_reference_and_potential(chain):
    model, q, v, _ = chain
    km = model.kernel_model()
    F = np.empty(model.ndof)
    applied_forces(km, 0, q, v, 0.0, F)
    _assert_close(F, reference.applied_forces(model, 0, q, v), 1e-13)
    # at rest every load is conservative: F = −∂V/∂q
    F_rest = np.empty(model.ndof)
    applied_forces(km, 0, q, np.zeros(model.ndof), 0.0, F_rest)
    grad = _central(lambda x: np.array([potential_energy(km, 0, x)]), q)[0]
    _assert_close(F_rest, -grad, FD_RTOL)
    mass = reference.mass_diagonal(model, 0)
    assert np.isclose(kinetic_energy(km, 0, v), 0.5 * np.sum(mass * v * v), rtol=1e-14, atol=0)
