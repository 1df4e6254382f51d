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

from mcchain.contact import CONTACT, SEAT_TOLERANCE
from mcchain.kernels.config import INLINE, JIT, hypot, njit
from mcchain.kernels.forces import (
    applied_forces,
    mass_diagonal,
)
from mcchain.kernels.joints import (
    JOINT_CLEARANCE,
    JOINT_PRISMATIC,
    _add_point_rows,
    axis_row,
    constraint_jacobian,
    constraint_residual,
    constraint_velocity_rhs,
    driver_rate,
    driver_start,
    joint_rate_terms,
    joint_separation_rate,
    joint_vectors,
    prismatic_gamma,
    prismatic_normal,
    prismatic_rows,
    slider_displacement,
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
ASSEMBLY_DAMPING = 1e-3
"""Levenberg–Marquardt damping (relative to the largest diagonal of B M⁻¹ Bᵀ) of an
assembly step from a configuration where B has lost rank."""


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
            scale = max(scale, hypot(arr[i, k, 0], arr[i, k, 1]))
    for k in range(km.spring_point_a.shape[1]):
        for side in range(2):
            arr = km.spring_point_a if side == 0 else km.spring_point_b
            i = s % arr.shape[0]
            scale = max(scale, hypot(arr[i, k, 0], arr[i, k, 1]))
    return scale if scale > 0.0 else 1.0


@njit(**JIT)
def _norm(x, n):
    """Euclidean norm of x[:n]."""
    acc = 0.0
    for i in range(n):
        acc += x[i] * x[i]
    return math.sqrt(acc)


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
    return schur_factor_damped(B, minv, m, n, S_out, 0.0)


@njit(**JIT)
def schur_factor_damped(B, minv, m, n, S_out, damping):
    """S = B M⁻¹ Bᵀ + ``damping`` × max diag(S) I into ``S_out``, Cholesky-factored.

    The Levenberg–Marquardt form of the least-norm step: it stays defined where B loses
    rank (a linkage written straight, at a dead point) and tends to the plain step as
    ``damping`` → 0. False if even the damped matrix is not positive definite.
    """
    largest = 0.0
    for i in range(m):
        for j in range(i + 1):
            acc = 0.0
            for k in range(n):
                acc += B[i, k] * minv[k] * B[j, k]
            S_out[i, j] = acc
            S_out[j, i] = acc
        largest = max(largest, S_out[i, i])
    for i in range(m):
        S_out[i, i] += damping * largest
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
def _assembly_residual(km, s, q, target, free, psi_out, J_out):
    """Ψ(q) and ∂Ψ/∂q with every clearance joint held at d = c u (two rows each).

    ``target`` (njoint, 2) holds u. Rows: two per joint in joint order, then drivers; a
    prismatic joint's are its own two (offset normal to the axis, relative angle). A joint
    with ``free[k]`` (a journal under the contact law written off its wall) has no rows: it
    is not a constraint of the assembly.
    """
    J_out[:, :] = 0.0
    nj = km.joint_body_a.shape[0]
    r = 0
    for k in range(nj):
        if free[k]:
            continue
        a = km.joint_body_a[k]
        b = km.joint_body_b[k]
        pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
        if km.joint_kind[k] == JOINT_PRISMATIC:
            nx, ny = prismatic_normal(km, s, q, k)
            psi_out[r] = nx * dx + ny * dy
            tha = q[3 * a + 2] if a >= 0 else 0.0
            thb = q[3 * b + 2] if b >= 0 else 0.0
            rel = km.joint_relative_angle[s % km.joint_relative_angle.shape[0], k]
            psi_out[r + 1] = thb - tha - rel
            prismatic_rows(J_out, r, a, b, nx, ny, pax, pay, pbx, pby, dx, dy)
            r += 2
            continue
        c = 0.0
        if km.joint_kind[k] == JOINT_CLEARANCE:
            c = km.joint_clearance[s % km.joint_clearance.shape[0], k]
        psi_out[r] = dx - c * target[k, 0]
        psi_out[r + 1] = dy - c * target[k, 1]
        _add_point_rows(J_out, r, b, 1.0, 1.0, 0.0, pbx, pby)
        _add_point_rows(J_out, r, a, -1.0, 1.0, 0.0, pax, pay)
        _add_point_rows(J_out, r + 1, b, 1.0, 0.0, 1.0, pbx, pby)
        _add_point_rows(J_out, r + 1, a, -1.0, 0.0, 1.0, pax, pay)
        r += 2
    for j in range(km.driver_body.shape[0]):
        start = driver_start(km, s, j)[0]
        if km.driver_joint[j] >= 0:  # a slider driver: u·d = s_0
            along, k, ux, uy, pax, pay, pbx, pby, dx, dy = slider_displacement(km, s, q, j)
            psi_out[r + j] = along - start
            a = km.joint_body_a[k]
            b = km.joint_body_b[k]
            axis_row(J_out, r + j, a, b, ux, uy, pax, pay, pbx, pby, dx, dy)
            continue
        body = km.driver_body[j]
        psi_out[r + j] = q[3 * body + 2] - start
        J_out[r + j, 3 * body + 2] = 1.0


@njit(**JIT)
def law_start_joints(km, s, q, free_out, seated_out):
    """Clearance joints under the contact law whose journal the scene writes
    (``km.joint_written``, judged on the scene as written): ``free_out[k]`` for a journal
    written off its wall (free or pressed: not a constraint of the assembly), ``seated_out[k]``
    for one written on it (held on the wall in its written direction). Returns the number
    of free joints."""
    count = 0
    for k in range(km.joint_body_a.shape[0]):
        free_out[k] = km.joint_written[k] == 1
        seated_out[k] = km.joint_written[k] == 2
        if free_out[k]:
            count += 1
    return count


@njit(**JIT)
def _close_joints(km, s, q, target, free, minv, lscale, psi, J, S):
    """Gauss–Newton on Ψ(q) = 0 (:func:`_assembly_residual`, without the ``free`` joints),
    M-smallest steps, in place.

    Returns:
        0 converged (|Ψ| ≤ 1e-14 × ``lscale``), 1 not converged, 2 singular Jacobian.
    """
    n = q.shape[0]
    ma = psi.shape[0]
    start = np.empty(n)
    _assembly_residual(km, s, q, target, free, psi, J)
    for _it in range(ASSEMBLY_MAX_ITER):
        if max_abs(psi, ma) <= 1e-14 * lscale:
            return 0
        if not schur_factor(J, minv, ma, n, S):
            # rank lost where the guess is (bars written in line): damped steps move off it
            if not schur_factor_damped(J, minv, ma, n, S, ASSEMBLY_DAMPING):
                return 2
        size = _norm(psi, ma)
        for i in range(n):  # not start[:] = q: numba compiles its shape-error message (2.7 s)
            start[i] = q[i]
        project_onto_rows(J, minv, ma, n, S, psi, q)
        _assembly_residual(km, s, q, target, free, psi, J)
        # Far from the solution (a rough guess, large rotations) a full step can overshoot
        # and cycle: halve it until the residual decreases. Near it the full step is taken.
        for _half in range(30):
            if size <= 1e-8 * lscale or _norm(psi, ma) < size:
                break
            for i in range(n):
                q[i] = start[i] + 0.5 * (q[i] - start[i])
            _assembly_residual(km, s, q, target, free, psi, J)
    return 1


@njit(**JIT)
def _velocities_at_rest_in_bearings(km, s, J, minv, S, v):
    """Velocity analysis with every journal at rest in its bearing (ḋ = 0), in place.

    ``J`` is the two-rows-per-joint Jacobian of :func:`_assembly_residual` at the assembled
    positions (drivers' rows last); the M-smallest change of ``v`` that makes
    J v = (0, …, ω_drivers). For a driven mechanism without other freedom this is the
    velocity analysis from the driver speeds. Returns False (``v`` untouched)
    when J is rank-deficient.
    """
    ma = J.shape[0]
    n = v.shape[0]
    if not schur_factor(J, minv, ma, n, S):
        return False
    first_driver = ma - km.driver_body.shape[0]
    residual = np.empty(ma)
    for i in range(ma):
        acc = 0.0
        for k in range(n):
            acc += J[i, k] * v[k]
        residual[i] = acc
    for j in range(km.driver_body.shape[0]):
        residual[first_driver + j] -= driver_rate(km, s, j, 0.0)
    project_onto_rows(J, minv, ma, n, S, residual, v)
    return True


@njit(**JIT)
def ideal_joint_multipliers(km, s, q, v, minv, lscale, lam):
    """λ of the ideal-joint mechanism at t = 0, into ``lam`` (2 njoint + ndriver,): two rows
    per joint in joint order (a prismatic joint's own two), then the drivers.

    Every joint is closed (d = 0) from ``q`` (M-smallest correction), the velocities are
    analysed with the journals at rest in their bearings, and λ solves M q̈ + Jᵀλ = F,
    J q̈ = γ: the force on joint k's journal from its bearing is f = −(λ_2k, λ_2k+1) (N).
    ``q``, ``v`` are not changed. Returns the force scale max(|F|, |λ|) (N), or −1 when the
    ideal mechanism cannot be assembled or is redundant.
    """
    n = q.shape[0]
    nj = km.joint_body_a.shape[0]
    ma = 2 * nj + km.driver_body.shape[0]
    qi = q.copy()
    vi = v.copy()
    closed = np.zeros((nj, 2))
    held = np.zeros(nj, dtype=np.bool_)  # the ideal mechanism: every joint closed
    psi = np.empty(ma)
    J = np.empty((ma, n))
    S = np.empty((ma, ma))
    if _close_joints(km, s, qi, closed, held, minv, lscale, psi, J, S) != 0:
        return -1.0
    _assembly_residual(km, s, qi, closed, held, psi, J)
    if not _velocities_at_rest_in_bearings(km, s, J, minv, S, vi):
        return -1.0
    F = np.empty(n)
    applied_forces(km, s, qi, vi, 0.0, F)
    for i in range(ma):
        acc = 0.0
        for k in range(n):
            acc += J[i, k] * minv[k] * F[k]
        lam[i] = acc
    for k in range(nj):  # γ of an ideal joint: p_b θ̇_b² − p_a θ̇_a²; drivers: 0
        a = km.joint_body_a[k]
        b = km.joint_body_b[k]
        pax, pay, pbx, pby, dx, dy, wa, gx, gy = joint_rate_terms(km, s, qi, vi, k)
        if km.joint_kind[k] == JOINT_PRISMATIC:
            nx, ny = prismatic_normal(km, s, qi, k)
            ddx, ddy = joint_separation_rate(vi, a, b, pax, pay, pbx, pby)
            lam[2 * k] -= prismatic_gamma(nx, ny, gx, gy, dx, dy, ddx, ddy, wa)
        else:
            lam[2 * k] -= gx
            lam[2 * k + 1] -= gy
    cholesky_solve(S, ma, lam)
    return max(max_abs(F, n), max_abs(lam, ma))


@njit(**INLINE)
def ideal_joint_directions(km, s, q, v, minv, lscale, target, found):
    """Directions of the clearance joints' d from the ideal-joint mechanism at t = 0.

    The multipliers of :func:`ideal_joint_multipliers` give the force on each journal from
    its bearing, f = −λ. The journal presses on the wall opposite to f, so u = −f/|f|
    (λ/|λ|): written into ``target[k]`` and ``found[k] = True`` for every clearance joint
    whose eccentricity is unset and whose force is more than 1e-9 of the largest force.
    ``q``, ``v`` are not changed. Returns False when the ideal mechanism cannot be assembled
    or is redundant.
    """
    nj = km.joint_body_a.shape[0]
    lam = np.zeros(2 * nj + km.driver_body.shape[0])
    fscale = ideal_joint_multipliers(km, s, q, v, minv, lscale, lam)
    if fscale < 0.0:
        return False
    for k in range(nj):
        if km.joint_kind[k] != JOINT_CLEARANCE:
            continue
        alpha = km.joint_eccentricity[s % km.joint_eccentricity.shape[0], k]
        if alpha == alpha:
            continue
        size = hypot(lam[2 * k], lam[2 * k + 1])
        if size > 1e-9 * fscale and size > 0.0:
            target[k, 0] = lam[2 * k] / size
            target[k, 1] = lam[2 * k + 1] / size
            found[k] = True
    return True


@njit(**INLINE)
def assemble_one(km, s, q, v):
    """Project q and v of sample ``s`` onto the constraints (t = 0), in place.

    A clearance joint under the contact law (model contact or auto) whose journal the scene
    places off its wall (:func:`law_start_joints`: free, |d| < c, or pressed, |d| > c) is
    not a constraint of the assembly: only the other joints and the drivers are, and its
    journal goes where they take it. A journal placed on its wall stays there.

    Positions already satisfying |Φ| ≤ 1e-12 × the length scale (those constraints) are
    kept bit for bit. Otherwise every clearance joint held is first placed at d = c u: u the
    written d's direction for a journal under the law written on its wall; else from
    ``eccentricity``; else pressed on its bearing as the ideal-joint mechanism's force says
    (:func:`ideal_joint_directions`); else the direction of the given d, gravity's, +x.
    Gauss–Newton then takes the M-smallest correction. Velocities that do not satisfy
    B q̇ = ν (without the rows of the joints under the law: a journal's relative velocity
    is free there) are replaced by the velocity analysis with every held journal at rest in
    its bearing (:func:`_velocities_at_rest_in_bearings`), or, where that has no solution,
    the M-smallest correction onto B q̇ = ν.

    Returns:
        status bits (ASSEMBLY_FAILED, SINGULAR).
    """
    n = q.shape[0]
    m = 0
    for k in range(km.joint_kind.shape[0]):
        m += 1 if km.joint_kind[k] == JOINT_CLEARANCE else 2
    m += km.driver_body.shape[0]
    nj = km.joint_body_a.shape[0]
    lscale = length_scale(km, s)
    tol = 1e-12 * lscale
    minv = np.empty(n)
    mass_diagonal(km, s, minv)
    for i in range(n):
        minv[i] = 1.0 / minv[i]
    free = np.zeros(nj, dtype=np.bool_)
    seated = np.zeros(nj, dtype=np.bool_)
    nfree = law_start_joints(km, s, q, free, seated)
    phi = np.empty(m)
    constraint_residual(km, s, q, 0.0, phi)
    for k in range(nj):  # a journal under the law written free or pressed holds; one
        # written on its wall holds within the seat tolerance
        if free[k]:
            phi[km.joint_row[k]] = 0.0
        elif seated[k]:
            c = km.joint_clearance[s % km.joint_clearance.shape[0], k]
            if abs(phi[km.joint_row[k]]) <= SEAT_TOLERANCE * c:
                phi[km.joint_row[k]] = 0.0
    ma = 2 * (nj - nfree) + km.driver_body.shape[0]
    psi = np.empty(ma)
    J = np.empty((ma, n))
    S = np.empty((ma, ma))
    moved = not max_abs(phi, m) <= tol
    if moved:
        # hold each clearance journal at d = c u during the projection
        target = np.zeros((nj, 2))
        found = np.zeros(nj, dtype=np.bool_)
        unset = False
        for k in range(nj):
            if km.joint_kind[k] != JOINT_CLEARANCE or free[k]:
                continue
            alpha = km.joint_eccentricity[s % km.joint_eccentricity.shape[0], k]
            if seated[k]:  # written on the wall: it stays where it is written
                _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
                dist = hypot(dx, dy)
                target[k, 0] = dx / dist
                target[k, 1] = dy / dist
                found[k] = True
            elif alpha == alpha:
                target[k, 0] = math.cos(alpha)
                target[k, 1] = math.sin(alpha)
                found[k] = True
            else:
                unset = True
        if unset:
            ideal_joint_directions(km, s, q, v, minv, lscale, target, found)
        ig = s % km.gravity.shape[0]
        gnorm = hypot(km.gravity[ig, 0], km.gravity[ig, 1])
        for k in range(nj):
            if km.joint_kind[k] != JOINT_CLEARANCE or found[k] or free[k]:
                continue
            c = km.joint_clearance[s % km.joint_clearance.shape[0], k]
            _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
            dist = hypot(dx, dy)
            if dist > 1e-3 * c and dist > 0.0:
                target[k, 0] = dx / dist
                target[k, 1] = dy / dist
            elif gnorm > 0.0:
                target[k, 0] = km.gravity[ig, 0] / gnorm
                target[k, 1] = km.gravity[ig, 1] / gnorm
            else:
                target[k, 0] = 1.0
        code = _close_joints(km, s, q, target, free, minv, lscale, psi, J, S)
        if code == 2:
            return ASSEMBLY_FAILED | SINGULAR
        constraint_residual(km, s, q, 0.0, phi)
        for k in range(nj):
            if free[k]:
                phi[km.joint_row[k]] = 0.0
        if code != 0 or not max_abs(phi, m) <= tol:
            return ASSEMBLY_FAILED
    B = np.empty((m, n))
    constraint_jacobian(km, s, q, B)
    nu = np.empty(m)
    constraint_velocity_rhs(km, s, 0.0, nu)
    for i in range(m):
        acc = -nu[i]
        for k in range(n):
            acc += B[i, k] * v[k]
        nu[i] = acc
    for k in range(nj):  # under the law the journal's relative velocity is free
        if free[k] or (km.joint_kind[k] == JOINT_CLEARANCE and km.joint_model[k] == CONTACT):
            nu[km.joint_row[k]] = 0.0
    vscale = max_abs(nu, m)
    if vscale > 1e-12 * (1.0 + max_abs(v, n)):
        _assembly_residual(km, s, q, np.zeros((nj, 2)), free, psi, J)  # J: any target
        if not _velocities_at_rest_in_bearings(km, s, J, minv, S, v):
            mb = _drop_free_rows(km, free, B, nu, m)
            Sb = np.empty((mb, mb))
            if not schur_factor(B, minv, mb, n, Sb):
                return SINGULAR
            project_onto_rows(B, minv, mb, n, Sb, nu, v)
    return 0


@njit(**JIT)
def _drop_free_rows(km, free, B, nu, m):
    """Move the rows of B (m, n) and ν (m,) of the joints without ``free[k]`` up, in order;
    returns how many there are."""
    kept = 0
    for i in range(m):
        drop = False
        for k in range(free.shape[0]):
            if free[k] and km.joint_row[k] == i:
                drop = True
        if drop:
            continue
        for c in range(B.shape[1]):
            B[kept, c] = B[i, c]
        nu[kept] = nu[i]
        kept += 1
    return kept


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
