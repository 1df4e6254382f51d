"""Closed forms the kernels are checked against (tests) and measured against (benchmarks).

* The seed bar of the paper (a homogeneous bar of length 2l pinned at one end): the pendulum
  pulsation with an ideal pin, both pulsations with a clearance pin (a quartic in p), and the
  equilibrium angle under a horizontal tip load.
* The parallelogram four-bar: one crank angle, integrated from its energy.
* The undamped stability limit of an explicit Runge–Kutta tableau on the imaginary axis.
* A bar pinned at a distance a from its centre of mass with its inertia J uniform on
  [J_low, J_high]: the exact probability that p exceeds a limit, the quantiles of p, and the
  exact tolerance allocation of J (the requirement tests).

Every function is vectorised over numpy arrays where its arguments allow.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.integrate
from scipy.optimize import brentq

G = 9.81
"""Gravity of the test scenes, m/s²."""


def bar_inertia(mass: float, length: float) -> float:
    """Centroidal moment of inertia of a homogeneous bar, m L² / 12 (kg m²)."""
    return mass * length**2 / 12


def bar_pulsation(m, J, l, g=G):
    """Seed bar, ideal pin: p = √(m g l / (J + m l²)) (rad/s); l is half the bar's length."""
    return np.sqrt(m * g * l / (J + m * l * l))


def clearance_bar_pulsations(m, J, l, g, c) -> np.ndarray:
    """Both roots p > 0 of c J p⁴ − g (m l² + J + m c l) p² + m g² l = 0, ascending on the last
    axis (rad/s): the pendulum and the journal rolling in its bearing.

    The quadratic in p² is solved without cancellation (the small root as 2C / (b + √Δ)), so
    it holds as c -> 0, where the high root goes to infinity (inf at c = 0) and the low one to
    the ideal pin's pulsation."""
    m, J, l, g, c = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (m, J, l, g, c)))
    a = c * J
    b = g * (m * l * l + J + m * c * l)
    cc = m * g * g * l
    root = np.sqrt(b * b - 4 * a * cc)
    small = 2 * cc / (b + root)
    with np.errstate(divide="ignore"):
        big = np.where(a > 0, (b + root) / (2 * np.where(a > 0, a, 1.0)), np.inf)
    return np.sqrt(np.stack([small, big], axis=-1))


def tip_load_tan_phi(P: float = 5.0, mass: float = 2.0, g: float = G) -> float:
    """tan φ = 2 P / (m g): the clearance bar's equilibrium angle from the downward vertical
    under a horizontal force P at its free end."""
    return 2 * P / (mass * g)


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


def imaginary_axis_limit(A: np.ndarray, b: np.ndarray) -> float:
    """The y > 0 where |R(iy)| first exceeds 1 for the Runge–Kutta tableau (A, b): the largest
    p·h an undamped mode of pulsation p stays bounded at (2√2 for classical RK4)."""
    n = len(b)

    def amplification(y: float) -> float:
        z = 1j * y
        return abs(1.0 + z * (b @ np.linalg.solve(np.eye(n) - z * A, np.ones(n))))

    ys = np.linspace(1e-3, 6.0, 6001)
    grows = np.array([amplification(y) > 1.0 + 1e-12 for y in ys])
    if not grows.any():
        return math.inf
    i = int(np.argmax(grows))
    return float(brentq(lambda y: amplification(y) - 1.0 - 1e-12, ys[max(i - 1, 0)], ys[i]))


# -- the pinned bar with a uniform inertia (requirements) -----------------------------------
def pinned_bar_inertia_at(p, m: float, a: float, g: float = G):
    """The inertia J at which the bar pinned at distance a from its centre of mass has the
    pulsation p: J = m g a / p² − m a² (p² = m g a / (J + m a²) inverted), kg m²."""
    return m * g * a / np.asarray(p, dtype=float) ** 2 - m * a * a


def pinned_bar_exceedance(limit, m: float, a: float, J_low: float, J_high: float, g: float = G):
    """P(p > limit) for J ~ U[J_low, J_high]: p decreases with J, so p > limit exactly when
    J < J* = J(limit); the probability is (J* − J_low)/(J_high − J_low) clipped to [0, 1]."""
    J_star = pinned_bar_inertia_at(limit, m, a, g)
    return np.clip((J_star - J_low) / (J_high - J_low), 0.0, 1.0)


def pinned_bar_quantile(level, m: float, a: float, J_low: float, J_high: float, g: float = G):
    """The ``level`` quantile of p for J ~ U[J_low, J_high]: p at the inertia quantile
    J_low + (1 − level)(J_high − J_low) (p falls as J rises), rad/s."""
    J = J_low + (1.0 - np.asarray(level, dtype=float)) * (J_high - J_low)
    return bar_pulsation(m, J, a, g)


def pinned_bar_allocation(
    limit: float, target: float, m: float, a: float, J_low: float, J_high: float, g: float = G
) -> float:
    """The exact tolerance allocation of J for the requirement p <= limit: the smallest b
    with P(p > limit | J >= b) <= target, J ~ U[J_low, J_high]. Failures are the J < J*;
    keeping J >= b (b < J*) leaves P = (J* − b)/(J_high − b), equal to the target at
    b = (J* − target J_high)/(1 − target) (J_low when the whole range already meets it)."""
    J_star = float(pinned_bar_inertia_at(limit, m, a, g))
    b = (J_star - target * J_high) / (1.0 - target)
    return max(b, J_low)
