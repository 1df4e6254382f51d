"""Clearance joints under the contact law in time histories: free flight, impacts, the switch
from the link (model ``auto``), against an independent scipy reference and invariants.

The scene of most tests is the journal in a fixed bearing of :func:`mcchain.testing.contact.
journal_in_bearing`: one free body whose centre moves inside a clearance circle under gravity,
started at the top of the bearing (on the wall, as every contact model starts: from the link's
assembled state) with a small sideways speed, so it falls across the clearance, impacts the
bottom and bounces around.
"""

from __future__ import annotations

import numpy as np
import pytest

from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble
from mcchain.status import CONTACT_LOST, CONTACT_STEP_TOO_LARGE
from mcchain.testing.contact import Law, journal_in_bearing
from mcchain.testing.scenes import journal_tables

MASS, INERTIA, RADIUS, CLEARANCE, GRAVITY = 0.5, 1e-4, 0.01, 5e-4, 9.81
SIDEWAYS = 0.05  # m/s at the top of the bearing


def journal_scene(
    law: str = "hertz",
    stiffness: float = 1e9,
    restitution: float | None = None,
    model: str = "contact",
    method: str = "rk45",
    t_end: float = 0.05,
    dt: float = 1e-5,
    output_dt: float = 5e-4,
    rtol: float = 1e-8,
    atol: float = 1e-10,
    count: int | None = None,
    vary: str = "",
    friction: float = 0.0,
    bottom: bool = False,
    sideways: float = SIDEWAYS,
) -> str:
    e = "" if restitution is None else f"restitution = {restitution!r}"
    if friction:
        e += f"\nfriction = {friction!r}\nradius = {RADIUS!r}"
    sample = "" if count is None else f"[sample]\ncount = {count}\n[sample.vary]\n{vary}\n"
    contact = f"""[joint.contact]
law = "{law}"
stiffness = {stiffness!r}
{e}
"""
    height = -CLEARANCE if bottom else CLEARANCE
    return (
        journal_tables(
            (0.0, height), (sideways, 0.0), model, contact, MASS, INERTIA, CLEARANCE, GRAVITY
        )
        + f"""
[simulate]
t_end = {t_end!r}
dt = {dt!r}
output_dt = {output_dt!r}
method = "{method}"
rtol = {rtol!r}
atol = {atol!r}
{sample}"""
    )


def run(text: str, **overrides):
    scene = load_scene_text(text)
    model = compile_model(scene)
    sim = scene.simulate.model_copy(update=overrides)
    start = assemble(model)
    return simulate(
        model,
        sim,
        q_start=start.q,
        v_start=start.v,
        status=start.status,
        history_dtype=np.float64,
        diagnostics=True,
    )


def reference(
    law: Law,
    t_end: float,
    times: np.ndarray | None = None,
    height: float = CLEARANCE,
    sideways: float = SIDEWAYS,
):  # the journal of journal_scene, at (0, height) moving at (sideways, 0)
    return journal_in_bearing(
        law,
        clearance=CLEARANCE,
        mass=MASS,
        inertia=INERTIA,
        radius=RADIUS,
        position=(0.0, height),
        velocity=(sideways, 0.0),
        gravity=GRAVITY,
        t_end=t_end,
        times=times,
    )


def test_contact__hertz_conserves_energy_through_50_impacts():
    out = run(journal_scene(t_end=0.5, rtol=1e-10, atol=1e-13))
    assert out["status"][0] == 0
    impacts = int(out["impact_count"][0, 0])
    assert impacts >= 50, impacts
    energy = out["energy"][0].astype(np.float64)
    scale = MASS * GRAVITY * 2 * CLEARANCE + 0.5 * MASS * SIDEWAYS**2
    drift = np.max(np.abs(energy - energy[0])) / scale
    print(f"{impacts} impacts, energy drift {drift:.2e} of m g 2c + m v²/2")
    assert drift < 1e-6, drift


@pytest.mark.parametrize(
    ("law", "e"),
    [
        ("hertz", None),
        ("lankarani-nikravesh", 0.7),
        ("flores", 0.9),
        ("hunt-crossley", 0.8),
        ("gonthier", 0.6),
        ("hu-guo", 0.6),
    ],
)
def test_contact__matches_the_scipy_reference_over_the_first_impacts(law, e):
    t_end = 0.04
    out = run(journal_scene(law=law, restitution=e, t_end=t_end, rtol=1e-11, atol=1e-14))
    ref = reference(Law(law, 1e9, 1.5, 1.0 if e is None else e), t_end, out["time"])
    assert len(ref.impacts) >= 2
    assert int(out["impact_count"][0, 0]) == len(ref.impacts)
    q = out["q"][0, :, 0, :2].astype(np.float64)
    position_error = np.max(np.abs(q - ref.position[:, :2]))
    force = out["contact_force"][0, :, 0].astype(np.float64)
    force_error = np.max(np.abs(force - ref.normal_force)) / np.max(ref.normal_force)
    print(f"{law}: position {position_error:.2e} m, F_n {force_error:.2e} of the peak")
    assert position_error <= 1e-8
    assert force_error <= 1e-6


def dropped_restitution(law: str, e: float) -> tuple[float, float]:
    """The journal dropped from the top of its bearing: −δ̇⁺/δ̇⁻ of its first impact, from
    mcchain (δ̇⁻ = √(4 g c) after a free fall across the clearance, δ̇⁺ from the state in the
    free flight after the rebound, by the energy of the ballistic flight) and from the
    scipy reference."""
    t_end = 0.02  # the rebound is in flight: the fall takes 14.3 ms, the contact < 1 ms
    text = journal_scene(law=law, restitution=e, t_end=t_end, rtol=1e-11, atol=1e-14)
    text = text.replace(f"velocity = [{SIDEWAYS!r}, 0.0]", "velocity = [0.0, 0.0]")
    out = run(text)
    assert int(out["impact_count"][0, 0]) == 1
    y, vy = out["q"][0, -1, 0, 1], out["v"][0, -1, 0, 1]
    separation = np.sqrt(vy**2 + 2.0 * GRAVITY * (y + CLEARANCE))
    approach = np.sqrt(4.0 * GRAVITY * CLEARANCE)
    history = reference(Law(law, 1e9, 1.5, e), t_end, sideways=0.0)
    return separation / approach, history.impacts[0].restitution


@pytest.mark.parametrize(
    "law", ["lankarani-nikravesh", "flores", "hunt-crossley", "gonthier", "hu-guo"]
)
def test_contact__restitution_of_a_dropped_journal_matches_the_reference(law):
    """The table of the note: each law's measured restitution over e ∈ [0.3, 0.99]."""
    rows = []
    for e in (0.3, 0.5, 0.7, 0.9, 0.99):
        measured, expected = dropped_restitution(law, e)
        rows.append(f"{e}: {measured:.6f} (reference {expected:.6f})")
        assert measured == pytest.approx(expected, abs=1e-6)
    print(f"{law}: " + ", ".join(rows))


@pytest.mark.parametrize("law", ["gonthier", "hu-guo"])
@pytest.mark.parametrize("method", ["rk45", "rk4"])
def test_contact__journal_dropped_free_matches_the_reference(law, method):
    """The two laws added last, on a journal dropped free from mid-clearance (off the wall:
    the first contact has a located onset), against the event-located scipy reference
    (e = 0.7: at 0.5 both laws have χ = 1.5)."""
    t_end, e = 0.045, 0.7
    text = journal_scene(law=law, restitution=e, t_end=t_end, rtol=1e-11, atol=1e-14)
    text = text.replace(f"position = [0.0, {CLEARANCE!r}]", f"position = [0.0, {CLEARANCE / 2!r}]")
    text = text.replace(f"velocity = [{SIDEWAYS!r}, 0.0]", "velocity = [0.0, 0.0]")
    overrides = {"dt": 2e-7} if method == "rk4" else {}
    out = run(text.replace('method = "rk45"', f'method = "{method}"'), **overrides)
    history = reference(Law(law, 1e9, 1.5, e), t_end, out["time"], CLEARANCE / 2, 0.0)
    assert out["status"][0] == 0
    assert len(history.impacts) >= 2
    assert int(out["impact_count"][0, 0]) == len(history.impacts)
    q = out["q"][0, :, 0, :2].astype(np.float64)
    position_error = np.max(np.abs(q - history.position[:, :2]))
    print(f"{law} {method}: {len(history.impacts)} impacts, position {position_error:.2e} m")
    assert position_error <= 1e-8


PENETRATION_TOL = 1e-11
"""m: max_penetration against the reference's located maxima, each method's own error at the
settings below (measured: rk45 1.6e-13, rk4 4.3e-13, radau 9e-15 m). The largest δ at step
ends, the value before, was 7.1e-11 (rk45), 2.1e-10 (rk4) and 2.0e-10 m (radau) low."""


@pytest.mark.parametrize(
    ("method", "keys", "kernels"),
    [
        ("rk45", {"rtol": 1e-11, "atol": 1e-14}, "lanes"),
        ("rk4", {"dt": 2e-6}, "lanes"),
        ("rk4", {"dt": 2e-6}, "loop"),
        ("radau", {"rtol": 1e-10, "atol": 1e-13}, "lanes"),
    ],
    ids=["rk45", "rk4-lanes", "rk4-loop", "radau"],
)
def test_contact__max_penetration_is_the_continuous_peak(method, keys, kernels):
    """max_penetration is the largest δ over the run, not at the step ends: the maximum of
    each step's Hermite interpolant of δ (the lanes and the loop kernels,
    mcchain.kernels.contact.hermite_peak) or of radau's dense output, against the
    reference's maxima located as events (δ̇ crossing 0 downwards) over 7 impacts."""
    law, e, t_end = "lankarani-nikravesh", 0.9, 0.05
    out = run(journal_scene(law=law, restitution=e, method=method, t_end=t_end, **keys),
              kernels=kernels)  # fmt: skip
    ref = reference(Law(law, 1e9, 1.5, e), t_end)
    assert out["status"][0] == 0
    assert int(out["impact_count"][0, 0]) == len(ref.impacts) == 7
    error = out["max_penetration"][0, 0] - ref.max_penetration
    print(f"{method} ({kernels}): {ref.max_penetration:.6e} m, error {error:+.1e} m")
    assert abs(error) <= PENETRATION_TOL


def swinging(model: str, sideways_squared: float, **keys) -> str:
    """The journal on the bottom of its bearing, swinging along the wall like a pendulum of
    length c: v0² = ``sideways_squared`` g c (λ > 0 while v²/c + g cos φ > 0)."""
    speed = float(np.sqrt(sideways_squared * GRAVITY * CLEARANCE))
    return journal_scene(model=model, bottom=True, sideways=speed, **keys)


def lets_go_time(sideways_squared: float) -> float:
    """When the journal of :func:`swinging` leaves the wall (λ = 0): the pendulum of length c
    reaches cos φ = (2 − v0²/(g c)) / 3 at t = ∫ c dφ / √(v0² − 2 g c (1 − cos φ))."""
    from scipy.integrate import quad

    v0_squared = sideways_squared * GRAVITY * CLEARANCE
    angle = np.arccos((2.0 - sideways_squared) / 3.0)

    def seconds_per_radian(p: float) -> float:
        return CLEARANCE / np.sqrt(v0_squared - 2.0 * GRAVITY * CLEARANCE * (1.0 - np.cos(p)))

    time, _ = quad(seconds_per_radian, 0.0, angle, epsabs=1e-15, epsrel=1e-13)
    return float(time)


def test_auto__equals_the_link_until_the_link_lets_go():
    """Model auto runs the link's arithmetic (selects, no products by 0/1) until λ ≤ 0: its
    outputs are bit-identical to the link's before the switch.

    The journal swings up the wall with v0² = 3.5 g c: the link's force
    λ = m (v0²/c − 2g + 3g cos φ) reaches 0 at φ = 120°, where the journal leaves the wall.
    (The lanes are compiled with FMA contraction: in a larger mechanism LLVM may fuse a
    product differently in the two modules' code, an ulp apart; the loop kernels and
    generalized-α, one compiled kernel for both models, are bit-identical there too —
    tests/test_simulate_loop.py.)
    """
    keys = {"t_end": 0.05, "output_dt": 1e-4, "rtol": 1e-10, "atol": 1e-13}
    link = run(swinging("link", 3.5, **keys))
    auto = run(swinging("auto", 3.5, **keys))
    assert link["status"][0] & CONTACT_LOST  # the link would pull
    assert not auto["status"][0] & CONTACT_LOST  # the flag of the link model only
    switch = auto["first_separation_time"][0, 0]
    # rk45 lands its step just past λ = 0 (the link flags its loss at the next accepted state)
    print(f"switch at {switch!r} s, closed form {lets_go_time(3.5)!r} s")
    assert abs(switch - lets_go_time(3.5)) <= 1e-7
    assert switch <= link["contact_lost_time"][0]
    q = link["q"][0, :, 0, :2]
    angle = np.degrees(np.arctan2(q[:, 0], -q[:, 1]))
    assert angle[np.searchsorted(link["time"], switch)] == pytest.approx(120.0, abs=2.0)
    before = auto["time"] < switch - 1e-6
    for name in ("q", "v", "joint_force", "contact_force", "energy", "constraint_error"):
        np.testing.assert_array_equal(auto[name][0, before], link[name][0, before], name)
    assert np.all(auto["contact_mode"][0, before, 0] == 0)
    assert auto["contact_mode"][0, np.argmax(~before), 0] >= 1
    assert np.all(auto["contact_force"][0, :, 0] >= 0.0)
    assert auto["impact_count"][0, 0] >= 1  # it falls back onto the wall


def test_contact__a_fixed_step_too_large_for_the_stiffness_is_flagged():
    """ω_c h past CONTACT_STEP_LIMIT: flagged, NaN; a step within it follows the reference.

    Model auto: the journal starts on the link at the top of its bearing, where the link
    would pull (λ < 0), so the fixed-step kernel switches to the law at t = 0 and the
    journal falls free, as in the reference. The switch keeps the step's first stage,
    computed on the link (λ = −m g here, not ≈ 0 as where λ crosses 0 in a mechanism): a
    velocity error of g h / 6 in that step, 1.6e-7 m after 50 ms, within the bound below.
    """
    scene = {"method": "rk4", "output_dt": 1e-3, "t_end": 0.05, "model": "auto"}
    coarse = run(journal_scene(dt=5e-4, **scene))
    assert coarse["status"][0] & CONTACT_STEP_TOO_LARGE
    assert np.all(np.isnan(coarse["q"][0, -1]))
    assert coarse["impact_count"][0, 0] == -1
    fine = run(journal_scene(dt=2e-6, **scene))
    assert fine["status"][0] == 0
    assert fine["first_separation_time"][0, 0] == 0.0
    assert fine["contact_mode"][0, 1, 0] == 2  # free
    ref = reference(Law("hertz", 1e9, 1.5, 1.0), 0.05, fine["time"])
    error = np.max(np.abs(fine["q"][0, :, 0, :2] - ref.position[:, :2]))
    print(f"rk4 dt 2e-6: {error:.2e} m from the reference")
    assert error < 5e-7


def test_contact__converges_to_the_link_as_the_stiffness_grows():
    """Where the link holds (λ > 0: the journal swings on the bottom of its bearing up to
    75°), the contact model approaches it as K grows: the gap between the two is the static
    penetration (λ/K)^(1/m) and its vibration (the law starts undamped at δ = 0), O(K^-2/3)."""
    tight = {"t_end": 0.05, "output_dt": 1e-4, "rtol": 1e-11, "atol": 1e-14}
    link = run(swinging("link", 1.5, **tight))
    assert not link["status"][0]
    errors = []
    stiffnesses = (1e9, 1e10, 1e11, 1e12)
    for K in stiffnesses:
        out = run(swinging("contact", 1.5, stiffness=K, **tight))
        errors.append(np.max(np.abs(out["q"][0, :, 0, :2] - link["q"][0, :, 0, :2])))
    rates = -np.diff(np.log(errors)) / np.diff(np.log(stiffnesses))
    print("max |q - q_link| (m):", ", ".join(f"{e:.2e}" for e in errors), "rates", rates)
    assert errors[-1] < 1e-6
    assert np.all(rates > 0.55)


def test_auto__reseats_on_the_link_without_adding_energy():
    """A damped journal (model auto) bounces, settles on the bottom of its bearing and goes
    back to the link; the total energy (with the elastic energy under the law) never grows,
    across the switches included."""
    text = journal_scene(
        law="lankarani-nikravesh", restitution=0.5, model="auto", t_end=0.3,
        output_dt=1e-4, rtol=1e-10, atol=1e-13,
    )  # fmt: skip
    out = run(text)
    assert out["status"][0] == 0
    mode = out["contact_mode"][0, :, 0]
    reseats = np.flatnonzero((mode[:-1] >= 1) & (mode[1:] == 0))
    assert reseats.size >= 1
    assert mode[-1] == 0  # seated: sliding back and forth on the link at the bottom
    energy = out["energy"][0]
    scale = MASS * GRAVITY * 2 * CLEARANCE
    growth = np.max(np.diff(energy)) / scale
    at_switch = np.max(energy[reseats + 1] - energy[reseats]) / scale
    print(f"{reseats.size} re-seat(s); energy growth per output at most {growth:.1e}, "
          f"across a re-seat {at_switch:.1e} of m g 2c")  # fmt: skip
    assert at_switch <= 1e-9
    assert growth <= 1e-7


def test_contact__friction_matches_the_scipy_reference():
    """Regularised Coulomb friction at the contact point (slip t·ḋ + R ω, moment R F_t):
    the journal picks up spin at its impacts as the reference does."""
    t_end = 0.04
    text = journal_scene(
        law="lankarani-nikravesh", restitution=0.8, friction=0.1, t_end=t_end, rtol=1e-11,
        atol=1e-14,
    )  # fmt: skip
    out = run(text)
    law = Law("lankarani-nikravesh", 1e9, 1.5, 0.8, friction=0.1)
    ref = reference(law, t_end, out["time"])
    assert len(ref.impacts) >= 2
    assert abs(ref.velocity[-1, 2]) > 1e-3  # friction made it spin
    position = np.max(np.abs(out["q"][0, :, 0, :2] - ref.position[:, :2]))
    spin = np.max(np.abs(out["v"][0, :, 0, 2] - ref.velocity[:, 2]))
    print(f"friction: position {position:.2e} m, spin {spin:.2e} rad/s "
          f"(final spin {ref.velocity[-1, 2]:.3f} rad/s)")  # fmt: skip
    assert position <= 1e-8
    assert spin <= 1e-6 * np.max(np.abs(ref.velocity[:, 2]))


def test_contact__rk4_projection_keeps_the_law_rows_out_of_its_projection():
    """rk4-projection projects q and v onto the constraints after each step: a joint under
    the law must be left out (else the journal would be pulled back onto |d| = c)."""
    t_end = 0.03
    text = journal_scene(method="rk4-projection", dt=2e-6, output_dt=1e-3, t_end=t_end)
    out = run(text)
    assert out["status"][0] == 0
    assert np.nanmin(out["penetration"][0, :, 0]) < -5e-5  # it really flies free
    assert np.any(out["contact_mode"][0, :, 0] == 2)
    ref = reference(Law("hertz", 1e9, 1.5, 1.0), t_end, out["time"])
    error = np.max(np.abs(out["q"][0, :, 0, :2] - ref.position[:, :2]))
    print(f"rk4-projection dt 2e-6: {error:.2e} m from the reference")
    assert error < 1e-7


@pytest.mark.parametrize(("law", "e"), [("lankarani-nikravesh", 0.9), ("flores", 0.5)])
def test_generalized_alpha__contact_law_converges_to_the_reference_at_second_order(law, e):
    """The index-3 implicit method with the law's row λ_r = F_n(q, q̇) in its Newton system:
    the journal's impacts follow the event-located reference, with the O(h²) error of the
    method (halving h divides it by ≈ 4)."""
    t_end = 0.05
    errors = []
    for dt in (2e-6, 1e-6):
        text = journal_scene(law=law, restitution=e, method="generalized-alpha", dt=dt,
                             output_dt=5e-4, t_end=t_end)  # fmt: skip
        out = run(text)
        ref = reference(Law(law, 1e9, 1.5, e), t_end, out["time"])
        assert out["status"][0] == 0
        assert int(out["impact_count"][0, 0]) == len(ref.impacts) >= 2
        errors.append(np.max(np.abs(out["q"][0, :, 0, :2] - ref.position[:, :2])))
        force = out["contact_force"][0, :, 0]
        force_error = np.max(np.abs(force - ref.normal_force)) / np.max(ref.normal_force)
    print(f"{law}: position {errors[0]:.2e} → {errors[1]:.2e} m, F_n {force_error:.1e} of the peak")
    assert errors[1] <= 3e-9
    assert 3.0 <= errors[0] / errors[1] <= 5.0
    assert force_error <= 5e-5


def reseat_energy_growth(**keys) -> float:
    """A damped journal under model auto (L–N, e 0.5, 0.3 s) that ends back on the link after
    a contact: asserts that, and returns the largest growth of the energy between outputs,
    per m g 2c (a re-seat must not add energy)."""
    text = journal_scene(
        law="lankarani-nikravesh", restitution=0.5, model="auto", t_end=0.3, output_dt=1e-4,
        **keys,
    )  # fmt: skip
    out = run(text)
    mode = out["contact_mode"][0, :, 0]
    assert out["status"][0] == 0 and mode[-1] == 0
    assert np.any((mode[:-1] >= 1) & (mode[1:] == 0))
    return float(np.max(np.diff(out["energy"][0])) / (MASS * GRAVITY * 2 * CLEARANCE))


def test_generalized_alpha__auto_equals_the_link_bit_for_bit_and_reseats():
    """Model auto runs the link's Newton system until λ first reaches 0 (same kernel, the law's
    rows skipped): bit-identical outputs; a damped journal then re-seats without adding
    energy; a step too coarse for the contact is flagged."""
    keys = {"t_end": 0.05, "output_dt": 1e-4, "method": "generalized-alpha", "dt": 2e-6}
    link = run(swinging("link", 3.5, **keys))
    auto = run(swinging("auto", 3.5, **keys))
    switch = auto["first_separation_time"][0, 0]
    assert switch == link["contact_lost_time"][0]
    before = auto["time"] <= switch
    assert 50 < before.sum() < len(before)
    for name in ("q", "v", "joint_force", "contact_force", "energy", "constraint_error"):
        np.testing.assert_array_equal(auto[name][0, before], link[name][0, before], name)
    assert reseat_energy_growth(method="generalized-alpha", dt=2e-6) <= 1e-8
    coarse = run(journal_scene(method="generalized-alpha", dt=5e-4, output_dt=1e-3))
    assert coarse["status"][0] & CONTACT_STEP_TOO_LARGE
    assert np.isnan(coarse["q"][0, -1]).all()


@pytest.mark.parametrize(("law", "e"), [("hertz", None), ("lankarani-nikravesh", 0.9)])
def test_radau__contact_law_matches_the_reference(law, e):
    """Radau in segments between located events (onsets with the exact δ̇⁻, separations):
    the journal's impacts as the event-located DOP853 reference, to its tolerances."""
    t_end = 0.05
    text = journal_scene(
        law=law, restitution=e, method="radau", output_dt=5e-4, t_end=t_end, rtol=1e-10,
        atol=1e-13,
    )  # fmt: skip
    out = run(text)
    ref = reference(Law(law, 1e9, 1.5, 1.0 if e is None else e), t_end, out["time"])
    assert out["status"][0] == 0
    assert int(out["impact_count"][0, 0]) == len(ref.impacts) >= 5
    position = np.max(np.abs(out["q"][0, :, 0, :2] - ref.position[:, :2]))
    force = out["contact_force"][0, :, 0]
    force_error = np.max(np.abs(force - ref.normal_force)) / np.max(ref.normal_force)
    print(f"radau {law}: position {position:.1e} m, F_n {force_error:.1e} of the peak")
    assert position <= 1e-10
    assert force_error <= 1e-7


def test_radau__auto_switches_where_the_link_lets_go_and_reseats_without_adding_energy():
    keys = {"t_end": 0.05, "output_dt": 1e-4, "rtol": 1e-10, "atol": 1e-13, "method": "radau"}
    link = run(swinging("link", 3.5, **keys))
    auto = run(swinging("auto", 3.5, **keys))
    switch = auto["first_separation_time"][0, 0]
    assert abs(switch - lets_go_time(3.5)) <= 1e-10  # the event λ = 0, located
    before = auto["time"] < switch
    for name in ("q", "v", "joint_force", "energy"):  # the link's Radau runs the lanes' accel
        a, b = auto[name][0, before], link[name][0, before]
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-8 * np.max(np.abs(b)), err_msg=name)
    assert reseat_energy_growth(method="radau", rtol=1e-10, atol=1e-13) <= 1e-9


def test_auto__every_sample_of_the_shipped_fourbar_separates_and_none_fails():
    """Samples 132–135 of the shipped sweep, where rk45 once shrank its step towards hmin
    retrying a λ = 0 crossing in the first instants of a step (sample 134 was flagged
    diverged): each separates, with the switch where the link's λ reaches 0."""
    from pathlib import Path

    config = Path(__file__).resolve().parents[1] / "configs" / "fourbar-clearance.toml"
    scene = load_scene_text(config.read_text())
    model = compile_model(scene).select(132, 136)
    start = assemble(model)
    # the shipped float32 histories, as test_peaks' run of this sweep: the lane module
    # compiles once for both (the checks below read per-sample values only)
    out = simulate(model, scene.simulate, q_start=start.q, v_start=start.v, status=start.status)
    np.testing.assert_array_equal(out["status"], 0)
    switch = out["first_separation_time"][:, 2]
    assert np.all((0.2 < switch) & (switch < 0.35)), switch
    assert np.all(out["impact_count"][:, 2] >= 10)
