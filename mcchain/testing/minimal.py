"""Minimal-coordinate references: sympy Lagrangians integrated by scipy's DOP853.

They check the formulation itself (including the clearance joint's Φ̈ term) against a model
that has no constraints at all: the clearance bar (journal angle α, bar angle θ) and the
double pendulum with a clearance joint (θ₁, α, θ₂). sympy is imported when a model is built.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.integrate

from mcchain.model import Model
from mcchain.testing.dense import _param


@dataclass
class MinimalModel:
    """ODE in minimal coordinates p and the map back to absolute coordinates q(p, ṗ)."""

    npar: int
    mass_matrix: Callable
    forcing: Callable
    absolute: Callable  # (p, pd) -> (q, v)

    def integrate(self, p0, pd0, times, rtol=1e-12, atol=1e-14):
        """(q, v) at ``times`` from p(0) = p0, ṗ(0) = pd0. DOP853 (explicit, 8th order):
        these smooth, non-stiff motions need no implicit method, and scipy's Radau, with
        its finite-difference Jacobians of the sympy right-hand side, took 50 times as
        long to the same agreement (1e-14 m with radau over 0.2 s)."""
        n = self.npar

        def rhs(t, y):
            p, pd = y[:n], y[n:]
            M = np.array(self.mass_matrix(*p, *pd), dtype=float).reshape(n, n)
            f = np.array(self.forcing(*p, *pd), dtype=float).reshape(n)
            return np.concatenate([pd, np.linalg.solve(M, f)])

        sol = scipy.integrate.solve_ivp(
            rhs, (times[0], times[-1]), np.concatenate([p0, pd0]), method="DOP853",
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
    (sa,), (sb,) = _param(model, "joint_point_a", s), _param(model, "joint_point_b", s)
    c = float(_param(model, "joint_clearance", s)[0])
    R = sp.Matrix([[sp.cos(th), -sp.sin(th)], [sp.sin(th), sp.cos(th)]])
    journal = sp.Matrix(sa) + c * sp.Matrix([sp.cos(al), sp.sin(al)])
    com = journal - R @ sp.Matrix(sb)
    m, J = (
        float(x) for x in (_param(model, "body_mass", s)[0], _param(model, "body_inertia", s)[0])
    )
    return _lagrangian_model([al, th], [(m, J, com[0], com[1], th)], _param(model, "gravity", s))


def double_pendulum_minimal(model: Model, s: int = 0) -> MinimalModel:
    """Ground–bar1 ideal, bar1–bar2 with clearance: coordinates (θ₁, α, θ₂)."""
    import sympy as sp

    t1, al, t2 = sp.symbols("theta1 alpha theta2")
    pa, pb = _param(model, "joint_point_a", s), _param(model, "joint_point_b", s)
    c = float(_param(model, "joint_clearance", s)[1])
    mass, inertia = _param(model, "body_mass", s), _param(model, "body_inertia", s)

    def R(th):
        return sp.Matrix([[sp.cos(th), -sp.sin(th)], [sp.sin(th), sp.cos(th)]])

    com1 = sp.Matrix(pa[0]) - R(t1) @ sp.Matrix(pb[0])
    journal = com1 + R(t1) @ sp.Matrix(pa[1]) + c * sp.Matrix([sp.cos(al), sp.sin(al)])
    com2 = journal - R(t2) @ sp.Matrix(pb[1])
    bodies = [
        (float(mass[0]), float(inertia[0]), com1[0], com1[1], t1),
        (float(mass[1]), float(inertia[1]), com2[0], com2[1], t2),
    ]
    return _lagrangian_model([t1, al, t2], bodies, _param(model, "gravity", s))
