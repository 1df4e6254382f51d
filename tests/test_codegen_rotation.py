"""codegen: the rk4 lanes' sine-cosine of a later stage as the step start's turned by the
stage's increment δ (mcchain.codegen.sincos.rotated_sincos_code), by short polynomials where
|δ| ≤ SHORT_ROTATION_BOUND, by fdlibm's where |δ| ≤ ROTATION_BOUND, in full past it: each
lane's body by its own δ, bit for bit, whatever the lanes beside it take."""

from __future__ import annotations

import math
import re
from fractions import Fraction

import mpmath
import numpy as np
import pytest
from test_simulate_accuracy import MINIMAL_TOL, _minimal_start

from mcchain.codegen import generate
from mcchain.codegen.native import NativeModule
from mcchain.codegen.sincos import ROTATION_BOUND, SHORT_ROTATION_BOUND, rotated_sincos_code
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing.minimal import double_pendulum_minimal
from mcchain.testing.scenes import model_of, scene_model, slider_crank_text, straight_chain_text
from mcchain.testing.sincos import rotated_sincos, short_rotated_sincos, sincos

ROTATION_TOL = 2 * 2.0**-52  # |error| of sin and cos: 2 ulp of 1 (measured: 3.3e-16 at most)
ROUNDING_RTOL = 1e-12  # rotated against full over a short driven run: rounding differences
LANES = 4  # samples per lane group (every CPU's rows hold at least 4)
STEP = 4e-3  # s: the fast crank's last stage turns it by ω h (> π/4 from 196 rad/s)


def _exact_pairs(
    rng, starts: np.ndarray, bound: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(θ₀, δ, θ) with θ = θ₀ + δ exactly, |δ| ≤ ``bound``, δ spread over the interval and
    its edges."""
    deltas = np.concatenate(
        [
            rng.uniform(-bound, bound, starts.size - 6),
            [bound, -bound, 1e-300, -3e-9, 0.5 * bound, -0.5 * bound],
        ]
    )
    rows = []
    for theta0, delta in zip(starts, deltas, strict=True):
        theta = theta0 + delta
        delta = theta - theta0  # the increment θ − θ₀ as a double
        if abs(delta) <= bound and math.fsum([theta0, delta, -theta]) == 0.0:
            rows.append((theta0, delta, theta))
    return tuple(np.array(column) for column in zip(*rows, strict=True))  # type: ignore[return-value]


@pytest.mark.parametrize(
    ("turn", "bound"),
    [(rotated_sincos, ROTATION_BOUND), (short_rotated_sincos, SHORT_ROTATION_BOUND)],
    ids=["fdlibm", "short"],
)
def test_rotated_sincos__matches_math_within_two_ulp_of_one_over_many_turns(turn, bound):
    rng = np.random.default_rng(3)
    starts = np.concatenate(
        [
            rng.uniform(-60.0, 60.0, 20000),
            rng.uniform(-1e4, 1e4, 2000),
            np.arange(-40, 41) * 0.25 * np.pi,
        ]
    )
    rng.shuffle(starts)
    theta0, delta, theta = _exact_pairs(rng, starts, bound)
    assert theta0.size > 0.9 * starts.size  # most pairs are exact
    worst = 0.0
    for a, d, t in zip(theta0, delta, theta, strict=True):
        s, c = turn(*sincos(a), d)
        worst = max(worst, abs(s - math.sin(t)), abs(c - math.cos(t)))
    assert worst <= ROTATION_TOL


@pytest.mark.parametrize("turn", [rotated_sincos, short_rotated_sincos], ids=["fdlibm", "short"])
def test_rotated_sincos__at_no_increment_is_the_start(turn):
    for theta0 in np.random.default_rng(5).uniform(-60.0, 60.0, 1000):
        s0, c0 = sincos(theta0)
        assert turn(s0, c0, 0.0) == (s0, c0)


def _polynomials(short: bool) -> tuple[list[Fraction], list[Fraction]]:
    """The coefficients of sin δ (of δ³, δ⁵, ...) and of cos δ − 1 (of δ², δ⁴, ...) as the
    generated lines write them (exact: a double is a fraction)."""
    lines = rotated_sincos_code("s0", "c0", "d", "s", "c", "", short=short)
    number = r"-?\d+\.\d+(?:e-?\d+)?"
    (sine,) = (line for line in lines if line.startswith("_ps = "))
    (cosine,) = (line for line in lines if line.startswith("_cm = "))
    return (
        [Fraction(float(c)) for c in re.findall(number, sine)],
        [Fraction(float(c)) for c in re.findall(number, cosine)],
    )


def _taylor_bound(coefficients: list[Fraction], first: int, bound: Fraction) -> Fraction:
    """max over |δ| ≤ bound of |p(δ) − f(δ)|, p = Σ c_k δ^(first + 2k) (plus δ for the sine),
    f the sine (first = 3) or cos δ − 1 (first = 2), by the Taylor series: the coefficients'
    distances from 1/n! with their signs, and the first omitted term (an alternating series
    whose terms decrease for |δ| ≤ 1 bounds its tail by it)."""
    assert bound <= 1
    total = Fraction(0)
    for k, c in enumerate(coefficients):
        n = first + 2 * k
        exact = Fraction((-1) ** ((n - first) // 2 + 1), math.factorial(n))
        total += abs(c - exact) * bound**n
    omitted = first + 2 * len(coefficients)
    return total + bound**omitted / math.factorial(omitted)


def _fdlibm_error(points: int) -> tuple[float, float]:
    """The largest |p(δ) − f(δ)| of fdlibm's polynomials (as generated) at ``points`` points of
    [0, π/4] (sine: odd, cos δ − 1: even), evaluated exactly at 120 bits: a lower bound of
    their error on [−π/4, π/4]."""
    sine, cosine = _polynomials(short=False)
    worst = [mpmath.mpf(0), mpmath.mpf(0)]
    with mpmath.workprec(120):
        for i in range(points + 1):
            x = mpmath.mpf(float(ROTATION_BOUND)) * i / points
            ps = x + sum(mpmath.mpf(c.numerator) / c.denominator * x ** (3 + 2 * k)
                         for k, c in enumerate(sine))  # fmt: skip
            pc = sum(mpmath.mpf(c.numerator) / c.denominator * x ** (2 + 2 * k)
                     for k, c in enumerate(cosine))  # fmt: skip
            worst[0] = max(worst[0], abs(ps - mpmath.sin(x)))
            worst[1] = max(worst[1], abs(pc - (mpmath.cos(x) - 1)))
    return float(worst[0]), float(worst[1])


def test_short_rotation__error_bound_is_within_fdlibm_s_on_its_interval():
    """The short polynomials' error on the whole of [−SHORT_ROTATION_BOUND,
    SHORT_ROTATION_BOUND] (bounded exactly, in fractions) is no larger than the error fdlibm's
    reach on [−π/4, π/4] (sine 2.7e-18, cos δ − 1 9.8e-19; the short: 1.4e-21, 6.4e-19), each
    of sin δ and cos δ − 1: the tier loses nothing against the polynomials it replaces."""
    sine, cosine = _polynomials(short=True)
    assert len(sine) == 3 and len(cosine) == 3  # degree 7, and cos δ − 1 to δ⁶ (−1/2 first)
    bound = Fraction(SHORT_ROTATION_BOUND)
    short = (_taylor_bound(sine, 3, bound), _taylor_bound(cosine, 2, bound))
    fdlibm = _fdlibm_error(2000)
    assert fdlibm[0] > 2.6e-18 and fdlibm[1] > 9.7e-19  # the known minimax errors
    assert short[0] <= Fraction(fdlibm[0]) and short[1] <= Fraction(fdlibm[1])
    # not a loose bound: cos δ − 1's is its first omitted term (the rounded 1/4!, 1/6! add
    # less than 1e-3 of it)
    assert float(short[1]) == pytest.approx(float(bound) ** 8 / math.factorial(8), rel=1e-3)


def _one_tier(text: str, tier: str) -> str:
    """The rk4 text with every later stage's sine-cosine of every lane taken by one ``tier``:
    "short" (the longer tiers' loops never run), "fdlibm" (the fdlibm turning's loop run at
    every later stage, each lane taking it, the full loop never) or "full" (both loops run,
    each lane taking the full evaluation)."""
    edges = {name: f") > {bound!r} else" for name, bound in
             (("fdlibm", SHORT_ROTATION_BOUND), ("full", ROTATION_BOUND))}  # fmt: skip
    branches = {"fdlibm": "if nlong > 0:", "full": "if nbig > 0:"}
    for marker in (*edges.values(), *branches.values()):
        assert marker in text
    assert text.count(branches["fdlibm"]) == 1 and text.count(branches["full"]) == 1
    if tier == "short":
        return text.replace(branches["fdlibm"], "if nlong < 0:")
    taken = ("fdlibm",) if tier == "fdlibm" else ("fdlibm", "full")
    for name in taken:
        text = text.replace(branches[name], branches[name].replace("> 0", ">= 0"))
        text = text.replace(edges[name], ") >= 0.0 else")
    if tier == "fdlibm":
        text = text.replace(branches["full"], "if nbig < 0:")
    return text


def _run_both(
    monkeypatch, model, method: str, dt: float, steps: int, tier: str = "full"
) -> tuple[dict, dict]:
    """The lanes' run of ``model`` by ``method`` (rk4 or rk4-projection; lane groups of LANES
    samples, ``steps`` of ``dt``), as generated and with every later stage's sine-cosine by
    ``tier`` (_one_tier)."""
    from mcchain.codegen.topology import Topology

    real = generate.lane_kernels
    text = generate.generate_source(Topology.from_model(model), method)
    name = f"rotation_{tier}_{method.replace('-', '_')}"
    reference_kernels = NativeModule(_one_tier(text, tier), name)
    start = assemble(model)  # each sample's start consistent with its crank's speed
    sim = dict(t_end=steps * dt, dt=dt, output_dt=dt, method=method, kernels="lanes")
    rotated = simulate(model, sim, start.q, start.v, np.float64, lanes=LANES)
    monkeypatch.setattr(generate, "lane_kernels", lambda *args: reference_kernels)
    try:
        reference = simulate(model, sim, start.q, start.v, np.float64, lanes=LANES)
    finally:
        monkeypatch.setattr(generate, "lane_kernels", real)
    return rotated, reference


def _crank(omega: tuple[float, float], seed: int):
    """The driven slider-crank, 4 lane groups, the crank's speed drawn from ``omega`` (the
    random design's ``seed``)."""
    text = slider_crank_text() + (
        f'\n[sample]\ncount = {4 * LANES}\nseed = {seed}\ndesign = "random"\n[sample.vary]\n'
        f'"driver.crank.omega" = {{ uniform = [{omega[0]!r}, {omega[1]!r}] }}\n'
    )
    model = model_of(text)
    column = list(model.param_paths).index("driver.crank.omega")
    speeds = np.abs(np.asarray(model.parameters)[:, column])
    return model, speeds


def _histories(out: dict) -> dict[str, np.ndarray]:
    return {k: np.asarray(v) for k, v in out.items() if isinstance(v, np.ndarray)}


def test_rk4_lanes__a_lane_s_bits_do_not_depend_on_the_lanes_beside_it():
    """Every group has a lane whose increment is past the bound and one within it: each
    lane takes the full evaluation or the turned one by its own δ, so a sample's values are
    the same bit for bit in groups of LANES and alone in a group of one (as in any chunk or
    thread count)."""
    model, speeds = _crank((0.0, 500.0), seed=177)
    per_group = speeds.reshape(-1, LANES) * STEP
    # The premise: every group has a lane past the bound at every later stage (δ = h ω / 2 at
    # the second and third, h ω at the fourth) and one within it.
    assert (per_group.max(axis=1) > 2 * ROTATION_BOUND).all()
    assert (per_group.min(axis=1) < ROTATION_BOUND / 2).all()
    start = assemble(model)
    # Projected (at steps this long plain rk4 lets Φ drift past its tolerance): every lane
    # runs, no NaN is compared.
    sim = dict(t_end=20 * STEP, dt=STEP, output_dt=STEP, method="rk4-projection", kernels="lanes")
    grouped = simulate(model, sim, start.q, start.v, np.float64, lanes=LANES)
    alone = simulate(model, sim, start.q, start.v, np.float64, lanes=1)
    assert (grouped["status"] == 0).all() and np.isfinite(grouped["q"]).all()
    for name, values in _histories(grouped).items():
        assert np.array_equal(values, _histories(alone)[name], equal_nan=True), name


ROTOR = straight_chain_text([0.1], [0.1], angle=0.0) + (
    '[[driver]]\nbody = "b0"\nomega = 20.0\n'
    '[sample]\ncount = 16\nseed = 7\ndesign = "random"\n[sample.vary]\n'
    '"driver.b0.omega" = { choice = [-3.0, 2.0, 4.0, 8.0, 60.0, -150.0, 600.0, 900.0] }\n'
)
"""A driven bar alone (0.1 m, pinned at the origin): it turns at the drive's ω, so δ = a h ω
at every later stage (h/2 at the second and third, h at the fourth); speeds in each tier at
every later stage (at h = STEP: |ω| ≤ 5, 10 < |ω| ≤ 196, |ω| > 392 rad/s) and across two."""


@pytest.mark.parametrize("tier", ["short", "fdlibm", "full"])
def test_rk4_lanes__each_lane_takes_its_own_tier_beside_others(monkeypatch, tier):
    """Lane groups that mix rotors of every tier: each rotor whose every later stage's |δ| is
    in ``tier``'s interval has the values of the text that takes that tier for every lane,
    bit for bit, whatever the lanes beside it take."""
    model = model_of(ROTOR)
    column = list(model.param_paths).index("driver.b0.omega")
    speeds = np.abs(np.asarray(model.parameters)[:, column])
    small, large = speeds * STEP / 2, speeds * STEP  # |δ| at the 2nd and 3rd, at the 4th
    tiers = {
        "short": large <= SHORT_ROTATION_BOUND,
        "fdlibm": (small > SHORT_ROTATION_BOUND) & (large <= ROTATION_BOUND),
        "full": small > ROTATION_BOUND,
    }
    mine = tiers[tier]
    # the premise: some groups mix this tier's lanes with others'; each tier has lanes
    groups = mine.reshape(-1, LANES)
    assert (groups.any(axis=1) & ~groups.all(axis=1)).any()
    assert all(t.any() for t in tiers.values())
    rotated, reference = _run_both(monkeypatch, model, "rk4-projection", STEP, 20, tier)
    assert (reference["status"] == 0).all() and np.isfinite(reference["q"]).all()
    for name, values in _histories(reference).items():
        values_mine = _histories(rotated)[name]
        if values.shape[:1] == (model.nsample,):  # per sample: this tier's
            values, values_mine = values[mine], values_mine[mine]
        assert np.array_equal(values, values_mine, equal_nan=True), name


@pytest.mark.parametrize(
    ("tier", "top"), [("full", 100.0), ("fdlibm", 20.0)], ids=["full", "fdlibm"]
)
def test_rk4_lanes__slow_groups_are_turned_within_rounding(monkeypatch, tier, top):
    """The driven crank turning slowly (every lane's |δ| within ROTATION_BOUND; with the top
    speed 20 rad/s within SHORT_ROTATION_BOUND): its values as generated are those of the text
    that takes ``tier`` for every lane within rounding, and not bit for bit (the turned
    sine-cosine, the short one, was taken)."""
    model, speeds = _crank((0.0, top), seed=4)
    dt = STEP / 8  # a step the constraints hold at (within ctol)
    assert (speeds * dt < ROTATION_BOUND / 2).all()
    if tier == "fdlibm":
        assert (speeds * dt <= SHORT_ROTATION_BOUND).all()
    # 200 steps: the two tiers' pairs differ in a last bit here and there, and the crank's
    # reaches the outputs through its own reactions only (its rows are out of S,
    # Emitter.eliminate_prescribed): in 20 steps no output differed.
    rotated, reference = _run_both(monkeypatch, model, "rk4", dt, 200, tier)
    assert (rotated["status"] == 0).all() and (reference["status"] == 0).all()
    differs = False
    for name in ("q", "v", "joint_force", "driver_torque", "energy"):
        a, b = rotated[name], reference[name]
        differs |= not np.array_equal(a, b)
        np.testing.assert_allclose(a, b, rtol=0, atol=ROUNDING_RTOL * np.abs(b).max())
    assert differs  # the turned (short) branch was taken


def test_rk4_lanes__double_pendulum_matches_minimal_coordinates():
    """The rk4 lanes (every later stage turned) against the Lagrangian in (θ₁, α, θ₂)."""
    model = scene_model("double_pendulum")
    sim = dict(t_end=0.2, dt=1e-4, output_dt=0.01, method="rk4", kernels="lanes")
    out = simulate(model, sim, history_dtype=np.float64)
    joints = [("body", 0), ("joint", 1), ("body", 1)]
    p0, pd0 = _minimal_start(model, model.q0[0], model.v0[0], joints)
    q_ref, _ = double_pendulum_minimal(model).integrate(p0, pd0, out["time"])
    q = out["q"][0].reshape(len(out["time"]), -1)
    assert out["status"][0] == 0
    assert np.abs(q - q_ref).max() <= MINIMAL_TOL
