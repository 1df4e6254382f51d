"""Where a contact-law journal the file does not write starts: ``[joint.contact] start``.

"pressed" (model contact's default): the journal pressed along the ideal mechanism's joint
force at t = 0 by the δ₀ whose force K δ₀^m balances it, the rest re-assembled around it, at
rest in its bearing. Checked against closed forms written here: a bar hanging still from a
clearance pin (δ₀ = (m g / K)^(1/m) along gravity: it stays still under every method), and
the driven slider-crank at top dead centre (the ideal force from Newton–Euler of the rod and
slider, the pressed configuration from the loop closure with the pin offset by c + δ₀).
Histories against the event-located scipy reference (:mod:`mcchain.testing.contact`): a
spinning journal pressed at the bottom of its bearing (friction drags it up the wall) and a
journal started at the centre of its bearing ("centred", d = 0) that falls and impacts.
"seated" is the assembled state as it was; a written journal stays as written, and a start
given with one that contradicts it is refused.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcchain.contact import MODE_CONTACT, MODE_FREE, internal_cylinder_stiffness
from mcchain.errors import SceneError
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.start import contact_start
from mcchain.solvers.statics import assemble, start_multipliers
from mcchain.testing.comparisons import simulate_scene as run
from mcchain.testing.contact import Law, journal_in_bearing
from mcchain.testing.factory import write_scene
from mcchain.testing.scenes import flores_pin_text

MASS, INERTIA, HALF, CLEARANCE, GRAVITY, STIFFNESS = 2.0, 2.0 / 12, 0.5, 1e-3, 9.81, 1e9
PLACE_TOLERANCE = 1e-12  # m: the start state against its closed form
FORCE_RTOL = 1e-9  # the law's force at the start: K m δ^(m−1) times assembly's 1e-14 of the
# mechanism's size (5e-15 m on the bar) is 1e-9 of K δ₀^m at δ₀ = 7 µm
STILL_TOLERANCE = 1e-12  # m: a pressed bar stays where it starts
RADAU = {"method": "radau", "rtol": 1e-10, "atol": 1e-14}
METHODS = [
    # Radau over the bar's 10 ms took 110 s of CPU (its first millisecond 0.9 s: the steps
    # shrink past it); the default run holds it still over 1 ms, the long run over 10 ms
    pytest.param({**RADAU, "t_end": 1e-3, "output_dt": 1e-4}, id="radau-1ms"),
    pytest.param(RADAU, id="radau", marks=pytest.mark.long),
    pytest.param({"method": "rk4"}, id="rk4"),
    pytest.param({"method": "rk4", "kernels": "loop"}, id="rk4-loop"),
    pytest.param({"method": "rk4-projection"}, id="rk4-projection"),
    pytest.param({"method": "rk45", "rtol": 1e-12, "atol": 1e-16}, id="rk45"),
    pytest.param({"method": "generalized-alpha"}, id="generalized-alpha"),
]


def bar_text(
    start: str | None = None,
    law: str = "hertz",
    exponent: float = 1.5,
    sample: str = "",
    stiffness: float = STIFFNESS,
) -> str:
    """A 1 m bar hanging from a clearance pin at its top end, its position not written (it
    is placed on its pin and assembled), under the contact law."""
    law_keys = f'law = "{law}"\nstiffness = {stiffness!r}\nexponent = {exponent!r}\n'
    if law != "hertz":
        law_keys += "restitution = 0.5\n"
    if start is not None:
        law_keys += f'start = "{start}"\n'
    return f"""
[scene]
name = "hanging-bar"
gravity = [0.0, {-GRAVITY!r}]
[[body]]
name = "bar"
mass = {MASS!r}
inertia = {INERTIA!r}
angle = {-math.pi / 2!r}
[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [{-HALF!r}, 0.0]]
clearance = {CLEARANCE!r}
model = "contact"
[joint.contact]
{law_keys}
[simulate]
t_end = 0.01
dt = 1e-5
output_dt = 1e-3
method = "rk4"
{sample}"""


def start_of(text: str) -> tuple[object, np.ndarray, np.ndarray, np.ndarray]:
    """The model, and the time history's start state: assembled, then the contact start."""
    model = compile_model(load_scene_text(text))
    assembled = assemble(model)
    q, v, status = contact_start(model, assembled.q.copy(), assembled.v.copy(), assembled.status)
    return model, q, v, status


def hanging(delta0: float, clearance: float = CLEARANCE) -> np.ndarray:
    """The bar hanging straight down with its journal d = (0, −(c + δ₀)) from the pin."""
    return np.array([0.0, -(clearance + delta0) - HALF, -math.pi / 2])


@pytest.mark.parametrize("exponent, stiffness", [(1.5, STIFFNESS), (1.0, 1e7)])
def test_pressed__the_hanging_bar_is_pressed_by_its_weight(exponent, stiffness):
    delta0 = (MASS * GRAVITY / stiffness) ** (1.0 / exponent)  # 7.3 µm, 2.0 µm
    model, q, v, status = start_of(bar_text(exponent=exponent, stiffness=stiffness))
    assert model.joint_contact_start == ("pressed",)
    assert status[0] == 0
    np.testing.assert_allclose(q[0], hanging(delta0), rtol=0, atol=PLACE_TOLERANCE)
    np.testing.assert_array_equal(v[0], 0.0)
    law_force = start_multipliers(model, q[0], v[0], law=np.array([True]))[0]
    assert law_force == pytest.approx(MASS * GRAVITY, rel=FORCE_RTOL)


def test_pressed__each_sample_by_its_own_stiffness_and_clearance():
    vary = '"joint.O.clearance" = { uniform = [2e-4, 1e-3] }\n'
    vary += '"joint.O.contact.stiffness" = { uniform = [1e8, 1e10] }\n'
    sample = f"[sample]\ncount = 6\nseed = 4\n[sample.vary]\n{vary}"
    model, q, _, status = start_of(bar_text(sample=sample))
    assert not status.any()
    for s in range(model.nsample):
        c, K = model.joint_clearance[s, 0], model.joint_contact_stiffness[s, 0]
        expected = hanging((MASS * GRAVITY / K) ** (1.0 / 1.5), c)
        np.testing.assert_allclose(q[s], expected, rtol=0, atol=PLACE_TOLERANCE)


@pytest.mark.parametrize("settings", METHODS)
def test_pressed__the_hanging_bar_stays_still_under_every_method(settings):
    """In balance from t = 0: no transient, the law's force equal to the weight throughout,
    in contact, undamped (a damped law: no onset at t = 0), no impact."""
    delta0 = (MASS * GRAVITY / STIFFNESS) ** (1.0 / 1.5)
    out = run(bar_text(law="lankarani-nikravesh"), **settings)
    assert out["status"][0] == 0
    np.testing.assert_allclose(
        out["q"][0, :, 0], np.broadcast_to(hanging(delta0), (out["time"].size, 3)),
        rtol=0, atol=STILL_TOLERANCE,
    )  # fmt: skip
    np.testing.assert_allclose(out["contact_force"][0, :, 0], MASS * GRAVITY, rtol=1e-9)
    assert (out["contact_mode"][0, :, 0] == MODE_CONTACT).all()
    assert out["impact_count"][0, 0] == 0
    assert np.isnan(out["first_separation_time"][0, 0])
    assert out["peak_contact_force"][0, 0] == pytest.approx(MASS * GRAVITY, rel=1e-9)


def test_seated__is_the_assembled_state_untouched():
    model, q, v, _ = start_of(bar_text(start="seated"))
    assembled = assemble(model)
    np.testing.assert_array_equal(q, assembled.q)
    np.testing.assert_array_equal(v, assembled.v)
    np.testing.assert_allclose(q[0], hanging(0.0), rtol=0, atol=PLACE_TOLERANCE)


def test_centred__the_bar_hangs_from_the_bearing_centre():
    _, q, v, status = start_of(bar_text(start="centred"))
    assert status[0] == 0
    np.testing.assert_allclose(q[0], hanging(-CLEARANCE), rtol=0, atol=PLACE_TOLERANCE)
    np.testing.assert_array_equal(v[0], 0.0)


# -- the driven slider-crank -----------------------------------------------------------------
CRANK, ROD, SLIDER_MASS, ROD_MASS = 0.05, 0.12, 0.14, 0.21
OMEGA, PIN_CLEARANCE, PIN_RADIUS = 523.5987755982989, 5e-4, 0.01


def slider_crank_pressed() -> tuple[np.ndarray, np.ndarray, float]:
    """The Flores slider-crank at top dead centre (crank angle 0, ω constant), its piston
    pin B pressed: q, v (9,) and δ₀ in closed form.

    The ideal force on the slider from the rod at t = 0, by Newton–Euler: the slider's x
    acceleration at TDC is −r ω² − r² ω²/L (so f_x = m₃ ẍ_B); the rod's angular acceleration
    is 0 there, so its moment balance about its centre gives f_Ay = −f_y and its vertical
    balance f_Ay − f_y = m₂ g: f_y = −m₂ g/2. The journal presses opposite to f:
    u = −f/|f|, δ₀ = (|f|/K)^(1/1.5). The pressed configuration: crank along x, the rod at
    φ with L sin φ + (c + δ₀) u_y = 0 (the slider on its guide y = 0), the slider at
    B + (c + δ₀) u; velocities from the loop with ḋ = 0 (the slider's v_y = 0).
    """
    slider_acceleration = -CRANK * OMEGA**2 - CRANK**2 * OMEGA**2 / ROD
    f = np.array([SLIDER_MASS * slider_acceleration, -ROD_MASS * GRAVITY / 2])
    u = -f / np.hypot(*f)
    K = internal_cylinder_stiffness(PIN_RADIUS, PIN_CLEARANCE, 2.07e11, 0.3)
    delta0 = (np.hypot(*f) / K) ** (1.0 / 1.5)
    offset = (PIN_CLEARANCE + delta0) * u
    phi = -math.asin(offset[1] / ROD)
    a = np.array([CRANK, 0.0])
    b = a + ROD * np.array([math.cos(phi), math.sin(phi)])
    slider = b + offset
    q = np.array([CRANK / 2, 0.0, 0.0, *(a + b) / 2, phi, slider[0], slider[1], 0.0])
    phidot = -OMEGA * CRANK / (ROD * math.cos(phi))
    va = np.array([0.0, OMEGA * CRANK])
    rod_turn = phidot * np.array([-math.sin(phi), math.cos(phi)])
    rod = [*(va + rod_turn * ROD / 2), phidot]
    v = np.array([0.0, OMEGA * CRANK / 2, OMEGA, *rod, *(va + rod_turn * ROD), 0.0])
    return q, v, float(delta0)


def slider_crank_text(start: str | None = None) -> str:
    text = flores_pin_text(clearance=PIN_CLEARANCE).replace('model = "auto"', 'model = "contact"')
    if start is not None:
        text = text.replace("restitution = 0.9", f'restitution = 0.9\nstart = "{start}"')
    return text


def test_pressed__the_slider_crank_starts_at_its_closed_form():
    """The ideal force at t = 0 includes the inertia (2.72 kN at 5000 rpm, against the rod's
    weight 1.03 N): the pin is pressed by δ₀ = 11.5 µm along it, the loop closed around it."""
    q_ref, v_ref, delta0 = slider_crank_pressed()
    model, q, v, status = start_of(slider_crank_text())
    assert status[0] == 0
    assert 1.1e-5 < delta0 < 1.2e-5
    position = q[0].reshape(3, 3)[:, :2] - q_ref.reshape(3, 3)[:, :2]
    assert np.abs(position).max() <= PLACE_TOLERANCE, position
    angle = q[0].reshape(3, 3)[:, 2] - q_ref.reshape(3, 3)[:, 2]
    assert np.abs(angle).max() * ROD <= PLACE_TOLERANCE, angle
    np.testing.assert_allclose(v[0], v_ref, rtol=0, atol=1e-9 * OMEGA * CRANK)
    law = np.array([False, False, True, False])
    force = start_multipliers(model, q[0], v[0], law=law)[int(model.joint_row[2])]
    ideal = SLIDER_MASS * (CRANK * OMEGA**2 + CRANK**2 * OMEGA**2 / ROD)
    assert force == pytest.approx(math.hypot(ideal, ROD_MASS * GRAVITY / 2), rel=FORCE_RTOL)


def test_seated__the_slider_crank_pin_starts_on_its_wall_without_force():
    _, q, _, _ = start_of(slider_crank_text(start="seated"))
    model = compile_model(load_scene_text(slider_crank_text(start="seated")))
    np.testing.assert_array_equal(q, assemble(model).q)


# -- histories against the event-located reference ----------------------------------------
JOURNAL_MASS, JOURNAL_INERTIA, JOURNAL_CLEARANCE, SPIN = 0.5, 1e-4, 5e-4, 40.0


def journal_text(start: str, spin: float, friction: float, t_end: float) -> str:
    """A journal in a fixed bearing, its position not written (placed at the bearing centre,
    then assembled onto the wall below it), spinning at ``spin`` rad/s."""
    return f"""
[scene]
name = "journal"
gravity = [0.0, {-GRAVITY!r}]
[[body]]
name = "journal"
mass = {JOURNAL_MASS!r}
inertia = {JOURNAL_INERTIA!r}
angular_velocity = {spin!r}
[[joint]]
name = "J"
bodies = ["ground", "journal"]
points = [[0.0, 0.0], [0.0, 0.0]]
clearance = {JOURNAL_CLEARANCE!r}
model = "contact"
[joint.contact]
law = "lankarani-nikravesh"
stiffness = {STIFFNESS!r}
restitution = 0.8
friction = {friction!r}
radius = 0.01
start = "{start}"
[simulate]
t_end = {t_end!r}
dt = 1e-5
output_dt = 5e-4
method = "rk45"
rtol = 1e-11
atol = 1e-14
"""


@pytest.mark.parametrize(
    "start, spin, friction, t_end",
    [("pressed", SPIN, 0.1, 0.04), ("centred", 0.0, 0.0, 0.04)],
    ids=["pressed-spinning", "centred"],
)
def test_start__history_matches_the_event_located_reference(start, spin, friction, t_end):
    """Pressed: in contact from t = 0 (undamped, no onset), friction from the spin drags the
    journal up the wall; centred: it falls by c, impacts with a located onset and rebounds.
    Against the scipy reference started at the same place, to the existing contact tests'
    precision (position 1e-8 m, F_n 1e-6 of its peak)."""
    delta0 = (JOURNAL_MASS * GRAVITY / STIFFNESS) ** (1.0 / 1.5)
    y0 = -(JOURNAL_CLEARANCE + delta0) if start == "pressed" else 0.0
    out = run(journal_text(start, spin, friction, t_end))
    assert out["status"][0] == 0
    np.testing.assert_allclose(out["q"][0, 0, 0], [0.0, y0, 0.0], rtol=0, atol=PLACE_TOLERANCE)
    law = Law("lankarani-nikravesh", STIFFNESS, 1.5, 0.8, friction=friction)
    ref = journal_in_bearing(
        law, clearance=JOURNAL_CLEARANCE, mass=JOURNAL_MASS, inertia=JOURNAL_INERTIA, radius=0.01,
        position=(0.0, y0), spin=spin, gravity=GRAVITY, t_end=t_end, times=out["time"],
    )  # fmt: skip
    assert int(out["impact_count"][0, 0]) == len(ref.impacts)
    position = np.max(np.abs(out["q"][0, :, 0, :2] - ref.position[:, :2]))
    force = out["contact_force"][0, :, 0]
    force_error = np.max(np.abs(force - ref.normal_force)) / np.max(ref.normal_force)
    print(f"{start}: {len(ref.impacts)} impacts, position {position:.2e} m, F_n {force_error:.2e}")
    assert position <= 1e-8
    assert force_error <= 1e-6
    if start == "pressed":
        assert out["contact_mode"][0, 0, 0] == MODE_CONTACT
        assert abs(ref.position[-1, 0]) > 1e-5  # friction moved it along the wall
    else:
        assert out["contact_mode"][0, 0, 0] == MODE_FREE
        assert len(ref.impacts) >= 1


# -- what the scene may say ------------------------------------------------------------------
def test_auto__defaults_to_the_link_and_may_start_centred():
    text = bar_text().replace('model = "contact"', 'model = "auto"')
    model, q, _, _ = start_of(text)
    assert model.joint_contact_start == ("seated",)
    np.testing.assert_allclose(q[0], hanging(0.0), rtol=0, atol=PLACE_TOLERANCE)
    model, q, _, _ = start_of(text.replace("[simulate]", 'start = "centred"\n[simulate]', 1))
    np.testing.assert_allclose(q[0], hanging(-CLEARANCE), rtol=0, atol=PLACE_TOLERANCE)


@pytest.mark.parametrize(
    "change, message",
    [
        (('model = "contact"', 'model = "auto"'), 'model "auto" starts on the link'),
        (('model = "contact"', 'model = "link"'), 'model "link" has no contact law'),
    ],
    ids=["pressed-auto", "link"],
)
def test_start__refused_where_the_model_has_no_such_start(change, message):
    text = bar_text(start="pressed").replace(*change)
    with pytest.raises(SceneError, match=message) as error:
        load_scene_text(text)
    assert str(error.value).startswith("joint.O.contact.start: ")


WRITTEN = {  # the bar's position written: on the wall, pressed in by 5 µm, or at the centre
    "seated": 0.0,
    "pressed": 5e-6,
    "centred": -CLEARANCE,
}


@pytest.mark.parametrize("written", list(WRITTEN))
@pytest.mark.parametrize("start", [None, "seated", "pressed", "centred"])
def test_start__a_written_journal_stays_as_written(written, start):
    """Kept to the last bit whatever start says; a start that names another place than the
    written one is refused in one line."""
    centre = hanging(WRITTEN[written])
    text = bar_text(start=start).replace(
        "[[joint]]", f"position = [{float(centre[0])!r}, {float(centre[1])!r}]\n[[joint]]", 1
    )
    if start is not None and start != written:
        with pytest.raises(SceneError, match=f"joint.O.contact.start: '{start}' contradicts"):
            compile_model(load_scene_text(text))
        return
    model, q, _, status = start_of(text)
    assert status[0] == 0
    np.testing.assert_array_equal(q, np.asarray(model.q0))


def test_validate__prints_the_pressed_start(tmp_path, capsys):
    from mcchain.cli import main

    delta0 = (MASS * GRAVITY / STIFFNESS) ** (1.0 / 1.5)
    assert main(["validate", str(write_scene(tmp_path, bar_text()))]) == 0
    out = capsys.readouterr().out
    start = "starts on the contact law, pressed in: contact force 19.62 N"
    assert f"|d| - c {delta0:.6g} m; {start}" in out
