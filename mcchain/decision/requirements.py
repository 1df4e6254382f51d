"""Requirements on an ensemble: which outputs they read and which samples meet them (the
tolerance allocation is :mod:`mcchain.decision.allocation`).

A ``[[requirement]]`` (:class:`mcchain.scene.study.Requirement`) names a per-sample ensemble
variable (``output``) and one entry of each of its other dimensions (``select``); a sample
meets it when that value lies in [min, max].

**Failed is a status bit, never a value.** A sample with a failure bit in ``status``
(:data:`mcchain.status.FAILURE_BITS`) fails every requirement and is *undefined*, whatever
its stored value (``impact_count`` −1, a peak of 0, NaN): :func:`defined_samples` (from a
solver's ``status`` array) and :func:`defined_mask` (from a Dataset) say which samples are
defined; every verdict, count, allocation and check reads them. On a defined sample, the
time of an event (an output the registry marks ``event_time``, e.g.
``first_separation_time``) that is NaN means the event never happened: +inf for a
requirement, so it passes a ``min`` and fails a ``max``. Any other NaN fails and counts as
undefined (:func:`decision_values`).

* :func:`check_requirements`: the scene's requirements against what its analyses produce
  (run before anything is written; a bad one is one :class:`SceneError` line).
* :func:`requirement_met`: 1.0 met / 0.0 failed for an array of values.
* :func:`chunk_requirement_met`: ``requirement_met`` (sample, requirement) of one solved
  chunk, from the solver's arrays (per sample, so independent of the chunking).
* :func:`requirement_values`: a requirement's per-sample values from an xarray Dataset, as
  stored; :func:`requirement_decision_values`: the same as a requirement reads them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.errors import SceneError
from mcchain.status import FAILURE_BITS

if TYPE_CHECKING:
    from mcchain.ensemble.per_sample import StoredEnsemble
    from mcchain.model import Model
    from mcchain.scene.models import Scene
    from mcchain.scene.study import Requirement

VARIABLE = "requirement_met"
"""The ensemble variable (sample, requirement): 1 met, 0 failed."""
DIM = "requirement"
"""Its second dimension, labelled by the requirements' names."""

CONTACT_LAW_OUTPUTS = (
    "peak_contact_force",
    "impact_count",
    "max_penetration",
    "free_flight_time",
    "first_separation_time",
)
"""Per-joint outputs that exist only at joints with a contact law (NaN or -1 elsewhere), and
only in scenes that have one."""
NOT_OUTPUTS = ("parameters", "status", VARIABLE)
"""Per-sample variables a requirement cannot read: inputs, flags and requirements."""


# -- which outputs a scene produces ------------------------------------------------------------
def produced_outputs(scene: Scene, model: Model) -> dict[str, tuple[str, ...]]:
    """The per-sample variables (no ``time`` dim) a run of ``scene`` stores, with their dims.

    Mirrors :func:`mcchain.solvers.solve_chunk`: the equilibrium's with ``[equilibrium]``
    or ``[modes]`` (``joint_moment_eq`` with a prismatic joint), the modes' with
    ``[modes]`` (``mode_shape`` unless ``shapes = false``, ``omega_cycle`` with ``along``),
    every per-sample variable of ``[simulate]`` (the contact-law summaries only in a scene
    with a contact law), and the scene's ``[[output]]``s.
    """
    from mcchain.ensemble.registry import VARIABLES

    has: dict[str, bool] = {
        "equilibrium": scene.equilibrium is not None or scene.modes is not None,
        "modes": scene.modes is not None,
        "simulate": scene.simulate is not None,
    }
    skip = set(NOT_OUTPUTS)
    if not model.has_prismatic:
        skip.add("joint_moment_eq")
    if scene.modes is not None and not scene.modes.shapes:
        skip.add("mode_shape")
    if scene.modes is None or scene.modes.along is None:
        skip.add("omega_cycle")
    if not model.has_contact:
        skip.update(CONTACT_LAW_OUTPUTS)
    if not model.has_slider_drivers:
        skip.add("peak_driver_force")  # stored only with a slider driver
    out: dict[str, tuple[str, ...]] = {}
    for name, spec in VARIABLES.items():
        if name in skip or spec.dims[0] != "sample" or "time" in spec.dims:
            continue
        if has.get(spec.analysis, False):
            out[name] = spec.dims
    for output in scene.output:  # the scene's [[output]]s: (sample,) each
        out[output.name] = ("sample",)
    return out


def dim_labels(model: Model, scene: Scene) -> dict[str, list[Any]]:
    """The labels of every dim a per-sample output may have: names for body, dof, joint, xy,
    param and driver; indices for mode and phase."""
    from mcchain.ensemble.registry import model_coordinates

    labels: dict[str, list[Any]] = {k: list(v) for k, v in model_coordinates(model).items()}
    labels["mode"] = list(range(int(model.nmode)))
    along = scene.modes.along if scene.modes is not None else None
    labels["phase"] = list(range(along.points if along is not None else 0))
    return labels


def _index(where: str, dim: str, labels: Sequence[Any], key: str | int) -> int:
    if isinstance(key, bool) or not isinstance(key, int | str):
        raise SceneError(f"{where}: expected a label or an index, got {key!r}")
    if isinstance(key, int):
        if not 0 <= key < len(labels):
            raise SceneError(f"{where}: index {key} outside 0..{len(labels) - 1} of dim {dim}")
        return key
    names = [str(x) for x in labels]
    if key not in names:
        known = ", ".join(names) if names else "none"
        raise SceneError(f"{where}: unknown {dim} {key!r} (known: {known})")
    return names.index(key)


@dataclass(frozen=True)
class Selection:
    """Where a requirement reads its values: ``values = outputs[output][:, *index]``."""

    output: str
    dims: tuple[str, ...]
    index: tuple[int, ...]


def resolve_selection(
    requirement: Requirement,
    dims: tuple[str, ...],
    labels: Mapping[str, Sequence[Any]],
    where: str | None = None,
) -> Selection:
    """The integer index of a requirement's ``select`` in an output of ``dims``.

    Raises:
        SceneError: a dim not selected, a key that is not a dim of the output, an unknown
            label or an index out of range (the message names ``where``.select).
    """
    where = where or f"requirement.{requirement.name}"
    other = dims[1:]
    for key in requirement.select:
        if key not in other:
            have = ", ".join(other) if other else "only sample"
            raise SceneError(
                f"{where}.select.{key}: {requirement.output} has no dim {key!r} (dims: {have})"
            )
    index = []
    for dim in other:
        if dim not in requirement.select:
            example = labels.get(dim) or [0]
            raise SceneError(
                f"{where}.select: {requirement.output} has dim {dim!r}: select one entry, e.g. "
                f"{{ {dim} = {json.dumps(example[0] if isinstance(example[0], str) else 0)} }}"
            )
        index.append(
            _index(f"{where}.select.{dim}", dim, labels.get(dim, []), requirement.select[dim])
        )
    return Selection(requirement.output, dims, tuple(index))


def check_requirements(scene: Scene, model: Model) -> list[Selection]:
    """Check every ``[[requirement]]`` against the outputs the scene produces; return where
    each reads its values.

    Raises:
        SceneError: one line naming ``requirement.<name>.<key>``: an output that is not a
            per-sample variable of this scene, a bad ``select``, or a contact-law output
            selected at a joint without a contact law (its value would always be NaN).
    """
    produced = produced_outputs(scene, model)
    labels = dim_labels(model, scene)
    selections = []
    for requirement in scene.requirement:
        where = f"requirement.{requirement.name}"
        if requirement.output not in produced:
            known = (
                ", ".join(produced)
                if produced
                else "none (no [equilibrium], [modes] or [simulate])"
            )
            raise SceneError(
                f"{where}.output: {requirement.output!r} is not a per-sample variable this scene "
                f"produces (it produces: {known})"
            )
        selection = resolve_selection(requirement, produced[requirement.output], labels, where)
        if requirement.output in CONTACT_LAW_OUTPUTS:
            joint = selection.index[selection.dims[1:].index("joint")]
            if not int(np.asarray(model.joint_model)[joint]):
                raise SceneError(
                    f"{where}.select.joint: joint {model.joint_names[joint]!r} has no contact law, "
                    f"so {requirement.output} is NaN there (give it a [joint.contact] table)"
                )
        selections.append(selection)
    return selections


# -- evaluation ------------------------------------------------------------------------------
def defined_samples(status: np.ndarray) -> np.ndarray:
    """(nsample,) bool: True where ``status`` has no failure bit (the sample's values are
    defined), from a solver's or a Dataset's ``status`` array."""
    return (np.asarray(status).astype(np.int64) & FAILURE_BITS) == 0


def defined_mask(ds: StoredEnsemble) -> np.ndarray:
    """(nsample,) bool: the samples of a Dataset without a failure bit in ``status`` (all of
    them when it stores no ``status``). The one test of "failed" for every decision."""
    if "status" not in ds.data_vars:
        return np.ones(ds.sizes.get("sample", 0), dtype=bool)
    return defined_samples(ds["status"].values)


def is_event_time(output: str | None) -> bool:
    """Whether ``output`` is the time of an event, NaN when it never happened (the
    registry's ``event_time``)."""
    from mcchain.ensemble.registry import VARIABLES

    spec = VARIABLES.get(str(output)) if output is not None else None
    return bool(spec is not None and spec.event_time)


def decision_values(
    values: np.ndarray, defined: np.ndarray | None = None, output: str | None = None
) -> np.ndarray:
    """The values a requirement reads (float64, the shape of ``values``): NaN on a sample
    that is not ``defined`` (a failure bit: whatever was stored), +inf where an
    :func:`is_event_time` ``output`` is NaN on a defined sample (never), else as stored.

    Args:
        values: (nsample, ...) the output's values.
        defined: (nsample,) bool from :func:`defined_samples`; None: every sample defined.
        output: the output's name (for the event-time rule); None: not an event time.
    """
    x = np.array(values, dtype=np.float64)
    if defined is not None:
        mask = np.asarray(defined, dtype=bool).reshape((-1,) + (1,) * (x.ndim - 1))
        x = np.where(mask, x, np.nan)
        if is_event_time(output):
            x = np.where(mask & np.isnan(x), np.inf, x)
    elif is_event_time(output):
        x = np.where(np.isnan(x), np.inf, x)
    return x


def requirement_met(
    values: np.ndarray, requirement: Any, defined: np.ndarray | None = None
) -> np.ndarray:
    """1.0 where the sample meets ``requirement`` (float64, the shape of ``values``), 0.0
    where it fails it.

    A sample meets it when its :func:`decision_values` value lies in [requirement.min,
    requirement.max] (a missing limit is none): a sample not ``defined`` fails, an event
    that never happened (+inf) passes a ``min`` and fails a ``max``, any other NaN fails.

    Args:
        values: the output's values as stored.
        requirement: has ``min``, ``max`` and (for the event-time rule) ``output``.
        defined: (nsample,) bool, :func:`defined_samples`; None: every sample defined.
    """
    x = decision_values(values, defined, getattr(requirement, "output", None))
    met = ~np.isnan(x)
    if requirement.min is not None:
        met &= x >= requirement.min
    if requirement.max is not None:
        met &= x <= requirement.max
    return met.astype(np.float64)


def chunk_requirement_met(
    outputs: Mapping[str, np.ndarray],
    requirements: Sequence[Requirement],
    selections: Sequence[Selection],
) -> np.ndarray:
    """``requirement_met`` (nsample, nrequirement), int8, of one solved chunk: each sample
    from its own values and ``status`` only (a failure bit fails every requirement)."""
    defined = defined_samples(outputs["status"]) if "status" in outputs else None
    columns = []
    for requirement, sel in zip(requirements, selections, strict=True):
        where: tuple[Any, ...] = (slice(None), *sel.index)
        values = np.asarray(outputs[sel.output])[where]
        columns.append(requirement_met(values, requirement, defined))
    return np.stack(columns, axis=1).astype(np.int8)


@dataclass(frozen=True)
class RunRequirements:
    """A run's requirements, checked, and how each chunk's ``requirement_met`` is made."""

    requirements: tuple[Requirement, ...]
    selections: tuple[Selection, ...]

    def add_to(self, outputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The chunk's outputs with ``requirement_met`` added."""
        met = chunk_requirement_met(outputs, self.requirements, self.selections)
        return {**outputs, VARIABLE: met}

    def chunk_keywords(self) -> dict[str, Any]:
        """``labels`` and ``variable_attrs`` of
        :func:`mcchain.ensemble.registry.chunk_variables` for ``requirement_met``."""
        return {
            "labels": {DIM: [r.name for r in self.requirements]},
            "variable_attrs": {VARIABLE: variable_attributes(self.requirements)},
        }


def job_requirements(job: Any) -> RunRequirements | None:
    """The requirements of a run's job (:class:`mcchain.runner.job.Job`), or None without any."""
    requirements = tuple(getattr(job.scene, "requirement", None) or ())
    if not requirements:
        return None
    return RunRequirements(requirements, tuple(check_requirements(job.scene, job.model)))


def variable_attributes(requirements: Sequence[Requirement]) -> dict[str, Any]:
    """Attributes of ``requirement_met`` beyond the registry's: each requirement's limits
    (``min``, ``max``; NaN: none), ``target`` and ``confidence`` as arrays along the
    requirement dim, and ``requirements``, their definitions as JSON."""

    def limit(value: float | None) -> float:
        return math.nan if value is None else float(value)

    return {
        "min": np.array([limit(r.min) for r in requirements], dtype=np.float64),
        "max": np.array([limit(r.max) for r in requirements], dtype=np.float64),
        "target": np.array([r.target for r in requirements], dtype=np.float64),
        "confidence": np.array([r.confidence for r in requirements], dtype=np.float64),
        "requirements": json.dumps([r.model_dump(mode="json") for r in requirements]),
    }


def stored_requirements(ds: StoredEnsemble) -> list[Requirement]:
    """The requirements of a stored ensemble: from ``requirement_met``'s attributes, else
    from the scene in its settings (a run made before the variable existed); [] for none."""
    from mcchain.scene.study import Requirement

    if VARIABLE in ds.data_vars and "requirements" in ds[VARIABLE].attrs:
        data = json.loads(str(ds[VARIABLE].attrs["requirements"]))
    else:
        settings = json.loads(str(ds.attrs.get("settings", "{}")))
        data = (settings.get("scene") or {}).get("requirement") or []
    return [Requirement.model_validate(item) for item in data]


def requirement_values(ds: StoredEnsemble, requirement: Requirement) -> np.ndarray:
    """A requirement's per-sample values (float64, sample order) from a Dataset: its
    ``output`` with ``select`` applied by label or index.

    Raises:
        SceneError: the output is missing or the selection does not fit it.
    """
    where = f"requirement.{requirement.name}"
    if requirement.output not in ds.data_vars:
        raise SceneError(f"{where}.output: {requirement.output!r} is not in this ensemble")
    da = ds[requirement.output]
    dims = tuple(str(d) for d in da.dims)
    if dims[0] != "sample" or "time" in dims:
        raise SceneError(f"{where}.output: {requirement.output!r} is not a per-sample variable")
    labels = {
        d: (
            [str(v) for v in ds[d].values]
            if d in ds.coords and ds[d].dtype.kind in "OUS"
            else list(range(ds.sizes[d]))
        )
        for d in dims[1:]
    }
    sel = resolve_selection(requirement, dims, labels, where)
    return np.asarray(da.isel(dict(zip(dims[1:], sel.index, strict=True))).values, dtype=np.float64)


def requirement_decision_values(ds: StoredEnsemble, requirement: Requirement) -> np.ndarray:
    """:func:`requirement_values` as the requirement reads them (:func:`decision_values`):
    NaN on samples with a failure bit, +inf for an event that never happened."""
    return decision_values(
        requirement_values(ds, requirement), defined_mask(ds), requirement.output
    )


def dataset_requirement_met(ds: StoredEnsemble, requirement: Requirement) -> np.ndarray:
    """(nsample,) float64 ``requirement_met`` of one requirement, recomputed from a Dataset's
    values and ``status`` (the rule of :func:`requirement_met`; also right for a run stored
    before failure bits decided)."""
    return requirement_met(requirement_values(ds, requirement), requirement, defined_mask(ds))
