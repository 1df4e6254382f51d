"""The scene file's pydantic v2 models: the shape of a validated scene.

A scene file is TOML. Its tables map one to one onto the models below; every model forbids
unknown keys, every number must be finite, and ints are accepted where floats are expected
(``mass = 2`` is 2.0) but not the other way round (``count = 10.0`` is an error). Each field
documents its default; a field without a default is required, and a default is stated here
only: solvers read the validated sections (or ``Simulate``/``Storage``/... built from these
defaults), never a second literal.

Shape checks (types, ranges, one-key distributions) live in the models. Checks that relate
one part of the file to another (a joint naming a body, duplicate names, sampled paths) live
in :func:`mcchain.scene.checks.check_scene`, which :func:`mcchain.scene.load_scene` runs after
the models; both raise :class:`~mcchain.errors.SceneError` with a one-line ``key.path: reason``
message (:mod:`mcchain.scene.messages`). Kinematic checks (rank of B, assembly) need the
kernels and are not made here.

Conventions: SI units (m, kg, s, rad, N); ``"ground"`` is the fixed body; a joint's
``bodies = [bearing, journal]`` and its ``points`` are local coordinates on each of them (for
ground, global coordinates); angles are counter-clockwise from the global x axis.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    AllowInfNan,
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    PrivateAttr,
    Strict,
    field_validator,
    model_validator,
)

from mcchain.contact import HERTZ_EXPONENT, LAW_CODES, LawName
from mcchain.parameters import unset_value

GROUND_NAME = "ground"
"""The name of the fixed body in ``bodies``/``body`` keys."""

DEFAULT_GRAVITY = (0.0, -9.81)
DEFAULT_SAMPLE_COUNT = 1000
DEFAULT_SAMPLE_SEED = 0
DEFAULT_MAX_COUNT = 65536
"""``[sample] max_count`` when ``until`` is given without it."""
MAX_SEED = 2**64 - 1

DEFAULT_BAUMGARTE = (10.0, 10.0)
"""(α, β) of Φ̈ + 2αΦ̇ + β²Φ = 0 when ``[simulate] baumgarte`` is omitted, 1/s: critically
damped, drift decays in ~0.1–0.5 s, far below any step-size limit (|hα| ≪ 1); see
benchmarks/bench_simulate.py (drift chart)."""

Num = Annotated[float, Strict(), AllowInfNan(False)]
"""A finite number (TOML int or float)."""
Int = Annotated[int, Strict()]
"""A TOML integer (a float such as 10.0 is refused)."""
Vec2 = Annotated[list[Num], Field(min_length=2, max_length=2)]
"""Two finite numbers ``[x, y]``."""
Points = Annotated[list[Vec2], Field(min_length=2, max_length=2)]
"""Two local points ``[[xa, ya], [xb, yb]]``, one on each of the two bodies."""

NAME_RE = re.compile(r"^[^\s.\[\]\"'/\\]+$")


def _check_name(value: str) -> str:
    if not NAME_RE.match(value):
        raise ValueError(
            f"invalid name {value!r}: use a non-empty name without spaces, dots, brackets, "
            "quotes or slashes"
        )
    return value


Name = Annotated[str, Strict(), AfterValidator(_check_name)]
"""A name: non-empty, without whitespace, ``.``, ``[``, ``]``, quotes or slashes (they
delimit sampled paths such as ``body.bar.position[0]`` and run folder names)."""
BodyRef = Annotated[str, Strict()]
"""The name of a body, or ``"ground"``."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=False)


# -- [scene] -------------------------------------------------------------------------------
class SceneSection(_Section):
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
class Body(_Section):
    """``[[body]]``: a rigid body, with its state at t = 0."""

    name: Name = Field(description="unique body name (not ``ground``); required.")
    mass: Num = Field(gt=0, description="mass m, kg; required, > 0.")
    inertia: Num = Field(gt=0, description="centroidal moment of inertia J, kg m²; required.")
    scale_inertia: bool = Field(
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
class Contact(_Section):
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


class Joint(_Section):
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
class Driver(_Section):
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
class Force(_Section):
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
class Spring(_Section):
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


# -- [sample] ------------------------------------------------------------------------------
DISTRIBUTIONS = ("uniform", "normal", "lognormal", "truncnormal", "choice")


class Distribution(_Section):
    """A one-key table giving a parameter's distribution.

    * ``uniform = [low, high]`` (low <= high);
    * ``normal = [mean, std]`` (std >= 0);
    * ``lognormal = [mu, sigma]``: the log of the value is normal(mu, sigma), sigma >= 0;
    * ``truncnormal = [mean, std, low, high]``: normal(mean, std) restricted to [low, high],
      std > 0, low < high, low <= mean <= high;
    * ``choice = [v1, v2, ...]``: one of the values, each equally likely.
    """

    uniform: Annotated[list[Num], Field(min_length=2, max_length=2)] | None = None
    normal: Annotated[list[Num], Field(min_length=2, max_length=2)] | None = None
    lognormal: Annotated[list[Num], Field(min_length=2, max_length=2)] | None = None
    truncnormal: Annotated[list[Num], Field(min_length=4, max_length=4)] | None = None
    choice: Annotated[list[Num], Field(min_length=1)] | None = None

    @field_validator("uniform")
    @classmethod
    def _uniform(cls, v: list[float] | None) -> list[float] | None:
        if v is not None and v[0] > v[1]:
            raise ValueError(f"low > high ({v[0]!r} > {v[1]!r})")
        return v

    @field_validator("normal", "lognormal")
    @classmethod
    def _normal(cls, v: list[float] | None) -> list[float] | None:
        if v is not None and v[1] < 0:
            raise ValueError(f"the standard deviation must be >= 0, got {v[1]!r}")
        return v

    @field_validator("truncnormal")
    @classmethod
    def _truncnormal(cls, v: list[float] | None) -> list[float] | None:
        if v is None:
            return v
        mean, std, low, high = v
        if std <= 0:
            raise ValueError(f"the standard deviation must be > 0, got {std!r}")
        if low >= high:
            raise ValueError(f"bounds inverted or empty: low {low!r} >= high {high!r}")
        if not low <= mean <= high:
            raise ValueError(f"mean {mean!r} outside the bounds [{low!r}, {high!r}]")
        return v

    @model_validator(mode="after")
    def _one_key(self) -> Distribution:
        given = [k for k in DISTRIBUTIONS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                "a distribution is a table with exactly one of "
                f"{', '.join(DISTRIBUTIONS)}; got " + (", ".join(given) if given else "none")
            )
        return self

    @property
    def kind(self) -> str:
        """The distribution's name (``uniform``, ``normal``, ...)."""
        return next(k for k in DISTRIBUTIONS if getattr(self, k) is not None)

    @property
    def args(self) -> list[float]:
        """The distribution's numbers, as written."""
        value = getattr(self, self.kind)
        assert value is not None
        return list(value)

    def bounds(self) -> tuple[float, float] | None:
        """The closed interval of the values a bounded distribution can give (uniform,
        truncnormal, choice); None for the unbounded ones (normal, lognormal)."""
        a = self.args
        kind = self.kind
        if kind == "uniform":
            return a[0], a[1]
        if kind == "truncnormal":
            return a[2], a[3]
        if kind == "choice":
            return min(a), max(a)
        return None


def _flatten_dotted(value: Any, is_leaf: Any) -> Any:
    """Undo TOML's dotted bare keys: ``{"body": {"bar": {"mass": X}}}`` -> ``{"body.bar.mass": X}``.

    A sampled path should be a quoted key (``"body.bar.mass" = {...}``); written bare, TOML
    nests it. A nested table is flattened while it is not a leaf (a distribution table).
    """
    if not isinstance(value, dict):
        return value
    out: dict[str, Any] = {}

    def walk(prefix: str, node: Any) -> None:
        if isinstance(node, dict) and node and not is_leaf(node):
            for key, sub in node.items():
                walk(f"{prefix}.{key}" if prefix else key, sub)
        elif prefix in out:
            raise ValueError(f"path {prefix!r} given twice (as a quoted key and as dotted keys)")
        else:
            out[prefix] = node

    for key, sub in value.items():
        walk(key, sub)
    return out


def _is_distribution_table(node: dict[str, Any]) -> bool:
    return any(k in DISTRIBUTIONS for k in node) or not all(
        isinstance(v, dict) for v in node.values()
    )


class Sample(_Section):
    """``[sample]``: Monte Carlo sampling. Absent: one instance, no parameters.

    Designs fill the unit hypercube, one column per ``vary`` path, then each column is mapped
    through its distribution's inverse CDF:

    * ``"random"`` (default): independent uniforms; sample i, column j is a pure function of
      (seed, i, j) (a Philox4x32-10 counter-based generator keyed by the seed), so a sample's
      values never depend on the count or on the chunking.
    * ``"sobol"``: scrambled Sobol' points (scipy.stats.qmc, scrambling drawn from the seed);
      point i is the i-th of the sequence whatever the count. Counts that are powers of 2
      keep the balance properties.
    * ``"lhs"``: Latin hypercube (scipy.stats.qmc.LatinHypercube) stratified over the whole
      count: sample i's values depend on the count (not on the chunking).
    * ``"saltelli"``: Saltelli's layout for first- and total-order Sobol' indices (what
      ``SALib.sample.sobol.sample(..., calc_second_order=False)`` makes): with d varied paths,
      groups of d + 2 rows A, AB_1 .. AB_d, B per base point, A and B being the two halves of
      point g of a scrambled Sobol' sequence in 2d dimensions (scrambling drawn from the seed);
      AB_j is A with path j taken from B. The count must be a multiple of d + 2; row i never
      depends on the count. ``mcchain report`` then gives first- and total-order indices.
    """

    count: Int = Field(
        default=DEFAULT_SAMPLE_COUNT,
        ge=1,
        description=f"number of instances; default {DEFAULT_SAMPLE_COUNT} (CLI --samples).",
    )
    seed: Int = Field(
        default=DEFAULT_SAMPLE_SEED,
        ge=0,
        le=MAX_SEED,
        description="random seed, 0 <= seed < 2**64; default 0 (CLI --seed).",
    )
    design: Literal["random", "sobol", "lhs", "saltelli"] = Field(
        default="random",
        description='"random" (default), "sobol", "lhs" or "saltelli" (count a multiple of the '
        "number of varied paths + 2).",
    )
    vary: dict[str, Distribution] = Field(
        default_factory=dict,
        description="parameter path -> distribution, in parameter order; default none "
        "(``count`` identical instances).",
    )

    until: Literal["decided"] | None = Field(
        default=None,
        description='"decided": run batches of ``count`` samples until every requirement is '
        "decided (its sequential interval, docs/scenes.md), or ``max_count`` is reached; "
        "default none (``count`` samples).",
    )
    max_count: Int | None = Field(
        default=None,
        ge=1,
        description=f"with ``until``: the most samples the run may take; default "
        f"{DEFAULT_MAX_COUNT} (at least ``count``).",
    )

    @field_validator("vary", mode="before")
    @classmethod
    def _flatten(cls, v: Any) -> Any:
        return _flatten_dotted(v, _is_distribution_table)

    @model_validator(mode="after")
    def _until(self) -> Sample:
        if self.until is None:
            if self.max_count is not None:
                raise ValueError('`max_count` needs `until = "decided"`')
            return self
        if self.design in ("lhs", "saltelli"):
            raise ValueError(
                f'`until` needs a design that can be continued ("random" or "sobol"), got '
                f'"{self.design}"'
            )
        if self.max_count is not None and self.max_count < self.count:
            raise ValueError(f"`max_count` ({self.max_count}) is less than `count` ({self.count})")
        return self

    @property
    def until_max_count(self) -> int:
        """The most samples an ``until`` run may take (``max_count`` or its default)."""
        if self.max_count is not None:
            return int(self.max_count)
        return max(DEFAULT_MAX_COUNT, int(self.count))


def saltelli_count_error(nparam: int, count: int) -> str | None:
    """Why ``count`` samples cannot have Saltelli's layout over ``nparam`` varied paths (the
    count must be a multiple of ``nparam + 2``), or ``None`` if they can."""
    step = nparam + 2
    if count % step:
        return (
            f"must be a multiple of {step} (= number of varied paths + 2) for design "
            f'"saltelli", got {count}'
        )
    return None


# -- [[requirement]] ---------------------------------------------------------------------
REQUIREMENT_NAME_RE = re.compile(r"^[a-z0-9_-]+$")
DEFAULT_REQUIREMENT_TARGET = 0.01
DEFAULT_REQUIREMENT_CONFIDENCE = 0.95


def _check_requirement_name(value: str) -> str:
    if not REQUIREMENT_NAME_RE.match(value):
        raise ValueError(
            f"invalid requirement name {value!r}: use lower-case letters, digits, '_' and '-'"
        )
    return value


def _label_or_index(value: Any) -> str | int:
    if isinstance(value, bool) or not isinstance(value, str | int):
        raise ValueError(
            f"expected a label (a string) or a 0-based index (an integer), got {value!r}"
        )
    return value


LabelOrIndex = Annotated[str | int, PlainValidator(_label_or_index)]
"""A ``select`` entry: a label such as ``"B"`` or an index such as ``0``."""


class Requirement(_Section):
    """``[[requirement]]``: a limit on a per-sample output and the largest acceptable
    probability of breaking it.

    A sample fails the requirement when its output lies outside [``min``, ``max``]; a
    sample whose output is NaN (a failed instance) fails too, and is counted apart as
    undefined. Every run stores ``requirement_met`` (sample, requirement); ``mcchain export
    RUN --requirements`` gives the failure probability with its interval, the verdict, the
    quantile at the target and the tolerance allocation (docs/scenes.md).
    """

    name: Annotated[str, Strict(), AfterValidator(_check_requirement_name)] = Field(
        description="unique identifier, lower-case letters, digits, ``_`` and ``-``; required."
    )
    output: Annotated[str, Strict()] = Field(
        description="a per-sample ensemble variable this scene produces (``peak_contact_force``, "
        "``omega``, ``q_eq``, ...); required."
    )
    select: dict[str, LabelOrIndex] = Field(
        default_factory=dict,
        description="one entry for each of the output's dimensions besides ``sample``: a label "
        '(``{ joint = "B" }``) or a 0-based index (``{ mode = 0 }``); default none (an output '
        "with no other dimension).",
    )
    min: Num | None = Field(
        default=None,
        description="lower limit, in the output's units; default none (``max`` then required).",
    )
    max: Num | None = Field(
        default=None,
        description="upper limit, in the output's units; default none (``min`` then required).",
    )
    target: Num = Field(
        default=DEFAULT_REQUIREMENT_TARGET,
        gt=0,
        lt=1,
        description="the largest acceptable probability of failing, in (0, 1); default "
        f"{DEFAULT_REQUIREMENT_TARGET}.",
    )
    confidence: Num = Field(
        default=DEFAULT_REQUIREMENT_CONFIDENCE,
        gt=0,
        lt=1,
        description="two-sided confidence of every interval (and so of every verdict) of this "
        f"requirement, in (0, 1); default {DEFAULT_REQUIREMENT_CONFIDENCE}.",
    )

    @model_validator(mode="after")
    def _limits(self) -> Requirement:
        if self.min is None and self.max is None:
            raise ValueError("give `min`, `max` or both: the limits of the output")
        if self.min is not None and self.max is not None and self.min >= self.max:
            raise ValueError(f"min {self.min!r} must be below max {self.max!r}")
        return self


# -- analyses -----------------------------------------------------------------------------
class Equilibrium(_Section):
    """``[equilibrium]``: compute the static equilibrium (Newton on Φ = 0, Bᵀλ = F)."""

    tolerance: Num = Field(
        default=1e-10, gt=0, description="scaled residual tolerance; default 1e-10."
    )
    max_iterations: Int = Field(default=50, ge=1, description="Newton iterations; default 50.")


class ModesAlong(_Section):
    """``[modes] along``: the modes of frozen configurations over one turn of a driver."""

    driver: BodyRef = Field(description="the driver (named by its body) turned; required.")
    points: Int = Field(
        ge=1, le=3600, description="configurations, equally spaced over one turn; required."
    )


class Modes(_Section):
    """``[modes]``: eigenpulsations about the equilibrium. The equilibrium is computed for
    them even without ``[equilibrium]`` (which then only sets the Newton settings)."""

    shapes: bool = Field(
        default=True,
        description="store the mode shapes (mode_shape); default true, false to skip them.",
    )
    along: ModesAlong | None = Field(
        default=None,
        description="also the modes of frozen configurations along one turn of a driver "
        "(omega_cycle): ``{ driver = <body>, points = <count> }``; default none.",
    )


SIMULATE_METHODS = ("rk4", "rk4-projection", "generalized-alpha", "rk45", "radau")
FIXED_STEP_METHODS = ("rk4", "rk4-projection", "generalized-alpha")
LOOP_METHODS = ("rk4",)
"""The methods of the loop kernels (``[simulate] kernels = "loop"``)."""


class Simulate(_Section):
    """``[simulate]``: a time history from t = 0 to ``t_end``."""

    t_end: Num = Field(gt=0, description="end time, s; required.")
    dt: Num = Field(
        gt=0,
        description="time step, s (the initial step of the adaptive methods); required.",
    )
    method: Literal["rk4", "rk4-projection", "generalized-alpha", "rk45", "radau"] = Field(
        default="rk4",
        description='"rk4" (default), "rk4-projection", "generalized-alpha", "rk45" '
        '(adaptive embedded) or "radau".',
    )
    output_dt: Num | None = Field(
        default=None,
        gt=0,
        description="output interval, s; default dt. For fixed-step methods a whole "
        "multiple of dt.",
    )
    start: Literal["scene", "equilibrium"] = Field(
        default="scene",
        description='start state: "scene" (default: the scene\'s positions and velocities) '
        'or "equilibrium".',
    )
    perturb: dict[str, Num] = Field(
        default_factory=dict,
        description="additions to the start state: ``body.<name>.position[0|1]``, "
        "``body.<name>.angle``, ``body.<name>.velocity[0|1]``, "
        "``body.<name>.angular_velocity``; default none.",
    )
    rtol: Num = Field(default=1e-8, gt=0, description="relative tolerance (rk45, radau).")
    atol: Num = Field(default=1e-10, gt=0, description="absolute tolerance (rk45, radau).")
    rho_inf: Num = Field(
        default=0.8, ge=0, le=1, description="spectral radius at infinity (generalized-alpha)."
    )
    baumgarte: Vec2 | None = Field(
        default=None,
        description="[alpha, beta] of Φ̈ + 2αΦ̇ + β²Φ = 0, 1/s (rk4, rk45); default "
        "[10, 10] (critically damped; DEFAULT_BAUMGARTE).",
    )
    constraint_tolerance: Num = Field(
        default=1e-6, gt=0, description="max |Φ| past which a sample diverged; default 1e-6."
    )
    max_newton: Int = Field(
        default=20, ge=1, description="Newton iterations of implicit steps; default 20."
    )
    kernels: Literal["auto", "lanes", "loop"] = Field(
        default="auto",
        description='"lanes": kernels generated for the scene\'s topology (fastest per step, '
        'compiled once per topology); "loop": generic kernels compiled once per installation '
        '(method rk4); "auto" (default): the lanes, unless the method is rk4, the lanes would '
        "take over 20 s to compile and the run is short enough that the loop kernels' extra "
        "time stays under a quarter of that compile (about 4e5 instance-steps).",
    )

    @field_validator("perturb", mode="before")
    @classmethod
    def _flatten(cls, v: Any) -> Any:
        return _flatten_dotted(v, lambda node: False)

    @property
    def output_step(self) -> float:
        """``output_dt`` resolved (dt when omitted), s."""
        return self.dt if self.output_dt is None else self.output_dt

    @property
    def gains(self) -> tuple[float, float]:
        """``baumgarte`` resolved (:data:`DEFAULT_BAUMGARTE` when omitted), 1/s."""
        return (
            DEFAULT_BAUMGARTE
            if self.baumgarte is None
            else (float(self.baumgarte[0]), float(self.baumgarte[1]))
        )


class Storage(_Section):
    """``[storage]``: how the ensemble is written (all keys optional)."""

    history_dtype: Literal["float32", "float64"] = Field(
        default="float32", description='dtype of time histories; default "float32".'
    )
    compression: Literal["zlib", "zstd", "none"] = Field(
        # zstd: the merge of a 1e5-sample four-bar ran at 198 MB/s against zlib's 48 MB/s at
        # a size within 8 % (benchmarks/bench_runs.py), which keeps I/O under 10 % of a run
        default="zstd",
        description='"zstd" (default), "zlib" or "none".',
    )
    complevel: Int = Field(
        default=1, ge=0, le=22, description="compression level; default 1 (zlib: 0-9)."
    )
    chunk_size: Int = Field(
        default=1024, ge=1, description="samples per chunk; default 1024 (CLI --chunk-size)."
    )

    @model_validator(mode="after")
    def _zlib_level(self) -> Storage:
        if self.compression == "zlib" and self.complevel > 9:
            raise ValueError(f"complevel {self.complevel} > 9 for zlib")
        return self


# -- the scene -----------------------------------------------------------------------------
class Scene(_Section):
    """A validated scene. Build it with :func:`mcchain.scene.load_scene` (or
    ``load_scene_text``), which also runs
    :func:`~mcchain.scene.checks.check_scene`.

    ``text`` is the file's source text and ``source`` where it came from; neither is part of
    the validated data.
    """

    scene: SceneSection = Field(default_factory=SceneSection, description="``[scene]``.")
    body: Annotated[list[Body], Field(min_length=1)] = Field(
        description="``[[body]]``, at least one; coordinate order is file order."
    )
    joint: list[Joint] = Field(default_factory=list, description="``[[joint]]``; default none.")
    driver: list[Driver] = Field(default_factory=list, description="``[[driver]]``; default none.")
    force: list[Force] = Field(default_factory=list, description="``[[force]]``; default none.")
    spring: list[Spring] = Field(default_factory=list, description="``[[spring]]``; default none.")
    sample: Sample | None = Field(default=None, description="``[sample]``; default none.")
    equilibrium: Equilibrium | None = Field(
        default=None, description="``[equilibrium]``; absent: not computed."
    )
    modes: Modes | None = Field(default=None, description="``[modes]``; absent: not computed.")
    simulate: Simulate | None = Field(
        default=None, description="``[simulate]``; absent: no time history."
    )
    storage: Storage = Field(default_factory=Storage, description="``[storage]``.")
    requirement: list[Requirement] = Field(
        default_factory=list, description="``[[requirement]]``; default none."
    )

    _text: str = PrivateAttr(default="")
    _source: str = PrivateAttr(default="<string>")

    @model_validator(mode="after")
    def _default_names(self) -> Scene:
        for joint in self.joint:
            if joint.name is None:
                joint.name = f"{joint.bodies[0]}-{joint.bodies[1]}"
                joint._auto_name = True
        for force in self.force:
            if force.name is None:
                force.name = force.body
                force._auto_name = True
        for spring in self.spring:
            if spring.name is None:
                spring.name = f"{spring.bodies[0]}-{spring.bodies[1]}"
                spring._auto_name = True
        return self

    @property
    def name(self) -> str:
        """The scene's name (``[scene] name``, resolved)."""
        return self.scene.name or "scene"

    @property
    def text(self) -> str:
        """The source text of the scene file ("" when built from a dict)."""
        return self._text

    @property
    def source(self) -> str:
        """The file the scene was read from, or a label such as ``<string>``."""
        return self._source

    @property
    def body_names(self) -> list[str]:
        return [b.name for b in self.body]

    @property
    def joint_names(self) -> list[str]:
        return [str(j.name) for j in self.joint]

    @property
    def driver_names(self) -> list[str]:
        return [d.name for d in self.driver]

    @property
    def force_names(self) -> list[str]:
        return [str(f.name) for f in self.force]

    @property
    def spring_names(self) -> list[str]:
        return [str(s.name) for s in self.spring]

    @property
    def param_paths(self) -> list[str]:
        """The ``[sample.vary]`` paths, in order (empty without ``[sample]``)."""
        return list(self.sample.vary) if self.sample else []
