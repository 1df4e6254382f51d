"""``[[output]]``: a quantity reduced over a time window, continuously, at every step.

Each output is a scalar signal f(t) of the state (a body point's x, a joint force's
magnitude, the slider's x minus the ideal slider's, ...: :func:`output_signal`). Every kernel
feeds the signal at every accepted state, and each step of the run is reduced on an
interpolant of the signal over that step, restricted to the output's window [w0, w1] (its
ends located inside the steps that hold them):

* where the state gives the signal's rate (positions and angles with their velocities,
  velocities with their accelerations, a penetration with its rate): the cubic Hermite
  interpolant through (f, ḟ) at the step's two ends, exact at the ends, O(h⁴) between, the
  interpolant the contact kernels locate onsets and the peak penetration on
  (:func:`mcchain.kernels.contact._hermite`);
* otherwise (forces, accelerations): the cubic through the four step ends around the step,
  as the ``peak_*`` variables (:mod:`mcchain.kernels.peaks`): the step is processed one
  state late, the first and last steps with the first and last four points; an interior
  extremum is sought only on a step where the data rise into it and fall out of it (for a
  minimum: fall and rise), and it is capped at the four points' spread beyond their range
  (a cubic through a kink overshoots), the peaks' rules.

On each step: the largest and smallest values (the ends, and the interpolant's critical
points inside), the integrals of f and f² (4-point Gauss–Legendre on the clipped step, exact
for a cubic and its square), and for ``first_time_above``/``below`` the first time the
interpolant reaches the threshold (split at its critical points into monotone pieces, the
crossing bisected to 1e-15 of the step). :func:`output_value` turns these into the output:
max, min, max |f|, rms = √(∫f²/T), mean = ∫f/T (T the window's length covered), range =
max − min, or the crossing time (+inf if never).

State of one output: :data:`OUTPUT_WIDTH` numbers ``stride`` apart in a flat array, so that
the loop kernels (one sample, stride 1) and the generated lanes (the work array W, stride
LMAX) share these functions (the lanes get a copy of their source); a sample's four times and
count are kept once, as the peaks' clock. Rules every kernel keeps: scalars and flat arrays,
no allocation, never raise.
"""

from __future__ import annotations

import math

import numpy as np

from mcchain.codes import (
    OUTPUT_ANGLE,
    OUTPUT_ANGULAR_VELOCITY,
    OUTPUT_CONTACT_FORCE,
    OUTPUT_JOINT_FORCE,
    OUTPUT_PENETRATION,
    OUTPUT_POSITION,
    OUTPUT_VELOCITY,
    OUTPUT_WIDTH,
)
from mcchain.kernels.config import JIT, hypot, njit
from mcchain.kernels.contact import _hermite
from mcchain.kernels.joints import (
    clearance_rate,
    distance,
    joint_forces,
    joint_separation_rate,
    joint_vectors,
    point_acceleration,
    point_velocity,
    rotate,
)
from mcchain.kernels.output_steps import (
    cubic_gates,
    cubic_settles,
    cubic_slope,
    hermite_settles,
    hull_clear,
    middle_step_plain,
)

# Offsets of an output's state (times ``stride``).
FA, FB, FC, FD = 0, 1, 2, 3  # the last four values fed, oldest first
RD = 4  # the rate at the last one (Hermite signals)
HI, LO = 5, 6  # the largest and smallest value in the window so far
S1, S2 = 7, 8  # ∫f dt and ∫f² dt over the window so far
CROSS = 9  # the first time the threshold was reached (inf: not yet)
SPAN = 10  # the window's length covered so far, s

# Gauss–Legendre, 4 points on [-1, 1]: exact for polynomials of degree 7 (a cubic's square).
GL_X0 = 0.3399810435848563
GL_X1 = 0.8611363115940526
GL_W0 = 0.6521451548625461
GL_W1 = 0.3478548451374538


# -- the signal ------------------------------------------------------------------------------


@njit(**JIT)
def vector_component(fx, fy, rx, ry, component):
    """Component ``component`` (0 x, 1 y, 2 magnitude) of a vector (fx, fy) and its rate from
    the vector's rate (rx, ry): for the magnitude, |f| and f·ḟ/|f| (0 at |f| = 0)."""
    if component == 0:
        return fx, rx
    if component == 1:
        return fy, ry
    size = hypot(fx, fy)
    return size, (fx * rx + fy * ry) / size if size > 0.0 else 0.0


@njit(**JIT)
def body_signal(kind, component, c, sn, x, y, th, vx, vy, w, ax, ay, al, sx, sy):
    """A body's output quantity and its rate (NaN where the state does not give it), for a
    body at (x, y, θ) with (cos θ, sin θ) = (c, sn), velocities (vx, vy, w), accelerations
    (ax, ay, al), and the point (sx, sy) in its frame: its position, velocity or
    acceleration (component ``component``), or the body's angle or angular velocity."""
    if kind == OUTPUT_ANGLE:
        return th, w
    if kind == OUTPUT_ANGULAR_VELOCITY:
        return w, al
    px, py = rotate(c, sn, sx, sy)
    pvx, pvy = point_velocity(vx, vy, w, px, py)
    pax, pay = point_acceleration(ax, ay, al, w, px, py)
    if kind == OUTPUT_POSITION:
        return vector_component(x + px, y + py, pvx, pvy, component)
    if kind == OUTPUT_VELOCITY:
        return vector_component(pvx, pvy, pax, pay, component)
    value, _rate = vector_component(pax, pay, 0.0, 0.0, component)
    return value, math.nan


@njit(**JIT)
def _body_state(q, v, qdd, b, sx, sy, kind, component):
    """:func:`body_signal` of body ``b`` at (q, v, q̈)."""
    th = q[3 * b + 2]
    return body_signal(
        kind, component, math.cos(th), math.sin(th), q[3 * b], q[3 * b + 1], th, v[3 * b],
        v[3 * b + 1], v[3 * b + 2], qdd[3 * b], qdd[3 * b + 1], qdd[3 * b + 2], sx, sy,
    )  # fmt: skip


@njit(**JIT)
def _joint_state(km, s, q, v, jf, cf, k, kind, component):
    """A joint's output quantity and its rate: its force's component (values only, from the
    reactions ``jf``), its normal force ``cf`` (values only) or its penetration δ = |d| − c
    with δ̇ = e·ḋ."""
    if kind == OUTPUT_JOINT_FORCE:
        return vector_component(jf[k, 0], jf[k, 1], 0.0, 0.0, component)[0], math.nan
    if kind == OUTPUT_CONTACT_FORCE:
        return cf[k], math.nan
    pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
    ddx, ddy = joint_separation_rate(v, km.joint_body_a[k], km.joint_body_b[k], pax, pay, pbx,
                                     pby)  # fmt: skip
    rho = distance(dx, dy)
    clearance = km.joint_clearance[s % km.joint_clearance.shape[0], k]
    rate = clearance_rate(dx / rho, dy / rho, ddx, ddy) if rho > 0.0 else 0.0
    return rho - clearance, rate


@njit(**JIT)
def output_reactions(km, s, q, lam, laws, jf_out, cf_out):
    """The joint forces ``jf_out`` (njoint, 2) and normal forces ``cf_out`` (njoint,) the
    outputs read, as the histories store them (:func:`mcchain.kernels.joints.joint_forces`;
    a joint under the contact law, ``laws`` 1.0: F_n = max(λ, 0))."""
    joint_forces(km, s, q, lam, jf_out, cf_out)
    for k in range(laws.shape[0]):
        if laws[k] == 1.0 and cf_out[k] < 0.0:
            jf_out[k, 0] = 0.0 * jf_out[k, 0]
            jf_out[k, 1] = 0.0 * jf_out[k, 1]
            cf_out[k] = 0.0


@njit(**JIT)
def _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, component, index, sx, sy):
    """The quantity of one item (body, joint or driver ``index``), without a reference."""
    if kind <= OUTPUT_ANGULAR_VELOCITY:
        return _body_state(q, v, qdd, index, sx, sy, kind, component)
    if kind <= OUTPUT_PENETRATION:
        return _joint_state(km, s, q, v, jf, cf, index, kind, component)
    return -lam[km.driver_row[index]], math.nan


@njit(**JIT)
def output_signal(km, s, q, v, qdd, lam, jf, cf, kind, component, index, ref, sx, sy):
    """The signal of one output and its rate (NaN: not given by the state) for sample ``s``
    at (q, v) with accelerations q̈, multipliers λ and the reactions of
    :func:`output_reactions`. ``ref`` ≥ 0: the same item of the ideal copy
    (mcchain.solvers.ideal), whose quantity is subtracted; for a vector, the component of
    the difference (its magnitude: the distance between the two)."""
    if ref < 0:
        return _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, component, index, sx, sy)
    if component < 2:  # components and scalars: the difference of the two
        f1, r1 = _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, component, index, sx, sy)
        f2, r2 = _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, component, ref, sx, sy)
        return f1 - f2, r1 - r2
    fx1, rx1 = _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, 0, index, sx, sy)
    fy1, ry1 = _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, 1, index, sx, sy)
    fx2, rx2 = _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, 0, ref, sx, sy)
    fy2, ry2 = _single_signal(km, s, q, v, qdd, lam, jf, cf, kind, 1, ref, sx, sy)
    return vector_component(fx1 - fx2, fy1 - fy2, rx1 - rx2, ry1 - ry2, 2)


# -- the reduction on one step ----------------------------------------------------------------


@njit(**JIT)
def outputs_start(W, base, stride):
    """An empty output state: no value, extremes ∓inf, integrals 0, no crossing."""
    for i in range(OUTPUT_WIDTH):
        W[base + i * stride] = 0.0
    W[base + HI * stride] = -np.inf
    W[base + LO * stride] = np.inf
    W[base + CROSS * stride] = np.inf


@njit(**JIT)
def _crossing(t0, h, lo, hi, f0, r0, f1, r1, threshold, sense):
    """The time where sense·(p − threshold) rises through 0 on [lo, hi] (fractions of the
    step, the interpolant p monotone there, < 0 at lo, ≥ 0 at hi), by bisection."""
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        value, _slope = _hermite(mid, f0, r0, f1, r1, h)
        if sense * (value - threshold) >= 0.0:
            hi = mid
        else:
            lo = mid
        if hi - lo <= 1e-15:
            break
    return t0 + hi * h


@njit(**JIT)
def hermite_window(W, base, stride, t0, f0, r0, t1, f1, r1, w0, w1, threshold, reduce,
                   gate_hi, gate_lo, cap_lo, cap_hi):  # fmt: skip
    """Reduce the step [t0, t1] of the cubic Hermite interpolant through (f0, ḟ0), (f1, ḟ1)
    over its part inside the window [w0, w1] into the output state at ``W[base]``, for the
    reduction ``reduce`` (mcchain.codes.OUTPUT_REDUCTIONS): the extremes for max, min,
    max_abs and range, the integrals for rms and mean, the first time the interpolant is ≥
    (first_time_above) or ≤ (first_time_below) ``threshold`` (only what it needs: the feed
    runs at every step). ``gate_hi`` / ``gate_lo`` 1.0: an interior maximum / minimum is
    sought (else only the clipped ends count), capped to [``cap_lo``, ``cap_hi``]."""
    h = t1 - t0
    lo_t = max(t0, w0)
    hi_t = min(t1, w1)
    if not (h > 0.0 and hi_t > lo_t):
        return
    # the clipped step's ends as fractions; a step inside the window is [0, 1] exactly
    # (h / h = 1), without the divisions
    ta = 0.0 if lo_t == t0 else (lo_t - t0) / h
    tb = 1.0 if hi_t == t1 else (hi_t - t0) / h
    if tb > 1.0:
        tb = 1.0
    fa = f0
    if ta > 0.0:
        fa, _slope = _hermite(ta, f0, r0, f1, r1, h)
    fb = f1
    if tb < 1.0:
        fb, _slope = _hermite(tb, f0, r0, f1, r1, h)
    W[base + SPAN * stride] += hi_t - lo_t
    if reduce == 3 or reduce == 4:  # rms, mean: ∫ f and ∫ f² on [ta, tb]
        mid = 0.5 * (ta + tb)
        half = 0.5 * (tb - ta)
        g1, _slope = _hermite(mid - half * GL_X1, f0, r0, f1, r1, h)
        g2, _slope = _hermite(mid - half * GL_X0, f0, r0, f1, r1, h)
        g3, _slope = _hermite(mid + half * GL_X0, f0, r0, f1, r1, h)
        g4, _slope = _hermite(mid + half * GL_X1, f0, r0, f1, r1, h)
        s1 = GL_W1 * (g1 + g4) + GL_W0 * (g2 + g3)
        s2 = GL_W1 * (g1 * g1 + g4 * g4) + GL_W0 * (g2 * g2 + g3 * g3)
        W[base + S1 * stride] += h * half * s1
        W[base + S2 * stride] += h * half * s2
        return
    hi = max(W[base + HI * stride], max(fa, fb))  # the extremes with the clipped ends
    lo = min(W[base + LO * stride], min(fa, fb))
    if reduce < 6 and hull_clear(f0, r0, f1, r1, h, hi, lo):
        # no critical point can move an extreme: the roots below are not needed (the same
        # numbers; most steps of a feed are away from its running extremes)
        W[base + HI * stride] = hi
        W[base + LO * stride] = lo
        return
    sense = 1.0 if reduce == 6 else -1.0
    if reduce >= 6 and not W[base + CROSS * stride] == np.inf:
        return  # the crossing is found
    if reduce >= 6 and sense * (fa - threshold) >= 0.0:
        W[base + CROSS * stride] = lo_t
        return
    # p'(θ) ∝ qa θ² + qb θ + qc (contact.hermite_peak's quadratic), its roots in (ta, tb)
    rise = f1 - f0
    qa = 3.0 * h * (r0 + r1) - 6.0 * rise
    qb = 6.0 * rise - 4.0 * h * r0 - 2.0 * h * r1
    qc = h * r0
    u1 = math.nan
    u2 = math.nan
    if qa == 0.0:
        if qb != 0.0:
            u1 = -qc / qb
    else:
        disc = qb * qb - 4.0 * qa * qc
        if disc >= 0.0:
            root = math.sqrt(disc)
            qq = -0.5 * (qb + root) if qb >= 0.0 else -0.5 * (qb - root)
            u1 = qq / qa
            if qq != 0.0:
                u2 = qc / qq
    if u2 < u1:  # ascending (a NaN stays second)
        u1, u2 = u2, u1
    if reduce < 6:  # the extremes: the clipped ends and the critical points inside
        if u1 > ta and u1 < tb:
            v1, _slope = _hermite(u1, f0, r0, f1, r1, h)
            if gate_hi == 1.0:
                hi = max(hi, min(v1, cap_hi))
            if gate_lo == 1.0:
                lo = min(lo, max(v1, cap_lo))
        if u2 > ta and u2 < tb:
            v2, _slope = _hermite(u2, f0, r0, f1, r1, h)
            if gate_hi == 1.0:
                hi = max(hi, min(v2, cap_hi))
            if gate_lo == 1.0:
                lo = min(lo, max(v2, cap_lo))
        W[base + HI * stride] = hi
        W[base + LO * stride] = lo
        return
    # monotone pieces [ta, u1], [u1, u2], [u2, tb] (those inside): the first whose end
    # reaches the threshold holds the crossing
    start = ta
    for piece in range(3):
        end = tb if piece == 2 else (u1 if piece == 0 else u2)
        if not (end > start and end <= tb):
            continue
        value = fb
        if end < tb:
            value, _slope = _hermite(end, f0, r0, f1, r1, h)
        if sense * (value - threshold) >= 0.0:
            found = _crossing(t0, h, start, end, f0, r0, f1, r1, threshold, sense)
            W[base + CROSS * stride] = min(max(found, lo_t), hi_t)
            return
        start = end


@njit(**JIT)
def hermite_feed(W, base, stride, count, td, t, f, r, w0, w1, threshold, reduce):
    """Feed an output whose rate the state gives: the value ``f`` and rate ``r`` at time
    ``t`` (after ``td``, the last time fed; ``count`` values fed so far) close the step
    [td, t], reduced on its cubic Hermite interpolant (:func:`hermite_window`; a plain step,
    :func:`mcchain.kernels.output_steps.hermite_settles`, without it)."""
    f0 = W[base + FD * stride]
    r0 = W[base + RD * stride]
    hi = W[base + HI * stride]
    lo = W[base + LO * stride]
    settled, reduced, hi, lo = hermite_settles(count, td, f0, r0, t, f, r, w0, w1, reduce, hi, lo)
    if reduced:
        W[base + SPAN * stride] += t - td
        W[base + HI * stride] = hi
        W[base + LO * stride] = lo
    elif not settled:
        hermite_window(W, base, stride, td, f0, r0, t, f, r, w0, w1, threshold, reduce, 1.0,
                       1.0, -np.inf, np.inf)  # fmt: skip
    W[base + FD * stride] = f
    W[base + RD * stride] = r


@njit(**JIT)
def cubic_window(W, base, stride, ta, fa, tb, fb, tc, fc, td, fd, interval, w0, w1,
                 threshold, reduce):  # fmt: skip
    """Reduce step ``interval`` (0 [ta, tb], 1 [tb, tc], 2 [tc, td]) of the cubic through
    the four points: it is that step's Hermite interpolant with the cubic's slopes at its
    ends. On the middle step an interior maximum is sought only where the data rise into
    it and fall out of it (a minimum: fall and rise), on the first and last steps always;
    extremes are capped at the points' spread beyond their range (the peaks' rules)."""
    t0 = ta if interval == 0 else (tb if interval == 1 else tc)
    t1 = tb if interval == 0 else (tc if interval == 1 else td)
    f0 = fa if interval == 0 else (fb if interval == 1 else fc)
    f1 = fb if interval == 0 else (fc if interval == 1 else fd)
    gate_hi = 1.0
    gate_lo = 1.0
    if interval == 1:
        gate_hi, gate_lo = cubic_gates(fa, fb, fc, fd)
        if middle_step_plain(fa, fb, fc, fd, t0, t1, w0, w1, reduce):
            # Neither gate open, the step whole in the window: hermite_window would take
            # the extremes from the ends alone (fa = f0, fb = f1 exactly: ta 0, tb
            # (t1 - t0) / h = 1), so the slopes are not needed. The same numbers, without
            # the two slopes and the quadratic.
            W[base + SPAN * stride] += t1 - t0
            W[base + HI * stride] = max(W[base + HI * stride], max(f0, f1))
            W[base + LO * stride] = min(W[base + LO * stride], min(f0, f1))
            return
    r0 = cubic_slope(ta, fa, tb, fb, tc, fc, td, fd, t0)
    r1 = cubic_slope(ta, fa, tb, fb, tc, fc, td, fd, t1)
    top = max(max(fa, fb), max(fc, fd))
    low = min(min(fa, fb), min(fc, fd))
    spread = top - low
    hermite_window(
        W, base, stride, t0, f0, r0, t1, f1, r1, w0, w1, threshold, reduce, gate_hi, gate_lo,
        low - spread, top + spread,
    )  # fmt: skip


@njit(**JIT)
def cubic_feed(W, base, stride, count, tb, tc, td, t, f, w0, w1, threshold, reduce):
    """Feed an output known by its values only: with three earlier values, the step [tc, td]
    is reduced on the cubic through (tb, tc, td, t) (and the first step [tb, tc] once, when
    exactly three came before); the last step waits for :func:`output_last`. A plain step
    (:func:`mcchain.kernels.output_steps.cubic_settles`) without the cubic."""
    fb = W[base + FB * stride]
    fc = W[base + FC * stride]
    fd = W[base + FD * stride]
    hi = W[base + HI * stride]
    lo = W[base + LO * stride]
    settled, reduced, hi, lo = cubic_settles(count, tb, tc, td, t, fb, fc, fd, f, w0, w1, reduce,
                                             hi, lo)  # fmt: skip
    if reduced:
        W[base + SPAN * stride] += td - tc
        W[base + HI * stride] = hi
        W[base + LO * stride] = lo
    elif not settled:
        if count == 3.0:
            cubic_window(W, base, stride, tb, fb, tc, fc, td, fd, t, f, 0, w0, w1, threshold,
                         reduce)  # fmt: skip
        cubic_window(W, base, stride, tb, fb, tc, fc, td, fd, t, f, 1, w0, w1, threshold,
                     reduce)  # fmt: skip
    W[base] = fb
    W[base + FB * stride] = fc
    W[base + FC * stride] = fd
    W[base + FD * stride] = f


@njit(**JIT)
def output_last(W, base, stride, count, ta, tb, tc, td, hermite, w0, w1, threshold, reduce):
    """The steps an output known by its values only still holds at the end of the run
    (``hermite`` 0.0): the last one on the cubic through the last four values, or, in a run
    of two or three steps, the steps on the line or parabola through the values fed."""
    if hermite == 1.0 or count < 2.0:
        return
    fa = W[base]
    fb = W[base + FB * stride]
    fc = W[base + FC * stride]
    fd = W[base + FD * stride]
    if count >= 4.0:
        cubic_window(W, base, stride, ta, fa, tb, fb, tc, fc, td, fd, 2, w0, w1, threshold,
                     reduce)  # fmt: skip
    elif count == 3.0:  # the parabola through (tb, tc, td): slopes of its Newton form
        d1 = (fc - fb) / (tc - tb)
        d2 = (fd - fc) / (td - tc)
        e = (d2 - d1) / (td - tb)
        rb = d1 - e * (tc - tb)
        rc = d1 + e * (tc - tb)
        rd = d2 + e * (td - tc)
        hermite_window(W, base, stride, tb, fb, rb, tc, fc, rc, w0, w1, threshold, reduce,
                       1.0, 1.0, -np.inf, np.inf)  # fmt: skip
        hermite_window(W, base, stride, tc, fc, rc, td, fd, rd, w0, w1, threshold, reduce,
                       1.0, 1.0, -np.inf, np.inf)  # fmt: skip
    else:
        slope = (fd - fc) / (td - tc)
        hermite_window(W, base, stride, tc, fc, slope, td, fd, slope, w0, w1, threshold,
                       reduce, 1.0, 1.0, -np.inf, np.inf)  # fmt: skip


@njit(**JIT)
def output_value(W, base, stride, reduce):
    """The output from its state: max, min, max |f|, rms, mean, range, or the first
    crossing time (+inf if never) for ``reduce`` 0 … 7 (mcchain.codes.OUTPUT_REDUCTIONS);
    NaN if the window was never reached (no step fed)."""
    span = W[base + SPAN * stride]
    if not span > 0.0:
        return math.nan
    hi = W[base + HI * stride]
    lo = W[base + LO * stride]
    if reduce == 0:
        return hi
    if reduce == 1:
        return lo
    if reduce == 2:
        return max(hi, -lo)
    if reduce == 3:
        return math.sqrt(max(W[base + S2 * stride], 0.0) / span)
    if reduce == 4:
        return W[base + S1 * stride] / span
    if reduce == 5:
        return hi - lo
    return W[base + CROSS * stride]


# -- one sample (the loop kernels, generalized-α, radau) ----------------------------------------


@njit(**JIT)
def outputs_begin(ot):
    """Empty the state ``ot`` (OUTPUT_WIDTH nout + PEAK_CLOCK,) of one sample's outputs."""
    nout = (ot.shape[0] - 5) // OUTPUT_WIDTH
    for k in range(nout):
        outputs_start(ot, OUTPUT_WIDTH * k, 1)
    clock = OUTPUT_WIDTH * nout
    for i in range(5):
        ot[clock + i] = 0.0


@njit(**JIT)
def output_signals(km, s, spec, data, q, v, qdd, lam, jf, cf, f_out, r_out):
    """Every output's signal and rate (:func:`output_signal`) for sample ``s`` at the state
    (q, v, q̈, λ, and the reactions of :func:`output_reactions`) into ``f_out``, ``r_out``
    (nout,). ``spec`` (nout, 6) int64: kind, component, item, the ideal copy's item (−1:
    none), reduce, with rate (1) or not (0); ``data`` (*, nout, 5): the point (sx, sy), the
    window (w0, w1) and the threshold."""
    row = s % data.shape[0]
    for k in range(spec.shape[0]):
        f_out[k], r_out[k] = output_signal(
            km, s, q, v, qdd, lam, jf, cf, spec[k, 0], spec[k, 1], spec[k, 2], spec[k, 3],
            data[row, k, 0], data[row, k, 1],
        )  # fmt: skip


REFERENCE_HEAD = 7
"""Columns of an output's data (:data:`mcchain.solvers.output_plan.DATA_COLUMNS`) before its
tabulated reference (:func:`reference_signal`): the five columns, the knot count, the
nominal knot step (s)."""
REFERENCE_WIDTH = 5
"""Values of the tabulated reference per knot: t (s), the quantity's x and y (or a scalar
and 0), their rates."""


@njit(**JIT)
def reference_signal(data, k, t):
    """The ideal mechanism's quantity of output ``k`` (a point's x and y, or an angle and 0)
    and their rates at time ``t`` (s), from the table in ``data[0, k, REFERENCE_HEAD:]``
    (:data:`REFERENCE_WIDTH` values a knot, ascending in t; the knot count in column 5 and
    the nominal step in column 6): the cubic Hermite interpolant of the knots' values and
    rates on the interval that holds t (the first or last one outside the knots)."""
    n = int(data[0, k, 5])
    j = min(max(int(t / data[0, k, 6]), 0), n - 2)
    while j > 0 and t < data[0, k, REFERENCE_HEAD + REFERENCE_WIDTH * j]:
        j -= 1
    while j < n - 2 and t >= data[0, k, REFERENCE_HEAD + REFERENCE_WIDTH * (j + 1)]:
        j += 1
    a = REFERENCE_HEAD + REFERENCE_WIDTH * j
    b = a + REFERENCE_WIDTH
    h = data[0, k, b] - data[0, k, a]
    theta = (t - data[0, k, a]) / h
    x, rx = _hermite(theta, data[0, k, a + 1], data[0, k, a + 3], data[0, k, b + 1],
                     data[0, k, b + 3], h)  # fmt: skip
    y, ry = _hermite(theta, data[0, k, a + 2], data[0, k, a + 4], data[0, k, b + 2],
                     data[0, k, b + 4], h)  # fmt: skip
    return x, y, rx, ry


@njit(**JIT)
def reference_knots(q, v, body, sx, sy, kind, table):
    """The knots of a tabulated reference (:func:`reference_signal`) from a history: at each
    time i, the quantity ``kind`` (a position: the point (sx, sy) of ``body``; an angle) of
    the state q, v (ntime, 3 nbody) and its rates, into ``table[i, 1:5]`` (x, y, ẋ, ẏ; an
    angle: θ, 0, ω, 0), by :func:`body_signal` (column 0, the times, is the caller's)."""
    i = 3 * body
    for it in range(q.shape[0]):
        th = q[it, i + 2]
        c, sn = math.cos(th), math.sin(th)
        for component in range(2):
            if kind == OUTPUT_ANGLE and component == 1:
                value, rate = 0.0, 0.0
            else:
                value, rate = body_signal(
                    kind, component, c, sn, q[it, i], q[it, i + 1], th, v[it, i], v[it, i + 1],
                    v[it, i + 2], 0.0, 0.0, 0.0, sx, sy,
                )  # fmt: skip
            table[it, 1 + component] = value
            table[it, 3 + component] = rate


@njit(**JIT)
def outputs_feed(s, ot, spec, data, t, f, r):
    """Feed every output of sample ``s`` its signal ``f`` and rate ``r`` (nout,) at time
    ``t`` (:func:`output_signals`). A time not after the last one fed is skipped (a
    rejected step's repeated state)."""
    nout = spec.shape[0]
    clock = OUTPUT_WIDTH * nout
    count = ot[clock + 4]
    if count > 0.0 and not (t > ot[clock + 3]):
        return
    tb, tc, td = ot[clock + 1], ot[clock + 2], ot[clock + 3]
    row = s % data.shape[0]
    for k in range(nout):
        w0, w1, threshold = data[row, k, 2], data[row, k, 3], data[row, k, 4]
        reduce = spec[k, 4]
        if spec[k, 5] == 1:
            hermite_feed(ot, OUTPUT_WIDTH * k, 1, count, td, t, f[k], r[k], w0, w1, threshold,
                         reduce)  # fmt: skip
        else:
            cubic_feed(ot, OUTPUT_WIDTH * k, 1, count, tb, tc, td, t, f[k], w0, w1, threshold,
                       reduce)  # fmt: skip
    ot[clock] = tb
    ot[clock + 1] = tc
    ot[clock + 2] = td
    ot[clock + 3] = t
    ot[clock + 4] = min(count + 1.0, 4.0)


@njit(**JIT)
def outputs_finish(s, failed, ot, spec, data, values_out):
    """Sample ``s``'s outputs into ``values_out[s, :]``: NaN after a failure."""
    nout = spec.shape[0]
    clock = OUTPUT_WIDTH * nout
    count = ot[clock + 4]
    ta, tb, tc, td = ot[clock], ot[clock + 1], ot[clock + 2], ot[clock + 3]
    row = s % data.shape[0]
    for k in range(nout):
        output_last(
            ot, OUTPUT_WIDTH * k, 1, count, ta, tb, tc, td, 1.0 if spec[k, 5] == 1 else 0.0,
            data[row, k, 2], data[row, k, 3], data[row, k, 4], spec[k, 4],
        )  # fmt: skip
        value = output_value(ot, OUTPUT_WIDTH * k, 1, spec[k, 4])
        values_out[s, k] = math.nan if failed else value


@njit(**JIT)
def joint_laws(km, cst, laws):
    """``laws`` (njoint,) = 1.0 where a joint is under the contact law now (FM column 0 of
    the contact state ``cst``), else 0.0."""
    for k in range(laws.shape[0]):
        laws[k] = 0.0
    j = 0
    for k in range(laws.shape[0]):
        if km.joint_model[k] != 0:
            laws[k] = cst[j, 0]
            j += 1


@njit(**JIT)
def output_state(km, nout):
    """A sample's output state (OUTPUT_WIDTH nout + PEAK_CLOCK,), emptied, and the scratch
    of :func:`feed_outputs` (nout + nout + 4 njoint,)."""
    nj = km.joint_body_a.shape[0]
    ot = np.zeros(OUTPUT_WIDTH * nout + 5)
    outputs_begin(ot)
    return ot, np.zeros(2 * nout + 4 * nj)


@njit(**JIT)
def output_values_at(km, s, spec, data, q, v, qdd, lam, cst, scratch):
    """The outputs' signals and rates (views into ``scratch``) at a state whose contact-law
    joints are in the modes ``cst`` (mcchain.kernels.clearance)."""
    nout = spec.shape[0]
    nj = km.joint_body_a.shape[0]
    f = scratch[:nout]
    r = scratch[nout : 2 * nout]
    laws = scratch[2 * nout : 2 * nout + nj]
    cf = scratch[2 * nout + nj : 2 * nout + 2 * nj]
    jf = scratch[2 * nout + 2 * nj : 2 * nout + 4 * nj].reshape((nj, 2))
    joint_laws(km, cst, laws)
    output_reactions(km, s, q, lam, laws, jf, cf)
    output_signals(km, s, spec, data, q, v, qdd, lam, jf, cf, f, r)
    return f, r


@njit(**JIT)
def feed_outputs(km, s, ot, spec, data, t, q, v, qdd, lam, cst, scratch):
    """:func:`outputs_feed` of the state (q, v, q̈, λ) at time ``t`` whose contact-law
    joints are in the modes ``cst``, with the scratch of :func:`output_state`."""
    f, r = output_values_at(km, s, spec, data, q, v, qdd, lam, cst, scratch)
    outputs_feed(s, ot, spec, data, t, f, r)


@njit(**JIT)
def equilibrium_values(km, spec, data, Q, LAM, values_out):
    """The quantity of the one output ``spec`` (1, 6) at each sample's equilibrium: at
    (Q[s], v = 0, q̈ = 0) with multipliers LAM[s] (every clearance joint on the link) into
    ``values_out[s]``; NaN where the equilibrium is (NaN)."""
    n, ndof = Q.shape
    nj = km.joint_body_a.shape[0]
    zero = np.zeros(ndof)
    laws = np.zeros(nj)
    jf = np.zeros((nj, 2))
    cf = np.zeros(nj)
    for s in range(n):
        q = Q[s]
        lam = LAM[s]
        output_reactions(km, s, q, lam, laws, jf, cf)
        row = s % data.shape[0]
        value, _rate = output_signal(
            km, s, q, zero, zero, lam, jf, cf, spec[0, 0], spec[0, 1], spec[0, 2], spec[0, 3],
            data[row, 0, 0], data[row, 0, 1],
        )  # fmt: skip
        values_out[s] = value
