"""What the time integrators cost for the accuracy they give (``bench_simulate.py``,
``bench_chains.py``).

Sections (each prints a markdown table and saves a PNG chart into the output folder, plus
``bench.md`` with every table):

* ``work-precision``: error against ``radau`` at rtol 1e-12 versus CPU time per instance, for
  every method over a range of steps/tolerances, on the clearance bar, the double pendulum
  with a clearance joint and the driven four-bar with a clearance joint.
* ``stability``: the largest stable step versus clearance (1e-6 … 1e-2 m) per method on the
  clearance bar, with RK4's linear limit 2√2/p_max (p_max from the eigen step).
* ``drift``: max |Φ| over time for rk4 with and without Baumgarte, and rk4-projection.
* ``speed``: ns per instance-step of every method on the double pendulum with a clearance
  joint and the driven four-bar with a clearance joint, 10⁴ samples, 1 and 2 threads.
* ``chains``: rk4 on chains of N = 2 … 32 bars against MuJoCo's ``mujoco.rollout`` (RK4,
  same step; optional dependency) and against scipy ``solve_ivp`` per instance.

Timings are wall-clock minima over repeats, measured side by side in one run; on a busy
machine the CPU time is printed beside them.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mcchain.model import Model
from mcchain.status import Status
from mcchain.testing.closed_forms import imaginary_axis_limit
from mcchain.testing.comparisons import HISTORIES, REFERENCE, simulate_float64
from mcchain.testing.scenes import DOUBLE_PENDULUM, fourbar_text, model_of
from mcchain.testing.scenes import SCENES as SCENE_TEXTS
from mcchain.testing.scenes import straight_chain_text as chain_text
from mcchain.testing.scenes import swinging_bar_text as clearance_bar_text

SECTIONS = ("work-precision", "stability", "drift", "speed", "chains")

SCENES: dict[str, Callable[[], str]] = {
    c.name: (lambda c=c: SCENE_TEXTS[c.scene]()) for c in HISTORIES
}
"""The work-precision and speed scenes: those of the tests' history comparisons."""
T_END = {c.name: c.t_end for c in HISTORIES}


# ---------------------------------------------------------------------------------------------
# Helpers


def _simulate(model: Model, **sim: Any) -> dict[str, np.ndarray]:
    # The generated lanes, always: kernels = "auto" would take the loop kernels for short
    # runs of the longest chains, and these tables compare the lanes.
    return simulate_float64(model, {"kernels": "lanes", **sim}, diagnostics=True)


def _timed(fn: Callable[..., Any], repeat: int = 3) -> tuple[float, float, Any]:
    """(best wall s, best CPU s, last result) over ``repeat`` calls."""
    wall, cpu, result = math.inf, math.inf, None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        result = fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu, result


def _table(header: list[str], rows: list[list[Any]]) -> str:
    def cell(x: Any) -> str:
        if isinstance(x, float):
            return "–" if not math.isfinite(x) else f"{x:.3g}"
        return str(x)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(x) for x in row) + " |" for row in rows]
    return "\n".join(lines)


def _figure(ncols: int = 1):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, ncols, figsize=(5.2 * ncols, 4.2), squeeze=False)
    return fig, axes[0]


def _threads(n: int) -> None:
    import numba

    numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))  # type: ignore[attr-defined]


# ---------------------------------------------------------------------------------------------
# Sections


def work_precision(out: Path, quick: bool) -> str:
    """Error vs radau (rtol 1e-12) against CPU time per instance, every method, 3 scenes."""
    nbatch = 64
    fixed = [2e-3, 1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5, 2e-5, 1e-5]
    tols = [1e-4, 1e-6, 1e-8, 1e-10]
    if quick:
        fixed, tols = fixed[1::2], tols[::2]
    rows = []
    fig, axes = _figure(len(SCENES))
    _threads(1)
    for ax, (scene, text) in zip(axes, SCENES.items(), strict=True):
        t_end = T_END[scene]
        model = model_of(text())
        batch = model_of(text(), nsample=nbatch)
        out_dt = 0.01  # a multiple of every fixed step in the sweep
        ref = _simulate(model, t_end=t_end, dt=out_dt, output_dt=out_dt, **REFERENCE)["q"][0]
        for method in ("rk4", "rk4-projection", "generalized-alpha", "rk45", "radau"):
            xs, ys = [], []
            sweep = fixed if method in ("rk4", "rk4-projection", "generalized-alpha") else tols
            for value in sweep:
                if method in ("rk45", "radau"):
                    sim = dict(t_end=t_end, dt=out_dt, output_dt=out_dt, method=method,
                               rtol=value, atol=value * 1e-2)  # fmt: skip
                else:
                    sim = dict(t_end=t_end, dt=value, output_dt=out_dt, method=method)
                m, n = (model, 1) if method == "radau" else (batch, nbatch)
                _simulate(m.select(0, 1), **dict(sim, t_end=out_dt))  # compile outside timing
                wall, _, res = _timed(lambda m=m, sim=sim: _simulate(m, **sim), repeat=1 if
                                      method == "radau" else 2)  # fmt: skip
                err = float(np.nanmax(np.abs(res["q"][0] - ref)))
                if not np.all(np.isfinite(res["q"][0])):
                    err = math.inf
                per = wall / n
                rows.append([scene, method, value, err, per * 1e6])
                if math.isfinite(err):
                    xs.append(per)
                    ys.append(max(err, 1e-16))
            ax.loglog(xs, ys, "o-", label=method)
        ax.set_title(scene)
        ax.set_xlabel("time per instance, s (1 thread)")
        ax.set_ylabel("max position error vs radau 1e-12, m")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "work_precision.png", dpi=110)
    return _table(["scene", "method", "dt or rtol", "error (m)", "µs / instance"], rows)


def stability(out: Path, quick: bool) -> str:
    """Stability against clearance on the clearance bar, every method.

    Fixed-step methods: the largest stable step (bisection). Adaptive ones have no step to
    choose, so their mean accepted step at rtol 1e-6 on the released bar (0.3 rad) is charted
    beside the linear limits of an undamped mode, y/p_max, with y where |R(iy)| first exceeds
    1 for the method's stability function R (2√2 for RK4; ≈ 1.0 for Dormand–Prince).
    """
    from mcchain.kernels.tableaux import DOPRI5, RK4

    clearances = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2] if not quick else [1e-5, 1e-3]
    fixed = ["rk4", "rk4-projection", "generalized-alpha"]
    adaptive = ["rk45", "radau"]
    t_end, rtol = 0.2, 1e-6
    y_rk4, y_dp = imaginary_axis_limit(RK4.A, RK4.b), imaginary_axis_limit(DOPRI5.A, DOPRI5.b)
    rows: list[list[Any]] = []
    steps: dict[str, list[float]] = {m: [] for m in fixed + adaptive}
    p_maxes = []
    for c in clearances:
        model = model_of(clearance_bar_text(clearance=c, tilt=0.0))
        p_max = _p_max(model)
        p_maxes.append(p_max)
        for method in fixed:
            best = _largest_stable_step(model, method, 1e-6, 0.05)
            steps[method].append(best)
            # generalized-α is unconditionally stable: no linear limit (searched up to 0.05 s)
            linear = y_rk4 / p_max if method.startswith("rk4") else math.inf
            rows.append([c, method, p_max, linear, "largest stable step", best, "–"])
        swinging = model_of(clearance_bar_text(clearance=c, tilt=0.3))
        for method in adaptive:
            sim = dict(t_end=t_end, dt=1e-4, output_dt=t_end, method=method, rtol=rtol, atol=1e-9)
            res = _simulate(swinging, **sim)
            mean = t_end / float(res["steps"][0])
            steps[method].append(mean)
            flags = Status(int(res["status"][0])).name or "ok"
            linear = y_dp / p_max if method == "rk45" else math.inf  # radau: A-stable
            rows.append([c, method, p_max, linear, f"mean step, rtol {rtol:g}", mean, flags])
    fig, axes = _figure(2)
    limits = np.array([1.0 / p for p in p_maxes])
    for ax, methods, lims in (
        (axes[0], fixed, [(y_rk4, "RK4: 2√2 / p_max")]),
        (axes[1], adaptive, [(y_dp, f"DOPRI5: {y_dp:.3f} / p_max"), (y_rk4, "RK4: 2√2 / p_max")]),
    ):
        for method in methods:
            ax.loglog(clearances, steps[method], "o-", label=method)
        for (y, label), style in zip(lims, ("k--", "k:"), strict=False):
            ax.loglog(clearances, y * limits, style, label=label)
        ax.set_xlabel("clearance, m")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("largest stable step, s")
    axes[0].set_title("clearance bar: fixed steps")
    axes[1].set_ylabel(f"mean accepted step (rtol {rtol:g}), s")
    axes[1].set_title("clearance bar released at 0.3 rad: adaptive")
    fig.tight_layout()
    fig.savefig(out / "stability.png", dpi=110)
    header = ["clearance (m)", "method", "p_max (rad/s)", "linear limit (s)", "measure", "step (s)",
              "flags"]  # fmt: skip
    return _table(header, rows)


def _p_max(model: Model) -> float:
    """Largest eigenpulsation at the equilibrium (mcchain.solvers.statics)."""
    from mcchain.solvers.statics import assemble, solve_equilibrium, solve_modes

    assembled = assemble(model)
    eq = solve_equilibrium(model, assembled.q, assembled.status)
    return float(np.nanmax(solve_modes(model, eq).omega))


def _largest_stable_step(
    model: Model, method: str, lo: float, hi: float, steps: int = 400
) -> float:
    """Bisection (in log dt) on 'not flagged over ``steps`` steps from the equilibrium + 1e-8
    rad'; generalized-α also needs the energy not to grow."""

    def stable(dt: float) -> bool:
        sim = dict(t_end=steps * dt, dt=dt, method=method, perturb={"body.bar.angle": 1e-8})
        res = _simulate(model, **sim)
        e = res["energy"][0]
        return res["status"][0] == 0 and bool(np.all(e <= e[0] + 1e-9 * abs(e[0]) + 1e-12))

    if stable(hi):
        return hi
    if not stable(lo):
        return math.nan
    for _ in range(12):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def drift(out: Path, quick: bool) -> str:
    """max |Φ| over 2 s of the double pendulum with clearance (dt 1e-4)."""
    model = model_of(SCENES["double pendulum, clearance"]())
    t_end = 0.5 if quick else 2.0
    cases: dict[str, dict[str, Any]] = {
        "rk4, Baumgarte (default)": dict(method="rk4"),
        "rk4, no Baumgarte": dict(method="rk4", baumgarte=[0.0, 0.0]),
        "rk4-projection": dict(method="rk4-projection"),
    }
    fig, axes = _figure()
    rows = []
    for label, extra in cases.items():
        res = _simulate(model, t_end=t_end, dt=1e-4, output_dt=1e-3, constraint_tolerance=1.0,
                        **extra)  # fmt: skip
        err = res["constraint_error"][0]
        axes[0].semilogy(res["time"], np.maximum(err, 1e-18), label=label)
        rows.append([label, float(err[len(err) // 2]), float(err[-1]), float(np.nanmax(err))])
    axes[0].set_xlabel("time, s")
    axes[0].set_ylabel("max |Φ|, m")
    axes[0].set_title("double pendulum with clearance, dt = 1e-4 s")
    axes[0].grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "drift.png", dpi=110)
    return _table(["case", "max abs Φ at t/2 (m)", "at the end (m)", "overall (m)"], rows)


def speed(out: Path, quick: bool, nsample: int = 10_000, threads=(1, 2)) -> str:
    """ns per instance-step of every method (dt 1e-4), 1 and 2 threads."""
    from mcchain.codegen.layout import LMAX as LANES

    nsample = min(nsample, 1000) if quick else nsample
    # the double pendulum of the chains section (both bars at −60°), so that MuJoCo's
    # rollout of its ideal-joint twin below measures the same mechanism
    scenes: dict[str, Callable[[], str]] = {
        "double pendulum, clearance": lambda: chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4}),
        "four-bar, clearance": fourbar_text,
    }
    rows = []
    fig, axes = _figure()
    labels: list[str] = []
    values: dict[int, list[float]] = {th: [] for th in threads}
    for scene, text in scenes.items():
        for method in ("rk4", "rk4-projection", "rk45", "generalized-alpha", "radau"):
            n = (
                1
                if method == "radau"
                else (nsample if method != "generalized-alpha" else nsample // 4)
            )
            model = model_of(text(), nsample=n)
            # 2,000 steps for the explicit methods (a run's set-up — start state, parameter
            # packing, output arrays — is part of the figure but not all of it); the slow
            # methods 100 steps.
            t_end = 0.01 if method in ("generalized-alpha", "radau") else 0.2
            sim = dict(t_end=t_end, dt=1e-4, output_dt=1e-2, method=method, rtol=1e-8, atol=1e-10)
            if method == "radau":
                sim["output_dt"] = sim["dt"] = t_end
            _simulate(model.select(0, 1), **dict(sim, t_end=sim["output_dt"]))
            for th in threads:
                _threads(th)
                wall, cpu, res = _timed(lambda m=model, s=sim: _simulate(m, **s), repeat=2)
                if method in ("rk45", "radau"):
                    steps = (
                        float(np.sum(res.get("steps", [np.nan]))) if method == "rk45" else math.nan
                    )
                else:
                    steps = n * round(t_end / 1e-4)
                ns = wall / steps * 1e9 if steps == steps else wall / n * 1e9
                unit = "ns / instance-step" if steps == steps else "ns / instance (0.01 s)"
                rows.append([scene, method, th, n, ns, cpu / (steps if steps == steps else n) * 1e9,
                             unit])  # fmt: skip
                if method in ("rk4", "rk4-projection", "rk45"):
                    values[th].append(ns)
            if method in ("rk4", "rk4-projection", "rk45"):
                labels.append(f"{method}\n{scene.split(',')[0]}")
    # The reference of issue #3, side by side: MuJoCo's RK4 rollout of the ideal-joint double
    # pendulum (minimal coordinates), and mcchain's rk4 on the same ideal-joint scene.
    ideal = model_of(chain_text(**DOUBLE_PENDULUM), nsample=nsample)
    sim = dict(t_end=0.2, dt=1e-4, output_dt=1e-2, method="rk4")
    _simulate(ideal.select(0, 1), **dict(sim, t_end=1e-2))
    mj_steps = 200 if not quick else 20
    ratios = []
    for th in threads:
        _threads(th)
        wall, cpu, _ = _timed(lambda s=sim: _simulate(ideal, **s), repeat=2)
        ours = wall / (nsample * 2000) * 1e9
        rows.append(["double pendulum, ideal", "rk4", th, nsample, ours,
                     cpu / (nsample * 2000) * 1e9, "ns / instance-step"])  # fmt: skip
        mj = _mujoco_chain(**DOUBLE_PENDULUM, dt=1e-4, nstep=mj_steps, nsample=nsample, threads=th)
        rows.append(["double pendulum, ideal", "MuJoCo rollout, RK4", th, nsample, mj, math.nan,
                     "ns / instance-step"])  # fmt: skip
        clearance = next(r[4] for r in rows if r[:3] == ["double pendulum, clearance", "rk4", th])
        ratios.append(f"{th} thread(s): MuJoCo / mcchain = {mj / ours:.0f}× (ideal joints), "
                      f"{mj / clearance:.0f}× against the clearance version")  # fmt: skip
    x = np.arange(len(labels))
    for i, th in enumerate(threads):
        axes[0].bar(x + 0.4 * i, values[th], width=0.4, label=f"{th} thread(s)")
    axes[0].set_xticks(x + 0.2, labels, fontsize=7)
    axes[0].set_ylabel(f"ns per instance-step (lanes = {LANES})")
    axes[0].axhline(50, color="k", ls="--", lw=0.8)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "speed.png", dpi=110)
    _threads(max(threads))
    table = _table(["scene", "method", "threads", "samples", "wall ns", "CPU ns", "unit"], rows)
    return table + "\n\n" + "; ".join(ratios) + "."


def chains(out: Path, quick: bool, nsample: int = 10_000, threads: int = 2) -> str:
    """rk4 on chains of N bars vs MuJoCo rollout (RK4) and scipy solve_ivp, per instance-step."""
    sizes = [2, 4, 8, 16, 32] if not quick else [2, 4, 8]
    dt, nstep = 1e-4, 200 if not quick else 50
    nsample = min(nsample, 2000) if quick else nsample
    rows = []
    ours, mj, sp = [], [], []
    _threads(threads)
    for n_bar in sizes:
        lengths = [0.6, 0.4] if n_bar == 2 else [1.0 / n_bar] * n_bar
        masses = [1.5, 1.0] if n_bar == 2 else [1.0 / n_bar] * n_bar
        model = model_of(chain_text(lengths, masses), nsample=nsample)
        sim = dict(t_end=nstep * dt, dt=dt, output_dt=nstep * dt / 2, method="rk4")
        t0 = time.perf_counter()
        _simulate(model.select(0, 1), **dict(sim, t_end=dt, output_dt=dt))
        compile_s = time.perf_counter() - t0
        wall, _, _ = _timed(lambda m=model, s=sim: _simulate(m, **s), repeat=3)
        a = wall / (nsample * nstep) * 1e9
        b = _mujoco_chain(lengths, masses, dt, nstep, nsample, threads)
        c = _scipy_chain(model, dt)
        ours.append(a)
        mj.append(b)
        sp.append(c)
        rows.append([n_bar, a, b, b / a, c, c / a, compile_s])
    fig, axes = _figure()
    ax = axes[0]
    ax.loglog(sizes, ours, "o-", label="mcchain rk4 (lanes)")
    if np.isfinite(mj).any():
        ax.loglog(sizes, mj, "s-", label="MuJoCo rollout, RK4")
    ax.loglog(sizes, sp, "^-", label="scipy solve_ivp, dense KKT")
    slope = float(np.polyfit(np.log(sizes), np.log(ours), 1)[0])
    ax.set_title(f"chains, dt = {dt:g} s, {threads} threads (mcchain ∝ N^{slope:.2f})")
    ax.set_xlabel("bars N")
    ax.set_ylabel("ns per instance-step")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "chains.png", dpi=110)
    table = _table(["N", "mcchain ns", "MuJoCo ns", "MuJoCo/mcchain", "scipy ns", "scipy/mcchain",
                    "compile s"], rows)  # fmt: skip
    return table + f"\n\nmcchain cost ∝ N^{slope:.2f} (fit over N = {sizes[0]}…{sizes[-1]})."


def _mujoco_chain(lengths, masses, dt, nstep, nsample, threads, cpu=False) -> float:
    """ns per instance-step of ``mujoco.rollout`` on the same chain (hinges, RK4); NaN if
    mujoco is not installed (``pip install mujoco``). ``cpu``: this process's CPU time
    instead of wall time (one thread: not stretched by other jobs on a shared machine)."""
    try:
        import mujoco
        from mujoco import rollout
    except ImportError:
        return math.nan

    def nest(i: int) -> str:
        if i == len(lengths):
            return ""
        length, mass = lengths[i], masses[i]
        inertia = mass * length**2 / 12
        pos = "0 0 0" if i == 0 else f"{lengths[i - 1]} 0 0"
        return (
            f'<body pos="{pos}"><joint type="hinge" axis="0 1 0"/>'
            f'<inertial pos="{length / 2} 0 0" mass="{mass}" '
            f'diaginertia="{inertia} {inertia} {inertia}"/>'
            f'<geom type="capsule" fromto="0 0 0 {length} 0 0" size="0.01" contype="0" '
            f'conaffinity="0"/>{nest(i + 1)}</body>'
        )

    body = nest(0)
    xml = (
        f'<mujoco><option timestep="{dt}" integrator="RK4" gravity="0 0 -9.81"/>'
        f"<worldbody>{body}</worldbody></mujoco>"
    )
    model = mujoco.MjModel.from_xml_string(xml)
    datas = [mujoco.MjData(model) for _ in range(threads)]
    state0 = np.zeros(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    data = mujoco.MjData(model)
    data.qpos[0] = math.pi / 3
    mujoco.mj_getState(model, data, state0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    initial = np.tile(state0, (nsample, 1))
    rollout.rollout(model, datas, initial[:8], nstep=2)
    wall, cpu_time, _ = _timed(
        lambda: rollout.rollout(model, datas, initial, nstep=nstep), repeat=2
    )
    return (cpu_time if cpu else wall) / (nsample * nstep) * 1e9


def _scipy_chain(model: Model, dt: float, nstep: int = 20) -> float:
    """ns per step of scipy ``solve_ivp`` (RK45 held at dt) with a dense NumPy KKT right-hand
    side, one instance (the plain 'loop over instances' baseline)."""
    from scipy.integrate import solve_ivp

    from mcchain.kernels.forces import applied_forces, mass_diagonal
    from mcchain.kernels.joints import constraint_gamma, constraint_jacobian

    km = model.kernel_arrays()
    n, m = model.ndof, model.ncon
    M, F, B, g = np.zeros(n), np.zeros(n), np.zeros((m, n)), np.zeros(m)
    mass_diagonal(km, 0, M)
    K = np.zeros((n + m, n + m))

    def rhs(t, y):
        q, v = y[:n], y[n:]
        applied_forces(km, 0, q, v, t, F)
        constraint_jacobian(km, 0, q, B)
        constraint_gamma(km, 0, q, v, t, g)
        K[:n, :n] = np.diag(M)
        K[:n, n:] = B.T
        K[n:, :n] = B
        x = np.linalg.solve(K, np.concatenate([F, g]))
        return np.concatenate([v, x[:n]])

    y0 = np.concatenate([model.q0[0], model.v0[0]])
    rhs(0.0, y0)
    t0 = time.perf_counter()
    sol = solve_ivp(rhs, (0, nstep * dt), y0, method="RK45", first_step=dt, max_step=dt,
                    rtol=1e3, atol=1e3)  # fmt: skip
    wall = time.perf_counter() - t0
    return wall / max(len(sol.t) - 1, 1) * 1e9


# ---------------------------------------------------------------------------------------------

_RUNNERS = {
    "work-precision": work_precision,
    "stability": stability,
    "drift": drift,
    "speed": speed,
    "chains": chains,
}


def main(args: list[str] | None = None) -> int:
    """Run the benchmark sections; write PNGs and ``bench.md`` into ``--out``."""
    parser = argparse.ArgumentParser(prog="bench", description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="bench", help="output folder (default ./bench)")
    parser.add_argument(
        "--only",
        default=",".join(SECTIONS),
        help=f"comma-separated sections: {', '.join(SECTIONS)}",
    )
    parser.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    ns = parser.parse_args(args)
    chosen = [s.strip() for s in ns.only.split(",") if s.strip()]
    unknown = [s for s in chosen if s not in _RUNNERS]
    if unknown:
        parser.error(f"--only: unknown section {unknown[0]!r}; one of {', '.join(SECTIONS)}")
    out = Path(ns.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in chosen:
        t0 = time.perf_counter()
        table = _RUNNERS[name](out, ns.quick)
        text = f"## {name}\n\n{table}\n\n![{name}]({name.replace('-', '_')}.png)\n"
        (out / f"{name.replace('-', '_')}.md").write_text(text)
        print(text, f"({time.perf_counter() - t0:.0f} s)\n", flush=True)
    # bench.md: every section present in the folder, so a partial rerun keeps the others.
    report = ["# mcchain bench\n"]
    for name in SECTIONS:
        part = out / f"{name.replace('-', '_')}.md"
        if part.exists():
            report.append(part.read_text())
    (out / "bench.md").write_text("\n".join(report))
    print(out / "bench.md")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
