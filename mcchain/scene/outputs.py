"""``[[output]]``: a named per-sample quantity of the mechanism's motion or equilibrium.

An output is one quantity of the mechanism (a body point's position, velocity or
acceleration, a body's angle or angular velocity, a joint's force, normal force or
penetration, a driver's torque or force), optionally minus the same quantity of the same
instance with every clearance joint ideal (``relative_to = "ideal"``), either reduced over a
time window of the history (``reduce``: max, min, max_abs, rms, mean, range,
first_time_above, first_time_below) or taken at the equilibrium (``at = "equilibrium"``).
It is stored as a per-sample ensemble variable named after it, which requirements read.

:class:`Output` checks each table alone; :func:`check_outputs` checks it against the rest
of the scene (what it names, the sections it needs), each failure one ``SceneError`` line
``output.<name>.<key>: reason``. Numba-free: the scene loader imports it.
"""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING, Annotated, Literal, get_args

import numpy as np
from pydantic import AfterValidator, Field, Strict, field_validator

from mcchain.errors import SceneError
from mcchain.scene.fields import BodyRef, Num, Section, Vec2

if TYPE_CHECKING:
    from mcchain.model import Model
    from mcchain.scene.mechanism import Driver
    from mcchain.scene.models import Scene

OUTPUT_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")

Quantity = Literal[
    "position",
    "velocity",
    "acceleration",
    "angle",
    "angular_velocity",
    "joint_force",
    "contact_force",
    "penetration",
    "driver_torque",
    "driver_force",
]
BODY_QUANTITIES = ("position", "velocity", "acceleration", "angle", "angular_velocity")
JOINT_QUANTITIES = ("joint_force", "contact_force", "penetration")
DRIVER_QUANTITIES = ("driver_torque", "driver_force")
VECTOR_QUANTITIES = ("position", "velocity", "acceleration", "joint_force")
POINT_QUANTITIES = ("position", "velocity", "acceleration")
QUANTITY_UNITS = {
    "position": "m",
    "velocity": "m s-1",
    "acceleration": "m s-2",
    "angle": "rad",
    "angular_velocity": "rad s-1",
    "joint_force": "N",
    "contact_force": "N",
    "penetration": "m",
    "driver_torque": "N m",
    "driver_force": "N",
}
"""CF units of each quantity (and of its reductions, but for the crossing times: s)."""
Reduction = Literal[
    "max",
    "min",
    "max_abs",
    "rms",
    "mean",
    "range",
    "first_time_above",
    "first_time_below",
]
REDUCTIONS = get_args(Reduction)
CROSSINGS = ("first_time_above", "first_time_below")
STORED_PREFIX = "max_stored_"
"""The prefix of ``mcchain export``'s columns of stored maxima
(:data:`mcchain.ensemble.export.STORED_PREFIX`), which an output name may not take."""


def _check_output_name(value: str) -> str:
    if not OUTPUT_NAME_RE.match(value):
        raise ValueError(
            f"invalid output name {value!r}: start with a lower-case letter, then lower-case "
            "letters, digits and '_'"
        )
    return value


class Output(Section):
    """``[[output]]``: a per-sample quantity, continuous over a window or at the equilibrium
    (docs/scenes.md, ``[[output]]``)."""

    name: Annotated[str, Strict(), AfterValidator(_check_output_name)] = Field(
        description="the ensemble variable's name: ``[a-z][a-z0-9_]*``, not a built-in "
        "variable's; required."
    )
    of: Quantity = Field(description="the quantity; required.")
    body: BodyRef | None = Field(
        default=None, description="the body of a body quantity (position ... angular_velocity)."
    )
    point: Vec2 | None = Field(
        default=None,
        description="the point in the body's frame, m (position, velocity, acceleration); "
        "default the centre of mass.",
    )
    joint: Annotated[str, Strict()] | None = Field(
        default=None, description="the joint of a joint quantity."
    )
    driver: Annotated[str, Strict()] | None = Field(
        default=None, description="the driver (named by its body or joint) of a driver quantity."
    )
    component: Literal["x", "y", "magnitude"] | None = Field(
        default=None,
        description="the component of a vector quantity (global frame); required for them.",
    )
    relative_to: Literal["ideal"] | None = Field(
        default=None,
        description='"ideal": minus the same quantity of the same instance with every '
        "clearance joint ideal; default none.",
    )
    reduce: Reduction | None = Field(
        default=None, description="the reduction over the window (with [simulate])."
    )
    threshold: Num | None = Field(
        default=None, description="the level of first_time_above / first_time_below."
    )
    window: Vec2 | None = Field(
        default=None, description="[t0, t1], s; default the whole run (t0 < t1 <= t_end)."
    )
    cycles: Vec2 | None = Field(
        default=None,
        description="[k0, k1]: the window from turn k0 to turn k1 of the driver (0 <= k0 < k1).",
    )
    at: Literal["equilibrium"] | None = Field(
        default=None, description='"equilibrium": the value at the equilibrium (no reduce).'
    )

    @field_validator("window", "cycles")
    @classmethod
    def _ascending(cls, value: list[float] | None) -> list[float] | None:
        if value is not None and not 0.0 <= value[0] < value[1]:
            raise ValueError(f"expected [start, end] with 0 <= start < end, got {value!r}")
        return value

    @property
    def units(self) -> str:
        """CF units of the stored value."""
        return "s" if self.reduce in CROSSINGS else QUANTITY_UNITS[self.of]

    @property
    def long_name(self) -> str:
        """What the stored value is, in words."""
        item = self.body or self.joint or self.driver
        what = self.of.replace("_", " ")
        if self.of in POINT_QUANTITIES:
            where = "centre of mass of "
            if self.point is not None:
                where = f"point {list(self.point)} m of "
            what = f"{what} of the {where}{item}"
        else:
            what = f"{what} of {item}"
        if self.component is not None:
            what = f"{self.component} of the {what}"
        if self.relative_to == "ideal":
            what += " minus the ideal mechanism's"
        if self.at is not None:
            return f"{what} at the equilibrium"
        span = "over the run"
        if self.window is not None:
            span = f"over t in [{self.window[0]!r}, {self.window[1]!r}] s"
        elif self.cycles is not None:
            span = f"over turns [{self.cycles[0]!r}, {self.cycles[1]!r}] of the driver"
        if self.reduce in CROSSINGS:
            side = "above" if self.reduce == "first_time_above" else "below"
            return (
                f"first time the {what} is {side} {self.threshold!r} {span} (inf if never), "
                "continuous"
            )
        return f"{self.reduce} of the {what} {span}, continuous"


def _where(output: Output, index: int) -> str:
    return f"output.{output.name}" if OUTPUT_NAME_RE.match(output.name) else f"output[{index}]"


def check_outputs(scene: Scene) -> None:
    """The outputs against the rest of the scene; raise :class:`SceneError`.

    Names unique and not those of built-in ensemble variables; the item a quantity needs,
    known (a body, joint or driver) and of the right kind; no key the quantity does not take
    (a point on a joint quantity, a component of a scalar); ``reduce`` with ``[simulate]``
    or ``at = "equilibrium"`` with ``[equilibrium]`` (or ``[modes]``), not both; a window
    inside the run, a threshold exactly with the crossings; ``relative_to`` where the scene
    has a clearance joint and the quantity exists on an ideal joint.
    """
    if not scene.output:
        return  # (and the registry not imported: a scene loads without it)
    from mcchain.ensemble.registry import AXIS_OUTPUTS, COORDINATES, STEPS_TAKEN, VARIABLES

    # an output is stored beside every built-in variable, coordinate and axis output
    reserved = {*VARIABLES, *COORDINATES, *AXIS_OUTPUTS, STEPS_TAKEN}
    seen: dict[str, int] = {}
    for i, output in enumerate(scene.output):
        where = _where(output, i)
        if output.name in reserved:
            raise SceneError(f"{where}.name: {output.name!r} is a built-in ensemble variable")
        if output.name.startswith(STORED_PREFIX):
            raise SceneError(
                f"{where}.name: {STORED_PREFIX}* names the CSV columns of stored maxima"
            )
        if output.name in seen:
            raise SceneError(
                f"output[{i}].name: duplicate output name {output.name!r} "
                f"(also output[{seen[output.name]}])"
            )
        seen[output.name] = i
        _check_item(scene, where, output)
        _check_analysis(scene, where, output)


def _refuse(where: str, output: Output, keys: tuple[str, ...], why: str) -> None:
    for key in keys:
        if getattr(output, key) is not None:
            raise SceneError(f"{where}.{key}: {why}")


def _check_item(scene: Scene, where: str, output: Output) -> None:
    of = output.of
    if of in BODY_QUANTITIES:
        _refuse(where, output, ("joint", "driver"), f"a {of} output names a `body`")
        if output.body is None:
            raise SceneError(f"{where}.body: missing: a {of} output names its body")
        if output.body not in scene.body_names:
            known = ", ".join(scene.body_names)
            raise SceneError(f"{where}.body: unknown body {output.body!r} (known: {known})")
        if of not in POINT_QUANTITIES:
            _refuse(where, output, ("point",), f"a body's {of} is not a point's")
    elif of in JOINT_QUANTITIES:
        _refuse(where, output, ("body", "point", "driver"), f"a {of} output names a `joint`")
        if output.joint is None:
            raise SceneError(f"{where}.joint: missing: a {of} output names its joint")
        names = scene.joint_names
        if output.joint not in names:
            raise SceneError(
                f"{where}.joint: unknown joint {output.joint!r} (known: {', '.join(names)})"
            )
        joint = scene.joint[names.index(output.joint)]
        clearance = joint.clearance > 0 or f"joint.{joint.name}.clearance" in set(scene.param_paths)
        if of == "contact_force" and not clearance:
            raise SceneError(
                f"{where}.joint: joint {output.joint!r} has no clearance: no normal force "
                '(use of = "joint_force")'
            )
        if of == "penetration" and (not clearance or joint.resolved_model == "link"):
            raise SceneError(
                f"{where}.joint: joint {output.joint!r} has no contact law: its penetration "
                "is held at 0 (give it a [joint.contact] table)"
            )
    else:
        _refuse(where, output, ("body", "point", "joint"), f"a {of} output names a `driver`")
        if output.driver is None:
            raise SceneError(f"{where}.driver: missing: a {of} output names its driver")
        drivers = {d.name: d for d in scene.driver}
        if output.driver not in drivers:
            known = ", ".join(drivers) or "none"
            raise SceneError(f"{where}.driver: unknown driver {output.driver!r} (known: {known})")
        slides = drivers[output.driver].slides
        if of == "driver_torque" and slides:
            raise SceneError(
                f"{where}.of: driver {output.driver!r} moves a prismatic joint: it applies a "
                'force (of = "driver_force")'
            )
        if of == "driver_force" and not slides:
            raise SceneError(
                f"{where}.of: driver {output.driver!r} turns a body: it applies a torque "
                '(of = "driver_torque")'
            )
    if of in VECTOR_QUANTITIES and output.component is None:
        raise SceneError(f"{where}.component: missing: {of} is a vector (x, y or magnitude)")
    if of not in VECTOR_QUANTITIES and output.component is not None:
        raise SceneError(f"{where}.component: {of} is a scalar: it has no component")
    if output.relative_to == "ideal":
        if of in ("contact_force", "penetration"):
            raise SceneError(f"{where}.relative_to: an ideal joint has no {of.replace('_', ' ')}")
        if not has_clearance_joint(scene):
            raise SceneError(
                f"{where}.relative_to: the scene has no clearance joint: its ideal mechanism "
                "is itself"
            )


def has_clearance_joint(scene: Scene) -> bool:
    """Whether a joint of the scene has a clearance (written > 0, or sampled)."""
    sampled = set(scene.param_paths)
    return any(j.clearance > 0 or f"joint.{j.name}.clearance" in sampled for j in scene.joint)


def _check_analysis(scene: Scene, where: str, output: Output) -> None:
    if output.at is not None:
        if output.reduce is not None:
            raise SceneError(f"{where}.reduce: an output is reduced over time or `at` one state")
        _refuse(
            where, output, ("window", "cycles", "threshold"),
            'an output `at = "equilibrium"` has no time window or threshold',
        )  # fmt: skip
        if scene.equilibrium is None and scene.modes is None:
            raise SceneError(f"{where}.at: needs [equilibrium] (or [modes]) in the scene")
        if output.of in ("velocity", "acceleration", "angular_velocity", "penetration"):
            raise SceneError(
                f"{where}.at: the {output.of.replace('_', ' ')} at an equilibrium is 0 "
                "(statics holds the joints on the link)"
            )
        return
    if output.reduce is None:
        raise SceneError(f'{where}.reduce: missing: give `reduce` or `at = "equilibrium"`')
    sim = scene.simulate
    if sim is None:
        raise SceneError(f"{where}.reduce: needs [simulate] in the scene (a time history)")
    if output.reduce in CROSSINGS and output.threshold is None:
        raise SceneError(f"{where}.threshold: missing: {output.reduce} needs a threshold")
    if output.reduce not in CROSSINGS and output.threshold is not None:
        raise SceneError(f"{where}.threshold: only first_time_above and first_time_below take one")
    if output.window is not None and output.cycles is not None:
        raise SceneError(f"{where}.cycles: give `window` or `cycles`, not both")
    if output.window is not None and output.window[1] > sim.t_end:
        raise SceneError(
            f"{where}.window: ends at {output.window[1]!r} s, after simulate.t_end "
            f"({sim.t_end!r} s)"
        )
    if output.cycles is not None:
        driver = cycle_driver(scene, output, where)
        omega = abs(driver.omega) if driver.omega is not None else 0.0
        if driver.law != "constant" or not omega > 0.0:
            raise SceneError(
                f'{where}.cycles: counts the turns of a driver of law "constant" with '
                f"omega != 0; driver.{driver.name} is not (give `window` instead)"
            )
        end = 2.0 * math.pi * output.cycles[1] / omega
        if end > sim.t_end * (1.0 + 1e-12):
            raise SceneError(
                f"{where}.cycles: turn {output.cycles[1]!r} of driver.{driver.name} ends at "
                f"t = {end:.6g} s, after simulate.t_end ({sim.t_end!r} s)"
            )


def cycle_driver(scene: Scene, output: Output, where: str) -> Driver:
    """The driver whose turns ``cycles`` counts: the output's own driver (a driver
    quantity), else the scene's only driver of a body's angle."""
    turning = [d for d in scene.driver if not d.slides]
    if output.driver is not None:
        own = [d for d in scene.driver if d.name == output.driver]
        if own and not own[0].slides:
            return own[0]
        raise SceneError(f"{where}.cycles: driver {output.driver!r} slides: it has no turns")
    if len(turning) != 1:
        names = ", ".join(d.name for d in turning) or "none"
        raise SceneError(
            f"{where}.cycles: counts the turns of the scene's one driver of an angle; it has "
            f"{len(turning)} ({names}): give `window` instead"
        )
    return turning[0]


def output_window(output: Output, model: Model, t_end: float) -> np.ndarray:
    """(nsample or 1, 2) the window [w0, w1] of an output in each sample, s: as written,
    the whole run, or from turn k0 to turn k1 of its driver (2π k / |ω| with each sample's
    ω)."""
    if output.window is not None:
        return np.array([output.window], dtype=np.float64)
    if output.cycles is None:
        return np.array([[0.0, t_end]])
    d = turning_driver(model, output)
    omega = np.abs(np.asarray(model.driver_omega, dtype=np.float64)[:, d])
    turns = np.asarray(output.cycles, dtype=np.float64)
    return 2.0 * math.pi * turns[np.newaxis, :] / omega[:, np.newaxis]


def turning_driver(model: Model, output: Output) -> int:
    """The driver whose turns an output's ``cycles`` counts (:func:`cycle_driver`) in a
    model."""
    if output.driver is not None:
        return model.driver_names.index(output.driver)
    return next(d for d in range(model.ndriver) if int(model.driver_joint[d]) < 0)


def check_output_windows(scene: Scene, model: Model) -> None:
    """Every sample's window inside the run: a ``cycles`` window ends at the driver's turn
    k1, which a sampled speed moves; one ending after ``t_end`` is refused in one line."""
    if scene.simulate is None:
        return
    t_end = float(scene.simulate.t_end)
    for output in scene.output:
        if output.cycles is None or output.at is not None:
            continue
        ends = output_window(output, model, t_end)[:, 1]
        late = np.flatnonzero(ends > t_end * (1.0 + 1e-12))
        if late.size:
            s = int(late[0])
            d = turning_driver(model, output)
            omega = float(np.asarray(model.driver_omega)[s % model.driver_omega.shape[0], d])
            raise SceneError(
                f"output.{output.name}.cycles: turn {output.cycles[1]!r} of driver."
                f"{model.driver_names[d]} ends at t = {ends[s]:.6g} s in sample {s} (omega "
                f"{omega:.6g} rad/s), after simulate.t_end ({t_end!r} s)"
            )
