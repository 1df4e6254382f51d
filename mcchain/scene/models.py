"""The scene file's pydantic v2 models: the shape of a validated scene.

A scene file is TOML. Its tables map one to one onto the models below; every model forbids
unknown keys, every number must be finite, and ints are accepted where floats are expected
(``mass = 2`` is 2.0) but not the other way round (``count = 10.0`` is an error). Each field
documents its default; a field without a default is required, and a default is stated here
only: solvers read the validated sections (or ``Simulate``/``Storage``/... built from these
defaults), never a second literal.

The sections: the mechanism in :mod:`mcchain.scene.mechanism`, the sample and requirements in
:mod:`mcchain.scene.study`, the analyses (``[equilibrium]``, ``[modes]``, ``[simulate]``,
``[storage]``) and the whole :class:`Scene` here; their field types in
:mod:`mcchain.scene.fields`.

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

from typing import Annotated, Any, Literal

from pydantic import (
    Field,
    PrivateAttr,
    field_validator,
    model_validator,
)

from mcchain.scene.fields import (
    BodyRef,
    Bool,
    Int,
    Num,
    Section,
    Vec2,
    flatten_dotted,
)
from mcchain.scene.mechanism import Body, Driver, Force, Joint, SceneSection, Spring
from mcchain.scene.outputs import Output
from mcchain.scene.study import Requirement, Sample

DEFAULT_BAUMGARTE = (10.0, 10.0)
"""(α, β) of Φ̈ + 2αΦ̇ + β²Φ = 0 when ``[simulate] baumgarte`` is omitted, 1/s: critically
damped, drift decays in ~0.1–0.5 s, far below any step-size limit (|hα| ≪ 1); see
benchmarks/bench_simulate.py (drift chart)."""


# -- analyses -----------------------------------------------------------------------------
class Equilibrium(Section):
    """``[equilibrium]``: compute the static equilibrium (Newton on Φ = 0, Bᵀλ = F)."""

    tolerance: Num = Field(
        default=1e-10, gt=0, description="scaled residual tolerance; default 1e-10."
    )
    max_iterations: Int = Field(default=50, ge=1, description="Newton iterations; default 50.")


class ModesAlong(Section):
    """``[modes] along``: the modes of frozen configurations over one turn of a driver."""

    driver: BodyRef = Field(description="the driver (named by its body) turned; required.")
    points: Int = Field(
        ge=1, le=3600, description="configurations, equally spaced over one turn; required."
    )


class Modes(Section):
    """``[modes]``: eigenpulsations about the equilibrium. The equilibrium is computed for
    them even without ``[equilibrium]`` (which then only sets the Newton settings)."""

    shapes: Bool = Field(
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


class Simulate(Section):
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
    retry_failed: Bool = Field(
        default=True,
        description="solve a sample whose time integration fails again, tighter (rtol and "
        "atol, or dt, divided by 10, then 100), then by radau, before it counts as undefined "
        "(stored per sample in solved_by); default true, false to keep the failure.",
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
        return flatten_dotted(v, lambda node: False)

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


class Storage(Section):
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
    histories: Literal["all", "none", "failed"] = Field(
        default="all",
        description='time histories stored: "all" (default), "none", or "failed" (the '
        "samples that fail a requirement or carry a status flag).",
    )

    @model_validator(mode="after")
    def _zlib_level(self) -> Storage:
        if self.compression == "zlib" and self.complevel > 9:
            raise ValueError(f"complevel {self.complevel} > 9 for zlib")
        return self


# -- the scene -----------------------------------------------------------------------------


class Scene(Section):
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
    output: list[Output] = Field(default_factory=list, description="``[[output]]``; default none.")

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
