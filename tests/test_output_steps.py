"""kernels.output_steps: the plain steps of an output's feed, which the feeds take first and
the adaptive lanes evaluate for all lanes at once, against the feeds' full reductions, byte
for byte on the output's state: random steps with ties to the running extremes, extremes a
few ulp from the interpolant's hull, NaN, infinite and signed-zero data, zero-length steps,
windows that cut the step, hold it exactly or miss it, every reduction, the first values fed.
"""

from __future__ import annotations

import ast
import math

import numpy as np

from mcchain.codes import OUTPUT_WIDTH
from mcchain.kernels import output_steps as kos
from mcchain.kernels import outputs as ko
from mcchain.kernels.tableaux import CAP_MARGIN, KEEP_MARGIN, MAX_FACTOR, MIN_FACTOR, SAFETY

SPECIALS = [0.0, -0.0, 1.0, -1.0, math.nan, math.inf, -math.inf]


def _values(rng, scale: float) -> list[float]:
    """Four values of a signal (or specials, or ties among them)."""
    if rng.random() < 0.12:
        return [float(x) for x in rng.choice(SPECIALS, 4)]
    values = [float(x) for x in rng.normal(size=4) * scale]
    if rng.random() < 0.2:  # a flat stretch: ties between neighbours
        i = int(rng.integers(0, 3))
        values[i + 1] = values[i]
    return values


def _extremes(rng, values: list[float]) -> tuple[float, float]:
    """Running extremes: none yet, tied to a value, a few ulp from one, far, or NaN."""
    finite = [v for v in values if math.isfinite(v)] or [0.0]
    top, low = max(finite), min(finite)
    ulp = float(np.spacing(max(abs(top), abs(low), 1e-300)))
    odds = [0.1, 0.1, 0.2, 0.55, 0.05]  # mostly away from the step (the common case)
    hi = float(rng.choice([-math.inf, top, top + ulp * rng.integers(-300, 300),
                           top + abs(top) + 1.0, math.nan], p=odds))  # fmt: skip
    lo = float(rng.choice([math.inf, low, low + ulp * rng.integers(-300, 300),
                           low - abs(low) - 1.0, math.nan], p=odds))  # fmt: skip
    return hi, lo


def _window(rng, t0: float, t1: float) -> tuple[float, float]:
    h = t1 - t0
    if rng.random() < 0.5:  # the step whole inside (the common case), or at its edges
        return float(rng.choice([0.0, t0])), float(rng.choice([math.inf, t1, 0.024]))
    w0 = float(rng.choice([0.0, t0, t0 + 0.3 * h, t1, t1 + 1e-9]))
    w1 = float(rng.choice([math.inf, t1, t0 + 0.7 * h, t0, 0.024]))
    return w0, w1


def _state(rng, hi: float, lo: float) -> np.ndarray:
    state = np.zeros(OUTPUT_WIDTH)
    ko.outputs_start(state, 0, 1)
    state[ko.HI], state[ko.LO] = hi, lo
    state[ko.SPAN] = float(rng.choice([0.0, rng.uniform(0.0, 0.01)]))
    state[ko.S1], state[ko.S2] = (float(x) for x in rng.normal(size=2))
    return state


def test_hermite_settles__the_plain_step_is_the_full_reduction():
    rng = np.random.default_rng(61)
    settled = reduced = 0
    for _ in range(6000):
        t0 = float(rng.choice([0.0, 0.002, rng.uniform(0.0, 0.01)]))
        t1 = t0 + float(rng.choice([0.0, rng.uniform(1e-7, 1e-3)], p=[0.1, 0.9]))
        h = t1 - t0
        f0, f1, r0, r1 = _values(rng, 10.0 ** rng.integers(-6, 3))
        if math.isfinite(f1 - f0) and h > 0.0 and rng.random() < 0.8:  # rates of the size
            r0, r1 = (float(x) for x in rng.normal(size=2) * abs(f1 - f0 + 1e-9) / h * 3)
        hi, lo = _extremes(rng, [f0, f1, f0 + h * r0 / 3.0, f1 - h * r1 / 3.0])
        w0, w1 = _window(rng, t0, t1)
        count = float(rng.choice([0.0, 1.0, 2.0, 4.0]))
        code = int(rng.choice([0, 1, 2, 5, int(rng.integers(0, 8))]))
        threshold = float(rng.choice([0.0, f1, rng.normal()]))
        state = _state(rng, hi, lo)
        state[ko.FD], state[ko.RD] = f0, r0
        # the reduction as it is defined: the interpolant's window, then the shift
        expected = state.copy()
        if count >= 1.0:
            ko.hermite_window(expected, 0, 1, t0, f0, r0, t1, f1, r1, w0, w1, threshold, code,
                              1.0, 1.0, -math.inf, math.inf)  # fmt: skip
        expected[ko.FD], expected[ko.RD] = f1, r1
        fed = state.copy()
        ko.hermite_feed(fed, 0, 1, count, t0, t1, f1, r1, w0, w1, threshold, code)
        assert fed.tobytes() == expected.tobytes()
        ok, plain, high, low = kos.hermite_settles(count, t0, f0, r0, t1, f1, r1, w0, w1, code,
                                                   hi, lo)  # fmt: skip
        if ok:  # what the lanes write through their masks
            lanes = state.copy()
            if plain:
                lanes[ko.SPAN] = lanes[ko.SPAN] + (t1 - t0)
                lanes[ko.HI], lanes[ko.LO] = high, low
            lanes[ko.FD], lanes[ko.RD] = f1, r1
            assert lanes.tobytes() == expected.tobytes(), (count, t0, t1, f0, r0, f1, r1, w0,
                                                           w1, code, hi, lo)  # fmt: skip
        settled += ok
        reduced += plain
    assert reduced > 500 and settled - reduced > 500 and settled < 5500  # every way taken


def test_cubic_settles__the_plain_step_is_the_full_reduction():
    rng = np.random.default_rng(62)
    settled = reduced = opened = 0
    for _ in range(6000):
        times = np.cumsum(rng.uniform(1e-7, 1e-3, size=4)) + float(rng.choice([0.0, 0.002]))
        if rng.random() < 0.05:
            times[2] = times[1]  # a zero-length step
        tb, tc, td, t = (float(x) for x in times)
        fb, fc, fd, f = _values(rng, 10.0 ** rng.integers(-6, 3))
        hi, lo = _extremes(rng, [fb, fc, fd, f])
        w0, w1 = _window(rng, tc, td)
        count = float(rng.choice([0.0, 2.0, 3.0, 4.0, 4.0]))
        code = int(rng.choice([0, 1, 2, 5, int(rng.integers(0, 8))]))
        threshold = float(rng.choice([0.0, fd, rng.normal()]))
        state = _state(rng, hi, lo)
        state[ko.FA] = float(rng.normal())
        state[ko.FB], state[ko.FC], state[ko.FD] = fb, fc, fd
        expected = state.copy()
        if count >= 3.0:
            if count == 3.0:
                ko.cubic_window(expected, 0, 1, tb, fb, tc, fc, td, fd, t, f, 0, w0, w1,
                                threshold, code)  # fmt: skip
            ko.cubic_window(expected, 0, 1, tb, fb, tc, fc, td, fd, t, f, 1, w0, w1, threshold,
                            code)  # fmt: skip
        expected[ko.FA], expected[ko.FB], expected[ko.FC], expected[ko.FD] = fb, fc, fd, f
        fed = state.copy()
        ko.cubic_feed(fed, 0, 1, count, tb, tc, td, t, f, w0, w1, threshold, code)
        assert fed.tobytes() == expected.tobytes()
        ok, plain, high, low = kos.cubic_settles(count, tb, tc, td, t, fb, fc, fd, f, w0, w1,
                                                 code, hi, lo)  # fmt: skip
        if ok:
            lanes = state.copy()
            if plain:
                lanes[ko.SPAN] = lanes[ko.SPAN] + (td - tc)
                lanes[ko.HI], lanes[ko.LO] = high, low
            lanes[ko.FA], lanes[ko.FB], lanes[ko.FC], lanes[ko.FD] = fb, fc, fd, f
            assert lanes.tobytes() == expected.tobytes(), (count, tb, tc, td, t, fb, fc, fd, f,
                                                           w0, w1, code, hi, lo)  # fmt: skip
        settled += ok
        reduced += plain
        opened += plain and kos.cubic_gates(fb, fc, fd, f) != (0.0, 0.0)
    assert reduced > 500 and opened > 50 and settled - reduced > 500 and settled < 5500


def test_cap_margin__below_the_capped_error_the_ratio_is_the_largest():
    """The adaptive lanes take MAX_FACTOR without the power where the error norm is at most
    (MAX_FACTOR / SAFETY · CAP_MARGIN)^-(q+1): there the power's ratio is MAX_FACTOR after
    the clamp too (Python's float power is the C library's pow, as the lanes')."""
    rng = np.random.default_rng(63)
    for order_err in (1.0, 2.0, 3.0, 4.0, 5.0, 7.0):
        expo = -1.0 / (order_err + 1.0)
        cap = (MAX_FACTOR / SAFETY * CAP_MARGIN) ** -(order_err + 1.0)
        errors = [cap, math.nextafter(cap, 0.0), 5e-324, 1e-300]
        errors += [float(x) for x in cap * rng.uniform(0.0, 1.0, size=2000)]
        errors += [float(x) for x in cap * np.exp(-rng.uniform(0.0, 600.0, size=2000))]
        for en in errors:
            if en > 0.0:
                assert min(MAX_FACTOR, max(MIN_FACTOR, SAFETY * en**expo)) == MAX_FACTOR, en
        # ... and not far above it: the cap gives up little
        above = cap * (1.0 + 1e-5)
        assert SAFETY * above**expo < MAX_FACTOR


def test_keep_margin__a_cut_step_keeps_the_controller_step_without_the_power():
    """A step cut short to land (hh < hl) and accepted keeps hl = max(hl, hh · fac); the
    adaptive lanes skip the power (fac) where en ≥ KEEP_MARGIN (SAFETY hh / hl)^(q+1), the
    bound multiplied up as the lanes do. There the power's fac, clamped, gives hl exactly:
    error norms at the bound, an ulp either side of it, a millionth above it and anywhere
    above, steps from a hair short of hl to a millionth of it."""
    rng = np.random.default_rng(64)
    kept = 0
    for order_err in (1.0, 2.0, 3.0, 4.0, 5.0, 7.0):
        expo = -1.0 / (order_err + 1.0)
        cap = (MAX_FACTOR / SAFETY * CAP_MARGIN) ** -(order_err + 1.0)
        for _ in range(3000):
            hl = float(10.0 ** rng.uniform(-9.0, -2.0))
            hh = hl * float(rng.choice([1.0 - 1e-15, rng.uniform(1e-6, 1.0)]))
            bound = KEEP_MARGIN
            for _ in range(int(order_err) + 1):
                bound *= SAFETY * hh / hl
            for en in (bound, math.nextafter(bound, 0.0), math.nextafter(bound, 2.0),
                       bound * (1.0 + 1e-6), bound * float(rng.uniform(1.0, 1e3))):  # fmt: skip
                if not (hh < hl and 0.0 < en <= 1.0 and en >= bound):
                    continue
                fac = SAFETY * en**expo if en > cap else MAX_FACTOR
                fac = min(MAX_FACTOR, max(MIN_FACTOR, fac))
                assert max(hl, hh * fac) == hl, (order_err, hh, hl, en)
                kept += 1
    assert kept > 30000


def test_lanes_feed__its_vector_loop_touches_only_its_lane():
    """The adaptive lanes' feed of the slider-crank verdict (a tabulated reference and a
    values-only output): its loops marked independent (LLVM vectorises them) read and write
    only lane ``l``'s elements and call no function of the module (the plain steps are
    inlined), and the full feeds stay for the lanes flagged (the golden topologies have no
    outputs: the same checks as tests/test_codegen_golden.py, on a text with them)."""
    from test_codegen_golden import CONFIGS, LMAX_PINNED, PURE_CALLS, _lane_index_ok

    from mcchain.codegen.generate import generate_source
    from mcchain.codegen.schedule import INDEPENDENT_MARK
    from mcchain.codegen.topology import Topology
    from mcchain.scene import compile_model, load_scene
    from mcchain.solvers.output_plan import output_plan

    scene = load_scene(CONFIGS / "slider-crank-requirement.toml")
    model = compile_model(scene, nsample=2)
    timed = [o for o in scene.output if o.at is None]
    plan = output_plan(timed, model, float(scene.simulate.t_end))
    assert {rate for *_rest, rate in plan.signature} == {0, 1}  # both kinds of feed
    source = generate_source(Topology.from_model(model), "rk45", outputs=plan.signature,
                             lmax=LMAX_PINNED)  # fmt: skip
    lines = source.splitlines()
    marked = [node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.For)
              and lines[node.lineno - 1].endswith(INDEPENDENT_MARK)]  # fmt: skip
    shifts = [{n.id for n in ast.walk(loop) if isinstance(n, ast.Name)} & {"shift0", "shift1"}
              for loop in marked]  # fmt: skip
    feed = [loop for loop, names in zip(marked, shifts, strict=True) if names]
    assert len(feed) == 1
    for node in ast.walk(feed[0]):
        if isinstance(node, ast.Subscript):
            assert _lane_index_ok(ast.unparse(node.value), node.slice), ast.unparse(node)
        if isinstance(node, ast.Call):
            assert ast.unparse(node.func) in PURE_CALLS | {"range"}, ast.unparse(node)
    calls = [line.strip().split("(")[0] for line in lines if line.strip().endswith(")")]
    assert calls.count("hermite_feed") == 1 and calls.count("cubic_feed") == 1
