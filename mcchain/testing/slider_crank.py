"""Independent references of the ``[[output]]``s: a slider-crank with a clearance joint in
minimal coordinates, the ideal slider-crank in closed form, and reductions on dense output.

The slider-crank (crank r turning at ω from θ1(0), rod L, slider on the x axis through the
crank's pivot, the piston pin B between the rod's end and the slider with radial clearance c,
the paper's massless link |d| = c) has one degree of freedom under its driver: the direction
α of d = slider centre − rod end. With θ1 = θ1(0) + ω t:

    rod end      B = r (cos θ1, sin θ1) + L (cos θ2, sin θ2)
    slider       (x, 0) = B + c (cos α, sin α)
    so           sin θ2 = −(r sin θ1 + c sin α) / L,   x = r cos θ1 + L cos θ2 + c cos α.

Its equation of motion is Lagrange's in α (sympy, a rheonomic Lagrangian: the rod's and the
slider's kinetic energy and the rod's weight; the driven crank's motion is prescribed),
integrated by scipy's DOP853 at rtol 1e-13 with dense output. The ideal slider-crank (c = 0)
needs no integration: x = r cos θ1 + √(L² − r² sin² θ1). Nothing here shares code with the
kernels: a slip in either shows as a difference.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, minimize_scalar


@dataclass(frozen=True)
class SliderCrank:
    """The mechanism: lengths (m), the rod's and slider's masses (kg), the rod's centroidal
    inertia (kg m²), the clearance c (m), the crank's speed ω (rad/s) and start angle (rad),
    gravity g (m/s², along −y)."""

    crank: float
    rod: float
    m_rod: float
    J_rod: float
    m_slider: float
    clearance: float
    omega: float
    angle0: float = 0.0
    g: float = 9.81

    def crank_angle(self, t: float) -> float:
        return self.angle0 + self.omega * t

    def ideal_x(self, t: float) -> float:
        """The ideal slider's position (closed form), m."""
        th = self.crank_angle(t)
        r, L = self.crank, self.rod
        return r * math.cos(th) + math.sqrt(L * L - (r * math.sin(th)) ** 2)

    def ideal_velocity(self, t: float) -> float:
        """Its velocity (closed form), m/s."""
        th = self.crank_angle(t)
        r, L = self.crank, self.rod
        s = r * math.sin(th)
        return self.omega * (-r * math.sin(th) - s * r * math.cos(th) / math.sqrt(L * L - s * s))

    def slider_x(self, t: float, alpha: float) -> float:
        """The slider's position with the pin's journal in direction α, m."""
        th = self.crank_angle(t)
        r, L, c = self.crank, self.rod, self.clearance
        sin2 = -(r * math.sin(th) + c * math.sin(alpha)) / L
        return r * math.cos(th) + L * math.sqrt(1.0 - sin2 * sin2) + c * math.cos(alpha)


@dataclass
class ClearanceMotion:
    """A reference run: α(t) and α̇(t) by DOP853's dense output, and the slider's x."""

    mechanism: SliderCrank
    dense: Callable[[float | np.ndarray], np.ndarray]  # OdeSolution: one time or many
    t_end: float
    rhs: Callable[[float, np.ndarray], np.ndarray]  # (t, [α, α̇]) -> [α̇, α̈]
    slider_acceleration: Callable[[float, float, float, float], float]

    def alpha(self, t: float) -> float:
        return float(self.dense(t)[0])

    def x(self, t: float) -> float:
        """The slider's x, m."""
        return self.mechanism.slider_x(t, self.alpha(t))

    def error(self, t: float) -> float:
        """The slider's x minus the ideal slider's (closed form), m."""
        return self.x(t) - self.mechanism.ideal_x(t)

    def errors(self, t: np.ndarray) -> np.ndarray:
        """:meth:`error` at every time of ``t`` (s) at once, m: the same formulas on arrays
        (numpy's sin, cos and sqrt: equal to ``math``'s within an ulp or two), the dense
        output evaluated once for all of them."""
        alpha = self.dense(t)[0]
        mech = self.mechanism
        th = mech.angle0 + mech.omega * t
        r, L, c = mech.crank, mech.rod, mech.clearance
        sin2 = -(r * np.sin(th) + c * np.sin(alpha)) / L
        x = r * np.cos(th) + L * np.sqrt(1.0 - sin2 * sin2) + c * np.cos(alpha)
        return x - (r * np.cos(th) + np.sqrt(L * L - (r * np.sin(th)) ** 2))

    def pin_force(self, t: float) -> float:
        """|force on the slider by the rod| at the pin, N: the link's force lies along d, and
        the guide takes none along x, so m ẍ = F cos α."""
        y = self.dense(t)
        rate = self.rhs(t, y)[1]
        acceleration = self.slider_acceleration(t, float(y[0]), float(y[1]), float(rate))
        return abs(self.mechanism.m_slider * acceleration / math.cos(float(y[0])))


def _equation(
    mech: SliderCrank,
) -> tuple[
    Callable[[float, np.ndarray], np.ndarray], Callable[[float, float, float, float], float]
]:
    """α̈ = f(t, α, α̇) from Lagrange's equation, derived by sympy, and the slider's ẍ as a
    function of (t, α, α̇, α̈)."""
    import sympy as sp

    t = sp.symbols("t")
    a = sp.Function("alpha")(t)
    r, L, c = (sp.Float(x) for x in (mech.crank, mech.rod, mech.clearance))
    th1 = sp.Float(mech.angle0) + sp.Float(mech.omega) * t
    th2 = -sp.asin((r * sp.sin(th1) + c * sp.sin(a)) / L)
    ax, ay = r * sp.cos(th1), r * sp.sin(th1)
    rod = (ax + L / 2 * sp.cos(th2), ay + L / 2 * sp.sin(th2))
    slider_x = ax + L * sp.cos(th2) + c * sp.cos(a)
    kinetic = (
        sp.Float(mech.m_rod) / 2 * (sp.diff(rod[0], t) ** 2 + sp.diff(rod[1], t) ** 2)
        + sp.Float(mech.J_rod) / 2 * sp.diff(th2, t) ** 2
        + sp.Float(mech.m_slider) / 2 * sp.diff(slider_x, t) ** 2
    )
    potential = sp.Float(mech.m_rod) * sp.Float(mech.g) * rod[1]
    lagrangian = kinetic - potential
    ad, add = sp.diff(a, t), sp.diff(a, t, 2)
    equation = sp.diff(sp.diff(lagrangian, ad), t) - sp.diff(lagrangian, a)
    p, pd, pdd = sp.symbols("p pd pdd")
    equation = equation.subs(add, pdd).subs(ad, pd).subs(a, p)
    mass = sp.diff(equation, pdd)
    rest = equation.subs(pdd, 0)
    mass_f = sp.lambdify((t, p, pd), mass, "math")
    rest_f = sp.lambdify((t, p, pd), rest, "math")
    xdd = sp.diff(slider_x, t, 2).subs(add, pdd).subs(ad, pd).subs(a, p)
    xdd_f = sp.lambdify((t, p, pd, pdd), xdd, "math")

    def rhs(time: float, y: np.ndarray) -> np.ndarray:
        return np.array([y[1], -rest_f(time, y[0], y[1]) / mass_f(time, y[0], y[1])])

    return rhs, xdd_f


def clearance_motion(
    mech: SliderCrank, alpha0: float, alpha_rate0: float, t_end: float, rtol: float = 1e-13
) -> ClearanceMotion:
    """Integrate α from α(0) = ``alpha0``, α̇(0) = ``alpha_rate0`` to ``t_end``."""
    rhs, xdd = _equation(mech)
    sol = solve_ivp(
        rhs, (0.0, t_end), [alpha0, alpha_rate0], method="DOP853", rtol=rtol, atol=1e-15,
        dense_output=True,
    )  # fmt: skip
    assert sol.status == 0, sol.message
    return ClearanceMotion(mech, sol.sol, t_end, rhs, xdd)


def reduce_signal(
    f: Callable[[float], float],
    t0: float,
    t1: float,
    reduce: str,
    threshold: float = 0.0,
    samples: int = 20001,
    on_arrays: Callable[[np.ndarray], np.ndarray] | None = None,
) -> float:
    """A ``[[output]]`` reduction of f over [t0, t1], by dense sampling refined with scipy:
    extrema by bounded minimisation around each sampled extremum (to 1e-14 of the
    spacing), rms and mean by 8-point Gauss–Legendre between the samples, a crossing by
    ``brentq``. ``on_arrays``: f on an array of times at once (e.g.
    :meth:`ClearanceMotion.errors`), for the dense sampling and the quadrature nodes (the
    reference's 10⁵ evaluations one by one cost seconds); the refinements call f."""
    many = on_arrays or (lambda times: np.array([f(t) for t in times.ravel()]))
    ts = np.linspace(t0, t1, samples)
    fs = many(ts)
    if reduce in ("max", "min", "max_abs", "range"):

        def extreme(sign: float) -> float:
            g = sign * fs
            best = float(np.max(g))
            for i in np.flatnonzero((g[1:-1] >= g[:-2]) & (g[1:-1] >= g[2:])) + 1:
                found = minimize_scalar(
                    lambda t: -sign * f(t), bounds=(ts[i - 1], ts[i + 1]), method="bounded",
                    options={"xatol": 1e-14 * (ts[1] - ts[0])},
                )  # fmt: skip
                best = max(best, -float(found.fun))
            return sign * best

        hi, lo = extreme(1.0), extreme(-1.0)
        return {"max": hi, "min": lo, "max_abs": max(hi, -lo), "range": hi - lo}[reduce]
    if reduce in ("rms", "mean"):
        power = 2 if reduce == "rms" else 1
        nodes, weights = np.polynomial.legendre.leggauss(8)  # exact to degree 15 per piece
        half = 0.5 * (ts[1:] - ts[:-1])
        middle = 0.5 * (ts[1:] + ts[:-1])
        points = middle[:, None] + half[:, None] * nodes[None, :]
        values = many(points.ravel()).reshape(points.shape) ** power
        mean = float(np.sum(half * (values @ weights))) / (t1 - t0)
        return math.sqrt(mean) if reduce == "rms" else mean
    sense = 1.0 if reduce == "first_time_above" else -1.0
    g = sense * (fs - threshold)
    if g[0] >= 0.0:
        return t0
    hits = np.flatnonzero(g >= 0.0)
    if not hits.size:
        return math.inf
    i = int(hits[0])
    return float(brentq(lambda t: sense * (f(t) - threshold), ts[i - 1], ts[i], xtol=1e-16))


FLORES = dict(crank=0.05, rod=0.12, m_rod=0.21, J_rod=0.00025, m_slider=0.14)
"""The slider-crank of configs/slider-crank-flores.toml: lengths m, masses kg, inertia kg m²
(the crank, 0.30 kg and 0.0001 kg m², is driven)."""


def slider_crank_scene(
    clearance: float, omega: float, angle0: float, simulate: str, outputs: str = ""
) -> str:
    """The Flores slider-crank (:data:`FLORES`) with the massless link at the piston pin B
    (clearance c), its crank turning at ``omega`` from ``angle0``; ``simulate``: the body
    of its ``[simulate]`` table; ``outputs``: its ``[[output]]`` tables."""
    d = FLORES
    return f"""
[scene]
name = "slider-crank-link"
[[body]]
name = "crank"
mass = 0.30
inertia = 0.0001
[[body]]
name = "rod"
mass = {d["m_rod"]!r}
inertia = {d["J_rod"]!r}
[[body]]
name = "slider"
mass = {d["m_slider"]!r}
inertia = 0.0001
[[joint]]
name = "O"
bodies = ["ground", "crank"]
points = [[0.0, 0.0], [{-d["crank"] / 2!r}, 0.0]]
[[joint]]
name = "A"
bodies = ["crank", "rod"]
points = [[{d["crank"] / 2!r}, 0.0], [{-d["rod"] / 2!r}, 0.0]]
[[joint]]
name = "B"
bodies = ["rod", "slider"]
points = [[{d["rod"] / 2!r}, 0.0], [0.0, 0.0]]
clearance = {clearance!r}
[[joint]]
name = "P"
type = "prismatic"
bodies = ["ground", "slider"]
points = [[0.0, 0.0], [0.0, 0.0]]
axis = [1.0, 0.0]
[[driver]]
body = "crank"
omega = {omega!r}
angle0 = {angle0!r}
[simulate]
{simulate}
{outputs}
"""


def mechanism_of(clearance: float, omega: float, angle0: float) -> SliderCrank:
    """:func:`slider_crank_scene`'s mechanism as the reference takes it."""
    d = FLORES
    return SliderCrank(
        d["crank"], d["rod"], d["m_rod"], d["J_rod"], d["m_slider"], clearance, omega, angle0
    )


def start_of(q: np.ndarray, v: np.ndarray, clearance: float) -> tuple[float, float]:
    """α(0) and α̇(0) of an assembled state (q, v) of :func:`slider_crank_scene` (bodies
    crank, rod, slider): d = slider centre − rod end."""
    half = FLORES["rod"] / 2
    th, w = q[5], v[5]
    d = q[6:8] - q[3:5] - half * np.array([math.cos(th), math.sin(th)])
    dd = v[6:8] - v[3:5] - half * w * np.array([-math.sin(th), math.cos(th)])
    return math.atan2(d[1], d[0]), float(d[0] * dd[1] - d[1] * dd[0]) / clearance**2
