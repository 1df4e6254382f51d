"""The clearance joint's contact law: numba kernels against the independent scipy reference,
derivatives against central differences, measured restitution per law, energy through an
elastic impact, and the internal-cylinder stiffness.

Reference: :mod:`mcchain.testing.contact` (written again from the law's definition, no code
shared with :mod:`mcchain.kernels.contact`).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from mcchain.contact import LAW_CODES, LAW_NAMES, internal_cylinder_stiffness
from mcchain.kernels import contact as kc
from mcchain.testing import contact as ref

LAW_RTOL = 1e-14
"""Kernel vs reference: the same formula in a different association, a few ulps apart."""
FD_RTOL = 1e-6
"""Central differences with h = 1e-5 δ: truncation O(h²) ≈ 1e-10 relative, plus round-off."""
ENERGY_RTOL = 1e-8
"""Elastic impacts: the reference runs at rtol 1e-12; energy drifts ~1e-9 over a dozen."""
RESTITUTION_ELASTIC_TOL = 1e-9
"""Hertz (D = 0) through one impact: the reference measures 1 to ~1e-11."""

finite = {"allow_nan": False, "allow_infinity": False}
laws = st.sampled_from(sorted(LAW_CODES))
restitutions = st.floats(0.05, 1.0, **finite)
speeds = st.floats(1e-4, 10.0, **finite)
penetrations = st.floats(-1e-3, 1e-3, **finite)
rates = st.floats(-10.0, 10.0, **finite)
stiffnesses = st.floats(1e5, 1e12, **finite)
exponents = st.floats(1.0, 2.0, **finite)


# ---------------------------------------------------------------------------------------------
# (a) kernels against the reference law


def test_law_codes__names_round_trip():
    assert LAW_NAMES == {code: name for name, code in LAW_CODES.items()}
    assert set(LAW_CODES) == set(ref.LAWS)
    assert (kc.HERTZ, kc.LANKARANI_NIKRAVESH, kc.FLORES, kc.HUNT_CROSSLEY) == tuple(
        LAW_CODES[name] for name in ("hertz", "lankarani-nikravesh", "flores", "hunt-crossley")
    )


@settings(max_examples=300, deadline=None)
@given(laws, restitutions, st.one_of(speeds, st.floats(-1.0, 0.0, **finite)))
def test_damping_factor__matches_reference(name, e, approach):
    got = kc.damping_factor(LAW_CODES[name], e, approach)
    want = float(ref.hysteresis(name, e, approach))
    assert got == pytest.approx(want, rel=LAW_RTOL, abs=0.0)


def test_damping_factor__no_onset_is_undamped():
    for code in LAW_CODES.values():
        for approach in (0.0, -1.0, math.nan):
            assert kc.damping_factor(code, 0.5, approach) == 0.0
    assert kc.damping_factor(kc.HERTZ, 0.5, 1.0) == 0.0
    assert kc.damping_factor(99, 0.5, 1.0) == 0.0


@settings(max_examples=400, deadline=None)
@given(laws, restitutions, speeds, penetrations, rates, stiffnesses, exponents)
def test_normal_force__matches_reference(name, e, approach, delta, rate, K, m):
    D = kc.damping_factor(LAW_CODES[name], e, approach)
    got = kc.normal_force(delta, rate, K, m, D)
    want = float(ref.force(delta, rate, K, m, D))
    assert got >= 0.0
    # scale of the terms summed: near the clip (1 + D δ̇ ≈ 0) the force itself is round-off
    scale = K * max(delta, 0.0) ** m * (1.0 + abs(D * rate))
    assert abs(got - want) <= LAW_RTOL * scale
    f, _, _ = kc.normal_force_derivatives(delta, rate, K, m, D)
    assert f == got


def test_normal_force__zero_outside_contact_and_when_clipped():
    assert kc.normal_force(0.0, 1.0, 1e10, 1.5, 0.0) == 0.0
    assert kc.normal_force(-1e-6, 1.0, 1e10, 1.5, 0.0) == 0.0
    # pulling out fast: 1 + D δ̇ < 0 is clipped
    assert kc.normal_force(1e-6, -2.0, 1e10, 1.5, 1.0) == 0.0
    assert kc.normal_force_derivatives(1e-6, -2.0, 1e10, 1.5, 1.0) == (0.0, 0.0, 0.0)
    assert kc.normal_force(1e-6, 0.0, 1e10, 1.5, 1.0) == pytest.approx(1e10 * 1e-9, rel=1e-15)


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-1e-2, 1e-2, **finite),
    st.floats(0.0, 10.0, **finite),
    st.floats(0.0, 1.0, **finite),
    st.floats(0.0, 1e-3, **finite),
    st.floats(1e-4, 1e-2, **finite),
)
def test_friction__matches_reference(slip, normal, mu, v0, span):
    v1 = v0 + span
    ramp = 1.0 / (v1 - v0)
    got = kc.friction_force(normal, slip, mu, v0, ramp)
    want = float(ref.coulomb(normal, slip, mu, v0, v1))
    assert got == pytest.approx(want, rel=LAW_RTOL, abs=1e-300)
    cd = kc.friction_factor(slip, v0, ramp)
    assert 0.0 <= cd <= 1.0
    assert abs(got) <= mu * normal
    if slip != 0.0:
        assert got * slip <= 0.0  # friction opposes the slip


def test_friction__defaults_and_ramp():
    assert kc.friction_factor(0.0) == 0.0
    assert kc.friction_factor(kc.FRICTION_V0) == 0.0
    assert kc.friction_factor(-kc.FRICTION_V1) == 1.0
    mid = 0.5 * (kc.FRICTION_V0 + kc.FRICTION_V1)
    assert kc.friction_factor(mid) == pytest.approx(0.5, rel=1e-14)
    assert kc.friction_force(2.0, 1.0, 0.3) == pytest.approx(-0.6, rel=1e-15)
    assert kc.friction_force(2.0, -1.0, 0.3) == pytest.approx(0.6, rel=1e-15)


# ---------------------------------------------------------------------------------------------
# (b) derivatives against central differences


@settings(max_examples=300, deadline=None)
@given(
    laws,
    restitutions,
    speeds,
    st.floats(1e-6, 1e-3, **finite),
    rates,
    stiffnesses,
    exponents,
)
def test_normal_force_derivatives__central_differences(name, e, approach, delta, rate, K, m):
    D = kc.damping_factor(LAW_CODES[name], e, approach)
    s = 1.0 + D * rate
    hv = 1e-6 * (1.0 + abs(rate))
    if abs(s) < 0.1 or abs(D) * hv > 0.05:
        assume(False)  # within a difference step of the clip: one-sided there by definition
    f, dd, dr = kc.normal_force_derivatives(delta, rate, K, m, D)
    h = 1e-5 * delta
    fd_delta = (
        kc.normal_force(delta + h, rate, K, m, D) - kc.normal_force(delta - h, rate, K, m, D)
    ) / (2 * h)
    fd_rate = (
        kc.normal_force(delta, rate + hv, K, m, D) - kc.normal_force(delta, rate - hv, K, m, D)
    ) / (2 * hv)
    eps = np.finfo(float).eps
    assert abs(dd - fd_delta) <= FD_RTOL * abs(dd) + 10 * eps * f / h
    assert abs(dr - fd_rate) <= FD_RTOL * abs(dr) + 10 * eps * f / hv
    if s < 0:
        assert (f, dd, dr) == (0.0, 0.0, 0.0)


# ---------------------------------------------------------------------------------------------
# (c) restitution per law, (d) energy through elastic impacts


@pytest.fixture(scope="module")
def restitution():
    return ref.restitution_table()


def test_radial_impact__onset_speed_is_the_closed_form():
    law = ref.Law("flores", 1e10, 1.5, 0.5)
    history = ref.radial_impact(law, speed=0.05, gap=1e-3, push=9.81, mass=2.0)
    want = ref.radial_approach_speed(0.05, 1e-3, 9.81, 2.0)
    assert history.impacts[0].approach_speed == pytest.approx(want, rel=1e-10)
    assert history.impacts[0].time == pytest.approx(
        (want - 0.05) / (9.81 / 2.0), rel=1e-10
    )  # uniform acceleration until the onset


def test_restitution__hertz_is_elastic(restitution):
    np.testing.assert_allclose(restitution["hertz"], 1.0, rtol=0, atol=RESTITUTION_ELASTIC_TOL)


def test_restitution__lankarani_nikravesh_only_near_one(restitution):
    """L-N's χ = 3(1 − e²)/4 is exact to first order in (1 − e) (the 1990 derivation assumes e
    near 1): it under-dissipates everywhere, error O((1 − e)²), and badly at low e."""
    e = np.array(ref.RESTITUTIONS)
    got = restitution["lankarani-nikravesh"]
    assert np.all(got > e)
    near = e >= 0.9
    assert np.all(got[near] - e[near] <= 2.0 * (1 - e[near]) ** 2)
    assert got[e == 0.99][0] / 0.99 - 1 < 2e-4
    assert got[e == 0.9][0] / 0.9 - 1 < 0.02
    assert got[e == 0.3][0] > 2 * 0.3  # more than twice the nominal value


def test_restitution__hunt_crossley_like_lankarani_nikravesh(restitution):
    """H-C's χ = 3(1 − e)/2 has the same first order as L-N and dissipates more: between L-N
    and e, still far above e at low e."""
    e = np.array(ref.RESTITUTIONS)
    got = restitution["hunt-crossley"]
    assert np.all(got > e)
    assert np.all(got < restitution["lankarani-nikravesh"])
    near = e >= 0.9
    assert np.all(got[near] - e[near] <= 1.2 * (1 - e[near]) ** 2)
    assert got[e == 0.3][0] > 1.8 * 0.3


def test_restitution__flores_close_over_the_range(restitution):
    """Flores et al. (2011) built χ = 8(1 − e)/(5 e) for the whole range: it over-dissipates
    slightly (χ ≈ 1.6 (1 − e) against the exact first order 1.5 (1 − e)), yet is the closest
    of the three older damped laws for every e ≤ 0.9. Bands: measured values with a margin."""
    e = np.array(ref.RESTITUTIONS)
    got = restitution["flores"]
    assert np.all(got < e)
    relative = 1 - got / e
    bands = {0.3: 0.16, 0.5: 0.065, 0.7: 0.027, 0.9: 0.008, 0.99: 0.001}
    for k, ek in enumerate(ref.RESTITUTIONS):
        assert relative[k] <= bands[ek], (ek, relative[k])
    for k in np.flatnonzero(e <= 0.9):
        older = ("lankarani-nikravesh", "flores", "hunt-crossley")
        errors = {name: abs(restitution[name][k] - e[k]) for name in older}
        assert min(errors, key=errors.__getitem__) == "flores", (e[k], errors)


def test_restitution__hu_guo_closest_from_0_7(restitution):
    """Hu & Guo (2015), χ = 3(1 − e)/(2e): the exact first order 1.5 (1 − e) near e = 1 and
    more dissipation below; within 0.5 % for e ≥ 0.7, the closest of all the laws there, and
    under-restituting by < 10 % at e = 0.3. Bands: measured values with a margin."""
    e = np.array(ref.RESTITUTIONS)
    got = restitution["hu-guo"]
    assert np.all(got <= e)
    bands = {0.3: 0.10, 0.5: 0.026, 0.7: 0.0045, 0.9: 2e-4, 0.99: 1e-5}
    for k, ek in enumerate(ref.RESTITUTIONS):
        assert 1 - got[k] / ek <= bands[ek], (ek, got[k])
        if ek >= 0.7:
            errors = {n: abs(restitution[n][k] - ek) for n in ref.LAWS if n != "hertz"}
            assert min(errors, key=errors.__getitem__) == "hu-guo", (ek, errors)


def test_restitution__gonthier_within_5_percent_and_closest_at_low_e(restitution):
    """Gonthier et al. (2004), χ = (1 − e²)/e ≈ 2 (1 − e) near e = 1: it over-dissipates
    there (−0.33 % at 0.99, −4.4 % at 0.7) but stays within 5 % over the whole range and is
    the closest of the laws at e = 0.3 (+1.4 %). Bands: measured values with a margin."""
    e = np.array(ref.RESTITUTIONS)
    got = restitution["gonthier"]
    assert np.all(np.abs(got / e - 1) <= 0.045)
    assert got[-1] < e[-1]  # over-dissipates near e = 1
    errors = {n: abs(restitution[n][0] - e[0]) for n in ref.LAWS if n != "hertz"}
    assert min(errors, key=errors.__getitem__) == "gonthier", errors


def test_journal_in_bearing__hertz_conserves_energy():
    law = ref.Law("hertz", 1e10, 1.5, 1.0)
    mass, inertia = 1.0, 1e-4
    history = ref.journal_in_bearing(
        law,
        clearance=2e-4,
        mass=mass,
        inertia=inertia,
        radius=0.01,
        velocity=(0.05, 0.0),
        t_end=0.04,
        times=np.linspace(0.0, 0.04, 801),
    )
    assert len(history.impacts) >= 4
    energy = ref.journal_energy(history, law, mass, inertia)
    kinetic0 = 0.5 * mass * 0.05**2
    assert np.max(np.abs(energy - energy[0])) <= ENERGY_RTOL * kinetic0
    # in contact the samples carry the law's force, never a pull
    assert np.all(history.normal_force >= 0.0)
    assert np.all(history.normal_force[history.delta <= 0] == 0.0)


def test_journal_in_bearing__damped_impacts_lose_energy():
    law = ref.Law("flores", 1e10, 1.5, 0.7, friction=0.1)
    history = ref.journal_in_bearing(
        law,
        clearance=2e-4,
        mass=1.0,
        inertia=1e-4,
        radius=0.01,
        velocity=(0.05, 0.0),
        spin=10.0,
        t_end=0.02,
    )
    energy = ref.journal_energy(history, law, 1.0, 1e-4)
    assert len(history.impacts) >= 2
    assert energy[-1] < energy[0]
    for impact in history.impacts:
        if np.isfinite(impact.separation_time):
            assert impact.separation_speed < 0 < impact.approach_speed


# ---------------------------------------------------------------------------------------------
# (e) stiffness of internal cylindrical contact


def test_internal_cylinder_stiffness__steel_by_hand():
    # steel journal in a steel bearing: σ = (1 − 0.3²)/2.07e11 each; R_i R_j / c = 0.01·0.0101/1e-4
    sigma = 0.91 / 2.07e11
    by_hand = 4.0 / (3.0 * 2 * sigma) * math.sqrt(1.01)
    K = internal_cylinder_stiffness(0.01, 1e-4, 2.07e11, 0.3)
    assert K == pytest.approx(by_hand, rel=1e-14)
    assert K == pytest.approx(1.5240e11, rel=1e-4)
    assert internal_cylinder_stiffness(0.01, 1e-4, 2.07e11, 0.3, 2.07e11, 0.3) == K


@pytest.mark.parametrize(
    "args",
    [
        (0.0, 1e-4, 2e11, 0.3),
        (0.01, -1e-4, 2e11, 0.3),
        (0.01, 1e-4, 0.0, 0.3),
        (0.01, 1e-4, 2e11, 0.6),
    ],
)
def test_internal_cylinder_stiffness__rejects_bad_input(args):
    with pytest.raises(ValueError, match="must"):
        internal_cylinder_stiffness(*args)


def test_contact_mode__codes_link_contact_free_and_the_two_seated_kinds():
    """0 on the link; a seated journal (a start on the wall) is in contact whichever the
    sign of its δ; one seated by the switch of auto is free (its free flight counts from
    the switch); otherwise contact exactly where δ > 0."""
    from mcchain.contact import SEATED, SEATED_AT_SWITCH
    from mcchain.kernels.contact import contact_mode

    assert contact_mode(0.0, 1e-6, 0.3) == 0.0
    assert contact_mode(1.0, -1e-14, SEATED) == 1.0
    assert contact_mode(1.0, 1e-14, SEATED_AT_SWITCH) == 2.0
    assert contact_mode(1.0, -1e-14, SEATED_AT_SWITCH) == 2.0
    assert contact_mode(1.0, 1e-9, 0.3) == 1.0
    assert contact_mode(1.0, 0.0, 0.3) == 2.0


HERMITE_ROUNDING = 16.0 * np.finfo(float).eps
"""hermite_peak on an exact cubic: a few roundings of its four terms (relative to their sum
of magnitudes); the root's own rounding moves the value only quadratically."""


def hermite_rounding(scale: float) -> float:
    """:data:`HERMITE_ROUNDING` of ``scale``, and never less than a few steps of the smallest
    subnormal: below 2⁻¹⁰²² a rounding is that step, not a relative size (hypothesis found
    δ₀ = δ₁ = 2.2e-311 m, whose grid's interpolant rounded one step, 5e-324, above the peak)."""
    return HERMITE_ROUNDING * scale + 8.0 * np.finfo(float).smallest_subnormal


@settings(max_examples=300, deadline=None)
@given(
    st.floats(1e-8, 1e-3),  # h, s
    st.floats(0.02, 0.98),  # where in the step the maximum is
    st.floats(1e-7, 1e-3),  # the maximum P, m
    st.floats(1e-6, 1.0),  # how far the step's ends are below it, relative
    st.floats(-0.5, 0.5),  # the cubic term, relative
)
def test_hermite_peak__the_maximum_of_a_cubic(h, where, top, dip, skew):
    """δ(t) = P − k (t − t*)² + g (t − t*)³ with |g| h ≤ k/2: its only maximum on [0, h] is
    P at t* (δ − P = (t − t*)² (g (t − t*) − k) < 0 elsewhere), and the cubic Hermite
    interpolant of a cubic is the cubic itself."""
    peak_time = where * h
    k = top * dip / (h * h)
    g = skew * k / h

    def delta(t):
        return top - k * (t - peak_time) ** 2 + g * (t - peak_time) ** 3

    def rate(t):
        return -2.0 * k * (t - peak_time) + 3.0 * g * (t - peak_time) ** 2

    d0, r0, d1, r1 = delta(0.0), rate(0.0), delta(h), rate(h)
    scale = abs(d0) + abs(d1) + h * (abs(r0) + abs(r1))
    assert abs(kc.hermite_peak(d0, r0, d1, r1, h) - top) <= hermite_rounding(scale)


@settings(max_examples=300, deadline=None)
@given(
    penetrations,
    st.floats(0.0, 10.0, exclude_min=True),
    penetrations,
    st.floats(-10.0, 0.0),
    st.floats(1e-7, 1e-3),
)
@example(2.225073858507e-311, 5e-324, 2.225073858507e-311, 0.0, 1e-3)  # subnormal: one step
def test_hermite_peak__the_largest_value_of_the_interpolant(d0, r0, d1, r1, h):
    """A step where δ̇ turns from + to −: never below the ends or the interpolant on a fine
    grid, never above the grid by more than the grid's resolution (|δ''| ≤ 6 Σ|terms| per
    unit θ², spacing 1e-4)."""
    grid = np.linspace(0.0, 1.0, 10001)
    values = kc._hermite.py_func(grid, d0, r0, d1, r1, h)[0]
    scale = abs(d0) + abs(d1) + h * (abs(r0) + abs(r1))
    peak = kc.hermite_peak(d0, r0, d1, r1, h)
    assert peak >= max(d0, d1)
    assert peak >= max(values) - hermite_rounding(scale)
    assert peak <= max(values) + 6.0 * scale * 1e-8 / 8.0 + hermite_rounding(scale)


@settings(max_examples=300, deadline=None)
@given(penetrations, rates, penetrations, rates, st.floats(1e-7, 1e-3))
def test_hermite_peak__an_end_where_the_rate_does_not_turn_down(d0, r0, d1, r1, h):
    assume(not (r0 > 0.0 and r1 <= 0.0))
    assert kc.hermite_peak(d0, r0, d1, r1, h) == max(d0, d1)


def test_hermite_peak__monotone_steps_and_no_step_behind():
    assert kc.hermite_peak(0.0, 1.0, 1.0, 1.0, 1.0) == 1.0  # δ = θ: the end
    assert kc.hermite_peak(1.0, -1.0, 0.0, -1.0, 1.0) == 1.0  # δ = 1 − θ: the start
    assert kc.hermite_peak(0.0, 1.0, 0.0, -1.0, 1.0) == 0.25  # δ = θ − θ²
    assert kc.hermite_peak(math.nan, math.nan, 2e-6, 0.1, 1e-6) == 2e-6  # the first step


def one_step_bisection(d0, r0, d1, r1, h, rate0, rate1):
    """:func:`mcchain.kernels.contact.dwell_start` as it was written first, one bisection
    step at a time: the reference its two steps a round must equal bit for bit."""
    lo, hi = 0.0, 1.0
    for _ in range(60):
        theta = 0.5 * (lo + hi)
        value, slope = kc._hermite.py_func(theta, d0, r0, d1, r1, h)
        if kc.quasi_static_slack.py_func(rate0 + theta * (rate1 - rate0), value, slope) >= 0.0:
            hi = theta
        else:
            lo = theta
        if hi - lo <= 1e-14:
            break
    return hi


@settings(max_examples=400, deadline=None)
@given(
    st.floats(0.0, 1e-4),  # δ0, m
    rates,  # δ̇0, m/s
    st.floats(0.0, 1e-4),  # δ1, m
    rates,
    st.floats(1e-8, 1e-4),  # h, s
    st.floats(0.0, 1e6),  # ρ at the start, 1/s
    st.floats(0.0, 1e6),  # ρ at the end
)
@example(1e-6, -0.05, 1e-6, 0.05, 1e-5, 5e4, 5e4)  # |δ̇| dips and rises: two crossings
@example(1e-6, 0.0, 1e-6, 0.0, 1e-5, 1e4, 1e4)  # holds everywhere: hi falls to 2^-47
@example(1e-6, math.nan, 1e-6, 0.0, 1e-5, 1e4, 1e4)  # NaN: never holds, the step's end
def test_dwell_start__two_steps_a_round_equal_one_at_a_time(d0, r0, d1, r1, h, rate0, rate1):
    expected = one_step_bisection(d0, r0, d1, r1, h, rate0, rate1)
    assert kc.dwell_start(d0, r0, d1, r1, h, rate0, rate1) == expected
    assert kc.dwell_start.py_func(d0, r0, d1, r1, h, rate0, rate1) == expected


def test_contact_bookkeeping__onset_separation_and_the_seated_kinds_on_linear_steps():
    """On a linear δ(t) the Hermite crossing is exact: an onset half-way books half the
    step as free flight, one impact at δ̇⁻; a separation half-way books the other half and
    the first separation's time; a journal seated by the switch of auto flies free while
    within the tolerance and stops where it presses back."""
    from mcchain.contact import SEATED, SEATED_AT_SWITCH
    from mcchain.kernels.contact import contact_bookkeeping

    nan = math.nan
    # onset at t = 1.5 of a step [1, 2]: (vi, ins, nim, tff, tse, pkd)
    books = contact_bookkeeping(
        0.0, 0.0, 0.0, 0.25, nan, 0.0, -1e-6, 2e-6, 1e-6, 2e-6, 1.0, 2.0, 0.0
    )
    assert books[:4] == pytest.approx((2e-6, 1.0, 1.0, 0.75), rel=1e-12, abs=1e-12)
    assert books[4] != books[4] and books[5] == 1e-6
    # separation at t = 1.5: the other half is free flight, tse = 1.5
    books = contact_bookkeeping(
        2e-6, 1.0, 1.0, 0.0, nan, 1e-6, 1e-6, -2e-6, -1e-6, -2e-6, 1.0, 2.0, 0.0
    )
    assert books == pytest.approx((2e-6, 0.0, 1.0, 0.5, 1.5, 1e-6), rel=1e-12, abs=1e-12)
    # seated by the switch, within the tolerance: a whole step of free flight, still seated
    books = contact_bookkeeping(
        SEATED_AT_SWITCH, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1e-16, 5e-14, 1e-16, 1.0, 2.0, 1e-13
    )
    assert books == (SEATED_AT_SWITCH, 1.0, 0.0, 1.0, 1.0, 5e-14)
    # ... pressing back through the tolerance half-way: half a step free, then seated
    books = contact_bookkeeping(
        SEATED_AT_SWITCH, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2e-13, 2e-13, 2e-13, 1.0, 2.0, 1e-13
    )
    assert books[0] == SEATED and books[2] == 0.0 and abs(books[3] - 0.5) < 1e-12
