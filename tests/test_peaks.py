"""Per-sample peaks are the continuous peaks, located within the steps (mcchain.kernels.peaks,
mcchain.solvers.peaks), on every method path, against closed forms and a dense reference."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mcchain.kernels.peaks import cubic_peak, peaks_feed, peaks_finish, peaks_start
from mcchain.kernels.tableaux import PEAK_CLOCK, PEAK_WIDTH
from mcchain.testing.closed_forms import G
from mcchain.testing.factory import bar_scene_dict, toml_text

TILT = 1.0
"""Release angle of the swinging bar from the downward vertical, rad."""
MASS, LENGTH = 2.0, 1.0


def _tracked_peak(times: np.ndarray, values: np.ndarray) -> float:
    """The peak the kernels report for one quantity fed at ``times``."""
    pk = np.zeros(PEAK_WIDTH + PEAK_CLOCK)
    peaks_start(pk)
    for t, f in zip(times, values, strict=True):
        peaks_feed(pk, np.array([f]), t)
    out = np.zeros((1, 1))
    peaks_finish(0, False, pk, 1, out)
    return float(out[0, 0])


def test_cubic_peak__exact_for_a_cubic_on_any_step():
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 1.0, 4))
    c = np.array([0.3, 2.0, -6.0, 1.5])
    f = np.polyval(c[::-1], t)
    for interval in range(3):
        grid = np.linspace(t[interval], t[interval + 1], 200001)
        exact = np.polyval(c[::-1], grid).max()
        found = cubic_peak(t[0], f[0], t[1], f[1], t[2], f[2], t[3], f[3], interval)
        assert found == pytest.approx(exact, abs=1e-9)


def test_peaks_feed__fourth_order_in_the_step():
    """The peak of cos(t − t*) sampled every h, t* anywhere in a step: error ~ h⁴ (the
    largest value at step ends errs ~ h²/8)."""
    errors = []
    steps = [0.2 / 2**k for k in range(4)]
    for h in steps:
        worst = 0.0
        for shift in np.linspace(0.0, 1.0, 7, endpoint=False):
            times = np.arange(0.0, 3.0, h)
            peak_time = 1.5 + shift * h
            worst = max(worst, abs(1.0 - _tracked_peak(times, np.cos(times - peak_time))))
        errors.append(worst)
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert order > 3.7, errors
    assert errors[-1] < 1e-8


@pytest.mark.parametrize("where", ["first step", "last step"])
def test_peaks_feed__a_peak_in_the_first_or_last_step(where):
    h = 0.05
    times = np.arange(0.0, 1.0 + h / 2, h)
    peak_time = 0.4 * h if where == "first step" else times[-1] - 0.4 * h
    found = _tracked_peak(times, np.cos(times - peak_time))
    assert found == pytest.approx(1.0, abs=1e-6)


def test_peaks_feed__a_kink_does_not_overshoot():
    """A contact's onset: 0 then rising fast, then cut off (a re-seat): the cubic through
    the kink is capped, never more than the spread of its four points above their top."""
    times = np.arange(10.0)
    values = np.array([0.0, 0.0, 0.0, 0.0, 5.0, 9.0, 10.0, 0.0, 0.0, 0.0])
    found = _tracked_peak(times, values)
    assert 10.0 <= found <= 20.0


def _swinging_bar(method: str, **simulate: object) -> str:
    """The paper's bar released at rest TILT from hanging down, ideal pin at the origin."""
    doc = bar_scene_dict(mass=MASS, length=LENGTH, equilibrium=False, modes=False,
                         simulate={"t_end": 0.8, "method": method, **simulate})  # fmt: skip
    th = -math.pi / 2 + TILT
    half = LENGTH / 2
    doc["body"][0]["angle"] = th
    doc["body"][0]["position"] = [half * math.cos(th), half * math.sin(th)]
    return toml_text(doc)


BOTTOM_FORCE = MASS * G * (2.5 - 1.5 * math.cos(TILT))
"""|f| at the pin as the uniform bar passes the bottom, its largest (energy: ω² = 3g/(2l)
(cos θ − cos θ0) with l the half length; radial m g cos θ + m l ω², tangential m g sin θ/4)."""

METHODS = {
    # method, its settings, and the relative error its own accuracy allows at the peak
    "rk4": ({"dt": 2e-3, "output_dt": 0.02}, 1e-8),
    "rk4 loop": ({"dt": 2e-3, "output_dt": 0.02, "kernels": "loop"}, 1e-8),
    "rk4-projection": ({"dt": 2e-3, "output_dt": 0.02}, 1e-8),
    "rk45": ({"dt": 1e-3, "output_dt": 0.02, "rtol": 1e-10, "atol": 1e-12}, 1e-8),
    # second order: 1.7e-6, 2.7e-7, 6.7e-8 at dt = 1e-3, 4e-4, 2e-4 (its λ at step ends
    # errs as much). With rho_inf = 1 its λ alternates from step to step (±0.02 N at dt =
    # 1e-4), which no peak can be better than.
    "generalized-alpha": ({"dt": 4e-4, "output_dt": 0.02}, 1e-6),
    "radau": ({"dt": 1e-3, "output_dt": 0.02, "rtol": 1e-10, "atol": 1e-12}, 1e-8),
}


@pytest.mark.parametrize("name", list(METHODS))
def test_peak_joint_force__the_bottom_of_the_swing_on_every_method(name):
    """The bar's pin force peaks at the bottom, between two stored points (every 20 ms)
    and between step ends: each method reports m g (2.5 − 1.5 cos θ0) to its accuracy."""
    from mcchain.scene import compile_model, load_scene_text
    from mcchain.solvers import solve_chunk

    settings, rtol = METHODS[name]
    scene = load_scene_text(_swinging_bar(name.split()[0], **settings), name="swing")
    out = solve_chunk(compile_model(scene), scene)
    assert out["status"][0] == 0
    peak = float(out["peak_joint_force"][0, 0])
    assert peak == pytest.approx(BOTTOM_FORCE, rel=rtol)
    force = np.asarray(out["joint_force"][0, :, 0], float)
    stored = np.hypot(force[:, 0], force[:, 1]).max()
    assert BOTTOM_FORCE - stored > 100 * rtol * BOTTOM_FORCE  # the stored points miss it


SWEEP = Path(__file__).resolve().parent.parent / "configs" / "fourbar-contact-sweep.toml"
SWEEP_REFERENCE_RTOL = 1e-6
"""Agreement of rk45's tracked peaks (rtol 1e-12) with radau's located on its dense output
(rtol 1e-11) on the sweep's first sample up to 20 ms: measured 2.2e-7 for every peak (F_n
at B, each joint's |f|, the crank's torque). What is left is the two integrations' own
difference: radau locates each onset exactly, the kernels' step that begins in free flight
damps with its current δ̇ (docs/contact.md). (On the third sample up to 0.3 s, an impact
after the separation from the link at 0.25 s: 2.3e-6 and 1.3e-6 on the second — but radau
took 5 minutes there, the landing here seconds.)"""

SWEEP_SAMPLE = 0
"""The sweep's first sample: clearance 1.93e-4 m, above the 1e-4 m the start state is
written for, so the journal starts free and lands on its bush within the window (four
impacts); every peak of the window is one of theirs, between stored points."""


def _sweep_sample(method: str, **simulate: float) -> dict[str, np.ndarray]:
    """The shipped contact sweep's sample :data:`SWEEP_SAMPLE`, alone, up to 20 ms (its
    landing: the journal's first impacts), integrated by ``method``."""
    from mcchain.scene import compile_model, load_scene, load_scene_text
    from mcchain.solvers import solve_chunk

    parameters = compile_model(load_scene(SWEEP), nsample=SWEEP_SAMPLE + 1).parameters
    clearance, restitution = map(float, parameters[SWEEP_SAMPLE])
    text = SWEEP.read_text().split("[sample]")[0]
    text = text.replace("clearance = 1e-4 ", f"clearance = {clearance!r} ")
    text = text.replace("restitution = 0.9\n", f"restitution = {restitution!r}\n")
    text = text.replace("t_end = 0.6283185307179586", "t_end = 0.02")
    text = text.replace('method = "rk45"', f'method = "{method}"')
    for key, value in simulate.items():
        text = text.replace("[simulate]", f"[simulate]\n{key} = {value!r}")
    scene = load_scene_text(text, name="sweep-sample")
    return solve_chunk(compile_model(scene), scene)


@pytest.mark.slow
def test_peaks__the_shipped_contact_sweep_against_a_dense_reference():
    """Every peak (F_n at B, |f| of each joint, the crank's torque) of rk45 against radau's
    (scipy's Radau IIA(5), compiled), located on its dense output by bounded minimisation
    (mcchain.solvers.peaks); the stored points (every ms) miss the impacts."""
    tight = _sweep_sample("rk45", rtol=1e-12, atol=1e-15)
    reference = _sweep_sample("radau", rtol=1e-11, atol=1e-14)
    assert tight["status"][0] == 0 and reference["status"][0] == 0
    assert tight["impact_count"][0, 2] >= 1  # the peaks are the landing's impacts
    for name in ("peak_contact_force", "peak_joint_force", "peak_driver_torque"):
        ours, ref = np.asarray(tight[name][0], float), np.asarray(reference[name][0], float)
        finite = np.isfinite(ref)
        np.testing.assert_allclose(ours[finite], ref[finite], rtol=SWEEP_REFERENCE_RTOL)
    stored = np.nanmax(np.asarray(tight["contact_force"][0, :, 2], float))
    assert stored < reference["peak_contact_force"][0, 2]
