"""The scene models of the mechanism: ``[scene]``, ``[[body]]``, ``[[joint]]`` (with its
``contact``), ``[[driver]]``, ``[[force]]``, ``[[spring]]`` (conventions: see
:mod:`mcchain.scene.models`)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import (
    Field,
    PrivateAttr,
    model_validator,
)

from mcchain.contact import HERTZ_EXPONENT, LAW_CODES, ContactStart, LawName
from mcchain.parameters import unset_value
from mcchain.scene.fields import (
    BodyRef,
    Bool,
    Name,
    Num,
    Points,
    Section,
    Vec2,
)

DEFAULT_GRAVITY = (0.0, -9.81)


# -- [scene] -------------------------------------------------------------------------------
class SceneSection(Section):
    """``[scene]``: name and gravity. The whole table may be omitted."""

    name: Name | None = Field(
        default=None,
        description="scene name; default: the file's stem (``clearance-bar`` for "
        "``clearance-bar.toml``), or ``scene`` for text without a file.",
    )
    gravity: Vec2 = Field(
        default=list(DEFAULT_GRAVITY),
        description="gravitational acceleration, global frame, m/s²; default [0, -9.81].",
    )


# -- [[body]] ------------------------------------------------------------------------------
class Body(Section):
    """``[[body]]``: a rigid body, with its state at t = 0."""

    name: Name = Field(description="unique body name (not ``ground``); required.")
    mass: Num = Field(gt=0, description="mass m, kg; required, > 0.")
    inertia: Num = Field(gt=0, description="centroidal moment of inertia J, kg m²; required.")
    scale_inertia: Bool = Field(
        default=False,
        description="true: a sampled mass carries the inertia with it, J = J_written · m / "
        "m_written in every instance (the same shape and size, only denser or lighter); "
        "default false: J stays as written. Not with ``inertia`` sampled as well.",
    )
    position: Vec2 | None = Field(
        default=None,
        description="centre of mass (X, Y) at t = 0, m; default: placed on its joints "
        "(from a neighbour already placed, at the body's angle).",
    )
    angle: Num | None = Field(
        default=None,
        description="angle θ at t = 0, rad; default the driver's ``angle0`` for a driven body, "
        "else 0.",
    )
    velocity: Vec2 = Field(
        default=[0.0, 0.0], description="centre-of-mass velocity at t = 0, m/s; default [0, 0]."
    )
    angular_velocity: Num = Field(default=0.0, description="θ̇ at t = 0, rad/s; default 0.")


# -- [[joint]] -----------------------------------------------------------------------------
class Contact(Section):
    """``[joint.contact]``: the contact law of a clearance joint (see docs/contact.md).

    F_n = K δ^m (1 + D δ̇) for a penetration δ = |d| − c > 0 (clipped at F_n ≥ 0), 0 in free
    flight; D is fixed at each contact's onset from the restitution and the approach speed.
    """

    law: LawName = Field(
        default="lankarani-nikravesh",
        description=", ".join(f'"{name}"' for name in LAW_CODES)
        + ": the hysteresis damping D of the law "
        '("hertz": none; default "lankarani-nikravesh").',
    )
    stiffness: Num | None = Field(
        default=None,
        gt=0,
        description="K, N/m^exponent; required unless ``radius``, ``youngs_modulus`` and "
        "``poisson_ratio`` are given (then K of internal cylindrical contact, exponent "
        f"{HERTZ_EXPONENT}).",
    )
    exponent: Num = Field(
        default=unset_value("joint", "contact.exponent"),
        gt=0,
        description=f"m; default {unset_value('joint', 'contact.exponent')} (Hertz).",
    )
    restitution: Num | None = Field(
        default=None,
        gt=0,
        le=1,
        description="coefficient of restitution e, (0, 1]; required by the damped laws, "
        "ignored by hertz.",
    )
    friction: Num = Field(
        default=0.0,
        ge=0,
        description="Coulomb coefficient μ (regularised, Ambrósio); default 0 (none).",
    )
    radius: Num | None = Field(
        default=None,
        gt=0,
        description="journal radius R, m: the moment arm and slip of friction, and, with the "
        "materials, K; default: none (friction acts at the centres).",
    )
    youngs_modulus: Num | None = Field(
        default=None, gt=0, description="Young's modulus E of journal and bearing, Pa."
    )
    poisson_ratio: Num | None = Field(
        default=None, gt=-1, le=0.5, description="Poisson's ratio ν of journal and bearing."
    )
    start: ContactStart | None = Field(
        default=None,
        description='where a journal the file does not write starts: "pressed" (into its '
        "wall along the ideal mechanism's joint force at t = 0, by the δ₀ with K δ₀^m = that "
        'force, at rest in its bearing), "seated" (on its wall, no force) or "centred" '
        '(d = 0); default "pressed" for model contact, "seated" for auto (the link). A '
        "written journal stays as written.",
    )

    @model_validator(mode="after")
    def _stiffness_given_once(self) -> Contact:
        materials = (self.radius, self.youngs_modulus, self.poisson_ratio)
        given = [m is not None for m in materials]
        if self.stiffness is not None and any(given[1:]):
            raise ValueError(
                "give `stiffness`, or `radius`, `youngs_modulus` and `poisson_ratio`, not both"
            )
        if self.stiffness is None and not all(given):
            raise ValueError(
                "needs `stiffness`, or all of `radius`, `youngs_modulus` and `poisson_ratio`"
            )
        if self.stiffness is None and self.exponent != HERTZ_EXPONENT:
            raise ValueError(
                f"K from `radius` and the materials is for `exponent = {HERTZ_EXPONENT}`"
            )
        if self.law != "hertz" and self.restitution is None:
            raise ValueError(f"law {self.law!r} needs `restitution` (e in (0, 1])")
        return self


class Joint(Section):
    """``[[joint]]``: a revolute joint, ideal (``clearance = 0``) or with radial clearance,
    or an ideal prismatic (sliding) joint."""

    name: Name | None = Field(
        default=None,
        description='unique joint name; default "<bearing>-<journal>" (e.g. "ground-bar").',
    )
    bodies: Annotated[list[BodyRef], Field(min_length=2, max_length=2)] = Field(
        description="[bearing, journal] body names (``ground`` allowed); required."
    )
    points: Points = Field(
        description="[[x, y] on the bearing, [x, y] on the journal]: local coordinates of "
        "the bearing centre and the journal centre, m; required."
    )
    clearance: Num = Field(
        default=0.0,
        ge=0,
        description="radial clearance c, m; default 0 (ideal joint). A clearance > 0, or a "
        "sampled clearance, makes a clearance joint (one constraint row).",
    )
    eccentricity: Num | None = Field(
        default=None,
        description="initial direction α of d (journal centre minus bearing centre), global, "
        "rad; default: from the positions (NaN in the model). Ignored by ideal joints.",
    )
    model: Literal["link", "contact", "auto"] | None = Field(
        default=None,
        description='clearance joints in ``[simulate]``: "link" (the massless link, held '
        'while it pushes), "contact" (the contact law throughout: free flight and impacts) '
        'or "auto" (the link until its force λ first reaches 0, then the contact law); '
        'default "auto" with a ``[joint.contact]`` table, else "link". Statics and modes '
        "always use the link.",
    )
    contact: Contact | None = Field(
        default=None, description="``[joint.contact]``: the contact law; default none."
    )
    type: Literal["revolute", "prismatic"] = Field(
        default="revolute",
        description='"revolute" (a pin, the default) or "prismatic" (a slider: the two points '
        "stay on a line along ``axis`` and the relative angle is held).",
    )
    axis: Vec2 | None = Field(
        default=None,
        description="sliding direction of a prismatic joint in the first body's frame "
        "(ground: global), any non-zero length; required for a prismatic joint.",
    )
    relative_angle: Num | None = Field(
        default=None,
        description="θ_b − θ_a held by a prismatic joint, rad; default: as written or placed.",
    )

    _auto_name: bool = PrivateAttr(default=False)

    @property
    def resolved_model(self) -> str:
        """``model`` resolved: as given, else ``"auto"`` with a contact table, else ``"link"``."""
        if self.model is not None:
            return self.model
        return "auto" if self.contact is not None else "link"


# -- [[driver]] ----------------------------------------------------------------------------
class Driver(Section):
    """``[[driver]]``: prescribed rotation θ(t) of one body (``body``, the driver's name), or
    prescribed displacement s(t) of a prismatic joint (``joint``, the driver's name).

    ``law = "constant"``: θ = θ0 + ω t (s = s0 + v t). ``law = "harmonic"``: θ = θ0 + ω t +
    A (sin(2π f t + φ) − sin φ), a steady turn (ω, default 0) with a harmonic swing or speed
    fluctuation on top; θ(0) = θ0 either way (the same for s with s0, v).
    """

    body: BodyRef | None = Field(
        default=None, description="the driven body (not ground); this or ``joint`` is required."
    )
    joint: BodyRef | None = Field(
        default=None,
        description="the driven prismatic joint (its displacement along the axis); this or "
        "``body`` is required.",
    )
    law: Literal["constant", "harmonic", "table"] = Field(
        default="constant",
        description='"constant" (θ0 + ω t, default), "harmonic" (θ0 + ω t + A (sin(2π f t '
        '+ φ) − sin φ)) or "table" (a cubic spline through ``times`` and ``angles`` or '
        "``displacements``).",
    )
    omega: Num | None = Field(
        default=None,
        description='angular speed ω, rad/s; required for law "constant", default 0 for '
        '"harmonic".',
    )
    angle0: Num | None = Field(
        default=None, description="θ_0, rad; default: the body's initial ``angle``."
    )
    amplitude: Num | None = Field(
        default=None,
        description='A of law "harmonic", rad (m for a slider driver); required there, not '
        "allowed else.",
    )
    frequency: Num | None = Field(
        default=None,
        gt=0,
        description='f of law "harmonic", Hz (cycles per second); required there, not allowed '
        "else.",
    )
    phase: Num | None = Field(
        default=None, description='φ of law "harmonic", rad; default 0 there, not allowed else.'
    )
    displacement0: Num | None = Field(
        default=None,
        description="s0 of a slider driver, m: the displacement u·d along the joint's axis at "
        "t = 0; default: as written or placed.",
    )
    speed: Num | None = Field(
        default=None,
        description='v of a slider driver, m/s; required for law "constant", default 0 for '
        '"harmonic".',
    )
    times: list[Num] | None = Field(
        default=None,
        description='knots of law "table", s, increasing; the table must cover t = 0 (and '
        "``[simulate] t_end``).",
    )
    angles: list[Num] | None = Field(
        default=None, description='θ at ``times`` of law "table", rad (a body driver).'
    )
    displacements: list[Num] | None = Field(
        default=None, description='s at ``times`` of law "table", m (a slider driver).'
    )

    @property
    def name(self) -> str:
        """A driver is named by its body or its prismatic joint (``driver.crank.omega``,
        ``driver.P.speed``)."""
        return str(self.body if self.body is not None else self.joint)

    @property
    def slides(self) -> bool:
        """Whether the driver prescribes a prismatic joint's displacement."""
        return self.joint is not None


# -- [[force]] -----------------------------------------------------------------------------
class Force(Section):
    """``[[force]]``: a load on a body: a force (global frame), a couple, or both; constant, or
    ``law = "harmonic"``: value and torque times sin(2π f t + φ)."""

    name: Name | None = Field(
        default=None, description="unique force name; default: the body's name."
    )
    body: BodyRef = Field(description="the loaded body (not ground); required.")
    point: Vec2 = Field(
        default=[0.0, 0.0],
        description="local application point of ``value``, m; default [0, 0] (the centre of mass).",
    )
    value: Vec2 | None = Field(
        default=None, description="force [Fx, Fy], global frame, N; default [0, 0]."
    )
    torque: Num | None = Field(
        default=None, description="couple, N m, counter-clockwise positive; default 0."
    )
    law: Literal["constant", "harmonic", "table"] = Field(
        default="constant",
        description='"constant" (default), "harmonic" (``value`` and ``torque`` times '
        'sin(2π f t + φ)) or "table" (times a cubic spline through `times` and `factors`).',
    )
    frequency: Num | None = Field(
        default=None,
        gt=0,
        description='f of law "harmonic", Hz; required there, not allowed else.',
    )
    phase: Num | None = Field(
        default=None, description='φ of law "harmonic", rad; default 0 there, not allowed else.'
    )
    times: list[Num] | None = Field(
        default=None,
        description='knots of law "table", s, increasing; the table must cover t = 0 (and '
        "``[simulate] t_end``).",
    )
    factors: list[Num] | None = Field(
        default=None, description='the load\'s factor at ``times`` of law "table" (1: as written).'
    )

    _auto_name: bool = PrivateAttr(default=False)

    @model_validator(mode="after")
    def _value_or_torque(self) -> Force:
        if self.value is None and self.torque is None:
            raise ValueError("a force needs `value = [Fx, Fy]`, `torque = T`, or both")
        return self


# -- [[spring]] ----------------------------------------------------------------------------
class Spring(Section):
    """``[[spring]]``: a linear spring-damper between two points, acting along the line."""

    name: Name | None = Field(
        default=None, description='unique spring name; default "<a>-<b>" from ``bodies``.'
    )
    bodies: Annotated[list[BodyRef], Field(min_length=2, max_length=2)] = Field(
        description="[a, b] body names (``ground`` allowed); required."
    )
    points: Points = Field(description="[[x, y] on a, [x, y] on b], local, m; required.")
    stiffness: Num = Field(ge=0, description="stiffness k, N/m; required, >= 0.")
    rest_length: Num | None = Field(
        default=None,
        ge=0,
        description="rest length, m; default: the distance between the two points at the "
        "scene's initial positions (the spring is unstressed at t = 0).",
    )
    damping: Num = Field(
        default=0.0, ge=0, description="damping along the spring, N s/m; default 0."
    )

    _auto_name: bool = PrivateAttr(default=False)
