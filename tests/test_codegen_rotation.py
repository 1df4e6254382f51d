"""codegen: the rk4 lanes' sine-cosine of a later stage as the step start's turned by the
stage's increment δ (mcchain.codegen.sincos.rotated_sincos_code), and its fallback: a lane's
body whose |δ| is past ROTATION_BOUND takes the full evaluation, bit for bit, whatever the
lanes beside it take."""

from __future__ import annotations

import math

import numpy as np
from test_simulate_accuracy import MINIMAL_TOL, _minimal_start

from mcchain.codegen import generate
from mcchain.codegen.native import NativeModule
from mcchain.codegen.sincos import ROTATION_BOUND
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing.minimal import double_pendulum_minimal
from mcchain.testing.scenes import model_of, scene_model, slider_crank_text, straight_chain_text
from mcchain.testing.sincos import rotated_sincos, sincos

ROTATION_TOL = 2 * 2.0**-52  # |error| of sin and cos: 2 ulp of 1 (measured: 3.3e-16 at most)
ROUNDING_RTOL = 1e-12  # rotated against full over a short driven run: rounding differences
LANES = 4  # samples per lane group (every CPU's rows hold at least 4)
STEP = 4e-3  # s: the fast crank's last stage turns it by ω h (> π/4 from 196 rad/s)


def _exact_pairs(rng, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(θ₀, δ, θ) with θ = θ₀ + δ exactly, |δ| ≤ ROTATION_BOUND, δ spread over the interval
    and its edges."""
    deltas = np.concatenate(
        [
            rng.uniform(-ROTATION_BOUND, ROTATION_BOUND, starts.size - 6),
            [ROTATION_BOUND, -ROTATION_BOUND, 1e-300, -3e-9, 0.5, -0.5],
        ]
    )
    rows = []
    for theta0, delta in zip(starts, deltas, strict=True):
        theta = theta0 + delta
        delta = theta - theta0  # the increment θ − θ₀ as a double
        if abs(delta) <= ROTATION_BOUND and math.fsum([theta0, delta, -theta]) == 0.0:
            rows.append((theta0, delta, theta))
    return tuple(np.array(column) for column in zip(*rows, strict=True))  # type: ignore[return-value]


def test_rotated_sincos__matches_math_within_two_ulp_of_one_over_many_turns():
    rng = np.random.default_rng(3)
    starts = np.concatenate(
        [
            rng.uniform(-60.0, 60.0, 20000),
            rng.uniform(-1e4, 1e4, 2000),
            np.arange(-40, 41) * 0.25 * np.pi,
        ]
    )
    rng.shuffle(starts)
    theta0, delta, theta = _exact_pairs(rng, starts)
    assert theta0.size > 0.9 * starts.size  # most pairs are exact
    worst = 0.0
    for a, d, t in zip(theta0, delta, theta, strict=True):
        s, c = rotated_sincos(*sincos(a), d)
        worst = max(worst, abs(s - math.sin(t)), abs(c - math.cos(t)))
    assert worst <= ROTATION_TOL


def test_rotated_sincos__at_no_increment_is_the_start():
    for theta0 in np.random.default_rng(5).uniform(-60.0, 60.0, 1000):
        s0, c0 = sincos(theta0)
        assert rotated_sincos(s0, c0, 0.0) == (s0, c0)


def _full_only(text: str) -> str:
    """The rk4 text with its turned sine-cosine never taken: every stage's in full (the
    loop of the full evaluations run at every later stage, each lane taking them)."""
    full = "if nbig > 0:"
    past = f") > {ROTATION_BOUND!r} else"
    assert text.count(full) == 1 and past in text
    return text.replace(full, "if nbig >= 0:").replace(past, ") >= 0.0 else")


def _run_both(monkeypatch, model, method: str, dt: float, steps: int) -> tuple[dict, dict]:
    """The lanes' run of ``model`` by ``method`` (rk4 or rk4-projection; lane groups of LANES
    samples, ``steps`` of ``dt``), as generated and with the full evaluation at every stage."""
    from mcchain.codegen.topology import Topology

    real = generate.lane_kernels
    text = generate.generate_source(Topology.from_model(model), method)
    full = NativeModule(_full_only(text), f"rotation_full_{method.replace('-', '_')}")
    start = assemble(model)  # each sample's start consistent with its crank's speed
    sim = dict(t_end=steps * dt, dt=dt, output_dt=dt, method=method, kernels="lanes")
    rotated = simulate(model, sim, start.q, start.v, np.float64, lanes=LANES)
    monkeypatch.setattr(generate, "lane_kernels", lambda *args: full)
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
    '"driver.b0.omega" = { uniform = [0.0, 500.0] }\n'
)
"""A driven bar alone (0.1 m, pinned at the origin): it turns at the drive's ω, so δ = a h ω
at every later stage (h/2 at the second and third, h at the fourth)."""


def test_rk4_lanes__a_fast_lane_is_evaluated_in_full_beside_turned_ones(monkeypatch):
    """Lane groups that mix rotors fast enough that every later stage's δ is past the bound
    with slow ones: each fast rotor's values are those of the text that evaluates every
    sine-cosine in full, bit for bit, whatever the lanes beside it take (that the slow ones
    are turned: test_rk4_lanes__slow_groups_are_turned_within_rounding)."""
    model = model_of(ROTOR)
    column = list(model.param_paths).index("driver.b0.omega")
    speeds = np.abs(np.asarray(model.parameters)[:, column])
    fast = speeds * STEP / 2 > ROTATION_BOUND
    slow = speeds * STEP < ROTATION_BOUND  # turned at every later stage
    groups = fast.reshape(-1, LANES)
    assert (groups.any(axis=1) & ~groups.all(axis=1)).any()  # the premise: mixed groups
    assert slow.any()
    rotated, reference = _run_both(monkeypatch, model, "rk4-projection", STEP, 20)
    assert (reference["status"] == 0).all() and np.isfinite(reference["q"]).all()
    for name, values in _histories(reference).items():
        mine = _histories(rotated)[name]
        if values.shape[:1] == (model.nsample,):  # per sample: the fast ones
            values, mine = values[fast], mine[fast]
        assert np.array_equal(values, mine, equal_nan=True), name


def test_rk4_lanes__slow_groups_are_turned_within_rounding(monkeypatch):
    model, speeds = _crank((0.0, 100.0), seed=4)
    dt = STEP / 8  # a step the constraints hold at (within ctol)
    assert (speeds * dt < ROTATION_BOUND / 2).all()
    rotated, reference = _run_both(monkeypatch, model, "rk4", dt, 20)
    assert (rotated["status"] == 0).all() and (reference["status"] == 0).all()
    differs = False
    for name in ("q", "v", "joint_force", "driver_torque", "energy"):
        a, b = rotated[name], reference[name]
        differs |= not np.array_equal(a, b)
        np.testing.assert_allclose(a, b, rtol=0, atol=ROUNDING_RTOL * np.abs(b).max())
    assert differs  # the rotated branch was taken


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
