"""The ``[[output]]`` reductions (mcchain.kernels.outputs) on signals with closed forms:
every reduction, windows whose ends fall inside steps, crossings, the order in the step,
both interpolants (Hermite with the rate, the four-point cubic without), and the edges
(a window of part of one step, never crossing, a constant, a failure)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcchain.codes import OUTPUT_REDUCTIONS, OUTPUT_WIDTH
from mcchain.kernels import output_steps as kos
from mcchain.kernels import outputs as ko
from mcchain.kernels.config import JIT, njit

W0, W1 = 0.123, 2.71
"""A window whose ends fall inside steps, s."""
TIGHT = 1e-9
"""Tolerance against closed forms at h = 0.005 (errors O(h⁴ f'''') ≈ 1e-10 and below)."""


def signal(t: float) -> tuple[float, float]:
    """f = sin 2t + 0.3 t and its rate."""
    return math.sin(2.0 * t) + 0.3 * t, 2.0 * math.cos(2.0 * t) + 0.3


def reduce(
    name: str,
    times: np.ndarray,
    values: np.ndarray,
    rates: np.ndarray | None,
    w0: float = W0,
    w1: float = W1,
    threshold: float = 0.0,
    failed: bool = False,
) -> float:
    """The output the kernels give for one signal fed at ``times`` (rates None: values
    only, the four-point cubic)."""
    code = OUTPUT_REDUCTIONS[name]
    spec = np.array([[0, -1, 0, -1, code, 0 if rates is None else 1]], dtype=np.int64)
    data = np.array([[[0.0, 0.0, w0, w1, threshold]]])
    ot = np.zeros(OUTPUT_WIDTH + 5)
    ko.outputs_begin(ot)
    for i, t in enumerate(times):
        r = np.array([math.nan if rates is None else rates[i]])
        ko.outputs_feed(0, ot, spec, data, t, np.array([values[i]]), r)
    out = np.full((1, 1), -1.0)
    ko.outputs_finish(0, failed, ot, spec, data, out)
    return float(out[0, 0])


def sampled(h: float, t_end: float = 3.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    times = np.append(np.arange(0.0, t_end, h), t_end)
    pairs = np.array([signal(t) for t in times])
    return times, pairs[:, 0], pairs[:, 1]


def exact(name: str, threshold: float = 0.0) -> float:
    """The reduction of :func:`signal` over [W0, W1] in closed form."""
    f = lambda t: signal(t)[0]  # noqa: E731
    # f' = 0 where cos 2t = −0.15: t = (±acos(−0.15) + 2πk)/2
    root = math.acos(-0.15)
    critical = [(s * root + 2 * math.pi * k) / 2 for k in range(-1, 3) for s in (1, -1)]
    points = [W0, W1, *(t for t in critical if W0 < t < W1)]
    hi, lo = max(f(t) for t in points), min(f(t) for t in points)
    span = W1 - W0
    integral = (-math.cos(2 * W1) + math.cos(2 * W0)) / 2 + 0.15 * (W1**2 - W0**2)

    # ∫ f² = ∫ sin² 2t + 0.6 t sin 2t + 0.09 t²
    def square(t: float) -> float:
        return t / 2 - math.sin(4 * t) / 8 + 0.6 * (math.sin(2 * t) / 4 - t * math.cos(2 * t) / 2) \
            + 0.03 * t**3  # fmt: skip

    values = {
        "max": hi,
        "min": lo,
        "max_abs": max(hi, -lo),
        "range": hi - lo,
        "mean": integral / span,
        "rms": math.sqrt((square(W1) - square(W0)) / span),
    }
    if name in values:
        return values[name]
    from scipy.optimize import brentq

    sense = 1.0 if name == "first_time_above" else -1.0
    grid = np.linspace(W0, W1, 100001)
    g = np.array([sense * (f(t) - threshold) for t in grid])
    if g[0] >= 0:
        return W0
    i = int(np.flatnonzero(g >= 0)[0])
    return brentq(lambda t: sense * (f(t) - threshold), grid[i - 1], grid[i], xtol=1e-15)


@pytest.mark.parametrize("with_rate", [True, False], ids=["hermite", "cubic"])
@pytest.mark.parametrize("name", ["max", "min", "max_abs", "range", "mean", "rms"])
def test_reduction__closed_form_over_a_window_inside_steps(name, with_rate):
    times, values, rates = sampled(0.005)
    found = reduce(name, times, values, rates if with_rate else None)
    assert found == pytest.approx(exact(name), abs=TIGHT)


@pytest.mark.parametrize("with_rate", [True, False], ids=["hermite", "cubic"])
@pytest.mark.parametrize(("name", "threshold"), [("first_time_above", 1.1),
                                                 ("first_time_below", -0.2)])  # fmt: skip
def test_crossing__located_inside_the_step(name, threshold, with_rate):
    times, values, rates = sampled(0.005)
    found = reduce(name, times, values, rates if with_rate else None, threshold=threshold)
    assert found == pytest.approx(exact(name, threshold), abs=TIGHT)


def test_crossing__at_the_window_start_and_never():
    times, values, rates = sampled(0.01)
    above_at_start = reduce("first_time_above", times, values, rates, threshold=-10.0)
    assert above_at_start == W0  # already above where the window opens: its start
    assert reduce("first_time_above", times, values, rates, threshold=10.0) == math.inf
    assert reduce("first_time_below", times, values, None, threshold=-10.0) == math.inf


@pytest.mark.parametrize("with_rate", [True, False], ids=["hermite", "cubic"])
def test_reduction__fourth_order_in_the_step(with_rate):
    """The mean and the rms converge as h⁴ (the interpolant's order), the extremes at
    least as h³ (their error is the interpolant's at a point that moves with h)."""
    steps = [0.04 / 2**k for k in range(4)]
    for name, least in (("mean", 3.7), ("rms", 3.7), ("max", 2.9)):
        errors = []
        for h in steps:
            times, values, rates = sampled(h)
            found = reduce(name, times, values, rates if with_rate else None)
            errors.append(abs(found - exact(name)))
        order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
        assert order > least, (name, errors)


def test_extremes__never_below_the_largest_value_fed_in_the_window():
    """Continuous ≥ sampled: the interpolant passes through every value fed."""
    times, values, rates = sampled(0.05)
    inside = (times >= W0) & (times <= W1)
    for with_rate in (True, False):
        r = rates if with_rate else None
        assert reduce("max", times, values, r) >= values[inside].max()
        assert reduce("min", times, values, r) <= values[inside].min()


def test_window__part_of_one_step_and_a_constant():
    times = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    ones = np.ones(5)
    for with_rate in (True, False):
        r = np.zeros(5) if with_rate else None
        assert reduce("mean", times, ones * 2.5, r, 1.25, 1.5) == pytest.approx(2.5, rel=1e-15)
        assert reduce("rms", times, -ones, r, 1.25, 1.5) == pytest.approx(1.0, rel=1e-15)
        assert reduce("range", times, ones, r, 0.0, 4.0) == 0.0
    # a line inside one step: its mean is its value at the window's middle
    line = 0.5 * times
    assert reduce("mean", times, line, np.full(5, 0.5), 1.25, 1.5) == pytest.approx(0.6875)
    assert reduce("max", times, line, None, 1.25, 1.5) == pytest.approx(0.75)


def test_short_runs__two_and_three_points_are_reduced_too():
    """A run of one or two steps (values only): the line or parabola through them."""
    for n in (2, 3):
        times = np.linspace(0.0, 1.0, n)
        f = 3.0 * times**2 if n == 3 else 3.0 * times
        mean = 1.0 if n == 3 else 1.5  # ∫₀¹ 3t² = 1, ∫₀¹ 3t = 1.5
        assert reduce("mean", times, f, None, 0.0, 1.0) == pytest.approx(mean, rel=1e-14)


def test_failure__nan_and_a_repeated_time_is_skipped():
    times, values, rates = sampled(0.1)
    assert math.isnan(reduce("max", times, values, rates, failed=True))
    doubled = np.repeat(times, 2)
    once = reduce("mean", times, values, rates)
    twice = reduce("mean", doubled, np.repeat(values, 2), np.repeat(rates, 2))
    assert twice == once


def test_vector_component__magnitude_and_its_rate():
    f, r = ko.vector_component(3.0, 4.0, 1.0, 2.0, 2)
    assert (f, r) == (5.0, (3.0 + 8.0) / 5.0)
    assert ko.vector_component(0.0, 0.0, 1.0, 2.0, 2) == (0.0, 0.0)
    assert ko.vector_component(3.0, 4.0, 1.0, 2.0, 1) == (4.0, 2.0)


def test_body_signal__point_kinematics_against_finite_differences():
    """A point of a body on a known motion: the rate of its position is its velocity, the
    rate of its velocity its acceleration (central differences of the values)."""

    def state(t: float) -> list[float]:
        p = (0.3 * t**2, math.sin(t), 0.7 * t + 0.2 * t**3)
        v = (0.6 * t, math.cos(t), 0.7 + 0.6 * t**2)
        a = (0.6, -math.sin(t), 1.2 * t)
        return [math.cos(p[2]), math.sin(p[2]), *p, *v, *a]

    sx, sy, t, h = 0.4, -0.1, 0.8, 1e-5
    for kind in (0, 1, 3, 4):  # position, velocity, angle, angular velocity
        for component in (0, 1, 2):
            value, rate = ko.body_signal(kind, component, *state(t), sx, sy)
            up = ko.body_signal(kind, component, *state(t + h), sx, sy)[0]
            down = ko.body_signal(kind, component, *state(t - h), sx, sy)[0]
            assert rate == pytest.approx((up - down) / (2 * h), rel=1e-8, abs=1e-10)
    for component in (0, 1):  # the acceleration is the velocity's rate, values only
        value, rate = ko.body_signal(2, component, *state(t), sx, sy)
        assert value == ko.body_signal(1, component, *state(t), sx, sy)[1]
        assert math.isnan(rate)


@njit(**JIT)
def _cubic_window_in_full(W, base, stride, ta, fa, tb, fb, tc, fc, td, fd, interval, w0, w1,
                          threshold, reduce):  # fmt: skip
    """ko.cubic_window as it was before its shortcut (slopes and hermite_window always),
    compiled as it is: the reference the shortcut must match bit for bit."""
    t0 = ta if interval == 0 else (tb if interval == 1 else tc)
    t1 = tb if interval == 0 else (tc if interval == 1 else td)
    f0 = fa if interval == 0 else (fb if interval == 1 else fc)
    f1 = fb if interval == 0 else (fc if interval == 1 else fd)
    r0 = kos.cubic_slope(ta, fa, tb, fb, tc, fc, td, fd, t0)
    r1 = kos.cubic_slope(ta, fa, tb, fb, tc, fc, td, fd, t1)
    gate_hi = 1.0
    gate_lo = 1.0
    if interval == 1:
        gate_hi = 1.0 if fb >= fa and fc >= fd and (fb > fa or fc > fd) else 0.0
        gate_lo = 1.0 if fb <= fa and fc <= fd and (fb < fa or fc < fd) else 0.0
    top = max(max(fa, fb), max(fc, fd))
    low = min(min(fa, fb), min(fc, fd))
    spread = top - low
    ko.hermite_window(
        W, base, stride, t0, f0, r0, t1, f1, r1, w0, w1, threshold, reduce, gate_hi, gate_lo,
        low - spread, top + spread,
    )  # fmt: skip


def test_cubic_window__the_shortcut_without_slopes_is_bit_identical():
    """A middle step with neither gate open, whole in the window, skips the slopes: the
    state must be the full path's byte for byte, for every reduction, on monotone, flat,
    tied, signed-zero and NaN data, and windows that cut the step or hold it exactly."""
    rng = np.random.default_rng(37)
    values = [0.0, -0.0, 1.0, -1.0, 2.5, math.nan, math.inf, -math.inf]
    checked = shortcut = 0
    for _ in range(4000):
        t = np.cumsum(rng.uniform(1e-6, 1e-3, 4)) + rng.choice([0.0, 0.002])
        if rng.random() < 0.5:
            f = rng.choice(values, 4)
        else:
            f = np.sort(rng.normal(size=4)) * rng.choice([1.0, -1.0])
        w0, w1 = (
            rng.choice([0.0, t[1], t[1] - 1e-7, t[1] + 1e-7, 0.002]),
            rng.choice([math.inf, t[2], t[2] - 1e-7, t[2] + 1e-7, 0.024]),
        )
        reduce_code = int(rng.integers(0, 8))
        threshold = float(rng.choice([0.0, 1.0, -0.5]))
        for interval in (0, 1, 2):
            state = np.zeros(3 * OUTPUT_WIDTH)
            ko.outputs_start(state, 1, 3)
            state[1 + 3 * ko.HI] = rng.choice([-math.inf, 0.5, math.nan])
            state[1 + 3 * ko.LO] = rng.choice([math.inf, -0.5, math.nan])
            expected = state.copy()
            points = [x for pair in zip(t, f, strict=True) for x in pair]
            rest = (interval, w0, w1, threshold, reduce_code)
            ko.cubic_window(state, 1, 3, *points, *rest)
            _cubic_window_in_full(expected, 1, 3, *points, *rest)
            assert state.tobytes() == expected.tobytes()
            checked += 1
            fa, fb, fc, fd = f
            shortcut += interval == 1 and reduce_code in (0, 1, 2, 5) and t[1] >= w0 and (
                t[2] <= w1) and not (fb >= fa and fc >= fd and (fb > fa or fc > fd)) and not (
                fb <= fa and fc <= fd and (fb < fa or fc < fd))  # fmt: skip
    assert shortcut > 500  # the shortcut was taken often, not only the full path


@njit(**JIT)
def _hermite_window_in_full(W, base, stride, t0, f0, r0, t1, f1, r1, w0, w1, threshold,
                            reduce, gate_hi, gate_lo, cap_lo, cap_hi):  # fmt: skip
    """ko.hermite_window's extremes as they were before its shortcuts (the critical points
    always sought, the clipped ends always divided): the reference the shortcuts must match
    bit for bit (reductions max, min, max_abs, range)."""
    h = t1 - t0
    lo_t = max(t0, w0)
    hi_t = min(t1, w1)
    if not (h > 0.0 and hi_t > lo_t):
        return
    ta = (lo_t - t0) / h
    tb = (hi_t - t0) / h
    if tb > 1.0:
        tb = 1.0
    fa = f0
    if ta > 0.0:
        fa, _slope = ko._hermite(ta, f0, r0, f1, r1, h)
    fb = f1
    if tb < 1.0:
        fb, _slope = ko._hermite(tb, f0, r0, f1, r1, h)
    W[base + ko.SPAN * stride] += hi_t - lo_t
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
    if u2 < u1:
        u1, u2 = u2, u1
    hi = max(W[base + ko.HI * stride], max(fa, fb))
    lo = min(W[base + ko.LO * stride], min(fa, fb))
    if u1 > ta and u1 < tb:
        v1, _slope = ko._hermite(u1, f0, r0, f1, r1, h)
        if gate_hi == 1.0:
            hi = max(hi, min(v1, cap_hi))
        if gate_lo == 1.0:
            lo = min(lo, max(v1, cap_lo))
    if u2 > ta and u2 < tb:
        v2, _slope = ko._hermite(u2, f0, r0, f1, r1, h)
        if gate_hi == 1.0:
            hi = max(hi, min(v2, cap_hi))
        if gate_lo == 1.0:
            lo = min(lo, max(v2, cap_lo))
    W[base + ko.HI * stride] = hi
    W[base + ko.LO * stride] = lo


def test_hermite_window__the_hull_shortcut_is_bit_identical():
    """Extremes of a step whose Bézier hull lies inside the running extremes skip the
    critical points, and a step inside the window skips the divisions: the state must be
    the full path's byte for byte, for every extreme reduction, gates and caps, on steps
    whose interpolant just reaches, just misses or overshoots the running extremes (its
    critical point a few ulp from them), flat, signed-zero, NaN and infinite data, and
    windows that cut the step or hold it exactly."""
    rng = np.random.default_rng(38)
    specials = [0.0, -0.0, 1.0, -1.0, math.nan, math.inf, -math.inf]
    shortcut = 0
    for _ in range(8000):
        t0 = float(rng.choice([0.0, 0.002, rng.uniform(0.0, 0.01)]))
        t1 = t0 + float(rng.uniform(1e-7, 1e-3))
        h = t1 - t0
        if rng.random() < 0.15:
            f0, r0, f1, r1 = (float(x) for x in rng.choice(specials, 4))
        else:
            f0, f1 = (float(x) for x in rng.normal(size=2) * 10.0 ** rng.integers(-6, 3))
            r0, r1 = (float(x) for x in rng.normal(size=2) * abs(f1 - f0 + 1e-9) / h * 3)
        # the interpolant's true maximum and minimum on a fine grid: running extremes set
        # just above or below them (by a few ulp) or far away
        theta = np.linspace(0.0, 1.0, 257)
        curve = np.array([ko._hermite(x, f0, r0, f1, r1, h)[0] for x in theta])
        finite = curve[np.isfinite(curve)]
        top, low = (float(finite.max()), float(finite.min())) if finite.size else (0.0, 0.0)
        ulp = float(np.spacing(max(abs(top), abs(low), 1e-300)))
        # ... or a few hundred ulp from the Bézier hull, where the shortcut's test flips
        c1, c2 = f0 + h * r0 / 3.0, f1 - h * r1 / 3.0
        hull = (max(f0, f1, c1, c2), min(f0, f1, c1, c2))
        near = int(rng.integers(-400, 400))
        state = np.zeros(3 * OUTPUT_WIDTH)
        ko.outputs_start(state, 1, 3)
        state[1 + 3 * ko.HI] = float(rng.choice([-math.inf, top + ulp * rng.integers(-40, 40),
                                                  hull[0] + ulp * near, top + abs(top) + 1.0,
                                                  math.nan]))  # fmt: skip
        state[1 + 3 * ko.LO] = float(rng.choice([math.inf, low + ulp * rng.integers(-40, 40),
                                                  hull[1] - ulp * near, low - abs(low) - 1.0,
                                                  math.nan]))  # fmt: skip
        w0 = float(rng.choice([0.0, t0, t0 + 0.3 * h, t1 + 1e-9]))
        w1 = float(rng.choice([math.inf, t1, t0 + 0.7 * h, 0.024]))
        code = int(rng.choice([0, 1, 2, 5]))
        gate_hi, gate_lo = float(rng.integers(0, 2)), float(rng.integers(0, 2))
        cap_lo, cap_hi = (-math.inf, math.inf) if rng.random() < 0.7 else (low - 1e-3, top)
        expected = state.copy()
        rest = (t0, f0, r0, t1, f1, r1, w0, w1, 0.0, code, gate_hi, gate_lo, cap_lo, cap_hi)
        ko.hermite_window(state, 1, 3, *rest)
        _hermite_window_in_full(expected, 1, 3, *rest)
        assert state.tobytes() == expected.tobytes(), rest
        shortcut += bool(hull[0] < expected[1 + 3 * ko.HI] and hull[1] > expected[1 + 3 * ko.LO])
    assert shortcut > 300  # the hull inside the extremes often: not only the full path
