"""The scene models of the study: what is sampled (``[sample]``, its distributions) and what
is asked of the samples (``[[requirement]]``)."""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    Field,
    PlainValidator,
    Strict,
    field_validator,
    model_validator,
)

from mcchain.scene.fields import (
    Int,
    Num,
    Section,
    flatten_dotted,
)

DEFAULT_SAMPLE_COUNT = 1000
DEFAULT_SAMPLE_SEED = 0
DEFAULT_MAX_COUNT = 65536
"""``[sample] max_count`` when ``until`` is given without it."""
MAX_SEED = 2**64 - 1


# -- [sample] ------------------------------------------------------------------------------
DISTRIBUTIONS = ("uniform", "normal", "lognormal", "truncnormal", "choice")


class Distribution(Section):
    """A one-key table giving a parameter's distribution.

    * ``uniform = [low, high]`` (low <= high);
    * ``normal = [mean, std]`` (std >= 0);
    * ``lognormal = [mu, sigma]``: the log of the value is normal(mu, sigma), sigma >= 0;
    * ``truncnormal = [mean, std, low, high]``: normal(mean, std) restricted to [low, high],
      std > 0, low < high, low <= mean <= high;
    * ``choice = [v1, v2, ...]``: one of the values, each equally likely.

    ``within = [low, high]`` beside any of them restricts it to [low, high] (the
    distribution truncated there: values outside are never drawn, the others keep their
    relative likelihood); ``mcchain confirm`` writes it for an allocated range.
    """

    uniform: Annotated[list[Num], Field(min_length=2, max_length=2)] | None = None
    normal: Annotated[list[Num], Field(min_length=2, max_length=2)] | None = None
    lognormal: Annotated[list[Num], Field(min_length=2, max_length=2)] | None = None
    truncnormal: Annotated[list[Num], Field(min_length=4, max_length=4)] | None = None
    choice: Annotated[list[Num], Field(min_length=1)] | None = None
    within: Annotated[list[Num], Field(min_length=2, max_length=2)] | None = None

    @field_validator("within")
    @classmethod
    def _within(cls, v: list[float] | None) -> list[float] | None:
        if v is not None and not v[0] < v[1]:
            raise ValueError(f"low must be below high, got [{v[0]!r}, {v[1]!r}]")
        return v

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
        if self.within is not None:
            low, high = self.within
            own = self._own_bounds()
            if self.kind == "choice" and not any(low <= v <= high for v in self.args):
                raise ValueError(f"within: no value of choice lies in [{low!r}, {high!r}]")
            if own is not None and self.kind != "choice" and not (own[0] < high and low < own[1]):
                raise ValueError(
                    f"within: [{low!r}, {high!r}] does not overlap the {self.kind} range "
                    f"[{own[0]!r}, {own[1]!r}]"
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
        truncnormal, choice, or any with ``within``); None for the unbounded ones (normal,
        lognormal)."""
        own = self._own_bounds()
        if self.within is None:
            return own
        low, high = self.within
        if self.kind == "choice":
            inside = [v for v in self.args if low <= v <= high]
            return min(inside), max(inside)
        if own is None:
            return low, high
        return max(own[0], low), min(own[1], high)

    def _own_bounds(self) -> tuple[float, float] | None:
        a = self.args
        kind = self.kind
        if kind == "uniform":
            return a[0], a[1]
        if kind == "truncnormal":
            return a[2], a[3]
        if kind == "choice":
            return min(a), max(a)
        return None


def _is_distribution_table(node: dict[str, Any]) -> bool:
    return any(k in DISTRIBUTIONS for k in node) or not all(
        isinstance(v, dict) for v in node.values()
    )


class Sample(Section):
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
        return flatten_dotted(v, _is_distribution_table)

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


class Requirement(Section):
    """``[[requirement]]``: a limit on a per-sample output and the largest acceptable
    probability of breaking it.

    A sample fails the requirement when its output lies outside [``min``, ``max``]; a
    sample with a failure bit in ``status`` fails too, and is counted apart as undefined; a
    NaN time of an event that never happened means "never". Every run stores
    ``requirement_met`` (sample, requirement); ``mcchain export RUN --requirements`` gives
    the failure probability with its bounds, the verdict, the quantile at the target and the
    tolerance allocation (docs/scenes.md).
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
        ge=0.5,
        lt=1,
        description="C: each bound of this requirement is one-sided at C (P(fail) <= upper "
        "with probability C, >= lower with C), so each verdict is wrong with probability at "
        f"most 1 - C; in [0.5, 1); default {DEFAULT_REQUIREMENT_CONFIDENCE}.",
    )

    @model_validator(mode="after")
    def _limits(self) -> Requirement:
        if self.min is None and self.max is None:
            raise ValueError("give `min`, `max` or both: the limits of the output")
        if self.min is not None and self.max is not None and self.min >= self.max:
            raise ValueError(f"min {self.min!r} must be below max {self.max!r}")
        return self
