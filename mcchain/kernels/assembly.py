"""Assembly kernels and the projections the static and dynamic analyses share.

* scales of a sample (length, largest entry), the Schur complement S = B M⁻¹ Bᵀ (Cholesky) and
  the solves through it: least-norm projection of positions onto Φ(q) = 0, multipliers fitted
  to given forces;
* assembly: every sample's initial state projected onto the constraints (positions that
  already satisfy them are kept bit for bit), velocities onto B q̇ = ν.

``assemble_one`` treats one sample and returns status bits; ``assemble_batch`` loops over
the samples ``start:stop``. Nothing here raises.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mcchain.kernels.config import JIT
from mcchain.kernels.forces import (
    mass_diagonal,
)
from mcchain.kernels.joints import (
    JOINT_IDEAL,
    _add_point_rows,
    constraint_jacobian,
    constraint_residual,
    constraint_velocity_rhs,
    joint_vectors,
)
from mcchain.kernels.linalg import (
    cholesky,
    cholesky_solve,
)
from mcchain.status import (
    ASSEMBLY_FAILED,
    SINGULAR,
)

SCHUR_PIVOT_RTOL = 1e-12
"""Cholesky pivot of B M⁻¹ Bᵀ below this × its largest diagonal: rank-deficient B."""
ASSEMBLY_MAX_ITER = 50
PROJECTION_MAX_ITER = 20


# --------------------------------------------------------------------------------------
# scales
# --------------------------------------------------------------------------------------
@njit(**JIT)
def length_scale(km, s):
    """Characteristic length of sample ``s``, m: the largest attachment-point distance."""
    scale = 0.0
    for k in range(km.joint_point_a.shape[1]):
        for side in range(2):
            arr = km.joint_point_a if side == 0 else km.joint_point_b
            i = s % arr.shape[0]
            scale = max(scale, math.hypot(arr[i, k, 0], arr[i, k, 1]))
    for k in range(km.spring_point_a.shape[1]):
        for side in range(2):
            arr = km.spring_point_a if side == 0 else km.spring_point_b
            i = s % arr.shape[0]
            scale = max(scale, math.hypot(arr[i, k, 0], arr[i, k, 1]))
    return scale if scale > 0.0 else 1.0


@njit(**JIT)
def max_abs(x, n):
    """max |x[:n]|, NaN-propagating (a NaN entry gives NaN)."""
    result = 0.0
    for i in range(n):
        a = abs(x[i])
        if a > result or a != a:
            result = a
    return result


# --------------------------------------------------------------------------------------
# Schur complement solves (B M⁻¹ Bᵀ)
# --------------------------------------------------------------------------------------
@njit(**JIT)
def schur_factor(B, minv, m, n, S_out):
    """S = B M⁻¹ Bᵀ into ``S_out`` (m, m), Cholesky-factored in place; False if singular."""
    for i in range(m):
        for j in range(i + 1):
            acc = 0.0
            for k in range(n):
                acc += B[i, k] * minv[k] * B[j, k]
            S_out[i, j] = acc
            S_out[j, i] = acc
    return cholesky(S_out, m, SCHUR_PIVOT_RTOL)


@njit(**JIT)
def project_onto_rows(B, minv, m, n, S, residual, x):
    """x ← x − M⁻¹Bᵀ S⁻¹ residual: the M-orthogonal correction that removes ``residual``.

    ``S`` is the factor from :func:`schur_factor`; ``residual`` (m,) is overwritten.
    """
    cholesky_solve(S, m, residual)
    for k in range(n):
        acc = 0.0
        for i in range(m):
            acc += B[i, k] * residual[i]
        x[k] -= minv[k] * acc


@njit(**JIT)
def project_positions(km, s, q, t, minv, m, n, lscale, B, S, phi):
    """Gauss–Newton projection of q onto Φ(q, t) = 0 (M-smallest corrections), in place.

    ``B``, ``S``, ``phi`` are scratch of shapes (m, n), (m, m), (m,).

    Returns:
        ``True`` if |Φ| ≤ 1e-14 × ``lscale`` was reached within PROJECTION_MAX_ITER steps.
    """
    for _it in range(PROJECTION_MAX_ITER):
        constraint_residual(km, s, q, t, phi)
        if max_abs(phi, m) <= 1e-14 * lscale:
            return True
        constraint_jacobian(km, s, q, B)
        if not schur_factor(B, minv, m, n, S):
            return False
        project_onto_rows(B, minv, m, n, S, phi, q)
    constraint_residual(km, s, q, t, phi)
    return max_abs(phi, m) <= 1e-14 * lscale


@njit(**JIT)
def fit_multipliers(B, minv, F, m, n, S, lam_out):
    """λ of the least-squares fit Bᵀλ ≈ F in the M⁻¹ metric: S λ = B M⁻¹ F.

    ``S`` must hold the Cholesky factor of B M⁻¹ Bᵀ (:func:`schur_factor`).
    """
    for i in range(m):
        acc = 0.0
        for k in range(n):
            acc += B[i, k] * minv[k] * F[k]
        lam_out[i] = acc
    cholesky_solve(S, m, lam_out)


# --------------------------------------------------------------------------------------
# assembly
# --------------------------------------------------------------------------------------
@njit(**JIT)
def _assembly_residual(km, s, q, target, psi_out, J_out):
    """Ψ(q) and ∂Ψ/∂q with every clearance joint held at d = c u (two rows each).

    ``target`` (njoint, 2) holds u. Rows: two per joint (joint k at 2k), then drivers.
    """
    J_out[:, :] = 0.0
    nj = km.joint_body_a.shape[0]
    for k in range(nj):
        a = km.joint_body_a[k]
        b = km.joint_body_b[k]
        pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
        c = 0.0
        if km.joint_kind[k] != JOINT_IDEAL:
            c = km.joint_clearance[s % km.joint_clearance.shape[0], k]
        psi_out[2 * k] = dx - c * target[k, 0]
        psi_out[2 * k + 1] = dy - c * target[k, 1]
        _add_point_rows(J_out, 2 * k, b, 1.0, 1.0, 0.0, pbx, pby)
        _add_point_rows(J_out, 2 * k, a, -1.0, 1.0, 0.0, pax, pay)
        _add_point_rows(J_out, 2 * k + 1, b, 1.0, 0.0, 1.0, pbx, pby)
        _add_point_rows(J_out, 2 * k + 1, a, -1.0, 0.0, 1.0, pax, pay)
    for j in range(km.driver_body.shape[0]):
        body = km.driver_body[j]
        psi_out[2 * nj + j] = q[3 * body + 2] - km.driver_angle0[s % km.driver_angle0.shape[0], j]
        J_out[2 * nj + j, 3 * body + 2] = 1.0


@njit(**JIT)
def assemble_one(km, s, q, v):
    """Project q and v of sample ``s`` onto the constraints (t = 0), in place.

    Positions already satisfying |Φ| ≤ 1e-12 × the length scale are kept bit for bit.
    Otherwise every clearance joint is first placed at d = c u, u from ``eccentricity``,
    else the direction of the given d, else gravity's (a journal resting on its bearing's
    bottom), else +x; Gauss–Newton then takes the M-smallest correction. Velocities are
    corrected the same way onto B q̇ = ν unless they already satisfy it.

    Returns:
        status bits (ASSEMBLY_FAILED, SINGULAR).
    """
    n = q.shape[0]
    m = 0
    for k in range(km.joint_kind.shape[0]):
        m += 2 if km.joint_kind[k] == JOINT_IDEAL else 1
    m += km.driver_body.shape[0]
    nj = km.joint_body_a.shape[0]
    lscale = length_scale(km, s)
    tol = 1e-12 * lscale
    minv = np.empty(n)
    mass_diagonal(km, s, minv)
    for i in range(n):
        minv[i] = 1.0 / minv[i]
    phi = np.empty(m)
    constraint_residual(km, s, q, 0.0, phi)
    if not max_abs(phi, m) <= tol:
        # hold each clearance journal at d = c u during the projection
        target = np.zeros((nj, 2))
        ig = s % km.gravity.shape[0]
        gnorm = math.hypot(km.gravity[ig, 0], km.gravity[ig, 1])
        for k in range(nj):
            if km.joint_kind[k] == JOINT_IDEAL:
                continue
            alpha = km.joint_eccentricity[s % km.joint_eccentricity.shape[0], k]
            c = km.joint_clearance[s % km.joint_clearance.shape[0], k]
            _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
            dist = math.hypot(dx, dy)
            if alpha == alpha:
                target[k, 0] = math.cos(alpha)
                target[k, 1] = math.sin(alpha)
            elif dist > 1e-3 * c and dist > 0.0:
                target[k, 0] = dx / dist
                target[k, 1] = dy / dist
            elif gnorm > 0.0:
                target[k, 0] = km.gravity[ig, 0] / gnorm
                target[k, 1] = km.gravity[ig, 1] / gnorm
            else:
                target[k, 0] = 1.0
        ma = 2 * nj + km.driver_body.shape[0]
        psi = np.empty(ma)
        J = np.empty((ma, n))
        S = np.empty((ma, ma))
        converged = False
        for _it in range(ASSEMBLY_MAX_ITER):
            _assembly_residual(km, s, q, target, psi, J)
            if max_abs(psi, ma) <= 1e-14 * lscale:
                converged = True
                break
            if not schur_factor(J, minv, ma, n, S):
                return ASSEMBLY_FAILED | SINGULAR
            project_onto_rows(J, minv, ma, n, S, psi, q)
        constraint_residual(km, s, q, 0.0, phi)
        if not converged or not max_abs(phi, m) <= tol:
            return ASSEMBLY_FAILED
    B = np.empty((m, n))
    constraint_jacobian(km, s, q, B)
    nu = np.empty(m)
    constraint_velocity_rhs(km, s, nu)
    vscale = 0.0
    for i in range(m):
        acc = -nu[i]
        for k in range(n):
            acc += B[i, k] * v[k]
        nu[i] = acc
        vscale = max(vscale, abs(acc))
    if vscale > 1e-12 * (1.0 + max_abs(v, n)):
        S = np.empty((m, m))
        if not schur_factor(B, minv, m, n, S):
            return SINGULAR
        project_onto_rows(B, minv, m, n, S, nu, v)
    return 0


@njit(**JIT)
def assemble_batch(start, stop, km, q_out, v_out, status_out):
    """Assemble samples ``start:stop`` in place.

    Args:
        km: the kernel model (:meth:`mcchain.model.Model.kernel_model`).
        q_out: (nsample, 3 nbody) initial positions in, assembled positions out (NaN on failure).
        v_out: (nsample, 3 nbody) initial velocities in, consistent velocities out.
        status_out: (nsample,) uint32, bits OR-ed in.
    """
    for s in range(start, stop):
        bits = assemble_one(km, s, q_out[s], v_out[s])
        if bits != 0:
            status_out[s] |= bits
            q_out[s, :] = np.nan
            v_out[s, :] = np.nan
