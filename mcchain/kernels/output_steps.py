"""The common steps of an output's feed (:mod:`mcchain.kernels.outputs`), decided and done
without the step's interpolant.

Most steps a feed closes change its state in one plain way: the step lies outside the
output's window (nothing), or it lies whole inside it and cannot hold a new extreme (the
covered span grows by the step, the extremes take the step's two ends), or it is one of the
first values fed (nothing to reduce yet). :func:`hermite_settles` and :func:`cubic_settles`
say whether a step is such a step and give the new extremes: the feeds
(:func:`mcchain.kernels.outputs.hermite_feed`, :func:`~mcchain.kernels.outputs.cubic_feed`)
take them first and run the interpolant's reduction only for the other steps, and the
generated adaptive lanes evaluate them for every lane at once (vectorised, the state written
by masks) and call the feeds only for the lanes they leave. They are the feeds' own rules,
written once here, straight-line (the lanes inline them: :mod:`mcchain.codegen.inline`).
"""

from __future__ import annotations

from mcchain.kernels.config import JIT, njit

THIRD = 1.0 / 3.0
HULL_ROUNDING = 128.0 * 2.0**-52
"""A bound of the rounding of a cubic Hermite interpolant's value (about 25 ulp at most:
mcchain.kernels.contact._hermite) or of a Bézier point, relative to |f0| + |f1| + |h ḟ0| +
|h ḟ1|, with room to spare (128 machine epsilons; :func:`hull_clear`)."""


@njit(**JIT)
def hull_clear(f0, r0, f1, r1, h, hi, lo):
    """True where the cubic Hermite interpolant through (f0, ḟ0), (f1, ḟ1) over a step of
    length ``h`` cannot reach ``hi`` or ``lo``: it lies between the extremes of its Bézier
    points f0, f0 + h ḟ0 / 3, f1 − h ḟ1 / 3, f1, and those lie strictly inside (lo, hi) by
    more than any rounding of the points or of an interpolated value (HULL_ROUNDING of the
    terms' size). False for a NaN anywhere."""
    c1 = f0 + h * r0 * THIRD
    c2 = f1 - h * r1 * THIRD
    slack = HULL_ROUNDING * (abs(f0) + abs(f1) + abs(h * r0) + abs(h * r1))
    top = max(max(f0, f1), max(c1, c2))
    bottom = min(min(f0, f1), min(c1, c2))
    return top + slack < hi and bottom - slack > lo


@njit(**JIT)
def cubic_gates(fa, fb, fc, fd):
    """(gate_hi, gate_lo) of the middle step of four values: 1.0 where an interior maximum
    (minimum) is sought there, the data rising into it and falling out of it (falling and
    rising), else 0.0 (the peaks' rule, :mod:`mcchain.kernels.peaks`)."""
    gate_hi = 1.0 if fb >= fa and fc >= fd and (fb > fa or fc > fd) else 0.0
    gate_lo = 1.0 if fb <= fa and fc <= fd and (fb < fa or fc < fd) else 0.0
    return gate_hi, gate_lo


@njit(**JIT)
def extremes_only(reduce):
    """True for the reductions that keep only the extremes (max, min, max_abs, range)."""
    return reduce != 3 and reduce != 4 and reduce < 6


@njit(**JIT)
def step_inside(t0, t1, w0, w1, reduce):
    """True where the step [t0, t1] (t1 > t0) lies whole inside the window [w0, w1] and the
    reduction keeps only the extremes: the step's extremes are its ends' unless the
    interpolant passes them."""
    return extremes_only(reduce) and t1 > t0 and t0 >= w0 and t1 <= w1


@njit(**JIT)
def cubic_slope(ta, fa, tb, fb, tc, fc, td, fd, at):
    """The slope at ``at`` of the cubic through the four points (ascending times), from its
    Newton form."""
    d1 = (fb - fa) / (tb - ta)
    d2 = (fc - fb) / (tc - tb)
    d3 = (fd - fc) / (td - tc)
    e1 = (d2 - d1) / (tc - ta)
    e2 = (d3 - d2) / (td - tb)
    g = (e2 - e1) / (td - ta)
    u = at - ta
    xb = tb - ta
    xc = tc - ta
    return d1 + e1 * (2.0 * u - xb) + g * (3.0 * u * u - 2.0 * u * (xb + xc) + xb * xc)


@njit(**JIT)
def hermite_settles(count, t0, f0, r0, t1, f1, r1, w0, w1, reduce, hi, lo):
    """Whether feeding (f1, ḟ1) at ``t1`` after (f0, ḟ0) at ``t0`` (``count`` values fed
    so far) to an output whose rate the state gives, in the window [w0, w1] with running
    extremes ``hi``, ``lo``, changes its reduction in the plain way: (settled, reduced, hi,
    lo). Settled: no value fed before, the step outside the window, or ``reduced``: the step
    whole inside the window, an extremes reduction, and the interpolant unable to pass the
    extremes with the step's ends (:func:`hull_clear`); then the span grows by t1 − t0 and
    the extremes are the returned ``hi``, ``lo``."""
    step = t1 - t0
    high = max(hi, max(f0, f1))
    low = min(lo, min(f0, f1))
    outside = not (step > 0.0 and min(t1, w1) > max(t0, w0))
    inside = count >= 1.0 and step_inside(t0, t1, w0, w1, reduce)
    reduced = inside and hull_clear(f0, r0, f1, r1, step, high, low)
    return count < 1.0 or outside or reduced, reduced, high, low


@njit(**JIT)
def middle_step_plain(fa, fb, fc, fd, t0, t1, w0, w1, reduce):
    """True where the middle step [t0, t1] of four values (fa, fb, fc, fd) is reduced from
    its ends alone: neither gate open (:func:`cubic_gates`), an extremes reduction, the step
    whole inside the window [w0, w1]."""
    rise, fall = cubic_gates(fa, fb, fc, fd)
    return rise == 0.0 and fall == 0.0 and step_inside(t0, t1, w0, w1, reduce)


@njit(**JIT)
def cubic_settles(count, tb, tc, td, t, fb, fc, fd, f, w0, w1, reduce, hi, lo):
    """Whether feeding ``f`` at ``t`` (after the values fb, fc, fd at tb, tc, td; ``count``
    values fed so far) to an output known by its values only changes its reduction in the
    plain way: (settled, reduced, hi, lo). Settled: fewer than three values fed before
    (nothing reduced), or ``reduced``: four or more, the step [tc, td] whole inside the
    window, an extremes reduction, and the step's interpolant (the Hermite form of the cubic
    through the four) unable to pass the extremes with its ends: neither gate open
    (:func:`middle_step_plain`), or its hull clear of them (:func:`hull_clear`, with the
    cubic's slopes); then the span grows by td − tc and the extremes are the returned
    ``hi``, ``lo``."""
    high = max(hi, max(fc, fd))
    low = min(lo, min(fc, fd))
    plain = middle_step_plain(fb, fc, fd, f, tc, td, w0, w1, reduce)
    slope0 = cubic_slope(tb, fb, tc, fc, td, fd, t, f, tc)
    slope1 = cubic_slope(tb, fb, tc, fc, td, fd, t, f, td)
    inside = step_inside(tc, td, w0, w1, reduce)
    clear = inside and hull_clear(fc, slope0, fd, slope1, td - tc, high, low)
    reduced = count > 3.0 and (plain or clear)
    return count < 3.0 or reduced, reduced, high, low


__all__ = [
    "HULL_ROUNDING",
    "THIRD",
    "cubic_gates",
    "cubic_settles",
    "cubic_slope",
    "extremes_only",
    "hermite_settles",
    "hull_clear",
    "middle_step_plain",
    "step_inside",
]
