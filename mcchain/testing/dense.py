"""Slow, obvious dense references that the fast kernels are compared against.

Dense NumPy/SciPy, one sample at a time, written straight from the formulation (absolute
coordinates, constraints Φ, Jacobian B, KKT system) without sharing code with the kernels.
Used by the tests and by the benchmarks (the "plain SciPy loop").

* statics: Φ, F, B (complex step and written out), equilibrium by ``scipy.optimize.root``,
  eigenpulsations by ``scipy.linalg.eigh`` on the null space of B;
* dynamics: the index-1 accelerations and multipliers from the full KKT system
  [[M, Bᵀ], [B, 0]] (:func:`kkt_acceleration`), energy, and scipy Radau on those equations
  (:func:`integrate_kkt`).

Φ and F accept complex q: :func:`complex_step_jacobian` then gives their exact first
derivatives (error ~1e-16, no subtractive cancellation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.integrate
import scipy.linalg
import scipy.optimize

from mcchain.model import (
    DRIVER_HARMONIC,
    DRIVER_TABLE,
    GROUND,
    JOINT_IDEAL,
    JOINT_PRISMATIC,
    LOAD_CONSTANT,
    LOAD_HARMONIC,
    LOAD_TABLE,
    Model,
)
from mcchain.testing.factory import rotation

OMEGA = np.array([[0.0, -1.0], [1.0, 0.0]])
"""Ω: ∂(A s)/∂θ = Ω A s."""


def _param(model: Model, name: str, s: int) -> np.ndarray:
    arr = getattr(model, name)
    return arr[s % arr.shape[0]]


def _pose(q: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Centre r and rotation matrix A of body b (ground: 0, I); complex-safe."""
    if b == GROUND:
        return np.zeros(2, dtype=q.dtype), np.eye(2, dtype=q.dtype)
    th = q[3 * b + 2]
    c, sn = np.cos(th), np.sin(th)
    return q[3 * b : 3 * b + 2], np.array([[c, -sn], [sn, c]])


def _point(q: np.ndarray, b: int, local: np.ndarray) -> np.ndarray:
    r, A = _pose(q, b)
    return r + A @ local


def _point_velocity(q: np.ndarray, v: np.ndarray, b: int, local: np.ndarray) -> np.ndarray:
    """ṙ + θ̇ Ω A s of a body point (zero on the ground)."""
    if b == GROUND:
        return np.zeros(2)
    _, A = _pose(q, b)
    lever = A @ local
    return v[3 * b : 3 * b + 2] + v[3 * b + 2] * np.array([-lever[1], lever[0]])


def _prismatic_normal(model: Model, s: int, q: np.ndarray, k: int) -> np.ndarray:
    """n = A_a Ω u: the normal of prismatic joint k's axis u (fixed in its first body a)."""
    u = _param(model, "joint_axis", s)[k]
    normal = np.array([-u[1], u[0]])
    a = model.joint_body_a[k]
    return normal if a == GROUND else _pose(q, a)[1] @ normal


def _slider_axis(model: Model, s: int, q: np.ndarray, k: int) -> np.ndarray:
    """u = A_a u_0: the unit axis of prismatic joint k in the world (u_0 fixed in body a)."""
    u = _param(model, "joint_axis", s)[k]
    a = model.joint_body_a[k]
    return u if a == GROUND else _pose(q, a)[1] @ u


def constraints(model: Model, s: int, q: np.ndarray, t: float = 0.0) -> np.ndarray:
    """Φ(q, t) of sample s, (ncon,)."""
    phi = np.zeros(model.ncon, dtype=q.dtype)
    pa_all = _param(model, "joint_point_a", s)
    pb_all = _param(model, "joint_point_b", s)
    clearance = _param(model, "joint_clearance", s)
    for k in range(model.njoint):
        a, b = model.joint_body_a[k], model.joint_body_b[k]
        d = _point(q, b, pb_all[k]) - _point(q, a, pa_all[k])
        row = model.joint_row[k]
        if model.joint_kind[k] == JOINT_IDEAL:
            phi[row : row + 2] = d
        elif model.joint_kind[k] == JOINT_PRISMATIC:
            phi[row] = _prismatic_normal(model, s, q, k) @ d
            angle_a = q[3 * a + 2] if a != GROUND else 0.0
            angle_b = q[3 * b + 2] if b != GROUND else 0.0
            phi[row + 1] = angle_b - angle_a - _param(model, "joint_relative_angle", s)[k]
        else:
            phi[row] = np.sqrt(d[0] * d[0] + d[1] * d[1]) - clearance[k]
    for j in range(model.ndriver):
        k = int(model.driver_joint[j])
        if k >= 0:
            a, b = model.joint_body_a[k], model.joint_body_b[k]
            d = _point(q, b, pb_all[k]) - _point(q, a, pa_all[k])
            phi[model.driver_row[j]] = (
                _slider_axis(model, s, q, k) @ d - driver_law(model, s, j, t)[0]
            )
            continue
        phi[model.driver_row[j]] = q[3 * model.driver_body[j] + 2] - driver_law(model, s, j, t)[0]
    return phi


def driver_law(model: Model, s: int, j: int, t: float) -> tuple[float, float, float]:
    """(f, ḟ, f̈) of driver j of sample s at t: θ0 + ω t (+ A (sin(2π f t + φ) − sin φ) for
    a harmonic one), written out independently of the kernels."""
    slider = int(model.driver_joint[j]) >= 0
    theta0 = float(_param(model, "driver_displacement0" if slider else "driver_angle0", s)[j])
    omega = float(_param(model, "driver_speed" if slider else "driver_omega", s)[j])
    f, rate, acc = theta0 + omega * t, omega, 0.0
    if int(model.driver_law[j]) == DRIVER_TABLE:
        n = int(model.driver_table_size[j])
        return _piecewise_cubic(model.driver_table_knots[j, :n], model.driver_table_coef[j], t)
    if int(model.driver_law[j]) == DRIVER_HARMONIC:
        amp = float(_param(model, "driver_amplitude", s)[j])
        w = 2.0 * np.pi * float(_param(model, "driver_frequency", s)[j])
        phase = float(_param(model, "driver_phase", s)[j])
        f += amp * (np.sin(w * t + phase) - np.sin(phase))
        rate += amp * w * np.cos(w * t + phase)
        acc -= amp * w * w * np.sin(w * t + phase)
    return f, rate, acc


def applied_forces(
    model: Model, s: int, q: np.ndarray, v: np.ndarray | None = None, t: float = 0.0
) -> np.ndarray:
    """F(q, q̇, t) of sample s, (3 nbody,), by virtual work of each load; complex-safe in q."""
    dtype = np.result_type(q, float)
    v = np.zeros(model.ndof) if v is None else v
    F = np.zeros(model.ndof, dtype=dtype)
    g = _param(model, "gravity", s)
    mass = _param(model, "body_mass", s)
    for b in range(model.nbody):
        F[3 * b : 3 * b + 2] += mass[b] * g

    def add_point_force(body: int, local: np.ndarray, f: np.ndarray) -> None:
        if body == GROUND:
            return
        _, A = _pose(q, body)
        lever = A @ local
        F[3 * body : 3 * body + 2] += f
        F[3 * body + 2] += lever[0] * f[1] - lever[1] * f[0]

    for k in range(model.nforce):
        body = model.force_body[k]
        factor = load_factor(model, s, k, t)
        add_point_force(
            body, _param(model, "force_point", s)[k], factor * _param(model, "force_value", s)[k]
        )
        if body != GROUND:
            F[3 * body + 2] += factor * _param(model, "force_torque", s)[k]
    for k in range(model.nspring):
        a, b = model.spring_body_a[k], model.spring_body_b[k]
        sa, sb = _param(model, "spring_point_a", s)[k], _param(model, "spring_point_b", s)[k]
        u = _point(q, b, sb) - _point(q, a, sa)
        du = _point_velocity(q, v, b, sb) - _point_velocity(q, v, a, sa)
        k_s = _param(model, "spring_stiffness", s)[k]
        rest = _param(model, "spring_rest_length", s)[k]
        damping = _param(model, "spring_damping", s)[k]
        if rest == 0.0:
            f = -k_s * u - damping * du
        else:
            length = np.sqrt(u[0] * u[0] + u[1] * u[1])
            e = u / length
            f = -(k_s * (length - rest) + damping * (e @ du)) * e
        add_point_force(b, sb, f)
        add_point_force(a, sa, -f)
    return F


def mass_diagonal(model: Model, s: int) -> np.ndarray:
    """diag(M), (3 nbody,)."""
    m = _param(model, "body_mass", s)
    J = _param(model, "body_inertia", s)
    return np.stack([m, m, J], axis=1).reshape(-1)


def complex_step_jacobian(fun, x: np.ndarray, h: float = 1e-30) -> np.ndarray:
    """∂fun/∂x by the complex step: exact to round-off for complex-safe ``fun``."""
    x = np.asarray(x, dtype=float)
    cols = []
    for k in range(x.size):
        xc = x.astype(complex)
        xc[k] += 1j * h
        cols.append(np.imag(fun(xc)) / h)
    return np.stack(cols, axis=-1)


def constraint_jacobian(model: Model, s: int, q: np.ndarray) -> np.ndarray:
    """B = ∂Φ/∂q by the complex step, (ncon, 3 nbody)."""
    return complex_step_jacobian(lambda x: constraints(model, s, x), q)


def equilibrium_residual(model: Model, s: int, x: np.ndarray) -> np.ndarray:
    """[Bᵀλ − F; Φ] for x = [q; λ] (real)."""
    n = model.ndof
    q, lam = x[:n], x[n:]
    B = constraint_jacobian_formula(model, s, q)
    return np.concatenate([B.T @ lam - applied_forces(model, s, q), constraints(model, s, q)])


@dataclass
class ReferenceStatics:
    q: np.ndarray
    lam: np.ndarray
    omega: np.ndarray
    success: bool


def statics(model: Model, s: int, q_start: np.ndarray, xtol: float = 1e-13) -> ReferenceStatics:
    """Equilibrium by ``scipy.optimize.root`` (hybr) and eigenpulsations by ``scipy.linalg.eigh``
    (K by the complex step, the null space from ``scipy.linalg.null_space``)."""
    n = model.ndof
    q_start = np.asarray(q_start, dtype=float)
    B0 = constraint_jacobian_formula(model, s, q_start)
    F0 = applied_forces(model, s, q_start)
    lam0 = np.linalg.lstsq(B0.T, F0, rcond=None)[0]
    sol = scipy.optimize.root(
        lambda x: equilibrium_residual(model, s, x),
        np.concatenate([q_start, lam0]),
        method="hybr",
        options={"xtol": xtol},
    )
    q, lam = sol.x[:n], sol.x[n:]
    return ReferenceStatics(q=q, lam=lam, omega=modes(model, s, q, lam), success=bool(sol.success))


def modes(model: Model, s: int, q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Signed eigenpulsations about (q, λ) by ``scipy.linalg.eigh`` on the null space of B."""
    K = stiffness(model, s, q, lam)
    N = scipy.linalg.null_space(constraint_jacobian_formula(model, s, q))
    M = np.diag(mass_diagonal(model, s))
    p2 = scipy.linalg.eigh(N.T @ K @ N, N.T @ M @ N, eigvals_only=True)
    return np.sort(np.sign(p2) * np.sqrt(np.abs(p2)))


def constraint_jacobian_formula(model: Model, s: int, q: np.ndarray) -> np.ndarray:
    """B written out from the formulation (rows [I, Ω A_b s_b] / [−I, −Ω A_a s_a], e·∂d/∂q for
    clearance joints, 1 on θ for drivers); complex-safe so that K can be complex-stepped."""
    B = np.zeros((model.ncon, model.ndof), dtype=np.result_type(q, float))
    omega = np.array([[0.0, -1.0], [1.0, 0.0]])
    pa_all = _param(model, "joint_point_a", s)
    pb_all = _param(model, "joint_point_b", s)
    for k in range(model.njoint):
        a, b = model.joint_body_a[k], model.joint_body_b[k]
        d = _point(q, b, pb_all[k]) - _point(q, a, pa_all[k])
        rows = np.zeros((2, model.ndof), dtype=B.dtype)
        for body, local, sign in ((b, pb_all[k], 1.0), (a, pa_all[k], -1.0)):
            if body == GROUND:
                continue
            _, A = _pose(q, body)
            rows[:, 3 * body : 3 * body + 2] = sign * np.eye(2)
            rows[:, 3 * body + 2] = sign * (omega @ A @ local)
        row = model.joint_row[k]
        if model.joint_kind[k] == JOINT_IDEAL:
            B[row : row + 2] = rows
        elif model.joint_kind[k] == JOINT_PRISMATIC:
            # product rule on n·d: n·∂d/∂q, and ∂n/∂θ_a = Ω n on θ_a
            normal = _prismatic_normal(model, s, q, k)
            B[row] = normal @ rows
            if b != GROUND:
                B[row + 1, 3 * b + 2] = 1.0
            if a != GROUND:
                B[row, 3 * a + 2] += (omega @ normal) @ d
                B[row + 1, 3 * a + 2] = -1.0
        else:
            B[row] = d @ rows / np.sqrt(d[0] * d[0] + d[1] * d[1])
        for slid in np.flatnonzero(np.asarray(model.driver_joint) == k):  # u·d − s(t)
            axis = _slider_axis(model, s, q, k)
            B[model.driver_row[slid]] = axis @ rows
            if a != GROUND:
                B[model.driver_row[slid], 3 * a + 2] += (omega @ axis) @ d
    for j in range(model.ndriver):
        if int(model.driver_joint[j]) < 0:
            B[model.driver_row[j], 3 * model.driver_body[j] + 2] = 1.0
    return B


def stiffness(model: Model, s: int, q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """K = ∂(Bᵀλ − F)/∂q at fixed λ by the complex step of the written-out B and F."""
    K = complex_step_jacobian(
        lambda x: constraint_jacobian_formula(model, s, x).T @ lam - applied_forces(model, s, x),
        q,
    )
    return 0.5 * (K + K.T)


# -- dynamics ----------------------------------------------------------------------------
def _body(q: np.ndarray, v: np.ndarray, b: int):
    """r, A, ṙ, θ̇ of body b (ground at rest)."""
    if b == GROUND:
        return np.zeros(2), np.eye(2), np.zeros(2), 0.0
    return q[3 * b : 3 * b + 2], rotation(q[3 * b + 2]), v[3 * b : 3 * b + 2], v[3 * b + 2]


def equations(model: Model, s: int, q: np.ndarray, v: np.ndarray, t: float):
    """Dense M (n,n), B (m,n), γ (m,) with B q̈ = γ, Φ (m,), Φ̇ (m,), F (n,) of sample s."""
    n = model.ndof
    M = np.zeros((n, n))
    mass, inertia = _param(model, "body_mass", s), _param(model, "body_inertia", s)
    for b in range(model.nbody):
        M[3 * b, 3 * b] = M[3 * b + 1, 3 * b + 1] = mass[b]
        M[3 * b + 2, 3 * b + 2] = inertia[b]
    rows_B, gam, phi, phid = [], [], [], []
    pa_all, pb_all = _param(model, "joint_point_a", s), _param(model, "joint_point_b", s)
    clearance = _param(model, "joint_clearance", s)
    kinematics = {}  # joint -> (d, ḋ, ∂d/∂q, w, θ̇_a), for slider drivers
    for k in range(model.njoint):
        a, b = int(model.joint_body_a[k]), int(model.joint_body_b[k])
        ra, Aa, va, wa = _body(q, v, a)
        rb, Ab, vb, wb = _body(q, v, b)
        ua, ub = Aa @ pa_all[k], Ab @ pb_all[k]
        d = rb + ub - ra - ua
        dd = vb + wb * (OMEGA @ ub) - va - wa * (OMEGA @ ua)
        D = np.zeros((2, n))  # ∂d/∂q
        if b != GROUND:
            D[:, 3 * b : 3 * b + 2] = np.eye(2)
            D[:, 3 * b + 2] = OMEGA @ ub
        if a != GROUND:
            D[:, 3 * a : 3 * a + 2] = -np.eye(2)
            D[:, 3 * a + 2] = -(OMEGA @ ua)
        w = -(wb**2) * ub + wa**2 * ua  # d̈ = D q̈ + w
        kinematics[k] = (d, dd, D, w, wa)
        if model.joint_kind[k] == JOINT_IDEAL:
            rows_B += [D[0], D[1]]
            gam += list(-w)
            phi += list(d)
            phid += list(dd)
        elif model.joint_kind[k] == JOINT_PRISMATIC:
            # Φ = n·d with ṅ = θ̇_a Ω n, n̈ = θ̈_a Ω n − θ̇_a² n; and θ_b − θ_a − θ_0
            normal = _prismatic_normal(model, s, q, k)
            turn, angle = np.zeros(n), np.zeros(n)
            if a != GROUND:
                turn[3 * a + 2] = (OMEGA @ normal) @ d
                angle[3 * a + 2] = -1.0
            if b != GROUND:
                angle[3 * b + 2] = 1.0
            rows_B += [normal @ D + turn, angle]
            gam += [
                -(normal @ w) - 2 * wa * ((OMEGA @ normal) @ dd) + wa**2 * (normal @ d),
                0.0,
            ]
            theta = [q[3 * x + 2] if x != GROUND else 0.0 for x in (a, b)]
            relative = _param(model, "joint_relative_angle", s)[k]
            phi += [normal @ d, theta[1] - theta[0] - relative]
            phid += [wa * ((OMEGA @ normal) @ d) + normal @ dd, wb - wa]
        else:
            rho = np.linalg.norm(d)
            e = d / rho
            rows_B.append(e @ D)
            # Φ̈ = e·d̈ + (|ḋ|² − (e·ḋ)²)/|d| = 0
            gam.append(-(e @ w) - (dd @ dd - (e @ dd) ** 2) / rho)
            phi.append(rho - clearance[k])
            phid.append(e @ dd)
    for j in range(model.ndriver):
        f, rate, acc = driver_law(model, s, j, t)
        k = int(model.driver_joint[j])
        if k >= 0:  # u·d − s(t), u turning with body a as a prismatic joint's normal does
            d, dd, D, w, wa = kinematics[k]
            a = int(model.joint_body_a[k])
            axis = _slider_axis(model, s, q, k)
            turn = np.zeros(n)
            if a != GROUND:
                turn[3 * a + 2] = (OMEGA @ axis) @ d
            rows_B.append(axis @ D + turn)
            gam.append(acc - axis @ w - 2 * wa * ((OMEGA @ axis) @ dd) + wa**2 * (axis @ d))
            phi.append(axis @ d - f)
            phid.append(wa * ((OMEGA @ axis) @ d) + axis @ dd - rate)
            continue
        row = np.zeros(n)
        row[3 * int(model.driver_body[j]) + 2] = 1.0
        rows_B.append(row)
        gam.append(acc)
        phi.append(q[3 * int(model.driver_body[j]) + 2] - f)
        phid.append(v[3 * int(model.driver_body[j]) + 2] - rate)
    B = np.array(rows_B).reshape(-1, n)
    F = applied_forces(model, s, q, v, t)
    return M, B, np.array(gam), np.array(phi), np.array(phid), F


def kkt_acceleration(
    model: Model, s: int, q: np.ndarray, v: np.ndarray, t: float, baumgarte=(0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """(q̈, λ) from the dense KKT system with Baumgarte (α, β)."""
    M, B, gam, phi, phid, F = equations(model, s, q, v, t)
    alpha, beta = baumgarte
    n, m = M.shape[0], B.shape[0]
    K = np.zeros((n + m, n + m))
    K[:n, :n] = M
    K[:n, n:] = B.T
    K[n:, :n] = B
    x = np.linalg.solve(K, np.concatenate([F, gam - 2 * alpha * phid - beta**2 * phi]))
    return x[:n], x[n:]


def _piecewise_cubic(knots: np.ndarray, coef: np.ndarray, t: float) -> tuple[float, float, float]:
    """(g, ġ, g̈) at t of the compiled spline, by numpy's polynomial class on the segment that
    holds t (an evaluation independent of the kernels')."""
    i = int(np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2))
    segment = np.polynomial.Polynomial(coef[4 * i : 4 * i + 4])
    tau = t - knots[i]
    return float(segment(tau)), float(segment.deriv()(tau)), float(segment.deriv(2)(tau))


def load_factor(model: Model, s: int, k: int, t: float) -> float:
    """1 for a constant load, sin(2π f t + φ) for a harmonic one, the table's spline for a
    table one (written out anew)."""
    if int(model.force_law[k]) == LOAD_TABLE:
        n = int(model.force_table_size[k])
        return _piecewise_cubic(model.force_table_knots[k, :n], model.force_table_coef[k], t)[0]
    if int(model.force_law[k]) != LOAD_HARMONIC:
        return 1.0
    f = float(_param(model, "force_frequency", s)[k])
    return float(np.sin(2.0 * np.pi * f * t + float(_param(model, "force_phase", s)[k])))


def energy(model: Model, s: int, q: np.ndarray, v: np.ndarray) -> float:
    """Kinetic + potential energy (gravity, constant forces and couples, springs; harmonic
    loads have no potential)."""
    mass, inertia, g = (_param(model, x, s) for x in ("body_mass", "body_inertia", "gravity"))
    e = 0.0
    for b in range(model.nbody):
        r, w = q[3 * b : 3 * b + 2], v[3 * b + 2]
        e += 0.5 * (mass[b] * v[3 * b : 3 * b + 2] @ v[3 * b : 3 * b + 2] + inertia[b] * w * w)
        e -= mass[b] * g @ r
    point, value, torque = (
        _param(model, x, s) for x in ("force_point", "force_value", "force_torque")
    )
    for k in range(model.nforce):
        b = int(model.force_body[k])
        if b != GROUND and int(model.force_law[k]) == LOAD_CONSTANT:
            e -= value[k] @ (q[3 * b : 3 * b + 2] + rotation(q[3 * b + 2]) @ point[k])
            e -= torque[k] * q[3 * b + 2]
    spa, spb = _param(model, "spring_point_a", s), _param(model, "spring_point_b", s)
    k_, l0 = _param(model, "spring_stiffness", s), _param(model, "spring_rest_length", s)
    for k in range(model.nspring):
        a, b = int(model.spring_body_a[k]), int(model.spring_body_b[k])
        pa = _body(q, q, a)[0] + _body(q, q, a)[1] @ spa[k]
        pb = _body(q, q, b)[0] + _body(q, q, b)[1] @ spb[k]
        e += 0.5 * k_[k] * (np.linalg.norm(pb - pa) - l0[k]) ** 2
    return float(e)


def integrate_kkt(
    model: Model, s: int, q0, v0, times: np.ndarray, rtol=1e-12, atol=1e-13, baumgarte=(0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """scipy Radau on the dense index-1 equations: q, v at ``times`` (ntime, ndof)."""
    n = model.ndof

    def rhs(t, y):
        qdd, _ = kkt_acceleration(model, s, y[:n], y[n:], t, baumgarte)
        return np.concatenate([y[n:], qdd])

    sol = scipy.integrate.solve_ivp(
        rhs, (times[0], times[-1]), np.concatenate([q0, v0]), method="Radau",
        t_eval=times, rtol=rtol, atol=atol,
    )  # fmt: skip
    assert sol.status == 0, sol.message
    return sol.y[:n].T, sol.y[n:].T


def clearance_angle(d: np.ndarray, dd: np.ndarray) -> tuple[float, float]:
    """Angle α of d and its rate (d × ḋ)/|d|²."""
    return float(np.arctan2(d[1], d[0])), float((d[0] * dd[1] - d[1] * dd[0]) / (d @ d))
