"""Slow, obvious references for the dynamics (simulate) kernels.

* :func:`kkt_acceleration`: the index-1 accelerations and multipliers of one sample by a dense
  NumPy solve of the full KKT system [[M, Bᵀ], [B, 0]] in absolute coordinates, written
  straight from DESIGN §2 (no code shared with the kernels).
* :func:`integrate_kkt`: scipy Radau on those equations.
* Minimal-coordinate models (sympy Lagrangians, scipy Radau at tight tolerances): the clearance
  bar (journal angle α, bar angle θ), the double pendulum with a clearance joint (θ₁, α, θ₂)
  and the parallelogram four-bar (one crank angle). They check the formulation itself,
  including the clearance joint's Φ̈ term.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.integrate

from mcchain.bench import fourbar_text
from mcchain.model import GROUND, JOINT_IDEAL, Model


def _p(model: Model, name: str, s: int) -> np.ndarray:
    arr = getattr(model, name)
    return np.asarray(arr[s % arr.shape[0]], dtype=float)


def _rot(th: float) -> np.ndarray:
    return np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])


OMEGA = np.array([[0.0, -1.0], [1.0, 0.0]])


def _body(q: np.ndarray, v: np.ndarray, b: int):
    """r, A, ṙ, θ̇ of body b (ground at rest)."""
    if b == GROUND:
        return np.zeros(2), np.eye(2), np.zeros(2), 0.0
    return q[3 * b : 3 * b + 2], _rot(q[3 * b + 2]), v[3 * b : 3 * b + 2], v[3 * b + 2]


def equations(model: Model, s: int, q: np.ndarray, v: np.ndarray, t: float):
    """Dense M (n,n), B (m,n), γ (m,) with B q̈ = γ, Φ (m,), Φ̇ (m,), F (n,) of sample s."""
    n = model.ndof
    M = np.zeros((n, n))
    mass, inertia = _p(model, "body_mass", s), _p(model, "body_inertia", s)
    for b in range(model.nbody):
        M[3 * b, 3 * b] = M[3 * b + 1, 3 * b + 1] = mass[b]
        M[3 * b + 2, 3 * b + 2] = inertia[b]
    rows_B, gam, phi, phid = [], [], [], []
    pa_all, pb_all = _p(model, "joint_point_a", s), _p(model, "joint_point_b", s)
    clearance = _p(model, "joint_clearance", s)
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
        if model.joint_kind[k] == JOINT_IDEAL:
            rows_B += [D[0], D[1]]
            gam += list(-w)
            phi += list(d)
            phid += list(dd)
        else:
            rho = np.linalg.norm(d)
            e = d / rho
            rows_B.append(e @ D)
            # Φ̈ = e·d̈ + (|ḋ|² − (e·ḋ)²)/|d| = 0
            gam.append(-(e @ w) - (dd @ dd - (e @ dd) ** 2) / rho)
            phi.append(rho - clearance[k])
            phid.append(e @ dd)
    theta0, omega = _p(model, "driver_angle0", s), _p(model, "driver_omega", s)
    for j in range(model.ndriver):
        row = np.zeros(n)
        row[3 * int(model.driver_body[j]) + 2] = 1.0
        rows_B.append(row)
        gam.append(0.0)
        phi.append(q[3 * int(model.driver_body[j]) + 2] - theta0[j] - omega[j] * t)
        phid.append(v[3 * int(model.driver_body[j]) + 2] - omega[j])
    B = np.array(rows_B).reshape(-1, n)
    F = forces(model, s, q, v)
    return M, B, np.array(gam), np.array(phi), np.array(phid), F


def forces(model: Model, s: int, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Generalised applied forces: gravity, constant loads and couples, spring-dampers."""
    n = model.ndof
    F = np.zeros(n)
    g, mass = _p(model, "gravity", s), _p(model, "body_mass", s)
    for b in range(model.nbody):
        F[3 * b : 3 * b + 2] += mass[b] * g

    def apply(b: int, f: np.ndarray, u: np.ndarray) -> None:
        if b != GROUND:
            F[3 * b : 3 * b + 2] += f
            F[3 * b + 2] += u[0] * f[1] - u[1] * f[0]

    point, value, torque = (_p(model, x, s) for x in ("force_point", "force_value", "force_torque"))
    for k in range(model.nforce):
        b = int(model.force_body[k])
        if b == GROUND:
            continue
        _, A, _, _ = _body(q, v, b)
        apply(b, value[k], A @ point[k])
        F[3 * b + 2] += torque[k]
    spa, spb = _p(model, "spring_point_a", s), _p(model, "spring_point_b", s)
    k_, l0, c_ = (
        _p(model, x, s) for x in ("spring_stiffness", "spring_rest_length", "spring_damping")
    )
    for k in range(model.nspring):
        a, b = int(model.spring_body_a[k]), int(model.spring_body_b[k])
        ra, Aa, va, wa = _body(q, v, a)
        rb, Ab, vb, wb = _body(q, v, b)
        ua, ub = Aa @ spa[k], Ab @ spb[k]
        u = rb + ub - ra - ua
        du = vb + wb * (OMEGA @ ub) - va - wa * (OMEGA @ ua)
        if l0[k] == 0.0:
            f = -k_[k] * u - c_[k] * du
        else:
            L = np.linalg.norm(u)
            e = u / L
            f = -(k_[k] * (L - l0[k]) + c_[k] * (e @ du)) * e
        apply(b, f, ub)
        apply(a, -f, ua)
    return F


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


def energy(model: Model, s: int, q: np.ndarray, v: np.ndarray) -> float:
    """Kinetic + potential energy (gravity, constant forces and couples, springs)."""
    mass, inertia, g = (_p(model, x, s) for x in ("body_mass", "body_inertia", "gravity"))
    e = 0.0
    for b in range(model.nbody):
        r, w = q[3 * b : 3 * b + 2], v[3 * b + 2]
        e += 0.5 * (mass[b] * v[3 * b : 3 * b + 2] @ v[3 * b : 3 * b + 2] + inertia[b] * w * w)
        e -= mass[b] * g @ r
    point, value, torque = (_p(model, x, s) for x in ("force_point", "force_value", "force_torque"))
    for k in range(model.nforce):
        b = int(model.force_body[k])
        if b != GROUND:
            e -= value[k] @ (q[3 * b : 3 * b + 2] + _rot(q[3 * b + 2]) @ point[k])
            e -= torque[k] * q[3 * b + 2]
    spa, spb = _p(model, "spring_point_a", s), _p(model, "spring_point_b", s)
    k_, l0 = _p(model, "spring_stiffness", s), _p(model, "spring_rest_length", s)
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


# ---------------------------------------------------------------------------------------------
# Minimal coordinates (sympy Lagrangians)


@dataclass
class MinimalModel:
    """ODE in minimal coordinates p and the map back to absolute coordinates q(p, ṗ)."""

    npar: int
    mass_matrix: Callable
    forcing: Callable
    absolute: Callable  # (p, pd) -> (q, v)

    def integrate(self, p0, pd0, times, rtol=1e-12, atol=1e-14):
        n = self.npar

        def rhs(t, y):
            p, pd = y[:n], y[n:]
            M = np.array(self.mass_matrix(*p, *pd), dtype=float).reshape(n, n)
            f = np.array(self.forcing(*p, *pd), dtype=float).reshape(n)
            return np.concatenate([pd, np.linalg.solve(M, f)])

        sol = scipy.integrate.solve_ivp(
            rhs, (times[0], times[-1]), np.concatenate([p0, pd0]), method="Radau",
            t_eval=times, rtol=rtol, atol=atol,
        )  # fmt: skip
        assert sol.status == 0, sol.message
        qs, vs = zip(*(self.absolute(y[:n], y[n:]) for y in sol.y.T), strict=True)
        return np.array(qs), np.array(vs)


def _lagrangian_model(coords, bodies, gravity) -> MinimalModel:
    """Bodies: list of (mass, inertia, x(p), y(p), θ(p)) sympy expressions in ``coords``."""
    import sympy as sp

    n = len(coords)
    dots = sp.symbols(f"pd0:{n}")
    T = 0
    V = 0
    absolute = []
    for m, J, x, y, th in bodies:
        xd = sum(sp.diff(x, c) * d for c, d in zip(coords, dots, strict=True))
        yd = sum(sp.diff(y, c) * d for c, d in zip(coords, dots, strict=True))
        thd = sum(sp.diff(th, c) * d for c, d in zip(coords, dots, strict=True))
        T += sp.Rational(1, 2) * (m * (xd**2 + yd**2) + J * thd**2)
        V -= m * (gravity[0] * x + gravity[1] * y)
        absolute += [(x, y, th), (xd, yd, thd)]
    L = T - V
    Mm = sp.Matrix(n, n, lambda i, j: sp.diff(L, dots[i], dots[j]))
    f = sp.Matrix(
        [
            sp.diff(L, coords[i]) - sum(sp.diff(L, dots[i], coords[j]) * dots[j] for j in range(n))
            for i in range(n)
        ]
    )
    args = (*coords, *dots)
    Mf = sp.lambdify(args, Mm, "numpy")
    ff = sp.lambdify(args, f, "numpy")
    pos = sp.lambdify(args, [e for k, body in enumerate(absolute) if k % 2 == 0 for e in body])
    vel = sp.lambdify(args, [e for k, body in enumerate(absolute) if k % 2 == 1 for e in body])

    def to_abs(p, pd):
        a = (*p, *pd)
        return np.array(pos(*a), dtype=float), np.array(vel(*a), dtype=float)

    return MinimalModel(n, Mf, ff, to_abs)


def clearance_bar_minimal(model: Model, s: int = 0) -> MinimalModel:
    """One bar on a clearance joint to the ground: coordinates (α, θ)."""
    import sympy as sp

    al, th = sp.symbols("alpha theta")
    (sa,), (sb,) = _p(model, "joint_point_a", s), _p(model, "joint_point_b", s)
    c = float(_p(model, "joint_clearance", s)[0])
    R = sp.Matrix([[sp.cos(th), -sp.sin(th)], [sp.sin(th), sp.cos(th)]])
    journal = sp.Matrix(sa) + c * sp.Matrix([sp.cos(al), sp.sin(al)])
    com = journal - R @ sp.Matrix(sb)
    m, J = (float(x) for x in (_p(model, "body_mass", s)[0], _p(model, "body_inertia", s)[0]))
    return _lagrangian_model([al, th], [(m, J, com[0], com[1], th)], _p(model, "gravity", s))


def double_pendulum_minimal(model: Model, s: int = 0) -> MinimalModel:
    """Ground–bar1 ideal, bar1–bar2 with clearance: coordinates (θ₁, α, θ₂)."""
    import sympy as sp

    t1, al, t2 = sp.symbols("theta1 alpha theta2")
    pa, pb = _p(model, "joint_point_a", s), _p(model, "joint_point_b", s)
    c = float(_p(model, "joint_clearance", s)[1])
    mass, inertia = _p(model, "body_mass", s), _p(model, "body_inertia", s)

    def R(th):
        return sp.Matrix([[sp.cos(th), -sp.sin(th)], [sp.sin(th), sp.cos(th)]])

    com1 = sp.Matrix(pa[0]) - R(t1) @ sp.Matrix(pb[0])
    journal = com1 + R(t1) @ sp.Matrix(pa[1]) + c * sp.Matrix([sp.cos(al), sp.sin(al)])
    com2 = journal - R(t2) @ sp.Matrix(pb[1])
    bodies = [
        (float(mass[0]), float(inertia[0]), com1[0], com1[1], t1),
        (float(mass[1]), float(inertia[1]), com2[0], com2[1], t2),
    ]
    return _lagrangian_model([t1, al, t2], bodies, _p(model, "gravity", s))


def clearance_angle(d: np.ndarray, dd: np.ndarray) -> tuple[float, float]:
    """Angle α of d and its rate (d × ḋ)/|d|²."""
    return float(np.arctan2(d[1], d[0])), float((d[0] * dd[1] - d[1] * dd[0]) / (d @ d))


def parallelogram_closed_form(
    crank_length: float, masses, inertias, g: float, theta0: float, omega0: float, times
) -> tuple[np.ndarray, np.ndarray]:
    """Crank angle θ(t) and rate of a parallelogram whose cranks (homogeneous bars pinned at
    one end, lengths ``crank_length``) share one angle and whose coupler translates.

    Energy: T = ½ (J₁ + m₁ l² /4 + J₂ + m₂ l²/4 + m_c l²) θ̇²,
    V = g (m₁ l/2 + m₂ l/2 + m_c l) sin θ, with l the crank length (θ from +x, gravity −y).
    """
    m1, mc, m2 = masses
    J1, _, J2 = inertias
    ll = crank_length
    inertia = J1 + m1 * ll**2 / 4 + J2 + m2 * ll**2 / 4 + mc * ll**2
    moment = g * (m1 * ll / 2 + m2 * ll / 2 + mc * ll)

    def rhs(t, y):
        return [y[1], -moment * np.cos(y[0]) / inertia]

    sol = scipy.integrate.solve_ivp(
        rhs, (times[0], times[-1]), [theta0, omega0], method="Radau", t_eval=times,
        rtol=1e-13, atol=1e-14,
    )  # fmt: skip
    return sol.y[0], sol.y[1]


# ---------------------------------------------------------------------------------------------
# Test scenes (TOML text; consistent start states computed here in float64)


def _bar_text(clearance: float = 1e-3, tilt: float = 0.3, count: int | None = None) -> str:
    th = -np.pi / 2 + tilt
    journal = np.array([0.0, -clearance])  # journal at the bottom of its bearing
    com = journal - _rot(th) @ np.array([-0.5, 0.0])
    sample = "" if count is None else f"[sample]\ncount = {count}\nseed = 3\n"
    return f"""
[scene]
name = "clearance-bar"
gravity = [0.0, -9.81]
[[body]]
name = "bar"
mass = 2.0
inertia = 0.16666666666666666
position = [{float(com[0])!r}, {float(com[1])!r}]
angle = {float(th)!r}
[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]
clearance = {float(clearance)!r}
{sample}"""


def _parallelogram_text(crank=0.2, coupler=0.5, omega0=5.0) -> str:
    th = np.pi / 2
    c1 = 0.5 * crank * np.array([np.cos(th), np.sin(th)])
    tip = 2 * c1
    v1 = 0.5 * crank * omega0 * np.array([-np.sin(th), np.cos(th)])
    vt = 2 * v1
    return f"""
[scene]
name = "parallelogram"
gravity = [0.0, -9.81]
[[body]]
name = "crank1"
mass = 0.2
inertia = {float(0.2 * crank**2 / 12)!r}
position = [{float(c1[0])!r}, {float(c1[1])!r}]
angle = {float(th)!r}
velocity = [{float(v1[0])!r}, {float(v1[1])!r}]
angular_velocity = {float(omega0)!r}
[[body]]
name = "coupler"
mass = 0.5
inertia = {float(0.5 * coupler**2 / 12)!r}
position = [{float(tip[0] + coupler / 2)!r}, {float(tip[1])!r}]
angle = 0.0
velocity = [{float(vt[0])!r}, {float(vt[1])!r}]
[[body]]
name = "crank2"
mass = 0.2
inertia = {float(0.2 * crank**2 / 12)!r}
position = [{float(coupler + c1[0])!r}, {float(c1[1])!r}]
angle = {float(th)!r}
velocity = [{float(v1[0])!r}, {float(v1[1])!r}]
angular_velocity = {float(omega0)!r}
[[joint]]
name = "O1"
bodies = ["ground", "crank1"]
points = [[0.0, 0.0], [{float(-crank / 2)!r}, 0.0]]
[[joint]]
name = "A"
bodies = ["crank1", "coupler"]
points = [[{float(crank / 2)!r}, 0.0], [{float(-coupler / 2)!r}, 0.0]]
[[joint]]
name = "B"
bodies = ["coupler", "crank2"]
points = [[{float(coupler / 2)!r}, 0.0], [{float(crank / 2)!r}, 0.0]]
[[joint]]
name = "O2"
bodies = ["ground", "crank2"]
points = [[{float(coupler)!r}, 0.0], [{float(-crank / 2)!r}, 0.0]]
"""


_DOUBLE_PENDULUM = """
[scene]
name = "double-pendulum-clearance"
gravity = [0.0, -9.81]
[[body]]
name = "bar1"
mass = 1.5
inertia = 0.045
position = [0.15000000000000002, -0.25980762113533157]
angle = -1.0471975511965976
[[body]]
name = "bar2"
mass = 1.0
inertia = 0.013333333333333334
position = [0.4417749096279029, -0.6613901518985659]
angle = -0.7853981633974483
[[joint]]
name = "O"
bodies = ["ground", "bar1"]
points = [[0.0, 0.0], [-0.3, 0.0]]
[[joint]]
name = "B"
bodies = ["bar1", "bar2"]
points = [[0.3, 0.0], [-0.2, 0.0]]
clearance = 5e-4
"""


# the clearance double pendulum with every kind of load: driver, force + torque, springs
_LOADED = (
    _DOUBLE_PENDULUM.replace(
        'name = "double-pendulum-clearance"\ngravity = [0.0, -9.81]',
        'name = "loaded-double-pendulum"\ngravity = [0.3, -9.81]',
    )
    + """[[driver]]
body = "bar1"
omega = 1.5
[[force]]
name = "tip"
body = "bar2"
point = [0.2, 0.01]
value = [3.0, -1.0]
torque = 0.4
[[spring]]
name = "s0"
bodies = ["ground", "bar2"]
points = [[0.5, 0.2], [0.2, 0.0]]
stiffness = 300.0
rest_length = 0.3
damping = 2.0
[[spring]]
name = "s1"
bodies = ["bar1", "bar2"]
points = [[0.0, 0.05], [0.0, -0.05]]
stiffness = 50.0
damping = 0.5
"""
)

SCENES = {
    "clearance_bar": _bar_text,
    "parallelogram": _parallelogram_text,
    "double_pendulum": lambda: _DOUBLE_PENDULUM,
    "fourbar": fourbar_text,
    "loaded": lambda: _LOADED,
}


def scene_model(name: str, nsample: int | None = None, **kwargs) -> Model:
    """A test scene compiled to a Model (``nsample`` copies; kwargs for the bar builders)."""
    from mcchain.scene import compile_model, load_scene_text

    return compile_model(load_scene_text(SCENES[name](**kwargs), name=name), nsample=nsample)
