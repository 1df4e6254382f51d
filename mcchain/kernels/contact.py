"""The clearance joint's contact law, scalar by scalar: hysteresis damping factor, normal
force and its partial derivatives, regularised Coulomb friction.

With ``d`` the vector from the bearing point to the journal point, ``δ = |d| − c``,
``n = d/|d|`` and ``δ̇ = n·ḋ``:

    F_n = K δ^m (1 + D δ̇)   for δ > 0, clipped at F_n ≥ 0;   F_n = 0 for δ ≤ 0,

where ``D`` is fixed at the contact's onset (δ crossing 0 upwards, approach speed δ̇⁻ > 0):

    hertz                 D = 0
    lankarani-nikravesh   D = 3 (1 − e²) / (4 δ̇⁻)
    flores                D = 8 (1 − e) / (5 e δ̇⁻)
    hunt-crossley         D = 3 (1 − e) / (2 δ̇⁻)
    gonthier              D = (1 − e²) / (e δ̇⁻)
    hu-guo                D = 3 (1 − e) / (2 e δ̇⁻)

The journal body receives −F_n n at its point, the bearing body +F_n n. The law codes and
the friction defaults live in :mod:`mcchain.contact` (no numba), so the scene loader can name
them without compiling anything; they are re-exported here for the kernels.

Every function is ``@njit(**JIT)`` on scalars: no allocation, never raises (a division by
zero gives inf/NaN under ``error_model="numpy"``).
"""

from __future__ import annotations

import math

from mcchain.contact import (
    AUTO,
    FLORES,
    FRICTION_V0,
    FRICTION_V1,
    GONTHIER,
    HERTZ,
    HU_GUO,
    HUNT_CROSSLEY,
    LANKARANI_NIKRAVESH,
    RESEAT_RATE,
    SEATED,
    SEATED_AT_SWITCH,
)
from mcchain.kernels.config import JIT, fma, njit

__all__ = [
    "FLORES",
    "FRICTION_RAMP",
    "FRICTION_V0",
    "FRICTION_V1",
    "GONTHIER",
    "HERTZ",
    "HUNT_CROSSLEY",
    "HU_GUO",
    "LANKARANI_NIKRAVESH",
    "contact_bookkeeping",
    "contact_crossing",
    "contact_law",
    "contact_mode",
    "contact_power",
    "contact_slip",
    "damping_factor",
    "dwell_start",
    "elastic_energy",
    "friction_factor",
    "friction_force",
    "hermite_peak",
    "hertz_power",
    "normal_force",
    "normal_force_derivatives",
    "quasi_static_slack",
    "reseat_slack",
    "restitution_factor",
]


@njit(**JIT)
def restitution_factor(law, e):
    """χ(e) of ``law`` for restitution ``e`` ∈ (0, 1]: the hysteresis damping factor is
    D = χ / δ̇⁻ (:func:`damping_factor`). The one table of the laws: the loop kernels call
    it, the lane generator inlines it (:mod:`mcchain.codegen.inline`). 0 for ``HERTZ`` and
    for an unknown code."""
    if law == LANKARANI_NIKRAVESH:
        return 0.75 * (1.0 - e * e)
    if law == FLORES:
        return 1.6 * (1.0 - e) / e
    if law == HUNT_CROSSLEY:
        return 1.5 * (1.0 - e)
    if law == GONTHIER:
        return (1.0 - e * e) / e
    if law == HU_GUO:
        return 1.5 * (1.0 - e) / e
    return 0.0


@njit(**JIT)
def damping_factor(law, e, approach_speed):
    """Hysteresis damping factor D = χ(e) / δ̇⁻ (s/m) of ``law`` for restitution ``e`` and
    the approach speed δ̇⁻ (m/s) at the contact's onset.

    D = 0 for ``HERTZ``, for an unknown code, and when δ̇⁻ is not > 1e-200 (no located
    onset: a contact present at t = 0, or one entered from the link, stays undamped).
    """
    chi = restitution_factor(law, e)
    return chi / approach_speed if approach_speed > 1e-200 else 0.0


HERTZ_EXACT_MAX = 1e200
"""Largest δ whose δ^1.5 :func:`hertz_power` rounds once (correctly); above it δ·√δ."""


@njit(**JIT)
def hertz_power(x):
    """x^1.5 for x ≥ 0 (the Hertz exponent of :func:`contact_power`), correctly rounded for
    1e-200 ≤ x ≤ 1e200, without libm's ``pow``.

    √x is rounded once (r); x − r² is exact in one fused multiply-add (e), so
    x^1.5 = x √x = x r + x e / (2 r) + O(e²), and x e / (2 r) = e r / 2 (1 + e / r²): the
    fused x·r + e r / 2 rounds the exact value (to ~2^-100 relative) once. Checked against
    113-bit arithmetic on 2·10⁷ values over 1e-200 ≤ x ≤ 1e200 (correctly rounded in every
    case, where libm's ``pow(x, 1.5)`` was an ulp off in 0.08 % of them). Below 1e-200 the
    result is subnormal and the correction term underflows (within an ulp of the
    subnormal); above :data:`HERTZ_EXACT_MAX` x r (two roundings; x² would overflow in the
    correction: inf for x = inf). NaN gives NaN. Vectorises (no libm call)."""
    r = math.sqrt(x)
    e = fma(-r, r, x)
    return fma(x, r, 0.5 * e * r) if x <= HERTZ_EXACT_MAX else x * r


@njit(**JIT)
def contact_power(delta, m):
    """δ^m for the penetration δ ≥ 0 and the law's exponent m: :func:`hertz_power` for
    m = 1.5 (every law's Hertz exponent, and the one the materials give), libm's ``pow``
    for any other m. The one place the lanes and the loop kernels raise δ to m: the lane
    generator specialises a group of lanes whose exponents are all 1.5 to the first
    branch (no ``pow`` call in the vectorised stage)."""
    if m == 1.5:
        return hertz_power(delta)
    return delta**m


@njit(**JIT)
def normal_force_derivatives(delta, delta_rate, K, m, D):
    """F_n = K δ^m (1 + D δ̇) clipped at ≥ 0 (0 for δ ≤ 0) and its partial derivatives, in
    straight-line form (the lanes inline it).

    Args:
        delta: penetration δ, m.
        delta_rate: δ̇, m/s (positive while the journal goes in).
        K: stiffness, N/m^m.  m: exponent.  D: damping factor, s/m (:func:`damping_factor`).

    Returns:
        (F_n, ∂F_n/∂δ, ∂F_n/∂δ̇): N, N/m, N s/m. Where the force is zero (δ ≤ 0 or clipped)
        both derivatives are zero; at δ = 0 and at the clip they are the one-sided values
        from the zero side.
    """
    pp = max(delta, 0.0)
    pw = contact_power(pp, m)
    factor = max(1.0 + D * delta_rate, 0.0)
    fn = K * pw * factor
    delta_slope = K * m * (pw / pp if pp > 0.0 else 0.0) * factor
    rate_slope = K * pw * D if factor > 0.0 else 0.0
    return fn, delta_slope, rate_slope


@njit(**JIT)
def normal_force(delta, delta_rate, K, m, D):
    """F_n = K δ^m (1 + D δ̇) (N) for δ > 0, clipped at ≥ 0; 0 for δ ≤ 0
    (:func:`normal_force_derivatives`'s first value)."""
    fn, _delta_slope, _rate_slope = normal_force_derivatives(delta, delta_rate, K, m, D)
    return fn


@njit(**JIT)
def contact_law(delta, delta_rate, in_contact, onset_rate, K, m, law, e):
    """The law at one instant of a joint: F_n, ∂F_n/∂δ, ∂F_n/∂δ̇ (N, N/m, N s/m).

    D comes from the approach speed ``onset_rate`` δ̇⁻ of the contact in progress (located
    when it began; ≤ 0: none, undamped) when ``in_contact`` = 1 (in contact at the step's
    start), else from the current δ̇: the contact's first instants, where the onset is
    located only at the step's end. The loop kernels (mcchain.kernels.clearance) call it; the
    lanes inline it (mcchain.codegen.emitter).
    """
    rate = in_contact * onset_rate + (1.0 - in_contact) * delta_rate
    damping = damping_factor(law, e, rate)
    return normal_force_derivatives(delta, delta_rate, K, m, damping)


FRICTION_RAMP = 1.0 / (FRICTION_V1 - FRICTION_V0)
"""1/(v1 − v0), s/m: the slope of Ambrósio's c_d between v0 and v1."""


@njit(**JIT)
def friction_factor(tangential_speed, v0=FRICTION_V0, ramp=FRICTION_RAMP):
    """Ambrósio's dynamic correction c_d ∈ [0, 1] of the regularised Coulomb law.

    c_d = 0 for |v_t| ≤ v0, (|v_t| − v0)/(v1 − v0) for v0 < |v_t| < v1, 1 for |v_t| ≥ v1
    (J. Ambrósio, "Impact of rigid and flexible multibody systems: deformation description
    and contact models", in *Virtual Nonlinear Multibody Systems*, Kluwer 2003; used for
    clearance joints by Flores et al. 2008). ``v0`` (m/s) and ``ramp`` = 1/(v1 − v0) (s/m)
    default to ``FRICTION_V0`` and ``FRICTION_RAMP``.
    """
    return min(max((abs(tangential_speed) - v0) * ramp, 0.0), 1.0)


@njit(**JIT)
def friction_force(normal, tangential_speed, mu, v0=FRICTION_V0, ramp=FRICTION_RAMP):
    """Tangential friction force F_t = −μ c_d(v_t) F_n sign(v_t) (N) on the body whose contact
    point slides at ``tangential_speed`` v_t (m/s) relative to the other; ``normal`` F_n ≥ 0
    (``v0``, ``ramp``: :func:`friction_factor`)."""
    cd = friction_factor(tangential_speed, v0, ramp)
    return -mu * cd * normal * (1.0 if tangential_speed > 0.0 else -1.0)


@njit(**JIT)
def contact_slip(ex, ey, ddx, ddy, radius, clearance, omega_a, omega_b):
    """Slip v_t (m/s) of the journal's surface point on the bearing's along t = (−n_y, n_x):
    v_t = t·ḋ + R ω_b − (R + c) ω_a, with n = (``ex``, ``ey``), ḋ = (``ddx``, ``ddy``), R the
    journal radius (0: at the centres), c the clearance, ω_a, ω_b the bearing's and the
    journal's angular speeds (rad/s)."""
    return -ey * ddx + ex * ddy + radius * omega_b - (radius + clearance) * omega_a


@njit(**JIT)
def elastic_energy(delta, K, m):
    """K δ^(m+1) / (m+1) (J): the elastic energy the law stores at penetration δ (0 for
    δ ≤ 0)."""
    return K * max(delta, 0.0) ** (m + 1.0) / (m + 1.0)


@njit(**JIT)
def _hermite(theta, d0, r0, d1, r1, h):
    """The cubic Hermite interpolant of δ over a step of length h (δ0, δ̇0 at its start, δ1,
    δ̇1 at its end) and its time derivative, at the fraction ``theta`` of the step."""
    t2 = theta * theta
    t3 = t2 * theta
    value = (
        (2.0 * t3 - 3.0 * t2 + 1.0) * d0
        + (t3 - 2.0 * t2 + theta) * h * r0
        + (3.0 * t2 - 2.0 * t3) * d1
        + (t3 - t2) * h * r1
    )
    slope = (
        (6.0 * t2 - 6.0 * theta) * d0
        + (3.0 * t2 - 4.0 * theta + 1.0) * h * r0
        + (6.0 * theta - 6.0 * t2) * d1
        + (3.0 * t2 - 2.0 * theta) * h * r1
    ) / h
    return value, slope


@njit(**JIT)
def contact_crossing(d0, r0, d1, r1, h):
    """Where in a step the penetration crosses 0, and its rate there.

    δ is interpolated by the cubic Hermite polynomial through (δ0, δ̇0) at the step's start
    and (δ1, δ̇1) at its end (fourth-order accurate in h, like the integrators' states);
    the root is bracketed by the signs of δ0 and δ1 (they must differ) and found by the
    Illinois variant of regula falsi to 1e-14 of the step.

    Args:
        d0, r0: δ (m) and δ̇ (m/s) at the start of the step.
        d1, r1: the same at its end.
        h: the step, s (> 0).

    Returns:
        (θ, δ̇*): the fraction θ ∈ [0, 1] of the step at the crossing and δ̇ there (m/s).
    """
    lo, hi = 0.0, 1.0
    f_lo, f_hi = d0, d1
    theta = 0.5
    side = 0
    for _ in range(100):
        if f_hi == f_lo:
            theta = 0.5 * (lo + hi)
        else:
            theta = lo - f_lo * (hi - lo) / (f_hi - f_lo)
            if not (lo < theta < hi):
                theta = 0.5 * (lo + hi)
        value, _slope = _hermite(theta, d0, r0, d1, r1, h)
        if (value > 0.0) == (f_hi > 0.0):
            hi, f_hi = theta, value
            if side == 1:
                f_lo *= 0.5
            side = 1
        else:
            lo, f_lo = theta, value
            if side == -1:
                f_hi *= 0.5
            side = -1
        if hi - lo <= 1e-14 or value == 0.0:
            break
    _value, slope = _hermite(theta, d0, r0, d1, r1, h)
    return theta, slope


@njit(**JIT)
def hermite_peak(d0, r0, d1, r1, h):
    """The largest penetration in a step: the larger of δ0 and δ1 or, where δ̇ turns from
    + to − in the step (δ̇0 > 0 ≥ δ̇1), the maximum of the cubic Hermite interpolant of δ
    (:func:`contact_crossing`'s, through δ0, δ̇0 at the step's start and δ1, δ̇1 at its end).

    A contact's peak lies inside a step; δ at the step ends misses it by up to δ̈h²/8, the
    interpolant by O(h⁴), the order of the states' own error. With θ the fraction of the
    step, the interpolant's derivative is the quadratic a θ² + b θ + c,
    a = 3h(δ̇0 + δ̇1) − 6(δ1 − δ0), b = 6(δ1 − δ0) − h(4δ̇0 + 2δ̇1), c = h δ̇0 (> 0 at θ = 0,
    ≤ 0 at θ = 1: one maximum inside, at the root of this quadratic in closed form).
    Elsewhere the answer is an end, and costs two comparisons: the lanes call this at every
    step in contact. (An interpolant that rises, falls and rises again inside one step
    would be a step longer than the motion it resolves; its inner maximum is not sought.)

    Args:
        d0, r0: δ (m) and δ̇ (m/s) at the start of the step (NaN: no step behind, the
            answer is δ1).
        d1, r1: the same at its end.
        h: the step, s (≥ 0).

    Returns:
        The largest δ on the step, m.
    """
    best = d1
    if d0 > best:
        best = d0
    if not (r0 > 0.0 and r1 <= 0.0):
        return best
    rise = d1 - d0
    slope0 = h * r0
    slope1 = h * r1
    qa = 3.0 * (slope0 + slope1) - 6.0 * rise
    qb = 6.0 * rise - 4.0 * slope0 - 2.0 * slope1
    qc = slope0
    size = max(abs(qa), abs(qb), qc)
    qa = qa / size  # a largest coefficient of 1: tiny slopes' discriminant does not underflow
    qb = qb / size
    qc = qc / size
    # the root where the derivative turns from + (θ = 0) to − (θ = 1): the smaller positive
    # one, in the form without cancellation (qb ≥ 0 needs qa < 0 here)
    root = math.sqrt(max(qb * qb - 4.0 * qa * qc, 0.0))
    theta = (qb + root) / (-2.0 * qa) if qb >= 0.0 else 2.0 * qc / (root - qb)
    if theta > 0.0 and theta < 1.0:
        value, _slope = _hermite(theta, d0, r0, d1, r1, h)
        best = max(best, value)
    return best


@njit(**JIT)
def contact_bookkeeping(vi, ins, nim, tff, tse, pkd, d0, r0, d1, r1, h, t, seat):
    """What a step tells of a joint under the law: the step of length ``h`` ended at ``t``
    (s) with δ1, δ̇1 (m, m/s) and began with δ0, δ̇0; ``seat`` is its seat tolerance (m).

    Onset (δ crosses 0 upwards: located on the step's cubic Hermite interpolant,
    :func:`contact_crossing`; its rate is the approach speed δ̇⁻ and it counts an impact),
    separation (the first one's time kept), free flight, peak penetration (over a step in
    contact, δ0 > 0 or δ1 > 0: the largest value of its interpolant, :func:`hermite_peak`).
    A seated journal (``vi`` < 0) is in contact, undamped and without an onset, until it is
    off the wall by more than the tolerance; one seated by the switch of model auto
    (SEATED_AT_SWITCH) flies free from the switch while within the tolerance, and becomes an
    ordinary seated contact (SEATED) where δ rises above it (it presses back).

    Args:
        vi: the approach speed column δ̇⁻ (m/s; SEATED, SEATED_AT_SWITCH while seated).
        ins: 1.0 if in contact at the step's start. nim: impacts so far. tff: free flight so
            far (s). tse: the first separation's time (s; NaN before). pkd: peak δ so far (m).

    Returns:
        (vi, ins, nim, tff, tse, pkd) after the step. The loop kernels
        (mcchain.kernels.clearance.contact_step) and the lanes (their module copies this
        function) both book with it.
    """
    if vi < 0.0:  # seated
        if d1 < -seat:
            theta = 0.0
            if d0 > 0.0 and vi == SEATED:
                theta, rate = contact_crossing(d0, r0, d1, r1, h)
            tff += (1.0 - theta) * h
            if tse != tse:
                tse = t - h + theta * h
            vi = 0.0
            ins = 0.0
        else:
            ins = 1.0
            if vi == SEATED_AT_SWITCH:  # free flight from the switch ...
                if d1 <= seat:
                    tff += h
                else:  # ... until it presses back
                    theta, rate = contact_crossing(d0 - seat, r0, d1 - seat, r1, h)
                    tff += theta * h
                    vi = SEATED
    else:
        if d0 <= 0.0 and d1 > 0.0:
            theta, rate = contact_crossing(d0, r0, d1, r1, h)
            vi = rate
            nim += 1.0
            tff += theta * h
        elif d0 > 0.0 and d1 <= 0.0:
            theta, rate = contact_crossing(d0, r0, d1, r1, h)
            tff += (1.0 - theta) * h
            if tse != tse:
                tse = t - h + theta * h
        elif d0 <= 0.0:
            tff += h
        ins = 1.0 if d1 > 0.0 else 0.0
    if d0 > 0.0 or d1 > 0.0:  # in contact: δ's peak inside the step, on its interpolant
        pkd = max(pkd, hermite_peak(d0, r0, d1, r1, h))
    return vi, ins, nim, tff, tse, pkd


@njit(**JIT)
def contact_mode(law, delta, approach):
    """The ``contact_mode`` code of a joint: 0 on the link (``law`` = 0), else 1 in contact
    or 2 free. ``approach`` is the contact's δ̇⁻ column: a seated journal (< 0) is in contact
    whichever the sign of its δ (m), except one seated by the switch of model auto
    (SEATED_AT_SWITCH), which is free: its free flight counts from the switch."""
    free = (delta <= 0.0 and approach >= 0.0) or approach == SEATED_AT_SWITCH
    return law * (2.0 if free else 1.0)


@njit(**JIT)
def quasi_static_slack(rate, delta, delta_rate):
    """ρ δ − |δ̇|, m/s: > 0 where a journal pressed in by δ (m) moves slowly enough for a
    re-seat, ρ = RESEAT_RATE ω_c (1/s; mcchain.contact)."""
    return rate * delta - abs(delta_rate)


@njit(**JIT)
def reseat_slack(model, delta, delta_rate, normal, pulsation, kinetic, exponent, paid):
    """> 0 exactly where a joint under the law may count this instant towards its re-seat
    dwell (mcchain.contact): of model auto (``model`` = AUTO), pressed (δ > 0, F_n =
    ``normal`` > 0) quasi-statically (:func:`quasi_static_slack` with ω_c = ``pulsation``,
    1/s) and, with ``paid`` = 1 (a scene without drivers), with the kinetic energy T
    (``kinetic``, J) to pay for the re-seat's position step: it lifts the journal by δ
    against the load pressing it, m/(m+1) F_n δ beyond the elastic energy it drops
    (``exponent`` m), taken from T so that no energy is added.

    Returns the least of these margins, each in its own unit (m, N, m/s, J): only the sign
    is meant; it changes where the criterion starts or stops holding, which is where the
    ``radau`` path locates a dwell's start. −1 off model auto or on a NaN.
    """
    if model != AUTO or delta != delta or delta_rate != delta_rate or normal != normal or \
            pulsation != pulsation or kinetic != kinetic:  # fmt: skip
        return -1.0
    slow = quasi_static_slack(RESEAT_RATE * pulsation, delta, delta_rate)
    pressed = min(delta, normal, slow)
    if paid == 1.0:
        return min(pressed, kinetic - exponent / (exponent + 1.0) * normal * delta)
    return pressed


@njit(**JIT)
def _dwell_slack(theta, d0, r0, d1, r1, h, rate0, rate1):
    """:func:`quasi_static_slack` at the fraction ``theta`` of the step of
    :func:`dwell_start` (its arguments), on the step's Hermite interpolant, m/s."""
    value, slope = _hermite(theta, d0, r0, d1, r1, h)
    return quasi_static_slack(rate0 + theta * (rate1 - rate0), value, slope)


@njit(**JIT)
def dwell_start(d0, r0, d1, r1, h, rate0, rate1):
    """Where in a step the re-seat criterion's rate term ρ δ − |δ̇| rises through 0
    (:func:`quasi_static_slack`, ρ = RESEAT_RATE ω_c in 1/s; ``rate0`` at the step's
    start, ``rate1`` at its end, linear between), from < 0 at the start to ≥ 0 at the end.

    δ and δ̇ are the cubic Hermite interpolant of :func:`contact_crossing` and its
    derivative. A journal pressed in slowly meets the criterion at a shallow angle (δ̇ and
    ρ δ both vary slowly), and ω_c grows with δ^((m−1)/2) by ~1e-3 per step there: a straight
    line between the step's ends, or ρ held at one end, would place the crossing a tenth of
    the step off; bisection on the interpolant finds it to 1e-14 of the step.

    Two bisection steps a round: the midpoint and both quarter points are evaluated side by
    side (three independent chains of evaluations instead of one long one), then the
    midpoint's half is halved at its quarter point: the same points, the same bracket and
    the same result as one step at a time.

    Returns:
        θ ∈ [0, 1], the fraction of the step where the term first holds ≥ 0 (the bracket's
        upper end).
    """
    lo, hi = 0.0, 1.0
    for _ in range(30):  # at most 60 steps
        mid = 0.5 * (lo + hi)
        left = 0.5 * (lo + mid)
        right = 0.5 * (mid + hi)
        holds_mid = _dwell_slack(mid, d0, r0, d1, r1, h, rate0, rate1) >= 0.0
        holds_left = _dwell_slack(left, d0, r0, d1, r1, h, rate0, rate1) >= 0.0
        holds_right = _dwell_slack(right, d0, r0, d1, r1, h, rate0, rate1) >= 0.0
        lo = lo if holds_mid else mid
        hi = mid if holds_mid else hi
        if hi - lo <= 1e-14:
            break
        quarter = left if holds_mid else right
        holds_quarter = holds_left if holds_mid else holds_right
        lo = lo if holds_quarter else quarter
        hi = quarter if holds_quarter else hi
        if hi - lo <= 1e-14:
            break
    return hi
