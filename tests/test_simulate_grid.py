"""simulate: the output grid and the step are the ones written.

Stored times are k · output_dt (k = 0, 1, …) below t_end, then t_end itself, bit for bit; a
fixed-step method steps with the written dt and only its last step is shortened to land on
t_end; run.json counts the steps taken. The example is the issue's: t_end = 2π/10 (one crank
turn at 10 rad/s; two turns of the test four-bar's crank at 20 rad/s), output_dt = 1e-3,
dt = 1e-4.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from mcchain import open_run
from mcchain.runner import plan
from mcchain.scene.loading import load_section
from mcchain.scene.models import Simulate
from mcchain.solvers.grid import GRID_RTOL, output_times
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing.contact import Law
from mcchain.testing.scenes import fourbar_text, model_of

T_TURN = 0.6283185307179586  # s: 2π/10, not a whole number of output_dt nor of dt
T_WHOLE = 0.628  # s: a whole number of both; the stored point 628 of the T_TURN run
DT, OUTPUT_DT = 1e-4, 1e-3
OMEGA = 20.0  # rad/s, the test four-bar's crank

ANGLE_TOL = 1e-9  # rad: the crank's angle at t_end holds its driver to the constraint tolerance
REFERENCE_TOL = 1e-9  # rk4 (dt = 1e-4) vs rk45 at rtol 1e-12, both on t_end: 5e-13 m, 2e-11 N
GA_TOL = 1e-7  # generalized-α is second order: its reactions at t_end are 3.3e-6 N off
ONSET_TOL = 1e-9  # s: an onset located inside the short last step (the step is 1e-5 s)

FIXED = [("rk4", "lanes"), ("rk4", "loop"), ("rk4-projection", "lanes")]
FIXED += [("generalized-alpha", "lanes")]
ALL = [*FIXED, ("rk45", "lanes")]


def grid(t_end: float, method: str = "rk4", output_dt: float = OUTPUT_DT, dt: float = DT):
    return output_times(
        load_section(Simulate, "simulate", dict(t_end=t_end, dt=dt, output_dt=output_dt,
                                                method=method))
    )  # fmt: skip


@pytest.fixture(scope="module")
def fourbar():
    """The four-bar with ideal joints (no contact loss) and its assembled start."""
    model = model_of(fourbar_text().replace("clearance = 1e-4\n", ""))
    return model, assemble(model)


def history(fourbar, t_end: float, method: str, kernels: str = "lanes", **extra):
    model, start = fourbar
    settings = dict(t_end=t_end, dt=DT, output_dt=OUTPUT_DT, method=method, kernels=kernels)
    settings.update(extra)
    return simulate(model, settings, start.q, start.v, np.float64, diagnostics=True)


# ---------------------------------------------------------------------------------------------
# The grid


@pytest.mark.parametrize("method", ["rk4", "generalized-alpha", "rk45", "radau"])
def test_output_times__the_issue_example(method):
    g = grid(T_TURN, method)
    assert len(g.time) == 630
    k = np.arange(629)
    assert np.array_equal(g.time[:-1], k * OUTPUT_DT)  # exactly k · output_dt
    assert g.time[-1] == T_TURN  # bit for bit
    assert g.time[-2] == T_WHOLE
    if method in ("rk45", "radau"):
        assert g.nstep == 0  # adaptive: no schedule
        return
    # 628 intervals of 10 steps, then 3 whole steps and one of 0.0185 ms to land on t_end
    assert g.every == 10 and g.dt == DT and g.nstep == 6284
    assert g.last_step == T_TURN - (T_WHOLE + 3 * DT)
    assert 0.0 < g.last_step < DT
    assert g.step_time(6280) == T_WHOLE and g.step_time(6284) == T_TURN


@pytest.mark.parametrize(
    ("t_end", "points", "nstep"),
    [
        (T_WHOLE, 629, 6280),  # on both grids: no short step
        (0.3, 301, 3000),  # 0.3 / 1e-4 = 2999.9999999999995: rounding, not a step
        (0.6285, 630, 6285),  # on the step grid only: the last interval has 5 whole steps
        (0.05, 51, 500),
    ],
)
def test_output_times__t_end_on_the_step_grid_takes_no_short_step(t_end, points, nstep):
    g = grid(t_end)
    assert len(g.time) == points and g.time[-1] == t_end
    assert np.array_equal(g.time[:-1], np.arange(points - 1) * OUTPUT_DT)
    assert g.nstep == nstep and g.last_step == DT


def test_output_times__a_remainder_past_rounding_is_a_short_step():
    """GRID_RTOL separates rounding from a real remainder: 1e3 × GRID_RTOL · t_end past the
    last whole step is stepped (short), a tenth of GRID_RTOL · t_end is not."""
    real = grid(T_WHOLE * (1.0 + 1e3 * GRID_RTOL))
    assert real.nstep == 6281
    assert real.last_step == pytest.approx(1e3 * GRID_RTOL * T_WHOLE, rel=1e-3)
    assert real.time[-2] == T_WHOLE and len(real.time) == 630
    rounding = grid(T_WHOLE * (1.0 + 0.1 * GRID_RTOL))
    assert rounding.nstep == 6280 and rounding.last_step == DT and len(rounding.time) == 629


def test_output_times__output_dt_no_multiple_of_dt_is_refused_in_one_line():
    from mcchain.errors import SceneError

    with pytest.raises(SceneError, match=r"^simulate\.output_dt: must be a whole multiple"):
        grid(T_TURN, "rk4", output_dt=2.5e-4)
    assert grid(T_TURN, "rk45", output_dt=2.5e-4).time[-1] == T_TURN  # adaptive: allowed


def test_output_times__a_step_within_the_rounding_of_t_is_refused_in_one_line():
    """Fixed steps feed every start to the peak tracking, whose times must increase: a dt
    within STEP_ULPS ulps of t_end is refused (adaptive methods only start with it); one just
    past it gives strictly increasing starts, across an output time too."""
    from mcchain.errors import SceneError
    from mcchain.solvers.grid import STEP_ULPS

    t_end = 1.0
    with pytest.raises(SceneError, match=r"^simulate\.dt: .* within the rounding of the time"):
        grid(t_end, "rk4", dt=STEP_ULPS * math.ulp(t_end), output_dt=1e6 * math.ulp(t_end))
    assert grid(t_end, "rk45", dt=STEP_ULPS * math.ulp(t_end), output_dt=0.5).time[-1] == t_end
    g = grid(t_end, "rk4", dt=(STEP_ULPS + 1) * math.ulp(t_end), output_dt=0.25)
    for around in (2 * g.every, g.nstep - 2):  # the output time 0.5, then t_end
        starts = [g.step_time(n) for n in range(around - 2, min(around + 3, g.nstep + 1))]
        assert all(b > a for a, b in itertools.pairwise(starts))


# ---------------------------------------------------------------------------------------------
# The runs


@pytest.mark.parametrize(("method", "kernels"), ALL)
def test_simulate__the_issue_example_lands_on_t_end_with_the_written_step(fourbar, method, kernels):
    out = history(fourbar, T_TURN, method, kernels)
    assert out["status"][0] == 0
    time = out["time"]
    assert len(time) == 630 and time[-1] == T_TURN
    assert np.array_equal(time[:-1], np.arange(629) * OUTPUT_DT)
    # The crank has turned by ω t_end at the last point: the state is at t_end, and the
    # constraint error is evaluated there at the stored time (a state or a time off by one
    # ulp of a step, 1e-20 s, would not show; one of the stretched grid's steps would: 2e-5 rad).
    crank = out["q"][0, :, 0, 2]
    assert abs(crank[-1] - crank[0] - OMEGA * T_TURN) < ANGLE_TOL
    assert out["constraint_error"][0, -1] < ANGLE_TOL
    if method != "rk45":
        assert out["steps"][0] == 6284  # 6283 whole steps of dt, one of 0.0185 ms


@pytest.mark.parametrize(("method", "kernels"), ALL)
def test_simulate__states_at_0_628_are_the_same_bits_whatever_t_end(fourbar, method, kernels):
    """Step times come from the step index, not from t_end: the run to 0.628 and the run to
    2π/10 take the same steps up to 0.628 (rk45: the same accepted steps, each landing on
    the same output times)."""
    short = history(fourbar, T_WHOLE, method, kernels)
    long = history(fourbar, T_TURN, method, kernels)
    assert short["time"][-1] == long["time"][628] == T_WHOLE
    for name in ("q", "v"):
        assert np.array_equal(short[name][:, -1], long[name][:, 628]), name
        assert np.array_equal(short[name], long[name][:, :629]), name
    if method != "rk45":
        assert short["steps"][0] == 6280 and long["steps"][0] == 6284


@pytest.mark.parametrize(("method", "kernels"), FIXED)
def test_simulate__the_short_last_step_matches_an_adaptive_reference(fourbar, method, kernels):
    """The state at t_end after the short last step against rk45 at a tight tolerance, which
    lands on t_end by its own step control."""
    ref = history(fourbar, T_TURN, "rk45", rtol=1e-12, atol=1e-14)
    out = history(fourbar, T_TURN, method, kernels)
    tol = REFERENCE_TOL if method != "generalized-alpha" else GA_TOL
    np.testing.assert_allclose(out["q"][0, -1], ref["q"][0, -1], rtol=0, atol=tol)
    # the reactions at t_end as well (generalized-α: from the index-1 equations at the
    # landed state; its own multipliers after a fifth of a step were 0.7 % off)
    for name in ("driver_torque", "joint_force"):
        np.testing.assert_allclose(out[name][0, -1], ref[name][0, -1], rtol=0, atol=100 * tol)
    # and the last step is no whole one: stepping on to 0.6284 moves the state visibly
    on = history(fourbar, T_WHOLE + 4 * DT, method, kernels)
    assert np.abs(on["q"][0, -1] - out["q"][0, -1]).max() > 1e3 * tol


# ---------------------------------------------------------------------------------------------
# Contact: an onset inside the short last step


def test_simulate__an_onset_inside_the_short_last_step_is_located_in_it():
    """The journal of tests/test_contact_dynamics falls across its clearance and impacts the
    bottom; t_end is put inside the step that holds the impact, so the onset is found at the
    end of the short last step: its free-flight time is the reference's impact time only if
    that step is counted with its own length."""
    from test_contact_dynamics import journal_scene, reference, run

    dt = 1e-5
    law = Law("hertz", 1e9)
    t_impact = reference(law, 0.03, np.linspace(0.0, 0.03, 7)).impacts[0].time
    next_step = math.ceil(t_impact / dt) * dt
    t_end = t_impact + 0.5 * (next_step - t_impact)
    assert math.floor(t_end / dt) * dt < t_impact < t_end  # the impact is in the last step
    for method, kernels in (("rk4", "lanes"), ("rk4", "loop"), ("generalized-alpha", "lanes")):
        text = journal_scene(method=method, t_end=t_end, dt=dt, output_dt=50 * dt)
        out = run(text, kernels=kernels)
        assert out["status"][0] == 0 and out["time"][-1] == t_end, method
        assert out["impact_count"][0, 0] == 1, method
        # free flight from t = 0 up to the onset located in the last (short) step
        assert abs(out["free_flight_time"][0, 0] - t_impact) < ONSET_TOL, (method, kernels)


# ---------------------------------------------------------------------------------------------
# run.json and the stored file


SAMPLED = """
[sample]
count = 3
seed = 1
[sample.vary]
"body.rocker.mass" = { uniform = [0.2, 0.3] }
"""


@pytest.mark.parametrize("method", ["rk4", "rk45"])
def test_run__stores_the_grid_and_counts_the_steps_taken(tmp_path: Path, fourbar, method):
    scene = tmp_path / "fourbar.toml"
    section = f"[simulate]\nt_end = {T_TURN!r}\ndt = {DT!r}\noutput_dt = {OUTPUT_DT!r}\n"
    text = fourbar_text().replace("clearance = 1e-4\n", "") + SAMPLED
    # float64 histories, as test_simulate_methods' crank turn on this four-bar: its lane
    # entries, compiled once (an entry compiles per type of its arrays)
    text += '[storage]\nhistory_dtype = "float64"\n'
    scene.write_text(text + section + f'method = "{method}"\nkernels = "lanes"\n')
    result = plan.start_run(scene, out=tmp_path / "runs", progress=False)
    throughput = json.loads((result.folder / "run.json").read_text())["throughput"]
    with open_run(result.folder) as ds:
        time = ds.time.values
        assert time[-1] == T_TURN and np.array_equal(time[:-1], np.arange(629) * OUTPUT_DT)
        last = ds.q.sel(time=T_TURN)  # t_end is a stored time, bit for bit
        assert last.sizes["sample"] == 3
        written = json.loads(ds.attrs["settings"])["scene"]["simulate"]
        assert written["dt"] == DT and written["t_end"] == T_TURN  # as written, and as run
        if method == "rk4":
            taken = 6284.0  # per sample: 6283 whole steps and the short one
        else:  # the accepted steps of each sample, as the solver counts them, summed
            from mcchain.scene import compile_model, load_scene
            from mcchain.solvers import solve_chunk

            loaded = load_scene(scene)
            counted = solve_chunk(compile_model(loaded), loaded)["steps_taken"]
            taken = float(np.sum(counted)) / 3
            assert taken > 629  # at least one step per output interval
    assert throughput["steps_per_sample"] == taken
    assert throughput["instance_steps_per_s"] == pytest.approx(
        taken * throughput["samples_per_s"], rel=1e-12
    )
