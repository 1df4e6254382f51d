"""Named test and benchmark scenes (TOML text), with start states consistent to rounding.

* :func:`swinging_bar_text` — the seed bar on a clearance pin, released ``tilt`` rad from
  hanging, journal at the bottom of its bearing;
* :func:`hanging_clearance_bar_text` — the bar of ``configs/clearance-bar.toml`` hanging on
  its clearance pin: the ``[scene]``, ``[[body]]`` and ``[[joint]]`` tables that the run
  tests (until, extend, the pipeline, the viewer) complete with sections of their own;
* :func:`journal_tables` — a journal in a fixed bearing on ground (one free body, gravity
  along −y): the contact tests' scene, written free, pressed or seated;
* :func:`straight_chain_text` — bars pinned end to end, all at one angle, at rest (the
  chains benchmark; :data:`DOUBLE_PENDULUM` is its two-bar case);
* :func:`fourbar_text` — the driven four-bar of ``configs/fourbar-clearance.toml``;
* :func:`parallelogram_text` — a parallelogram four-bar with a closed form
  (:func:`mcchain.testing.closed_forms.parallelogram_closed_form`);
* :data:`DOUBLE_PENDULUM_TEXT` and :data:`LOADED_TEXT` — the clearance double pendulum, bare
  and with every kind of load (driver, force and couple, springs with damping);
* :func:`slider_crank_text` — a driven slider-crank with an offset pin and guide point
  (prismatic joint on the ground), and :data:`TELESCOPE_TEXT` — a prismatic joint between
  two moving bodies;
* :func:`flores_pin_text` — ``configs/slider-crank-flores.toml`` as one instance: the piston
  pin's clearance under the contact law (model auto), its ``[simulate]`` keys replaced
  (:func:`config_text` and :func:`with_lines`: a shipped scene with some lines replaced).

:data:`SCENES` names them for :func:`scene_model`. Random scenes come from
:mod:`mcchain.testing.factory`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from mcchain.model import Model
from mcchain.testing.factory import rotation


def _f(x: float) -> str:
    return repr(float(x))


def swinging_bar_text(clearance: float = 1e-3, tilt: float = 0.3, count: int | None = None) -> str:
    """A 1 m, 2 kg bar hanging from a clearance pin, released ``tilt`` rad from the vertical,
    the journal at the bottom of its bearing; ``count``: a ``[sample]`` of that many copies."""
    th = -math.pi / 2 + tilt
    com = np.array([0.0, -clearance]) - rotation(th) @ np.array([-0.5, 0.0])
    sample = "" if count is None else f"[sample]\ncount = {count}\nseed = 3\n"
    return f"""
[scene]
name = "clearance-bar"
gravity = [0.0, -9.81]
[[body]]
name = "bar"
mass = 2.0
inertia = {_f(2.0 / 12)}
position = [{_f(com[0])}, {_f(com[1])}]
angle = {_f(th)}
[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]
clearance = {_f(clearance)}
{sample}"""


def hanging_clearance_bar_text(name: str, angular_velocity: float | None = None) -> str:
    """The ``[scene]``, ``[[body]]`` and ``[[joint]]`` tables of a scene named ``name``: the
    2 kg, 1 m bar (J = 1/6 kg m²) hanging from a 1 mm clearance pin at the origin, its journal
    at the bottom of the bearing, at rest or turning at ``angular_velocity`` rad/s. The
    caller appends the other sections."""
    turning = "" if angular_velocity is None else f"angular_velocity = {angular_velocity!r}\n"
    return f"""[scene]
name = "{name}"
gravity = [0.0, -9.81]
[[body]]
name = "bar"
mass = 2.0
inertia = 0.16666666666666666
position = [0.0, -0.501]
angle = -1.5707963267948966
{turning}[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]
clearance = 1e-3
eccentricity = -1.5707963267948966
"""


def journal_tables(
    position: tuple[float, float],
    velocity: tuple[float, float] = (0.0, 0.0),
    model: str = "contact",
    contact: str = "",
    mass: float = 0.5,
    inertia: float = 1e-4,
    clearance: float = 5e-4,
    gravity: float = 9.81,
) -> str:
    """The ``[scene]``, ``[[body]]`` and ``[[joint]]`` tables of a journal (``mass`` kg,
    ``inertia`` kg m²) in a bearing of radial ``clearance`` m fixed on ground at the origin,
    under ``gravity`` m/s² along −y: its centre written at ``position`` (m, from the bearing
    centre) moving at ``velocity`` (m/s), the joint's ``model`` followed by ``contact`` (the
    text of its ``[joint.contact]`` table, or nothing). The caller appends ``[simulate]``."""
    return f"""
[scene]
name = "journal"
gravity = [0.0, {-gravity!r}]

[[body]]
name = "journal"
mass = {mass!r}
inertia = {inertia!r}
position = [{position[0]!r}, {position[1]!r}]
velocity = [{velocity[0]!r}, {velocity[1]!r}]

[[joint]]
name = "J"
bodies = ["ground", "journal"]
points = [[0.0, 0.0], [0.0, 0.0]]
clearance = {clearance!r}
model = "{model}"
{contact}
"""


def straight_chain_text(
    lengths: list[float], masses: list[float], angle: float = -math.pi / 3,
    clearance: dict[int, float] | None = None,
) -> str:  # fmt: skip
    """Bars pinned end to end from the origin, all at ``angle`` (rad from +x), at rest.

    ``clearance`` maps a joint index (0: the ground pin) to a radial clearance; the journal
    then sits along the bar, so the start is consistent.
    """
    clearance = clearance or {}
    parts = ['[scene]\nname = "chain"\ngravity = [0.0, -9.81]\n']
    tip = np.zeros(2)
    u = np.array([math.cos(angle), math.sin(angle)])
    for i, (length, mass) in enumerate(zip(lengths, masses, strict=True)):
        tip = tip + clearance.get(i, 0.0) * u
        com = tip + 0.5 * length * u
        parts.append(
            f'[[body]]\nname = "b{i}"\nmass = {_f(mass)}\ninertia = {_f(mass * length**2 / 12)}\n'
            f"position = [{_f(com[0])}, {_f(com[1])}]\nangle = {_f(angle)}\n"
        )
        tip = com + 0.5 * length * u
    for i, length in enumerate(lengths):
        a = '"ground"' if i == 0 else f'"b{i - 1}"'
        pa = "[0.0, 0.0]" if i == 0 else f"[{_f(lengths[i - 1] / 2)}, 0.0]"
        extra = f"clearance = {_f(clearance[i])}\n" if i in clearance else ""
        parts.append(
            f'[[joint]]\nname = "j{i}"\nbodies = [{a}, "b{i}"]\n'
            f"points = [{pa}, [{_f(-length / 2)}, 0.0]]\n{extra}"
        )
    return "\n".join(parts)


DOUBLE_PENDULUM: dict[str, Any] = dict(lengths=[0.6, 0.4], masses=[1.5, 1.0])


def fourbar_text() -> str:
    """The driven four-bar of ``configs/fourbar-clearance.toml`` (clearance 1e-4 m at B)."""
    return """
[scene]
name = "fourbar-clearance"
gravity = [0.0, -9.81]
[[body]]
name = "crank"
mass = 0.1
inertia = 8.333333333333333e-05
position = [0.02500000000000001, 0.04330127018922193]
angle = 1.0471975511965976
velocity = [-0.8660254037844386, 0.5000000000000002]
angular_velocity = 20.0
[[body]]
name = "coupler"
mass = 0.3
inertia = 0.00225
position = [0.17582706516355487, 0.16825760557544506]
angle = 0.5756344435187036
velocity = [-1.4099950572949895, 0.5037254605303013]
angular_velocity = -3.9441000934466874
[[body]]
name = "rocker"
mass = 0.25
inertia = 0.0013020833333333333
position = [0.30085606180870794, 0.12499706859834622]
angle = 1.5639477787895628
velocity = [-0.5439696535105508, 0.0037254605303010955]
angular_velocity = 4.351859284464434
[[joint]]
name = "O2"
bodies = ["ground", "crank"]
points = [[0.0, 0.0], [-0.05, 0.0]]
[[joint]]
name = "A"
bodies = ["crank", "coupler"]
points = [[0.05, 0.0], [-0.15, 0.0]]
[[joint]]
name = "B"
bodies = ["coupler", "rocker"]
points = [[0.15, 0.0], [0.125, 0.0]]
clearance = 1e-4
[[joint]]
name = "O4"
bodies = ["ground", "rocker"]
points = [[0.3, 0.0], [-0.125, 0.0]]
[[driver]]
body = "crank"
omega = 20.0
"""


def parallelogram_text(crank: float = 0.2, coupler: float = 0.5, omega0: float = 5.0) -> str:
    """Two cranks (0.2 kg) joined by a coupler (0.5 kg), all pinned, released with ω0 at
    90°: the coupler translates and both cranks share one angle."""
    th = np.pi / 2
    c1 = 0.5 * crank * np.array([np.cos(th), np.sin(th)])
    tip = 2 * c1
    v1 = 0.5 * crank * omega0 * np.array([-np.sin(th), np.cos(th)])
    vt = 2 * v1
    return f"""
[scene]
name = "parallelogram"
gravity = [0.0, -9.81]
[[body]]
name = "crank1"
mass = 0.2
inertia = {float(0.2 * crank**2 / 12)!r}
position = [{float(c1[0])!r}, {float(c1[1])!r}]
angle = {float(th)!r}
velocity = [{float(v1[0])!r}, {float(v1[1])!r}]
angular_velocity = {float(omega0)!r}
[[body]]
name = "coupler"
mass = 0.5
inertia = {float(0.5 * coupler**2 / 12)!r}
position = [{float(tip[0] + coupler / 2)!r}, {float(tip[1])!r}]
angle = 0.0
velocity = [{float(vt[0])!r}, {float(vt[1])!r}]
[[body]]
name = "crank2"
mass = 0.2
inertia = {float(0.2 * crank**2 / 12)!r}
position = [{float(coupler + c1[0])!r}, {float(c1[1])!r}]
angle = {float(th)!r}
velocity = [{float(v1[0])!r}, {float(v1[1])!r}]
angular_velocity = {float(omega0)!r}
[[joint]]
name = "O1"
bodies = ["ground", "crank1"]
points = [[0.0, 0.0], [{float(-crank / 2)!r}, 0.0]]
[[joint]]
name = "A"
bodies = ["crank1", "coupler"]
points = [[{float(crank / 2)!r}, 0.0], [{float(-coupler / 2)!r}, 0.0]]
[[joint]]
name = "B"
bodies = ["coupler", "crank2"]
points = [[{float(coupler / 2)!r}, 0.0], [{float(crank / 2)!r}, 0.0]]
[[joint]]
name = "O2"
bodies = ["ground", "crank2"]
points = [[{float(coupler)!r}, 0.0], [{float(-crank / 2)!r}, 0.0]]
"""


DOUBLE_PENDULUM_TEXT = """
[scene]
name = "double-pendulum-clearance"
gravity = [0.0, -9.81]
[[body]]
name = "bar1"
mass = 1.5
inertia = 0.045
position = [0.15000000000000002, -0.25980762113533157]
angle = -1.0471975511965976
[[body]]
name = "bar2"
mass = 1.0
inertia = 0.013333333333333334
position = [0.4417749096279029, -0.6613901518985659]
angle = -0.7853981633974483
[[joint]]
name = "O"
bodies = ["ground", "bar1"]
points = [[0.0, 0.0], [-0.3, 0.0]]
[[joint]]
name = "B"
bodies = ["bar1", "bar2"]
points = [[0.3, 0.0], [-0.2, 0.0]]
clearance = 5e-4
"""


# the clearance double pendulum with every kind of load: driver, force + torque, springs
LOADED_TEXT = (
    DOUBLE_PENDULUM_TEXT.replace(
        'name = "double-pendulum-clearance"\ngravity = [0.0, -9.81]',
        'name = "loaded-double-pendulum"\ngravity = [0.3, -9.81]',
    )
    + """[[driver]]
body = "bar1"
omega = 1.5
[[force]]
name = "tip"
body = "bar2"
point = [0.2, 0.01]
value = [3.0, -1.0]
torque = 0.4
[[spring]]
name = "s0"
bodies = ["ground", "bar2"]
points = [[0.5, 0.2], [0.2, 0.0]]
stiffness = 300.0
rest_length = 0.3
damping = 2.0
[[spring]]
name = "s1"
bodies = ["bar1", "bar2"]
points = [[0.0, 0.05], [0.0, -0.05]]
stiffness = 50.0
damping = 0.5
"""
)


SLIDER_CRANK: dict[str, float] = dict(
    crank=0.05, rod=0.12, m_crank=0.12, m_rod=0.2, m_slider=0.3, J_crank=1e-4, J_rod=4e-4,
    J_slider=1e-4, pin_height=0.01, guide_point=0.02,
)  # fmt: skip
"""The slider-crank of :func:`slider_crank_text`: lengths m, masses kg, inertias kg m²; the
rod's pin sits ``pin_height`` above the slider's centre, the guide holds the slider at a
point ``guide_point`` ahead of its centre (so the guide carries a couple)."""


def slider_crank_text(omega: float = 100.0 * math.pi, angle0: float = 0.7) -> str:
    """A driven slider-crank (crank, connecting rod, slider on a horizontal guide through the
    crank's pivot) written with its dimensions only: :data:`SLIDER_CRANK`, gravity −9.81,
    crank at ``angle0`` turning at ``omega``."""
    d = SLIDER_CRANK
    return f"""
[scene]
name = "slider-crank"
[[body]]
name = "crank"
mass = {_f(d["m_crank"])}
inertia = {_f(d["J_crank"])}
[[body]]
name = "rod"
mass = {_f(d["m_rod"])}
inertia = {_f(d["J_rod"])}
angle = -0.3
[[body]]
name = "slider"
mass = {_f(d["m_slider"])}
inertia = {_f(d["J_slider"])}
[[joint]]
name = "O"
bodies = ["ground", "crank"]
points = [[0.0, 0.0], [{_f(-d["crank"] / 2)}, 0.0]]
[[joint]]
name = "A"
bodies = ["crank", "rod"]
points = [[{_f(d["crank"] / 2)}, 0.0], [{_f(-d["rod"] / 2)}, 0.0]]
[[joint]]
name = "B"
bodies = ["rod", "slider"]
points = [[{_f(d["rod"] / 2)}, 0.0], [0.0, {_f(d["pin_height"])}]]
[[joint]]
name = "P"
type = "prismatic"
bodies = ["ground", "slider"]
points = [[0.0, 0.0], [{_f(d["guide_point"])}, 0.0]]
axis = [1.0, 0.0]
[[driver]]
body = "crank"
omega = {_f(omega)}
angle0 = {_f(angle0)}
"""


TELESCOPE_TEXT = """
[scene]
name = "telescope"
[[body]]
name = "sleeve"
mass = 1.0
inertia = 0.05
angle = -1.2
[[body]]
name = "rod"
mass = 0.5
inertia = 0.02
angle = -1.2
[[joint]]
name = "O"
bodies = ["ground", "sleeve"]
points = [[0.0, 0.0], [-0.3, 0.0]]
[[joint]]
name = "T"
type = "prismatic"
bodies = ["sleeve", "rod"]
points = [[0.2, 0.02], [-0.1, 0.0]]
axis = [1.0, 0.1]
[[spring]]
name = "S"
bodies = ["sleeve", "rod"]
points = [[0.0, 0.0], [0.0, 0.0]]
stiffness = 400.0
rest_length = 0.35
damping = 0.3
"""
"""A pendulum whose rod slides in a sleeve along an axis turned 0.1 rad from the sleeve's
own (a prismatic joint between two moving bodies, whose normal turns with the sleeve), held
by a spring-damper: two degrees of freedom."""


def flores_pin_text(
    t_end: float = 0.03,
    clearance: float = 1e-4,
    method: str = "radau",
    rtol: float = 1e-11,
    atol: float = 1e-13,
    output_dt: float = 1e-5,
) -> str:
    """The shipped Flores slider-crank (5000 rpm, piston pin of clearance ``clearance`` m,
    Lankarani–Nikravesh e = 0.9, model auto) without its ``[sample]`` table. At the defaults
    (30 ms) the pin's link lets go at 9.9 ms and the journal impacts its bearing 6 times,
    re-seating twice (21.8 and 26.4 ms)."""
    text = config_text("slider-crank-flores.toml").split("[sample]")[0]
    keys = {"t_end": t_end, "clearance": clearance, "method": method, "rtol": rtol,
            "atol": atol, "output_dt": output_dt}  # fmt: skip
    return with_lines(text, {k: f"{k} = {v!r}".replace("'", '"') for k, v in keys.items()})


def config_text(name: str) -> str:
    """The text of the shipped scene ``configs/<name>``."""
    from pathlib import Path

    config = Path(__file__).resolve().parents[2] / "configs" / name
    return config.read_text(encoding="utf-8")


def with_lines(text: str, lines: dict[str, str]) -> str:
    """``text`` with every line whose key (the text before ``=``, stripped) is in ``lines``
    replaced by ``lines[key]`` (one or more lines), e.g. ``{"count": "count = 16"}``."""
    out = [lines.get(line.split("=")[0].strip(), line) for line in text.splitlines()]
    return "\n".join(out) + "\n"


def model_of(text: str, nsample: int | None = None, name: str = "<string>") -> Model:
    """A scene text compiled to a Model of ``nsample`` instances (default: the scene's)."""
    from mcchain.scene import compile_model, load_scene_text

    return compile_model(load_scene_text(text, name=name), nsample=nsample)


SCENES: dict[str, Callable[..., str]] = {
    "clearance_bar": swinging_bar_text,
    "parallelogram": parallelogram_text,
    "double_pendulum": lambda: DOUBLE_PENDULUM_TEXT,
    "fourbar": fourbar_text,
    "loaded": lambda: LOADED_TEXT,
    "slider_crank": slider_crank_text,
    "telescope": lambda: TELESCOPE_TEXT,
    "flores_pin": flores_pin_text,
}
"""The named scenes of the simulation tests and benchmarks."""


def scene_model(name: str, nsample: int | None = None, **kwargs: Any) -> Model:
    """A named scene compiled to a Model (``nsample`` copies; kwargs for its builder)."""
    return model_of(SCENES[name](**kwargs), nsample=nsample, name=name)
