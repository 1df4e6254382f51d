"""A clearance joint under a contact law starts where it is written.

A journal in a fixed bearing (one free body whose centre is the journal, the bearing on
ground; gravity along −y) written free inside its bearing, pressed into the wall or seated
on it: assembly keeps the written state bit for bit, every integrator starts in the mode the
state says, and the closed forms hold — a free fall from |d0| meets the wall at
t1 = √(2 (c − |d0|)/g); a pressed start has F_n(0) = K δ0^m; a seated start gives the same
history whichever side of 0 rounding puts δ(0).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcchain.contact import MODE_CONTACT, MODE_FREE, MODE_LINK
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble, initial_state_warnings, written_state
from mcchain.testing.factory import write_scene
from mcchain.testing.scenes import fourbar_text, journal_tables

MASS, INERTIA, CLEARANCE, GRAVITY, STIFFNESS, EXPONENT = 0.5, 1e-4, 5e-4, 9.81, 1e9, 1.5
ONSET_TOLERANCE = 1e-12  # s: the onset is located on the step's cubic Hermite interpolant,
# exact for a free fall (quadratic in t), to 1e-14 of the step
FORCE_RTOL = 1e-12  # F_n(0) = K δ0^m evaluated from the written state: rounding only
SEATED_TOLERANCE = 1e-12  # m: histories from δ(0) = ±1e-16 (the rounding of a closed form)
METHODS = [  # radau first: its stepper is the longest compile, wanted early by other files
    pytest.param({"method": "radau", "rtol": 1e-10, "atol": 1e-14}, id="radau"),
    pytest.param({"method": "rk4"}, id="rk4"),
    pytest.param({"method": "rk4", "kernels": "loop"}, id="rk4-loop"),
    pytest.param({"method": "rk45", "rtol": 1e-12, "atol": 1e-16}, id="rk45"),
    pytest.param({"method": "generalized-alpha"}, id="generalized-alpha"),
]
LAWS = [("hertz", None), ("lankarani-nikravesh", 0.8), ("flores", 0.8)]


def journal_text(
    y0: float,
    law: str = "hertz",
    restitution: float | None = None,
    model: str = "contact",
    x0: float = 0.0,
    sideways: float = 0.0,
    t_end: float = 0.0075,
) -> str:
    """The journal written at (x0, y0) from the bearing centre, at rest or moving sideways."""
    e = "" if restitution is None else f"restitution = {restitution!r}"
    law_table = f"""[joint.contact]
law = "{law}"
stiffness = {STIFFNESS!r}
exponent = {EXPONENT!r}
{e}"""
    return (
        journal_tables(
            (x0, y0),
            (sideways, 0.0),
            model,
            law_table if model != "link" else "",
            MASS,
            INERTIA,
            CLEARANCE,
            GRAVITY,
        )
        + f"""
[simulate]
t_end = {t_end!r}
dt = 1e-6
output_dt = 2.5e-4
method = "rk4"
"""
    )


def run(text: str, **settings):
    scene = load_scene_text(text)
    model = compile_model(scene)
    start = assemble(model)
    out = simulate(
        model,
        scene.simulate.model_copy(update=settings),
        q_start=start.q,
        v_start=start.v,
        status=start.status,
        history_dtype=np.float64,
    )
    return model, start, out


@pytest.mark.parametrize("law, restitution", LAWS, ids=[law for law, _ in LAWS])
@pytest.mark.parametrize("settings", METHODS)
def test_start__a_journal_dropped_from_half_the_clearance_meets_the_wall_at_t1(
    settings, law, restitution
):
    y0 = -CLEARANCE / 2
    _, start, out = run(journal_text(y0, law, restitution), **settings)
    np.testing.assert_array_equal(start.q[0], [0.0, y0, 0.0])  # kept as written
    np.testing.assert_array_equal(out["q"][0, 0, 0], [0.0, y0, 0.0])
    assert out["contact_mode"][0, 0, 0] == MODE_FREE
    assert out["status"][0] == 0
    t1 = math.sqrt(2.0 * (CLEARANCE - abs(y0)) / GRAVITY)
    assert out["impact_count"][0, 0] == 1  # the contact lasts past t_end (7.5 ms > t1)
    assert abs(out["free_flight_time"][0, 0] - t1) < ONSET_TOLERANCE


@pytest.mark.parametrize("settings", METHODS)
def test_start__a_journal_dropped_from_its_bearing_centre_meets_the_wall_at_t1(settings):
    """Written at the bearing centre (d = 0, where the normal is undefined and F_n = 0): it
    stays there as written, falls by c and lands at t1 = √(2 c / g)."""
    _, start, out = run(journal_text(0.0, t_end=0.0105), **settings)  # in contact at t_end
    np.testing.assert_array_equal(start.q[0], [0.0, 0.0, 0.0])
    assert out["status"][0] == 0 and out["impact_count"][0, 0] == 1
    t1 = math.sqrt(2.0 * CLEARANCE / GRAVITY)
    assert abs(out["free_flight_time"][0, 0] - t1) < ONSET_TOLERANCE


@pytest.mark.parametrize("settings", METHODS)
@pytest.mark.parametrize("model_name", ["contact", "auto"])
def test_start__a_pressed_written_state_keeps_its_force(settings, model_name):
    """The journal pressed into the bottom of its bearing by δ0 = (m g / K)^(1/m), where
    the law carries its weight: written, it is kept (auto too: off the wall it starts under
    the law), F_n(0) = K δ0^m, and it stays at rest (undamped, no onset, no impact)."""
    delta0 = (MASS * GRAVITY / STIFFNESS) ** (1.0 / EXPONENT)
    y0 = -(CLEARANCE + delta0)
    _, start, out = run(journal_text(y0, "flores", 0.8, model=model_name, t_end=0.002), **settings)
    np.testing.assert_array_equal(start.q[0], [0.0, y0, 0.0])
    written = STIFFNESS * (-y0 - CLEARANCE) ** EXPONENT
    assert abs(out["contact_force"][0, 0, 0] - written) <= FORCE_RTOL * written
    assert out["contact_mode"][0, 0, 0] == MODE_CONTACT
    assert out["impact_count"][0, 0] == 0
    assert np.isnan(out["first_separation_time"][0, 0])
    np.testing.assert_allclose(out["q"][0, :, 0, 1], y0, rtol=0, atol=1e-15)


@pytest.mark.parametrize("settings", METHODS)
def test_start__seated_journals_written_either_side_of_zero_give_one_history(settings):
    """Seated at the bottom with δ(0) = ±1e-16 m (a closed form's rounding) and sliding
    sideways, under a damped law: both start in contact, undamped and without an onset
    (not a 'contact' met after 1e-10 s with δ̇⁻ ≈ 1e-6 m/s, D ≈ 1e5 s/m), and their
    histories agree to 1e-12 m."""
    histories = []
    for offset in (-1e-16, 1e-16):
        text = journal_text(-(CLEARANCE + offset), "lankarani-nikravesh", 0.5, sideways=0.05)
        _, start, out = run(text, t_end=0.01, **settings)
        assert start.q[0, 1] == -(CLEARANCE + offset)
        assert out["status"][0] == 0
        histories.append(out)
    low, high = histories
    # the same contacts: it presses from t = 0, swings up the wall, rebounds and lands again
    assert low["impact_count"][0, 0] == high["impact_count"][0, 0]
    assert low["free_flight_time"][0, 0] == pytest.approx(high["free_flight_time"][0, 0], abs=1e-12)
    np.testing.assert_allclose(low["q"], high["q"], rtol=0, atol=SEATED_TOLERANCE)
    np.testing.assert_array_equal(low["contact_mode"], high["contact_mode"])


def test_start__auto_starts_on_the_link_only_on_the_wall_where_it_pushes():
    """Model auto: seated at the bottom (the link pushes: weight) it starts on the link;
    seated at the top (the link would pull) under the law; written free, under the law."""
    bottom = run(journal_text(-CLEARANCE, model="auto", t_end=1e-3))[2]
    top = run(journal_text(CLEARANCE, model="auto", t_end=1e-3))[2]
    free = run(journal_text(-CLEARANCE / 2, model="auto", t_end=1e-3))[2]
    assert bottom["contact_mode"][0, 0, 0] == MODE_LINK
    assert bottom["contact_force"][0, 0, 0] == pytest.approx(MASS * GRAVITY, rel=1e-12)
    assert top["contact_mode"][0, 0, 0] == MODE_FREE or top["contact_mode"][0, 0, 0] == MODE_CONTACT
    assert top["first_separation_time"][0, 0] == 0.0
    assert free["contact_mode"][0, 0, 0] == MODE_FREE
    np.testing.assert_array_equal(free["q"][0, 0, 0], [0.0, -CLEARANCE / 2, 0.0])


def pressed_fourbar(model_name: str = "contact", press: float = 1e-6) -> tuple[str, float]:
    """The four-bar of fourbar_text with joint B under the law and its journal pressed
    into the wall by ``press``: the rocker turned about O4 (its velocity with it), every
    ideal joint and the driver still hold. Returns the text and δ0 of the written state."""
    text = fourbar_text()
    model = compile_model(load_scene_text(text))
    q, v = model.q0[0].copy(), model.v0[0].copy()
    o4 = np.array([0.3, 0.0])

    def turned(angle: float) -> tuple[np.ndarray, float]:
        c, s = np.cos(angle), np.sin(angle)
        centre = o4 + np.array([[c, -s], [s, c]]) @ (q[6:8] - o4)
        th = q[8] + angle
        pin = centre + 0.125 * np.array([np.cos(th), np.sin(th)])  # rocker's B point
        th2 = q[5]
        bearing = q[3:5] + 0.15 * np.array([np.cos(th2), np.sin(th2)])
        return np.array([*centre, th]), float(np.hypot(*(pin - bearing)) - 1e-4)

    sign = 1.0 if turned(1e-7)[1] > turned(0.0)[1] else -1.0  # the turn that presses B in
    low, high = 0.0, 1e-3  # bisection on the rocker's turn for δ = press
    for _ in range(200):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if turned(sign * mid)[1] < press else (low, mid)
    rocker, delta0 = turned(sign * low)
    w = v[8]
    vel = w * np.array([-(rocker[1] - o4[1]), rocker[0] - o4[0]])
    text = text.replace(
        "position = [0.30085606180870794, 0.12499706859834622]",
        f"position = [{float(rocker[0])!r}, {float(rocker[1])!r}]",
    )
    text = text.replace("angle = 1.5639477787895628", f"angle = {float(rocker[2])!r}")
    old_velocity = next(line for line in text.splitlines() if line.startswith("velocity = [-0.54"))
    text = text.replace(old_velocity, f"velocity = [{float(vel[0])!r}, {float(vel[1])!r}]")
    contact = f"""model = "{model_name}"
[joint.contact]
law = "hertz"
stiffness = {STIFFNESS!r}
"""
    text = text.replace("clearance = 1e-4\n", "clearance = 1e-4\n" + contact)
    return text, delta0


@pytest.mark.parametrize("model_name", ["contact", "auto"])
def test_start__a_pressed_fourbar_runs_from_its_written_state(model_name):
    text, delta0 = pressed_fourbar(model_name)
    assert 0.9e-6 < delta0 < 1.1e-6
    scene = load_scene_text(text + "\n[simulate]\nt_end = 1e-3\ndt = 1e-6\noutput_dt = 1e-4\n")
    model = compile_model(scene)
    start = assemble(model)
    np.testing.assert_array_equal(start.q, model.q0)  # kept bit for bit, journal pressed
    np.testing.assert_array_equal(start.v, model.v0)
    assert initial_state_warnings(*written_state(scene)) == []
    out = simulate(
        model, scene.simulate, q_start=start.q, v_start=start.v, status=start.status,
        history_dtype=np.float64,
    )  # fmt: skip
    written = STIFFNESS * delta0**EXPONENT
    assert abs(out["contact_force"][0, 0, 2] - written) <= 1e-9 * written  # δ0 from the text
    assert out["contact_mode"][0, 0, 2] == MODE_CONTACT


def test_validate__names_the_start_model_gap_and_force(tmp_path, capsys):
    from mcchain.cli import main

    delta0 = (MASS * GRAVITY / STIFFNESS) ** (1.0 / EXPONENT)
    for y0, expected in (
        (-CLEARANCE / 2, "starts on the contact law, free: contact force 0 N"),
        (-(CLEARANCE + delta0), "starts on the contact law, pressed in: contact force 4.905 N"),
        (-CLEARANCE, "starts on the contact law, seated on the wall: contact force 0 N"),
    ):
        path = write_scene(tmp_path, journal_text(y0), name=f"j{y0!r}.toml")
        assert main(["validate", str(path)]) == 0
        out = capsys.readouterr().out
        assert expected in out, out
        assert f"|d| - c {np.hypot(0.0, y0) - CLEARANCE:.6g} m" in out
        assert "warning" not in out


def test_warnings__a_journal_moved_onto_its_wall_is_named_however_small():
    """Under the link a journal written 1e-5 m inside its wall is moved onto it: named."""
    text = journal_text(-(CLEARANCE - 1e-5), model="link")
    lines = initial_state_warnings(*written_state(load_scene_text(text)))
    assert len(lines) == 1 and lines[0].startswith("body.journal: assembly moved it by 1e-05 m")
