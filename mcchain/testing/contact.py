"""Independent scipy reference of the clearance joint's contact law: impacts located by events.

Written again from the law's definition (it shares no code with :mod:`mcchain.kernels.contact`
or :mod:`mcchain.contact`, so a slip in one shows as a difference from the other):

    δ = |d| − c,  n = d/|d|,  δ̇ = n·ḋ,
    F_n = K δ^m (1 + D δ̇) for δ > 0, clipped at F_n ≥ 0;   F_n = 0 for δ ≤ 0,
    D = 0 (hertz), 3(1 − e²)/(4 δ̇⁻) (lankarani-nikravesh), 8(1 − e)/(5 e δ̇⁻) (flores),
        3(1 − e)/(2 δ̇⁻) (hunt-crossley), (1 − e²)/(e δ̇⁻) (gonthier), 3(1 − e)/(2 e δ̇⁻) (hu-guo),

δ̇⁻ being δ̇ at the contact's onset. Two scenes:

* :func:`radial_impact` — one degree of freedom: a mass on a line driven into a wall by a
  constant force; the approach speed has a closed form (:func:`radial_approach_speed`);
* :func:`journal_in_bearing` — a free journal (mass, inertia, radius) whose centre moves in a
  fixed bearing of radial clearance c under gravity, with regularised Coulomb friction.

Both integrate with ``scipy.integrate.solve_ivp`` (DOP853 by default, rtol ≤ 1e-11) phase by
phase: a free phase ends at the located onset (δ crossing 0 upwards, a terminal event) where
δ̇⁻ is read and D fixed; a contact phase ends at the located separation (δ crossing 0
downwards) where δ̇⁺ is read. A contact present at t = 0 has no onset: it is undamped and is
not an impact. The largest penetration of each contact is located as another event (δ̇
crossing 0 downwards inside a contact phase), on the solver's dense output.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

REFERENCE_RTOL = 1e-12
"""Relative tolerance of the reference integrations (the contract asks for ≤ 1e-11)."""

_DAMPING: dict[str, Callable[[float], float]] = {
    # χ(e) with D = χ / δ̇⁻
    "hertz": lambda e: 0.0,
    "lankarani-nikravesh": lambda e: 0.75 * (1.0 - e**2),
    "flores": lambda e: 1.6 * (1.0 - e) / e,
    "hunt-crossley": lambda e: 1.5 * (1.0 - e),
    "gonthier": lambda e: (1.0 - e**2) / e,
    "hu-guo": lambda e: 3.0 * (1.0 - e) / (2.0 * e),
}

LAWS: tuple[str, ...] = tuple(_DAMPING)
"""The law names, as a scene spells them."""


@dataclass(frozen=True)
class Law:
    """One ``[joint.contact]`` table.

    Attributes:
        name: one of :data:`LAWS`.
        stiffness: K, N/m^exponent.   exponent: m.   restitution: e ∈ (0, 1].
        friction: Coulomb coefficient μ (0: none).
        v0, v1: Ambrósio's regularisation speeds (m/s): no friction below v0, full above v1.
    """

    name: str
    stiffness: float
    exponent: float = 1.5
    restitution: float = 1.0
    friction: float = 0.0
    v0: float = 1e-4
    v1: float = 1e-3


def hysteresis(name: str, e, approach_speed):
    """D (s/m) for law ``name``, restitution e and onset speed δ̇⁻; 0 where δ̇⁻ ≤ 0."""
    e = np.asarray(e, dtype=float)
    v = np.asarray(approach_speed, dtype=float)
    chi = np.asarray(_DAMPING[name](e), dtype=float)
    positive = v > 0
    return np.where(positive, chi / np.where(positive, v, 1.0), 0.0)


def force(delta, delta_rate, K, m, D):
    """F_n (N), vectorised: K δ^m (1 + D δ̇) where δ > 0, at least 0, and 0 where δ ≤ 0."""
    delta, delta_rate, K, m, D = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (delta, delta_rate, K, m, D))
    )
    inside = delta > 0
    pressed = np.where(inside, delta, 1.0) ** m
    return np.where(inside, np.maximum(K * pressed * (1.0 + D * delta_rate), 0.0), 0.0)


def coulomb(normal, slip, mu, v0, v1):
    """Regularised Coulomb force −μ c_d(|v_t|) F_n sign(v_t) (N), c_d ramping 0 → 1 on
    [v0, v1]."""
    speed = np.abs(slip)
    ramp = np.clip((speed - v0) / (v1 - v0), 0.0, 1.0)
    return -mu * ramp * normal * np.sign(slip)


@dataclass
class Impact:
    """One contact: onset (time, δ̇⁻ > 0) and separation (time, δ̇⁺ < 0; NaN if none)."""

    time: float
    approach_speed: float
    separation_time: float = float("nan")
    separation_speed: float = float("nan")

    @property
    def restitution(self) -> float:
        """Measured −δ̇⁺ / δ̇⁻."""
        return -self.separation_speed / self.approach_speed


@dataclass
class ContactHistory:
    """A reference run, sampled at the requested times.

    Attributes:
        t: (nt,) s.   position: (nt, ndof) m or rad.   velocity: (nt, ndof).
        delta, delta_rate, normal_force: (nt,) m, m/s, N.
        impacts: every located onset, in order.
        events: (time, state) of every onset and separation, in order.
        max_penetration: the largest δ (m): at the located maxima of the contacts (δ̇
            crossing 0 downwards while in contact) and at the sample times; 0 if never in
            contact.
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    delta: np.ndarray
    delta_rate: np.ndarray
    normal_force: np.ndarray
    impacts: list[Impact] = field(default_factory=list)
    events: list[tuple[float, np.ndarray]] = field(default_factory=list)
    max_penetration: float = 0.0


@dataclass(frozen=True)
class _Scene:
    ndof: int
    gap: Callable[[np.ndarray], float]  # δ(y)
    gap_rate: Callable[[np.ndarray], float]  # δ̇(y)
    rhs: Callable[[float, np.ndarray, float], np.ndarray]  # ẏ(t, y, D)


def _run(
    scene: _Scene,
    law: Law,
    y0: np.ndarray,
    t_end: float,
    times: np.ndarray,
    method: str,
    rtol: float,
    atol: float | np.ndarray,
    max_step: float,
) -> ContactHistory:
    """Integrate phase by phase, restarting at each located onset and separation."""
    times = np.asarray(times, dtype=float)
    t0, y = 0.0, np.asarray(y0, dtype=float)
    in_contact = scene.gap(y) > 0.0
    D = 0.0  # a contact present at t = 0 has no onset: undamped
    impacts: list[Impact] = []
    events: list[tuple[float, np.ndarray]] = []
    apexes: list[float] = []  # δ at the located maxima of the contacts
    ts: list[np.ndarray] = []
    ys: list[np.ndarray] = []

    while t0 < t_end:

        def crossing(t, yy, *_):
            return scene.gap(yy)

        crossing.terminal = True  # type: ignore[attr-defined]
        crossing.direction = -1.0 if in_contact else 1.0  # type: ignore[attr-defined]

        def apex(t, yy, *_):
            return scene.gap_rate(yy)

        apex.direction = -1.0  # type: ignore[attr-defined]
        sample = times[(times >= t0) & (times <= t_end)]
        last = next((t[-1] for t in reversed(ts) if len(t)), None)
        if last is not None and sample.size and sample[0] == last:
            sample = sample[1:]  # the previous phase ended exactly on a sample time
        sol = solve_ivp(
            scene.rhs,
            (t0, t_end),
            y,
            method=method,
            t_eval=sample,
            events=(crossing, apex),
            rtol=rtol,
            atol=atol,
            max_step=max_step,
            args=(D,),
        )
        if sol.status < 0:
            raise RuntimeError(f"reference integration failed at t = {t0:g}: {sol.message}")
        ts.append(sol.t)
        # (a phase with no sample time in it gives scipy's empty list, not an array)
        ys.append(np.asarray(sol.y, dtype=float).reshape(y.size, -1).T)
        if in_contact:
            apexes += [scene.gap(state) for state in sol.y_events[1]]
        if sol.status == 0:
            break
        t0 = float(sol.t_events[0][0])
        y = np.asarray(sol.y_events[0][0], dtype=float)
        crossing_rate = float(scene.gap_rate(y))
        events.append((t0, y.copy()))
        if in_contact:
            if impacts and np.isnan(impacts[-1].separation_time):
                impacts[-1].separation_time = t0
                impacts[-1].separation_speed = crossing_rate
            D = 0.0
        else:
            impacts.append(Impact(time=t0, approach_speed=crossing_rate))
            D = float(hysteresis(law.name, law.restitution, crossing_rate))
        in_contact = not in_contact

    t = np.concatenate(ts) if ts else np.empty(0)
    Y = np.concatenate(ys) if ys else np.empty((0, 2 * scene.ndof))
    delta = np.array([scene.gap(row) for row in Y])
    rate = np.array([scene.gap_rate(row) for row in Y])
    # D of the contact each sample belongs to (0 outside contacts and before the first onset)
    D_t = np.zeros_like(t)
    for imp in impacts:
        end = imp.separation_time if np.isfinite(imp.separation_time) else np.inf
        D_t[(t >= imp.time) & (t <= end)] = hysteresis(
            law.name, law.restitution, imp.approach_speed
        )
    fn = force(delta, rate, law.stiffness, law.exponent, D_t)
    peak = max([0.0, *apexes, *delta[np.isfinite(delta)]])
    return ContactHistory(
        t=t,
        position=Y[:, : scene.ndof],
        velocity=Y[:, scene.ndof :],
        delta=delta,
        delta_rate=rate,
        normal_force=fn,
        impacts=impacts,
        events=events,
        max_penetration=float(peak),
    )


def radial_approach_speed(speed: float, gap: float, push: float, mass: float) -> float:
    """Closed form of δ̇⁻ for :func:`radial_impact`: √(v₀² + 2 f h / m) (m/s)."""
    return float(np.sqrt(speed**2 + 2.0 * push * gap / mass))


def radial_impact(
    law: Law,
    *,
    mass: float = 1.0,
    gap: float = 1e-4,
    speed: float = 1.0,
    push: float = 0.0,
    t_end: float | None = None,
    times: np.ndarray | None = None,
    method: str = "DOP853",
    rtol: float = REFERENCE_RTOL,
    max_step: float = np.inf,
) -> ContactHistory:
    """A mass on a line, a gap ``gap`` (m) from a wall, moving at ``speed`` (m/s) towards it and
    pushed towards it by a constant force ``push`` (N).

    The coordinate is the distance travelled x (m); δ = x − gap. Integrates to ``t_end``
    (default: twice the free-flight time to the wall plus 50 δ_max/δ̇⁻, enough to leave the
    wall again at every restitution of the restitution table). ``position``/``velocity`` in
    the history are x and ẋ.
    """
    K, m = law.stiffness, law.exponent

    def rhs(t, y, D):
        delta = y[0] - gap
        return np.array([y[1], (push - float(force(delta, y[1], K, m, D))) / mass])

    scene = _Scene(1, lambda y: y[0] - gap, lambda y: y[1], rhs)
    v_in = radial_approach_speed(speed, gap, push, mass)
    if t_end is None:
        # reach the wall, then a few contact durations (δ_max / v⁻ scales them)
        delta_max = (0.5 * (m + 1.0) * mass * v_in**2 / K) ** (1.0 / (m + 1.0))
        t_end = 2.0 * gap / max(v_in, 1e-300) + 50.0 * delta_max / v_in
    if times is None:
        times = np.linspace(0.0, t_end, 201)
    scale = max(gap, 1e-12)
    atol = np.array([rtol * scale, rtol * v_in])
    return _run(scene, law, np.array([0.0, speed]), t_end, times, method, rtol, atol, max_step)


def journal_in_bearing(
    law: Law,
    *,
    clearance: float,
    mass: float,
    inertia: float,
    radius: float,
    position: tuple[float, float] = (0.0, 0.0),
    velocity: tuple[float, float] = (0.0, 0.0),
    angle: float = 0.0,
    spin: float = 0.0,
    gravity: float = 9.81,
    t_end: float = 0.05,
    times: np.ndarray | None = None,
    method: str = "DOP853",
    rtol: float = REFERENCE_RTOL,
    max_step: float = np.inf,
) -> ContactHistory:
    """A free journal (``mass`` kg, ``inertia`` kg m², ``radius`` m) whose centre moves inside a
    fixed bearing of radial clearance ``clearance`` (m), under gravity −``gravity`` ŷ (m/s²).

    Coordinates (x, y, θ): the journal centre relative to the bearing centre (m) and its angle
    (rad); d = (x, y). The journal receives −F_n n at the contact and the friction
    −μ c_d F_n sign(v_t) t with t = (−n_y, n_x) and the slip v_t = t·ṙ + R θ̇ of its surface
    point on the fixed bearing (torque R F_t about its centre).
    """
    c, K, m = clearance, law.stiffness, law.exponent
    mu, v0, v1 = law.friction, law.v0, law.v1

    def geometry(y):
        r = np.hypot(y[0], y[1])
        n = np.array([y[0], y[1]]) / r if r > 0 else np.array([1.0, 0.0])
        return r - c, n

    def gap(y):
        return float(np.hypot(y[0], y[1]) - c)

    def gap_rate(y):
        _, n = geometry(y)
        return float(n[0] * y[3] + n[1] * y[4])

    def rhs(t, y, D):
        delta, n = geometry(y)
        rate = n[0] * y[3] + n[1] * y[4]
        fn = float(force(delta, rate, K, m, D))
        tx, ty = -n[1], n[0]
        ft = 0.0
        if mu > 0.0 and fn > 0.0:
            slip = tx * y[3] + ty * y[4] + radius * y[5]
            ft = float(coulomb(fn, slip, mu, v0, v1))
        fx = -fn * n[0] + ft * tx
        fy = -fn * n[1] + ft * ty - mass * gravity
        return np.array([y[3], y[4], y[5], fx / mass, fy / mass, radius * ft / inertia])

    scene = _Scene(3, gap, gap_rate, rhs)
    if times is None:
        times = np.linspace(0.0, t_end, 501)
    y0 = np.array([position[0], position[1], angle, velocity[0], velocity[1], spin])
    v_scale = max(np.sqrt(2.0 * gravity * 2.0 * c), np.hypot(*velocity), 1e-12)
    atol = np.array(
        [rtol * c, rtol * c, rtol, rtol * v_scale, rtol * v_scale, rtol * v_scale / radius]
    )
    return _run(scene, law, y0, t_end, times, method, rtol, atol, max_step)


def journal_energy(
    history: ContactHistory, law: Law, mass: float, inertia: float, gravity: float = 9.81
) -> np.ndarray:
    """Kinetic + gravity + elastic energy K δ^(m+1)/(m+1) of a :func:`journal_in_bearing`
    history (J): conserved by the ``hertz`` law without friction."""
    v = history.velocity
    kinetic = 0.5 * mass * (v[:, 0] ** 2 + v[:, 1] ** 2) + 0.5 * inertia * v[:, 2] ** 2
    m = law.exponent
    elastic = law.stiffness * np.maximum(history.delta, 0.0) ** (m + 1.0) / (m + 1.0)
    return kinetic + mass * gravity * history.position[:, 1] + elastic


RESTITUTIONS: tuple[float, ...] = (0.3, 0.5, 0.7, 0.9, 0.99)
"""Nominal restitutions of the restitution table (tests and benchmark)."""


def measured_restitution(name: str, e: float, exponent: float = 1.5) -> float:
    """−δ̇⁺/δ̇⁻ of one free impact (no push) of law ``name`` with nominal restitution ``e``.

    With D = χ(e)/δ̇⁻ the ratio depends on χ and the exponent only (scaling δ by the maximum
    penetration and t by the contact time removes K, the mass and δ̇⁻), so one impact at
    K = 1e10 N/m^m, 1 kg, 1 m/s stands for all."""
    history = radial_impact(Law(name, 1e10, exponent, e), mass=1.0, gap=1e-4, speed=1.0)
    return history.impacts[0].restitution


def restitution_table(
    laws: tuple[str, ...] = LAWS, restitutions: tuple[float, ...] = RESTITUTIONS
) -> dict[str, np.ndarray]:
    """Measured restitution of each law (rows) at each nominal e (columns)."""
    return {name: np.array([measured_restitution(name, e) for e in restitutions]) for name in laws}
