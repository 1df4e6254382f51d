"""Batch kernels of the static analyses: equilibrium (Newton), eigenpulsations and the
modal damping of the damped modes.

Each ``*_one`` function treats one sample and returns status bits; each ``*_batch``
function loops over the samples ``start:stop`` and calls it (threads run blocks of samples:
:func:`mcchain.solvers.threads.over_samples`). No reductions across samples, so a
sample's numbers are bit-identical alone, in any chunk, with any thread count. Failed samples
get NaN outputs and their bits (mcchain.status). Work arrays are allocated once per sample.
Assembly and the shared Schur-complement projections are in :mod:`mcchain.kernels.assembly`.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.kernels.assembly import (
    SCHUR_PIVOT_RTOL,
    fit_multipliers,
    length_scale,
    project_positions,
    schur_factor,
)
from mcchain.kernels.config import INLINE, JIT, hypot, njit
from mcchain.kernels.forces import (
    applied_forces,
    applied_stiffness_add,
    damping_matrix_add,
    mass_diagonal,
    potential_energy,
)
from mcchain.kernels.joints import (
    JOINT_CLEARANCE,
    constraint_gamma,
    constraint_hessian_add,
    constraint_jacobian,
    constraint_residual,
    joint_forces,
    joint_vectors,
)
from mcchain.kernels.linalg import (
    EPS,
    cholesky,
    cholesky_solve,
    jacobi_eigh,
    lu_factor,
    lu_solve,
    null_space,
)
from mcchain.status import (
    ASSEMBLY_FAILED,
    CONTACT_LOST,
    EQUILIBRIUM_NOT_CONVERGED,
    SINGULAR,
    UNSTABLE_EQUILIBRIUM,
)

KKT_PIVOT_RTOL = 1e-13
"""LU pivot below this × max |J| entry: the Newton KKT matrix is singular."""
RANK_RTOL = 1e-9
"""A row of B (after QR pivoting) shorter than this × the first: B has lost rank."""
ZERO_MODE_RTOL = 1e3 * EPS
"""|p²| below this × the eigen problem's scale is an exact zero mode (not noise)."""
MAX_ROTATION_STEP = 0.5
"""Largest body rotation of one Newton step, rad (the step is shortened to it)."""


# --------------------------------------------------------------------------------------
# equilibrium
# --------------------------------------------------------------------------------------
@njit(**JIT)
def _equilibrium_residual(km, s, q, lam, n, m, fscale, lscale, v_rest, B, F, R_out):
    """R = [Bᵀλ − F; Φ] into ``R_out``; B and F are overwritten for q (F at rest, v_rest = 0).

    Returns:
        (max norm, sum of squares) of the scaled residual: force rows / F scale, moment rows
        / (F scale × L scale), constraint rows / L scale. The max norm decides convergence,
        the smooth sum of squares is the line-search merit (the Newton direction always
        descends it).
    """
    constraint_jacobian(km, s, q, B)
    applied_forces(km, s, q, v_rest, 0.0, F)
    for k in range(n):
        acc = -F[k]
        for i in range(m):
            acc += B[i, k] * lam[i]
        R_out[k] = acc
    constraint_residual(km, s, q, 0.0, R_out[n:])
    norm = 0.0
    merit = 0.0
    for k in range(n + m):
        if k >= n:
            scale = lscale
        elif k % 3 == 2:
            scale = fscale * lscale
        else:
            scale = fscale
        a = abs(R_out[k]) / scale
        merit += a * a
        if a > norm or a != a:
            norm = a
    return norm, merit


@njit(**INLINE)
def _flip_pulled_journals(km, s, q, lam):
    """Move every clearance journal with λ ≤ 0 to the mirror side of its bearing (d → −d)
    by translating its body (the bearing's if the journal is the ground). True if any."""
    flipped = False
    for k in range(km.joint_kind.shape[0]):
        if km.joint_kind[k] != JOINT_CLEARANCE or lam[km.joint_row[k]] > 0.0:
            continue
        _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
        b = km.joint_body_b[k]
        sign = -2.0
        if b < 0:
            b = km.joint_body_a[k]
            sign = 2.0
        q[3 * b] += sign * dx
        q[3 * b + 1] += sign * dy
        flipped = True
    return flipped


@njit(**INLINE)
def _kkt_matrix(K, B, minv, mu, n, m, J_out):
    """J = [[K + μ M, Bᵀ], [B, 0]] into ``J_out`` (n + m, n + m)."""
    J_out[:, :] = 0.0
    for i in range(n):
        for k in range(n):
            J_out[i, k] = K[i, k]
        J_out[i, i] += mu / minv[i]
    for i in range(m):
        for k in range(n):
            J_out[n + i, k] = B[i, k]
            J_out[k, n + i] = B[i, k]


@njit(**INLINE)
def _scaled_step_norm(step, n, size, fscale, lscale):
    """max |step| with x, y / L scale, θ as is, λ / F scale."""
    result = 0.0
    for k in range(size):
        if k >= n:
            scale = fscale
        elif k % 3 == 2:
            scale = 1.0
        else:
            scale = lscale
        result = max(result, abs(step[k]) / scale)
    return result


@njit(**INLINE)
def equilibrium_one(km, s, q, lam, tol, max_iter, history):
    """Newton on (q, λ) for Φ(q) = 0, Bᵀλ = F(q), from q, in place.

    Jacobian [[K, Bᵀ], [B, 0]] with K = ∂(Bᵀλ)/∂q − ∂F/∂q (exact). λ starts from the least
    squares fit of Bᵀλ = F. Globalisation: the step is capped (MAX_ROTATION_STEP, one length
    scale) and each trial point is projected back onto Φ = 0; a step is accepted if it
    lowers the scaled residual's sum of squares (Armijo). Otherwise K is shifted to K + μ M
    (Levenberg–Marquardt, μ ×4 per try): such a damped step is also accepted if it lowers
    the potential energy, with λ refitted, so a far start slides down to a stable
    equilibrium; μ shrinks ×4 per success and returns to 0 (pure Newton, quadratic).
    Once the residual is ≤ ``tol``, one more (polishing) step is taken unless it is
    already at round-off level. If a clearance joint then needs λ ≤ 0, its journal is moved
    to the mirror side of the bearing and Newton restarts once (the contact equilibrium).

    Args:
        q: (3 nbody,) start in, equilibrium out.
        lam: (ncon,) multipliers out.
        history: (max_iter + 1, 2) per iteration: the scaled residual norm before it and the
            scaled max norm of its Newton step (x, y / L scale; θ; λ / F scale). NaN after.

    Returns:
        (status bits, iterations taken to reach ``tol``).
    """
    n = q.shape[0]
    m = lam.shape[0]
    lscale = length_scale(km, s)
    minv = np.empty(n)
    mass_diagonal(km, s, minv)
    for i in range(n):
        minv[i] = 1.0 / minv[i]
    B = np.empty((m, n))
    F = np.empty(n)
    v_rest = np.zeros(n)
    constraint_jacobian(km, s, q, B)
    applied_forces(km, s, q, v_rest, 0.0, F)
    fscale = 0.0
    for k in range(n):
        fscale = max(fscale, abs(F[k]) / (lscale if k % 3 == 2 else 1.0))
    if not fscale > 0.0:
        fscale = 1.0
    # λ₀: least squares Bᵀλ ≈ F, i.e. S λ = B M⁻¹ F
    S = np.empty((m, m))
    if not schur_factor(B, minv, m, n, S):
        return SINGULAR, 0
    fit_multipliers(B, minv, F, m, n, S, lam)

    size = n + m
    R = np.empty(size)
    J = np.empty((size, size))
    piv = np.empty(size, dtype=np.int64)
    step = np.empty(size)
    q_trial = np.empty(n)
    lam_trial = np.empty(m)
    R_trial = np.empty(size)
    B_work = np.empty((m, n))
    phi_work = np.empty(m)
    K = np.empty((n, n))
    norm, merit = _equilibrium_residual(km, s, q, lam, n, m, fscale, lscale, v_rest, B, F, R)
    energy = potential_energy(km, s, q)
    iterations = 0
    converged = False
    polished = False
    flipped = False
    mu = 0.0  # Levenberg–Marquardt shift, 1/s²: 0 is plain Newton
    mu_unit = 0.0
    for it in range(max_iter + 1):
        if not converged:
            history[it, 0] = norm
            if norm <= tol:
                converged = True
                iterations = it
        if converged and (polished or norm <= 16.0 * EPS):
            if flipped or not _flip_pulled_journals(km, s, q, lam):
                break
            # a journal held by λ < 0 sits on the wrong side of its bearing: the mirror
            # position (d → −d) is the contact equilibrium; restart Newton from there once
            flipped = True
            converged = False
            polished = False
            project_positions(km, s, q, 0.0, minv, m, n, lscale, B_work, S, phi_work)
            _equilibrium_residual(km, s, q, lam, n, m, fscale, lscale, v_rest, B, F, R)
            if not schur_factor(B, minv, m, n, S):
                return SINGULAR, it
            fit_multipliers(B, minv, F, m, n, S, lam)
            norm, merit = _equilibrium_residual(
                km, s, q, lam, n, m, fscale, lscale, v_rest, B, F, R
            )
            energy = potential_energy(km, s, q)
            mu = 0.0
            continue
        if it == max_iter:
            break
        K[:, :] = 0.0
        constraint_hessian_add(km, s, q, lam, K)
        applied_stiffness_add(km, s, q, 0.0, K)
        if mu_unit == 0.0:
            # the shift's natural unit: the largest stiffness over mass ratio, ≈ p_max²
            for k in range(n):
                mu_unit = max(mu_unit, abs(K[k, k]) * minv[k])
            if not mu_unit > 0.0:
                mu_unit = 1.0
        accepted = False
        for _try in range(60):
            _kkt_matrix(K, B, minv, mu, n, m, J)
            if not lu_factor(J, size, piv, KKT_PIVOT_RTOL):
                if mu == 0.0 and converged:
                    return SINGULAR, it
                if mu > 1e12 * mu_unit:
                    return SINGULAR, it
                mu = 1e-2 * mu_unit if mu == 0.0 else 4.0 * mu
                continue
            for i in range(size):
                step[i] = -R[i]
            lu_solve(J, size, piv, step)
            if mu == 0.0 and not converged:
                history[it, 1] = _scaled_step_norm(step, n, size, fscale, lscale)
            if converged:
                # polishing step: full Newton
                for k in range(n):
                    q[k] += step[k]
                for i in range(m):
                    lam[i] += step[n + i]
                norm, merit = _equilibrium_residual(
                    km, s, q, lam, n, m, fscale, lscale, v_rest, B, F, R
                )
                polished = True
                accepted = True
                break
            # cap the step (MAX_ROTATION_STEP rad, one length scale) so that a far start
            # creeps towards an equilibrium instead of jumping branches
            alpha = 1.0
            for k in range(n):
                limit = MAX_ROTATION_STEP if k % 3 == 2 else lscale
                if abs(step[k]) * alpha > limit:
                    alpha = limit / abs(step[k])
            for k in range(n):
                q_trial[k] = q[k] + alpha * step[k]
            for i in range(m):
                lam_trial[i] = lam[i] + alpha * step[n + i]
            # back onto Φ = 0: removes the linearisation error of long steps (a clearance
            # journal must stay on its circle of radius c); second order near the solution
            if project_positions(km, s, q_trial, 0.0, minv, m, n, lscale, B_work, S, phi_work):
                trial, trial_merit = _equilibrium_residual(
                    km, s, q_trial, lam_trial, n, m, fscale, lscale, v_rest, B, F, R_trial
                )
                if trial_merit <= (1.0 - 2e-4 * alpha) * merit:
                    accepted = True
                elif mu > 0.0:
                    # a damped step that lowers the potential is progress towards a stable
                    # equilibrium even where the residual must first grow; λ is refitted
                    trial_energy = potential_energy(km, s, q_trial)
                    if trial_energy < energy and schur_factor(B, minv, m, n, S):
                        fit_multipliers(B, minv, F, m, n, S, lam_trial)
                        trial, trial_merit = _equilibrium_residual(
                            km, s, q_trial, lam_trial, n, m, fscale, lscale, v_rest, B, F, R_trial
                        )
                        accepted = True
            if accepted:
                mu = 0.25 * mu if mu > 1e-6 * mu_unit else 0.0
                break
            mu = 1e-2 * mu_unit if mu == 0.0 else 4.0 * mu
        if not accepted:
            _equilibrium_residual(km, s, q, lam, n, m, fscale, lscale, v_rest, B, F, R)
            return EQUILIBRIUM_NOT_CONVERGED, it + 1
        if polished:
            continue
        # element loops: an array-to-array slice assignment compiles numba's shape-error
        # message formatting (benchmarks/results/startup/breakdown.md)
        for k in range(n):
            q[k] = q_trial[k]
        for i in range(m):
            lam[i] = lam_trial[i]
        for i in range(size):
            R[i] = R_trial[i]
        norm = trial
        merit = trial_merit
        energy = potential_energy(km, s, q)
    if not converged:
        return EQUILIBRIUM_NOT_CONVERGED, max_iter
    return 0, iterations


@njit(**JIT)
def equilibrium_batch(
    start, stop, km, tol, max_iter, q_out, lam_out, iterations_out, history_out, status_out
):
    """Equilibrium of samples ``start:stop``, starting from ``q_out``.

    Args:
        km: the kernel model (:meth:`mcchain.model.Model.kernel_model`).
        tol: scaled residual tolerance.
        max_iter: Newton iteration limit.
        q_out: (nsample, 3 nbody) start in (assembled), equilibrium out.
        lam_out: (nsample, ncon) multipliers out.
        iterations_out: (nsample,) int64 Newton iterations to reach ``tol``.
        history_out: (nsample, max_iter + 1, 2) scaled residual and Newton step norms per
            iteration (see :func:`equilibrium_one`), NaN-filled by the caller.
        status_out: (nsample,) uint32; samples already flagged are skipped (NaN).
    """
    for s in range(start, stop):
        if status_out[s] != 0:
            q_out[s, :] = np.nan
            lam_out[s, :] = np.nan
            continue
        bits, iterations = equilibrium_one(
            km, s, q_out[s], lam_out[s], tol, max_iter, history_out[s]
        )
        iterations_out[s] = iterations
        if bits != 0:
            status_out[s] |= bits
            q_out[s, :] = np.nan
            lam_out[s, :] = np.nan
            continue
        # continuous contact needs λ > 0 at every clearance joint
        for k in range(km.joint_kind.shape[0]):
            if km.joint_kind[k] == JOINT_CLEARANCE and not lam_out[s, km.joint_row[k]] > 0.0:
                status_out[s] |= CONTACT_LOST


# --------------------------------------------------------------------------------------
# eigenpulsations
# --------------------------------------------------------------------------------------
@njit(**INLINE)
def modes_one(km, s, q, lam, omega_out, shapes_out, want_shapes):
    """Eigenpulsations about the equilibrium (q, λ) of sample ``s``: (Nᵀ K N) v = p² (Nᵀ M N) v,
    N a null-space basis of B.

    N spans the null space of B (QR of Bᵀ with pivoting); (NᵀKN) v = p² (NᵀMN) v is
    reduced with the Cholesky factor L of NᵀMN to the symmetric C = L⁻¹ NᵀKN L⁻ᵀ and solved
    by Jacobi. |p²| ≤ ZERO_MODE_RTOL × max(‖C‖, g/L) is an exact zero. p is reported signed,
    p = sign(p²) √|p²|, ascending; any p² < 0 flags UNSTABLE_EQUILIBRIUM.

    Args:
        omega_out: (nmode,) rad/s.
        shapes_out: (nmode, 3 nbody) mass-normalised mode shapes z = N v (if ``want_shapes``).

    Returns:
        status bits (SINGULAR if B lost rank, UNSTABLE_EQUILIBRIUM).
    """
    n = q.shape[0]
    m = lam.shape[0]
    f = omega_out.shape[0]
    B = np.empty((m, n))
    constraint_jacobian(km, s, q, B)
    Q = np.empty((n, n))
    work = np.empty((n, m + 1))
    rank = null_space(B, m, n, RANK_RTOL, Q, work)
    if rank != m or n - rank != f:
        return SINGULAR
    K = np.zeros((n, n))
    constraint_hessian_add(km, s, q, lam, K)
    applied_stiffness_add(km, s, q, 0.0, K)
    mdiag = np.empty(n)
    mass_diagonal(km, s, mdiag)
    # reduced matrices; N = Q[:, m:]
    KN = np.empty((n, f))
    for i in range(n):
        for j in range(f):
            acc = 0.0
            for k in range(n):
                acc += 0.5 * (K[i, k] + K[k, i]) * Q[k, m + j]
            KN[i, j] = acc
    Kr = np.empty((f, f))
    Mr = np.empty((f, f))
    for i in range(f):
        for j in range(f):
            acck = 0.0
            accm = 0.0
            for k in range(n):
                acck += Q[k, m + i] * KN[k, j]
                accm += Q[k, m + i] * mdiag[k] * Q[k, m + j]
            Kr[i, j] = acck
            Mr[i, j] = accm
    for i in range(f):
        for j in range(i):
            avg = 0.5 * (Kr[i, j] + Kr[j, i])
            Kr[i, j] = avg
            Kr[j, i] = avg
    if not cholesky(Mr, f, SCHUR_PIVOT_RTOL):
        return SINGULAR
    # C = L⁻¹ Kr L⁻ᵀ: forward-substitute columns, then rows
    for j in range(f):
        for i in range(f):
            acc = Kr[i, j]
            for k in range(i):
                acc -= Mr[i, k] * Kr[k, j]
            Kr[i, j] = acc / Mr[i, i]
    for i in range(f):
        for j in range(f):
            acc = Kr[i, j]
            for k in range(j):
                acc -= Mr[j, k] * Kr[i, k]
            Kr[i, j] = acc / Mr[j, j]
    cnorm = 0.0
    for i in range(f):
        for j in range(f):
            cnorm += Kr[i, j] * Kr[i, j]
    cnorm = math.sqrt(cnorm)
    ig = s % km.gravity.shape[0]
    gravity_scale = hypot(km.gravity[ig, 0], km.gravity[ig, 1]) / length_scale(km, s)
    threshold = ZERO_MODE_RTOL * max(cnorm, gravity_scale)
    mu = np.empty(f)
    W = np.empty((f, f))
    if not jacobi_eigh(Kr, f, mu, W):
        return SINGULAR
    bits = 0
    for i in range(f):
        if abs(mu[i]) <= threshold:
            mu[i] = 0.0
        if mu[i] < 0.0:
            bits |= UNSTABLE_EQUILIBRIUM
            omega_out[i] = -math.sqrt(-mu[i])
        else:
            omega_out[i] = math.sqrt(mu[i])
    if want_shapes:
        # v = L⁻ᵀ w, z = N v; sign fixed so the largest component is positive
        for j in range(f):
            for i in range(f - 1, -1, -1):
                acc = W[i, j]
                for k in range(i + 1, f):
                    acc -= Mr[k, i] * W[k, j]
                W[i, j] = acc / Mr[i, i]
            big = 0.0
            for k in range(n):
                acc = 0.0
                for i in range(f):
                    acc += Q[k, m + i] * W[i, j]
                shapes_out[j, k] = acc
                if abs(acc) > abs(big):
                    big = acc
            if big < 0.0:
                for k in range(n):
                    shapes_out[j, k] = -shapes_out[j, k]
    return bits


@njit(**JIT)
def modes_batch(start, stop, km, q_eq, lam_eq, want_shapes, omega_out, shapes_out, status_out):
    """Eigenpulsations of samples ``start:stop`` about their equilibria.

    Args:
        q_eq: (nsample, 3 nbody), lam_eq: (nsample, ncon) the equilibria.
        omega_out: (nsample, nmode) signed p, rad/s, ascending.
        want_shapes: whether to write ``shapes_out``.
        shapes_out: (nsample, nmode, 3 nbody); any (1, nmode, 3 nbody) array if not wanted.
        status_out: (nsample,) uint32; failed samples are skipped (NaN).
    """
    for s in range(start, stop):
        if status_out[s] & (ASSEMBLY_FAILED | EQUILIBRIUM_NOT_CONVERGED | SINGULAR):
            omega_out[s, :] = np.nan
            continue
        shapes = shapes_out[s % shapes_out.shape[0]]
        bits = modes_one(km, s, q_eq[s], lam_eq[s], omega_out[s], shapes, want_shapes)
        status_out[s] |= bits
        if bits & SINGULAR:
            omega_out[s, :] = np.nan
            if want_shapes:
                shapes_out[s] = np.nan


@njit(**JIT)
def modal_damping_batch(start, stop, km, q_eq, shapes, damping_out):
    """Modal damping D = Z C Zᵀ of samples ``start:stop``: the dampers' C = −∂F/∂q̇ at the
    equilibrium seen by their mass-normalised mode shapes Z (Z M Zᵀ = I, Z K Zᵀ = diag p²),
    so the damped modes solve the f × f quadratic problem (s² I + s D + diag p²) ξ = 0.

    Args:
        q_eq: (nsample, 3 nbody) equilibria.
        shapes: (nsample, nmode, 3 nbody) mode shapes from :func:`modes_batch`.
        damping_out: (nsample, nmode, nmode) D, 1/s; NaN where the shapes are NaN.
    """
    n = q_eq.shape[1]
    f = shapes.shape[1]
    for s in range(start, stop):
        Z = shapes[s]
        if np.isnan(Z).any() or np.isnan(q_eq[s]).any():
            damping_out[s] = np.nan
            continue
        C = np.zeros((n, n))
        damping_matrix_add(km, s, q_eq[s], 1.0, C)
        CZ = np.zeros((n, f))  # C Zᵀ
        for k in range(n):
            for j in range(f):
                for col in range(n):
                    CZ[k, j] += C[k, col] * Z[j, col]
        for i in range(f):
            for j in range(i + 1):
                acc = 0.0
                for k in range(n):
                    acc += Z[i, k] * CZ[k, j] + Z[j, k] * CZ[k, i]
                damping_out[s, i, j] = 0.5 * acc  # symmetric to the last bit
                damping_out[s, j, i] = 0.5 * acc


@njit(**JIT)
def joint_forces_batch(start, stop, km, q, lam, force_out, contact_out):
    """Joint forces of samples ``start:stop`` from (q, λ): see :func:`joints.joint_forces`.

    Args:
        q: (nsample, 3 nbody); lam: (nsample, ncon).
        force_out: (nsample, njoint, 2) N; contact_out: (nsample, njoint) N (NaN: ideal).
    """
    for s in range(start, stop):
        joint_forces(km, s, q[s], lam[s], force_out[s], contact_out[s])


@njit(**JIT)
def dynamic_multipliers_batch(start, stop, km, q, v, lam_out, status_out):
    """λ of M q̈ + Bᵀλ = F(q, q̇), B q̈ = γ(q, q̇) for samples ``start:stop``: the joint and
    driver forces of the mechanism moving through (q, q̇) (inverse dynamics where the
    drivers fix the motion), by the Schur complement λ = S⁻¹(B M⁻¹ F − γ).

    Args:
        q, v: (nsample, 3 nbody) states; lam_out: (nsample, ncon) written (NaN: skipped or
            singular). status_out: (nsample,) uint32: samples with a failure bit are
            skipped; SINGULAR is OR-ed where B loses rank.
    """
    n = q.shape[1]
    m = lam_out.shape[1]
    B = np.empty((m, n))
    S = np.empty((m, m))
    F = np.empty(n)
    minv = np.empty(n)
    gamma = np.empty(m)
    for s in range(start, stop):
        lam_out[s, :] = np.nan
        if status_out[s] & (ASSEMBLY_FAILED | EQUILIBRIUM_NOT_CONVERGED | SINGULAR):
            continue
        mass_diagonal(km, s, minv)
        for i in range(n):
            minv[i] = 1.0 / minv[i]
        constraint_jacobian(km, s, q[s], B)
        constraint_gamma(km, s, q[s], v[s], 0.0, gamma)
        applied_forces(km, s, q[s], v[s], 0.0, F)
        if not schur_factor(B, minv, m, n, S):
            status_out[s] |= SINGULAR
            continue
        for r in range(m):
            acc = -gamma[r]
            for k in range(n):
                acc += B[r, k] * minv[k] * F[k]
            lam_out[s, r] = acc
        cholesky_solve(S, m, lam_out[s])
