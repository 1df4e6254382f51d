"""``[[output]]``s of the motion against independent references: a slider-crank with a
clearance joint in minimal coordinates (mcchain.testing.slider_crank, sympy + DOP853 at rtol
1e-13) and the ideal slider-crank in closed form, for every method; the continuous reductions
against the stored points; the ideal copy against separate runs with and without the
clearance."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.ideal import ideal_model, with_ideal_copy
from mcchain.solvers.output_plan import output_plan
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.testing.slider_crank import (
    clearance_motion,
    mechanism_of,
    reduce_signal,
    slider_crank_scene,
    start_of,
)

CLEARANCE, OMEGA, ANGLE0 = 5e-4, 150.0, 0.3
"""The piston pin's clearance (m), the crank's speed (rad/s) and start angle (rad)."""
T_END = 0.008
WINDOW = (0.003, 0.007)
REFERENCE_TOLERANCE = 1e-8
"""The issue's bound on a motion output against the reference, m (found: 1e-14 to 1e-9)."""
OUTPUTS = f"""
[[output]]
name = "error"
of = "position"
body = "slider"
component = "x"
relative_to = "ideal"
reduce = "max_abs"
[[output]]
name = "error_window"
of = "position"
body = "slider"
component = "x"
relative_to = "ideal"
reduce = "max"
window = [{WINDOW[0]!r}, {WINDOW[1]!r}]
[[output]]
name = "error_rms"
of = "position"
body = "slider"
component = "x"
relative_to = "ideal"
reduce = "rms"
[[output]]
name = "error_mean"
of = "position"
body = "slider"
component = "x"
relative_to = "ideal"
reduce = "mean"
[[output]]
name = "error_below"
of = "position"
body = "slider"
component = "x"
relative_to = "ideal"
reduce = "first_time_below"
threshold = -1e-4
[[output]]
name = "pin_force"
of = "joint_force"
joint = "B"
component = "magnitude"
reduce = "max"
window = [{WINDOW[0]!r}, {WINDOW[1]!r}]
"""
METHODS = {
    "rk45": 'method = "rk45"\nrtol = 1e-13\natol = 1e-15',
    "rk4": 'method = "rk4"',
    "rk4-loop": 'method = "rk4"\nkernels = "loop"',
    "rk4-projection": 'method = "rk4-projection"',
    "generalized-alpha": 'method = "generalized-alpha"',
    "radau": 'method = "radau"\nrtol = 1e-12\natol = 1e-14',
}
FORCE_TOLERANCE = {"generalized-alpha": 1e-5, "radau": 1e-10}
"""Relative tolerance of the windowed pin force against the reference: 1e-9 for the
fourth- and fifth-order methods (found 7e-14); generalized-α is second order (1.2e-6 at
dt = 1e-6); radau interpolates a force between its long steps by the cubic through four
step ends (8e-12)."""


def _text(method: str, output_dt: float = 1e-4, outputs: str = OUTPUTS) -> str:
    simulate_table = f"t_end = {T_END!r}\ndt = 1e-6\noutput_dt = {output_dt!r}\n{METHODS[method]}"
    storage = '\n[storage]\nhistory_dtype = "float64"\n'
    return slider_crank_scene(CLEARANCE, OMEGA, ANGLE0, simulate_table, outputs) + storage


@functools.cache
def _reference():
    model = compile_model(load_scene_text(_text("rk45")))
    start = assemble(model)
    alpha0, rate0 = start_of(start.q[0], start.v[0], CLEARANCE)
    return clearance_motion(mechanism_of(CLEARANCE, OMEGA, ANGLE0), alpha0, rate0, T_END)


@functools.cache
def _expected() -> tuple[dict[str, float], float]:
    """The reference's reductions (the outputs' names to their values) and its windowed max
    pin force: the same for every method, computed once."""
    ref = _reference()
    error = functools.partial(reduce_signal, ref.error, on_arrays=ref.errors)
    expected = {
        "error": error(0.0, T_END, "max_abs"),
        "error_window": error(*WINDOW, "max"),
        "error_rms": error(0.0, T_END, "rms", samples=4001),
        "error_mean": error(0.0, T_END, "mean", samples=4001),
        "error_below": error(0.0, T_END, "first_time_below", -1e-4),
    }
    return expected, reduce_signal(ref.pin_force, *WINDOW, "max")


@functools.cache
def _solved(method: str) -> dict[str, np.ndarray]:
    scene = load_scene_text(_text(method))
    return solve_chunk(compile_model(scene), scene)


@pytest.mark.parametrize("method", list(METHODS))
def test_motion_output__against_the_minimal_coordinate_reference(method):
    expected, force = _expected()
    out = _solved(method)
    assert out["status"][0] == 0 or method != "rk45"
    assert 1e-4 < expected["error"] < 2 * CLEARANCE  # a motion error the size of c
    for name, value in expected.items():
        tolerance = REFERENCE_TOLERANCE if name != "error_below" else 1e-9  # s
        assert abs(out[name][0] - value) <= tolerance, (name, out[name][0], value)
    assert out["pin_force"][0] == pytest.approx(force, rel=FORCE_TOLERANCE.get(method, 1e-9))


@pytest.mark.parametrize("method", ["rk4", "rk4-loop", "rk45"])
def test_continuous_reductions__never_below_the_stored_points(method):
    """The continuous max |error| and windowed maxima ≥ the largest value at the run's
    stored points (its float64 histories; the ideal slider's from a separate run, which the
    copy matches bit for bit with a fixed step and to rounding with rk45's), and within
    the interpolant's error of them."""
    slack = 1e-13 if method == "rk45" else 0.0  # rk45: the copy's run is not the same run
    out = _solved(method)
    scene = load_scene_text(_text(method))
    ideal = ideal_model(compile_model(scene))
    alone = simulate(ideal, scene.simulate, *(assemble(ideal).q, assemble(ideal).v),
                     history_dtype=np.float64)  # fmt: skip
    t = out["time"]
    stored = out["q"][0, :, 2, 0] - alone["q"][0, :, 2, 0]
    inside = (t >= WINDOW[0]) & (t <= WINDOW[1])
    assert out["error"][0] >= np.max(np.abs(stored)) - slack
    assert out["error_window"][0] >= np.max(stored[inside]) - slack
    force = np.hypot(*np.moveaxis(out["joint_force"][0, :, 2, :], -1, 0))
    assert out["pin_force"][0] >= np.max(force[inside])  # the run's own histories
    # between stored points 1e-4 s apart the continuous maximum is above them by up to
    # f''(h/2)²/2 ≈ 3e-7 m here, and not more
    assert out["error"][0] - np.max(np.abs(stored)) < 1e-6


@pytest.mark.parametrize("method", ["rk4", "rk4-loop", "rk4-projection", "rk45"])
def test_ideal_copy__the_difference_of_two_separate_runs(method):
    """The run with the ideal copy integrates the mechanism exactly as a run without it
    (bit for bit: the same arithmetic, and with rk45 the same steps, the copy following
    them) and the copy as a separate run of the ideal mechanism (with a fixed step the
    same steps: to 6e-17 m; rk45's copy takes the mechanism's steps: 3e-15 m): the signal
    the output reduces, x − x_ideal at every stored point (here every step), is the
    difference of the two runs' histories to 1e-12 m."""
    scene = load_scene_text(_text(method, output_dt=1e-6))
    model = compile_model(scene)
    ideal = ideal_model(model)
    start, start_ideal = assemble(model), assemble(ideal)
    both = simulate(
        with_ideal_copy(model, ideal), scene.simulate,
        np.concatenate([start.q, start_ideal.q], 1), np.concatenate([start.v, start_ideal.v], 1),
        history_dtype=np.float64, outputs=output_plan(scene.output, model, T_END),
    )  # fmt: skip
    main = simulate(model, scene.simulate, start.q, start.v, history_dtype=np.float64)
    alone = simulate(ideal, scene.simulate, start_ideal.q, start_ideal.v, history_dtype=np.float64)
    signal = both["q"][0, :, 2, 0] - both["q"][0, :, 5, 0]
    separate = main["q"][0, :, 2, 0] - alone["q"][0, :, 2, 0]
    assert np.max(np.abs(signal - separate)) <= 1e-12
    assert np.array_equal(both["q"][0, :, :3], main["q"][0])  # the mechanism: bit for bit
    # the mechanism's own energy and max |Φ|, not the copy's
    assert np.array_equal(both["energy"], main["energy"])
    assert np.array_equal(both["constraint_error"], main["constraint_error"])
    # every step stored: the continuous max |x − x_ideal| is the stored one to the
    # interpolant's error inside a 1e-6 s step
    assert 0.0 <= both["output_values"][0, 0] - np.max(np.abs(separate)) < 1e-12


def test_rk45_lanes__a_sample_s_outputs_do_not_depend_on_its_lane():
    """rk45 lanes take the next sample of their block when theirs is finished: the outputs
    of a sample that starts in a lane after another one (reductions reset, its own row of
    the window data) are those of the sample run alone, bit for bit."""
    scene = load_scene_text(_text("rk45"))
    model = compile_model(scene, nsample=5)
    ideal = ideal_model(model)
    start, start_ideal = assemble(model), assemble(ideal)
    both = with_ideal_copy(model, ideal)
    q = np.concatenate([start.q, start_ideal.q], 1)
    v = np.concatenate([start.v, start_ideal.v], 1)

    def run(first: int, stop: int, lanes: int | None) -> dict[str, np.ndarray]:
        part = both.select(first, stop)
        plan = output_plan(scene.output, model.select(first, stop), T_END)
        # float64 histories, as _solved's: the lane entry compiled there (an entry compiles
        # per type of its arrays: float32 would compile the module once more, 5 s cold)
        return simulate(part, scene.simulate, q[first:stop], v[first:stop], lanes=lanes,
                        outputs=plan, history_dtype=np.float64)  # fmt: skip

    alone = run(0, 1, None)
    # one lane per group: 5 groups in at most 4 blocks (2 per thread, 1 or 2 threads), so a
    # lane takes a second sample
    shared = run(0, 5, 1)
    assert np.isfinite(alone["output_values"]).all()
    for i in range(5):
        assert np.array_equal(shared["output_values"][i], alone["output_values"][0])
        assert np.array_equal(shared["q"][i], alone["q"][0])


PEAKS = """
[[output]]
name = "pin_peak"
of = "joint_force"
joint = "B"
component = "magnitude"
reduce = "max"
[[output]]
name = "pin_penetration"
of = "penetration"
joint = "B"
reduce = "max"
[[output]]
name = "torque_late"
of = "driver_torque"
driver = "crank"
reduce = "max_abs"
window = [0.008, 0.012]
"""


@pytest.mark.parametrize(
    "method", ['method = "rk45"\nrtol = 1e-9\natol = 1e-12', 'method = "rk4"',
               'method = "rk4"\nkernels = "loop"'], ids=["rk45", "rk4", "rk4-loop"],
)  # fmt: skip
def test_force_outputs__the_peaks_over_the_whole_run_and_a_window(method):
    """Under the contact law (the Flores slider-crank's pin lets go at 9.9 ms and impacts):
    a force's max over the whole run is its continuous peak (``peak_joint_force``, the same
    interpolant and rules), the penetration's max is ``max_penetration`` (the same Hermite
    interpolant), and a windowed max |driver torque| is never below the stored points in it
    nor above the whole run's peak."""
    from mcchain.testing.scenes import flores_pin_text

    text = flores_pin_text(t_end=0.012, method="rk45", rtol=1e-9, atol=1e-12, output_dt=1e-5)
    text = text.replace('method = "rk45"\nrtol = 1e-09\natol = 1e-12', method)
    text = text.replace("[simulate]", '[storage]\nhistory_dtype = "float64"\n[simulate]')
    scene = load_scene_text(text + PEAKS)
    assert scene.simulate.method in method
    out = solve_chunk(compile_model(scene), scene)
    assert out["status"][0] == 0
    b = 2  # joint B
    assert out["pin_peak"][0] == pytest.approx(out["peak_joint_force"][0, b], rel=1e-12)
    assert out["pin_penetration"][0] == pytest.approx(out["max_penetration"][0, b], rel=1e-9)
    assert out["max_penetration"][0, b] > 0.0  # it impacts
    t = out["time"]
    inside = (t >= 0.008) & (t <= 0.012)
    stored = np.max(np.abs(out["driver_torque"][0, inside, 0]))
    assert stored <= out["torque_late"][0]
    # The run's peak lies in the window: the two maxima are one, reduced by two feeds that
    # can round an ulp apart either way (as pin_peak and peak_joint_force above).
    assert out["torque_late"][0] <= out["peak_driver_torque"][0, 0] * (1.0 + 1e-12)
