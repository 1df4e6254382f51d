"""Slow, obvious reference implementations that the fast kernels are compared against.

Dense NumPy/SciPy, one sample at a time, written straight from DESIGN §2 without sharing
code with the kernels. Used by the tests and by ``benchmarks/bench_statics.py`` (the "plain
SciPy loop": ``scipy.optimize.root`` + ``scipy.linalg.eigh`` per instance).

Φ and F are written so that they accept complex q: :func:`complex_step_jacobian` then gives
their exact first derivatives (error ~1e-16, no subtractive cancellation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize

from mcchain.model import GROUND, JOINT_IDEAL, Model


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
        else:
            phi[row] = np.sqrt(d[0] * d[0] + d[1] * d[1]) - clearance[k]
    theta0 = _param(model, "driver_angle0", s)
    omega = _param(model, "driver_omega", s)
    for j in range(model.ndriver):
        phi[model.driver_row[j]] = q[3 * model.driver_body[j] + 2] - theta0[j] - omega[j] * t
    return phi


def applied_forces(model: Model, s: int, q: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
    """F(q, q̇) of sample s, (3 nbody,), by virtual work of each load; complex-safe in q."""
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
        add_point_force(
            body, _param(model, "force_point", s)[k], _param(model, "force_value", s)[k]
        )
        if body != GROUND:
            F[3 * body + 2] += _param(model, "force_torque", s)[k]
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
    """B written out from DESIGN §2 (rows [I, Ω A_b s_b] / [−I, −Ω A_a s_a], e·∂d/∂q for
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
        else:
            B[row] = d @ rows / np.sqrt(d[0] * d[0] + d[1] * d[1])
    for j in range(model.ndriver):
        B[model.driver_row[j], 3 * model.driver_body[j] + 2] = 1.0
    return B


def stiffness(model: Model, s: int, q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """K = ∂(Bᵀλ − F)/∂q at fixed λ by the complex step of the written-out B and F."""
    K = complex_step_jacobian(
        lambda x: constraint_jacobian_formula(model, s, x).T @ lam - applied_forces(model, s, x),
        q,
    )
    return 0.5 * (K + K.T)


# -- closed forms of the seed bar (DESIGN §3) -----------------------------------------------
def bar_pulsation(m: float, J: float, l: float, g: float) -> float:
    """Seed bar, ideal pin: p² = m g l / (J + m l²)."""
    return float(np.sqrt(m * g * l / (J + m * l * l)))


def clearance_bar_pulsations(m: float, J: float, l: float, g: float, c: float) -> np.ndarray:
    """Both roots of c J p⁴ − g (m l² + J + m c l) p² + m g² l = 0, ascending.

    The quadratic in p² is solved without cancellation (product of roots for the small one).
    """
    a = c * J
    b = g * (m * l * l + J + m * c * l)
    cc = m * g * g * l
    big = (b + np.sqrt(b * b - 4 * a * cc)) / (2 * a)
    small = cc / (a * big)
    return np.sqrt(np.array([small, big]))
