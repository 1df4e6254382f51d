"""simulate: method coefficients, generated evaluation vs the dense reference, settings."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mcchain.codegen.generate import lane_kernels
from mcchain.codegen.topology import Topology, pack_parameters
from mcchain.errors import SceneError
from mcchain.kernels.tableaux import DOPRI5, RK4, GeneralizedAlpha
from mcchain.model import JointKind, Model
from mcchain.solvers.simulate import METHODS, simulate
from mcchain.testing.dense import energy, equations, kkt_acceleration
from mcchain.testing.scenes import scene_model
from mcchain.testing.sincos import sincos

COEF_TOL = 1e-15  # tableau identities hold to rounding of the fractions
SINCOS_TOL = 2.3e-16  # the fdlibm kernels: about one ulp of a value ≤ 1
ACCEL_RTOL = 1e-10  # generated Schur/LDLᵀ vs dense LU of the full KKT, conditioning ~1e4
FORCE_RTOL = 1e-10


@pytest.mark.parametrize("tab", [RK4, DOPRI5], ids=lambda t: t.name)
def test_tableau__order_conditions(tab):
    A, b, c = tab.A, tab.b, tab.c
    assert np.allclose(A.sum(axis=1), c, atol=COEF_TOL, rtol=0)
    assert np.allclose(np.triu(A), 0.0)  # explicit
    conditions = {
        1: [(b.sum(), 1.0)],
        2: [(b @ c, 1 / 2)],
        3: [(b @ c**2, 1 / 3), (b @ A @ c, 1 / 6)],
        4: [
            (b @ c**3, 1 / 4),
            (b @ (c * (A @ c)), 1 / 8),
            (b @ A @ c**2, 1 / 12),
            (b @ A @ A @ c, 1 / 24),
        ],
        5: [(b @ c**4, 1 / 5), (b @ A @ A @ A @ c, 1 / 120), (b @ (c**2 * (A @ c)), 1 / 10)],
    }
    for order in range(1, tab.order + 1):
        for value, expected in conditions[order]:
            assert value == pytest.approx(expected, abs=COEF_TOL * 10)


def test_tableau__dopri5_embedded_pair_and_fsal():
    bhat = DOPRI5.b - DOPRI5.b_error
    assert DOPRI5.b_error.sum() == pytest.approx(0.0, abs=COEF_TOL)
    c, A = DOPRI5.c, DOPRI5.A
    for value, expected in [
        (bhat.sum(), 1), (bhat @ c, 1 / 2), (bhat @ c**2, 1 / 3), (bhat @ A @ c, 1 / 6),
        (bhat @ c**3, 1 / 4), (bhat @ A @ A @ c, 1 / 24),
    ]:  # fmt: skip
        assert value == pytest.approx(expected, abs=10 * COEF_TOL)
    np.testing.assert_array_equal(A[-1], DOPRI5.b)  # first same as last


def test_generalized_alpha__coefficients():
    undamped = GeneralizedAlpha.from_rho(1.0)
    assert (undamped.alpha_m, undamped.alpha_f, undamped.gamma, undamped.beta) == (
        0.5, 0.5, 0.5, 0.25,
    )  # fmt: skip
    for rho in (0.0, 0.3, 0.8):
        c = GeneralizedAlpha.from_rho(rho)
        assert c.gamma == pytest.approx(0.5 + c.alpha_f - c.alpha_m)
        assert c.beta == pytest.approx(0.25 * (c.gamma + 0.5) ** 2)
        assert c.alpha_m <= c.alpha_f <= 0.5  # second order, unconditionally stable


def test_sincos__matches_numpy():
    rng = np.random.default_rng(1)
    quadrant_edges = (np.arange(-40, 41) + 0.5) * np.pi / 2
    for x in np.concatenate(
        [
            rng.uniform(-60, 60, 2000),
            rng.uniform(-1e5, 1e5, 200),
            np.arange(-8, 9) * np.pi / 4,
            np.nextafter(quadrant_edges, np.inf),
            np.nextafter(quadrant_edges, -np.inf),
        ]
    ):
        s, c = sincos(x)
        assert abs(s - np.sin(x)) <= SINCOS_TOL and abs(c - np.cos(x)) <= SINCOS_TOL


BAUMGARTE = (3.0, 7.0)
"""α, β of the accel kernels' checks at random states (:func:`accel_at_random_states`)."""
T_ACCEL = 0.3


def accel_at_random_states(
    module: Any, model: Model, topo: Topology, n: int = 5, seed: int = 7
) -> tuple[np.ndarray, ...]:
    """``module.accel`` at ``n`` random states near the model's start, off the constraints
    (Baumgarte :data:`BAUMGARTE` on, t = :data:`T_ACCEL`): the packed parameters P, Q, V,
    q̈, λ, max |Φ|, singular counts, each with the states along its last axis."""
    rng = np.random.default_rng(seed)
    Q = model.q0[0][:, None] + rng.normal(0.0, 0.02, (model.ndof, n))
    V = rng.normal(0.0, 1.0, (model.ndof, n))
    P = np.repeat(pack_parameters(model, topo), n, axis=1)
    qdd, lam = np.zeros((model.ndof, n)), np.zeros((model.ncon, n))
    chk, sing = np.zeros(n), np.zeros(n)
    alpha, beta = BAUMGARTE
    module.accel(P, Q, V, T_ACCEL, 2 * alpha, beta**2, 1e-8, qdd, lam, chk, sing)
    return P, Q, V, qdd, lam, chk, sing


@pytest.mark.parametrize(
    "name", ["loaded", "fourbar", "clearance_bar", "slider_crank", "telescope"]
)
def test_accel__matches_dense_kkt(name):
    """Generated lane evaluation == dense KKT solve, with Baumgarte, at random states."""
    model = scene_model(name)
    topo = Topology.from_model(model)
    module = lane_kernels(topo, "accel")
    P, Q, V, qdd, lam, chk, sing = accel_at_random_states(module, model, topo)
    n, t, (alpha, beta) = Q.shape[1], T_ACCEL, BAUMGARTE
    for j in range(n):
        ref_qdd, ref_lam = kkt_acceleration(model, 0, Q[:, j], V[:, j], t, (alpha, beta))
        np.testing.assert_allclose(qdd[:, j], ref_qdd, rtol=ACCEL_RTOL, atol=ACCEL_RTOL)
        np.testing.assert_allclose(lam[:, j], ref_lam, rtol=ACCEL_RTOL, atol=ACCEL_RTOL)
        phi = equations(model, 0, Q[:, j], V[:, j], t)[3]
        assert chk[j] == pytest.approx(np.abs(phi).max(), rel=1e-12)
        assert sing[j] == 0.0
    jf, cf = np.zeros((2 * model.njoint, n)), np.zeros((model.njoint, n))
    dtq, cerr, en = np.zeros((model.ndriver, n)), np.zeros(n), np.zeros(n)
    module.outputs(P, Q, V, lam, t, jf, cf, dtq, cerr, en)
    for j in range(n):
        assert en[j] == pytest.approx(energy(model, 0, Q[:, j], V[:, j]), rel=FORCE_RTOL)
    for k in range(model.njoint):
        row = model.joint_row[k]
        if model.joint_kind[k] == JointKind.IDEAL:
            np.testing.assert_allclose(jf[2 * k : 2 * k + 2], -lam[row : row + 2], rtol=1e-15)
            assert np.isnan(cf[k]).all()
        elif model.joint_kind[k] == JointKind.PRISMATIC:  # normal force; the couple in cf
            np.testing.assert_allclose(np.hypot(*jf[2 * k : 2 * k + 2]), np.abs(lam[row]))
            np.testing.assert_allclose(cf[k], -lam[row + 1], rtol=1e-15)
        else:
            np.testing.assert_allclose(cf[k], lam[row], rtol=1e-15)
            np.testing.assert_allclose(np.hypot(*jf[2 * k : 2 * k + 2]), np.abs(lam[row]))
    np.testing.assert_allclose(dtq, -lam[model.driver_row], rtol=1e-15)


def test_methods__table_lists_every_method():
    assert set(METHODS) == {"rk4", "rk4-projection", "generalized-alpha", "rk45", "radau"}


def test_simulate__output_dt_not_a_multiple_of_dt_is_a_scene_error():
    model = scene_model("clearance_bar")
    with pytest.raises(SceneError, match=r"^simulate\.output_dt: .*multiple of dt"):
        simulate(model, dict(t_end=0.01, dt=1e-4, output_dt=2.5e-4))


def test_simulate__bad_perturb_path_is_a_scene_error():
    model = scene_model("clearance_bar")
    with pytest.raises(SceneError, match=r"^simulate\.perturb\.body\.nope\.angle: no body"):
        simulate(model, dict(t_end=0.01, dt=1e-4, perturb={"body.nope.angle": 0.1}))


def test_simulate__perturbed_start_is_projected_onto_the_constraints():
    model = scene_model("double_pendulum")
    out = simulate(
        model,
        dict(
            t_end=1e-3, dt=1e-4, perturb={"body.bar2.angle": 0.1, "body.bar1.angular_velocity": 2.0}
        ),
        history_dtype=np.float64,
    )
    q0, v0 = out["q"][0, 0], out["v"][0, 0]
    assert q0[1, 2] == model.q0[0, 5] + 0.1  # the perturbed coordinate is kept
    assert v0[0, 2] == 2.0
    assert out["constraint_error"][0, 0] < 1e-12
    _, B, *_ = equations(model, 0, q0.ravel(), v0.ravel(), 0.0)
    assert np.abs(B @ v0.ravel()).max() < 1e-12
    assert out["status"][0] == 0


def _run_lane_body(lines: list[str], W: np.ndarray, kw: int = 0, kr: int = 0) -> np.ndarray:
    """Execute straight-line lane code in Python for lane 0 (the loop body as generated;
    ``kw``, ``kr``: the fixed step's stage rows, this stage's and the previous one's)."""
    import math

    scope = dict(np=np, math=math, W=W, l=0, ah=0.3, ts=0.1, tau=1e-12, kw=kw, kr=kr,
                 balpha2=20.0, bbeta2=100.0)  # fmt: skip
    exec("\n".join(lines), scope)
    return W


def test_demand_order__same_stores_as_written():
    """Scheduling lane code keeps every value: reads after a store see it, redefinitions and
    += chains keep their order; then on a real generated body (a 3-bar chain with a clearance
    joint, a spring and a load), executed in Python."""
    from mcchain.codegen.generate import _blocks, _fill, _tokens
    from mcchain.codegen.layout import LMAX, Layout
    from mcchain.codegen.schedule import demand_order
    from mcchain.scene import compile_model, load_scene_text
    from mcchain.testing.factory import chain_scene_text

    body = [
        "a = W[0 + l]",
        "b = W[64 + l] + a",
        "W[0 + l] = b * 2.0",
        "c = W[0 + l] + 1.0",
        "a = a + c",
        "F0 = a * 1.5",
        "F0 += b",
        "W[128 + l] = F0",
        "W[64 + l] = W[64 + l] * 3.0 + c",
    ]
    start = np.arange(1.0, 200.0)
    assert np.array_equal(
        _run_lane_body(demand_order(body), start.copy()), _run_lane_body(body, start.copy())
    )

    model = compile_model(load_scene_text(chain_scene_text(3, {1}, 5, springs=1, forces=1)))
    topo = Topology.from_model(model)
    lay = Layout(topo, RK4.nstage, fixed_step=True)
    template = "for l in range(nl):\n    @@load_params\n    @@load_stage_sub\n    @@accel_stage\n"
    template += "    @@store_stage\n"
    blocks = _blocks(topo, RK4, lay)
    text = _fill(template, blocks, _tokens(topo, RK4.nstage, lay), lay)
    stage = {"kr": lay.rows["kq0"] * LMAX, "kw": lay.rows["kq1"] * LMAX}  # stage 1's rows
    body = [line.strip() for line in text.splitlines()[1:] if line.strip()]
    rng = np.random.default_rng(3)
    W = rng.uniform(0.5, 1.5, lay.size * LMAX)
    q = slice(lay.rows["q"] * LMAX, (lay.rows["q"] + topo.ndof) * LMAX)
    W[q] = np.repeat(model.q0[0], LMAX)
    expected = _run_lane_body(body, W.copy(), **stage)
    assert np.isfinite(expected).all()
    assert np.array_equal(_run_lane_body(demand_order(body), W.copy(), **stage), expected)


def _index1_functions(model, sim):
    """f(t, y) and ∂f/∂y of the index-1 equations of sample 0 as the compiled Radau
    evaluates them (:func:`mcchain.kernels.radau.radau_rhs` and ``radau_jacobian``)."""
    from mcchain.kernels import radau as kr
    from mcchain.kernels.clearance import NCST
    from mcchain.kernels.forces import mass_diagonal
    from mcchain.scene.models import Simulate
    from mcchain.solvers.simulate import SINGULAR_PIVOT

    km = model.kernel_model()
    cols, first = model.constraint_pattern()
    ncon, ndof = model.ncon, model.ndof
    minv = np.zeros(ndof)
    mass_diagonal(km, 0, minv)
    acc = (1.0 / minv, cols, first, np.zeros((0, NCST)), np.zeros((ncon, 3)),
           np.zeros((ncon, ndof)), np.zeros((ncon, ncon)), np.zeros(ndof), np.zeros(ncon),
           np.zeros(ncon), np.zeros(ndof), np.zeros(ncon))  # fmt: skip
    alpha, beta = Simulate(**sim).gains
    args = (2.0 * alpha, beta * beta, SINGULAR_PIVOT, acc)

    def rhs(t, y):
        f = np.zeros(2 * ndof)
        assert kr.radau_rhs(km, 0, t, np.ascontiguousarray(y), f, *args)
        return f

    def jac(t, y):
        y = np.ascontiguousarray(y)
        J = np.zeros((2 * ndof, 2 * ndof))
        work = (np.zeros(2 * ndof), np.zeros(2 * ndof))
        assert kr.radau_jacobian(km, 0, t, y, rhs(t, y), J, *work, *args)
        return J

    return rhs, jac


def test_radau__takes_the_steps_scipy_takes_with_the_same_jacobian():
    """The compiled Radau (:mod:`mcchain.kernels.radau`) is scipy's Radau step for step:
    given the Jacobian it forms, scipy's ``solve_ivp(method="Radau")`` on the same
    right-hand side takes the same accepted steps with the same evaluations (``nfev``) and
    ends at the same state, to rounding; ``rejected_steps`` is -1 (not counted)."""
    from scipy.integrate import solve_ivp

    model = scene_model("clearance_bar")
    sim = dict(t_end=0.05, dt=0.01, output_dt=0.05, method="radau", rtol=1e-8, atol=1e-10)
    res = simulate(model, sim, history_dtype=np.float64, diagnostics=True)
    rhs, jac = _index1_functions(model, sim)
    y0 = np.concatenate([model.q0[0], model.v0[0]])
    sol = solve_ivp(rhs, (0.0, 0.05), y0, method="Radau", rtol=1e-8, atol=1e-10, jac=jac)
    assert sol.status == 0 and res["steps"].shape == (1,)
    assert res["steps"][0] == len(sol.t) - 1 > 5
    assert res["evaluations"][0] == sol.nfev
    assert res["rejected_steps"][0] == -1
    end = np.concatenate([res["q"][0, -1].ravel(), res["v"][0, -1].ravel()])
    # To rounding of the state's size: scipy solves its Newton systems with LAPACK, the
    # kernel with its own LU, so an entry near 0 may differ by ulps of the largest entry
    # (5e-14 on an entry of 0.03 next to one of 1.3, after issue 28 reordered Φ's arithmetic).
    scale = np.abs(sol.y[:, -1]).max()
    np.testing.assert_allclose(end, sol.y[:, -1], rtol=0.0, atol=1e-12 * scale)
    assert all(res[k].dtype == np.int64 for k in ("steps", "rejected_steps", "evaluations"))


DIAGNOSTICS = ("steps", "rejected_steps", "evaluations")


@pytest.mark.parametrize("method", ["rk4", "rk4-projection", "generalized-alpha"])
def test_diagnostics__fixed_step_counts_are_exact(method):
    """Fixed steps: t_end / dt accepted steps, none rejected; RK4 evaluates 4 stages a step
    and stage 0 once more at t_end; generalized-α one residual at the start and at least one
    per step (Newton), at most ``max_newton``. A sample failed on entry counts nothing."""
    from mcchain.status import ASSEMBLY_FAILED

    model = scene_model("clearance_bar", nsample=2)
    sim = dict(t_end=0.05, dt=1e-3, method=method, max_newton=20)
    status = np.array([0, ASSEMBLY_FAILED], np.uint32)
    # float64 histories as the other clearance-bar tests: their lane entries, compiled once
    res = simulate(model, sim, status=status, diagnostics=True, history_dtype=np.float64)
    nstep = 50
    assert res["status"][0] == 0
    for key in DIAGNOSTICS:
        assert res[key].dtype == np.int64 and res[key].shape == (2,)
        assert res[key][1] == 0
    assert res["steps"][0] == nstep and res["rejected_steps"][0] == 0
    if method == "generalized-alpha":
        assert 1 + nstep <= res["evaluations"][0] <= 1 + 20 * nstep
    else:
        assert res["evaluations"][0] == 4 * nstep + 1


def test_diagnostics__rk45_counts_attempts_and_fsal_stages(monkeypatch):
    """rk45: accepted + rejected = the attempts its step limit counts (a limit of that many
    passes, one fewer flags DIVERGED); evaluations = 1 + 6 per attempt (7 stages, the last
    reused as the next first: FSAL)."""
    import mcchain.solvers.simulate as simulate_module
    from mcchain.status import DIVERGED

    model = scene_model("clearance_bar")
    sim = dict(t_end=0.05, dt=0.05, output_dt=0.05, method="rk45", rtol=1e-9, atol=1e-11)
    res = simulate(model, sim, diagnostics=True, history_dtype=np.float64)  # as above
    steps, rejected = int(res["steps"][0]), int(res["rejected_steps"][0])
    attempts = steps + rejected
    assert res["status"][0] == 0 and steps > 5 and rejected > 0
    assert res["evaluations"][0] == 1 + (DOPRI5.nstage - 1) * attempts
    monkeypatch.setattr(simulate_module, "ADAPTIVE_MAX_STEPS", attempts)
    assert simulate(model, sim, history_dtype=np.float64)["status"][0] == 0
    monkeypatch.setattr(simulate_module, "ADAPTIVE_MAX_STEPS", attempts - 1)
    assert simulate(model, sim, history_dtype=np.float64)["status"][0] & DIVERGED


ONE_TURN = 2.0 * np.pi / 20.0  # s: one turn of the four-bar's crank at 20 rad/s


@pytest.mark.parametrize(
    ("method", "kernels"),
    [("rk4", "lanes"), ("rk4", "loop"), ("generalized-alpha", "lanes"), ("rk45", "lanes")],
)
def test_simulate__one_crank_turn_ends_at_t_end_with_the_written_grid(method, kernels):
    """t_end = 2π/ω is no whole number of output_dt: the stored times are k · output_dt,
    then t_end itself, and the crank has turned exactly once at the last output (the fixed
    steps are dt as written, the last one shortened to land on t_end)."""
    from mcchain.solvers.statics import assemble
    from mcchain.testing.scenes import fourbar_text, model_of

    model = model_of(fourbar_text().replace("clearance = 1e-4\n", ""))  # ideal: no contact loss
    start = assemble(model)
    settings = dict(t_end=ONE_TURN, dt=1e-4, output_dt=1e-3, method=method, kernels=kernels)
    out = simulate(model, settings, start.q, start.v, np.float64, diagnostics=True)
    assert out["status"][0] == 0
    time = out["time"]
    assert len(time) == 315 + 1  # 0, 1, …, 314 ms, then t_end = 314.159… ms
    assert time[-1] == ONE_TURN
    assert np.array_equal(time[:-1], np.arange(315) * 1e-3)
    crank = out["q"][0, :, 0, 2]
    np.testing.assert_allclose(crank[-1] - crank[0], 2.0 * np.pi, rtol=0, atol=1e-9)
    if method in ("rk4", "generalized-alpha"):
        assert out["steps"][0] == 314 * 10 + 2  # then 0.1 ms and 0.059 ms to t_end


def test_simulate__a_whole_number_of_outputs_keeps_the_written_grid():
    from mcchain.scene.loading import load_section
    from mcchain.scene.models import Simulate
    from mcchain.solvers.grid import output_times

    section = load_section(Simulate, "simulate", dict(t_end=0.05, dt=1e-4, output_dt=1e-3))
    grid = output_times(section)
    assert grid.dt == 1e-4 and grid.every == 10 and grid.nstep == 500 and grid.last_step == 1e-4
    np.testing.assert_array_equal(grid.time, np.arange(51) * 1e-3)
