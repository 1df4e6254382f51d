"""The ensemble's variables, declared once, and Datasets built from them.

Every variable an analysis may store is a :class:`VariableSpec` in :data:`VARIABLES`: its
name, dims, CF ``units`` and ``long_name``, a dtype rule and the analysis that produces it.
:func:`chunk_variables` turns the dict a solver returns for one chunk of samples
(``mcchain.solvers.solve_chunk``) into the variables of a part file, with coordinates and
attributes, checking every array against its declaration; :func:`build_dataset` gives the
same as an :class:`xarray.Dataset`, and :func:`validate_dataset` checks a Dataset read back
from disk.

Dtype rules: ``float64`` for parameters, equilibria and eigenpulsations (always);
``history`` for time histories (the scene's ``[storage] history_dtype``, float32 by
default); ``uint32`` for ``status``; ``int32`` for counts; ``bool`` for flags (stored as
int8 with the ``dtype = "bool"`` attribute that xarray decodes).

Dims whose size comes from the model: ``body``, ``dof`` (3), ``joint``, ``xy`` (2),
``param``, ``driver``; from the solver's arrays: ``mode`` and ``time``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.ensemble.histories import HISTORY_SAMPLE
from mcchain.ensemble.spec import VariableSpec
from mcchain.parameters import param_units
from mcchain.status import FLAG_MASKS, FLAG_MEANINGS, STATUS_DTYPE

if TYPE_CHECKING:
    import xarray as xr

    from mcchain.model import Model

DOF_NAMES = ("x", "y", "theta")
XY_NAMES = ("x", "y")

ANALYSES = ("sample", "equilibrium", "modes", "simulate", "requirement", "always")
"""Who produces a variable: the sampler, an analysis section of the scene, the
``[[requirement]]`` tables, or every run."""

DTYPE_RULES = ("float64", "history", "uint32", "int32", "int8", "bool")


def _v(
    name: str,
    dims: tuple[str, ...],
    units: str,
    long_name: str,
    dtype: str,
    analysis: str,
    *,
    event_time: bool = False,
    **attrs: Any,
) -> VariableSpec:
    return VariableSpec(name, dims, units, long_name, dtype, analysis, attrs, event_time)


_MIXED_Q = "m (x, y), rad (theta)"
_MIXED_V = "m s-1 (x, y), rad s-1 (theta)"
_S = ("sample",)
_DAMPED_OMEGA = "damped pulsations |Im s| of the modes with the dampers (0: real roots)"
_DAMPING_RATIO = "damping ratios -(s1 + s2)/(2 sqrt(s1 s2)) = -Re s/|s| (>= 1: overdamped)"
_ST = ("sample", "time")

VARIABLES: dict[str, VariableSpec] = {
    spec.name: spec
    for spec in (
        _v(
            "parameters",
            ("sample", "param"),
            "mixed",
            "sampled parameter values, one column per [sample.vary] path",
            "float64",
            "sample",
            comment="units of each column in coordinate param_units",
        ),
        _v("status", _S, "1", "per-sample status flags", "uint32", "always"),
        _v(
            "q_eq",
            ("sample", "body", "dof"),
            _MIXED_Q,
            "equilibrium configuration",
            "float64",
            "equilibrium",
        ),
        _v(
            "joint_force_eq",
            ("sample", "joint", "xy"),
            "N",
            "force on body b by body a at equilibrium",
            "float64",
            "equilibrium",
        ),
        _v(
            "joint_moment_eq",
            ("sample", "joint"),
            "N m",
            "couple on body b by body a at a prismatic joint at equilibrium (NaN for revolute "
            "joints); with joint_force_eq at b's joint point, the whole reaction",
            "float64",
            "equilibrium",
        ),
        _v(
            "iterations",
            _S,
            "1",
            "Newton iterations of the equilibrium",
            "int32",
            "equilibrium",
        ),
        _v(
            "stable",
            _S,
            "1",
            "equilibrium stability (all p^2 >= 0)",
            "bool",
            "modes",
        ),
        _v(
            "omega",
            ("sample", "mode"),
            "rad s-1",
            "eigenpulsations p, ascending; signed: -sqrt(-p^2) where p^2 < 0 (unstable)",
            "float64",
            "modes",
        ),
        _v("damped_omega", ("sample", "mode"), "rad s-1", _DAMPED_OMEGA, "float64", "modes"),
        _v(
            "omega_cycle",
            ("sample", "phase", "mode"),
            "rad s-1",
            "eigenpulsations of the mechanism frozen along one turn of a driver ([modes] along), "
            "ascending; signed as omega; NaN where a configuration cannot be assembled",
            "float64",
            "modes",
        ),
        _v("damping_ratio", ("sample", "mode"), "1", _DAMPING_RATIO, "float64", "modes"),
        _v(
            "mode_shape",
            ("sample", "mode", "body", "dof"),
            "kg-1/2 (x, y), kg-1/2 m-1 (theta)",
            "undamped mode shapes z = N v, mass-normalised: z^T M z = 1",
            "float64",
            "modes",
        ),
        _v("q", ("sample", "time", "body", "dof"), _MIXED_Q, "positions", "history", "simulate"),
        _v("v", ("sample", "time", "body", "dof"), _MIXED_V, "velocities", "history", "simulate"),
        _v(
            "joint_force",
            ("sample", "time", "joint", "xy"),
            "N",
            "force on body b by body a",
            "history",
            "simulate",
        ),
        _v(
            "contact_force",
            ("sample", "time", "joint"),
            "N",
            "normal contact force of clearance joints: lambda of the link, F_n >= 0 of the "
            "contact law (NaN for ideal joints)",
            "history",
            "simulate",
        ),
        _v(
            "joint_moment",
            ("sample", "time", "joint"),
            "N m",
            "couple on body b by body a at a prismatic joint (NaN for revolute joints); with "
            "joint_force at b's joint point, the whole reaction",
            "history",
            "simulate",
        ),
        _v(
            "penetration",
            ("sample", "time", "joint"),
            "m",
            "penetration |d| - c of joints with a contact law (NaN for the others)",
            "history",
            "simulate",
        ),
        _v(
            "contact_mode",
            ("sample", "time", "joint"),
            "1",
            "model in use at joints with a contact law (-1 for the others and after a failure)",
            "int8",
            "simulate",
            flag_values=np.array([0, 1, 2], dtype=np.int8),
            flag_meanings="link contact free",
        ),
        _v(
            "driver_torque",
            ("sample", "time", "driver"),
            "N m",
            "torque the driver applies (NaN for slider drivers)",
            "history",
            "simulate",
        ),
        _v(
            "driver_force",
            ("sample", "time", "driver"),
            "N",
            "force a slider driver applies along its prismatic joint's axis (NaN for drivers "
            "of an angle)",
            "history",
            "simulate",
        ),
        _v(
            "constraint_error",
            _ST,
            "m",
            "max |Phi| over the constraint rows",
            "history",
            "simulate",
        ),
        _v(
            "energy",
            _ST,
            "J",
            "mechanical energy: kinetic + potential (gravity, springs, constant loads) + the "
            "elastic energy K delta^(m+1)/(m+1) stored in contacts under a contact law",
            "history",
            "simulate",
        ),
        _v(
            "peak_joint_force",
            ("sample", "joint"),
            "N",
            "continuous peak over the run of |joint_force| (prismatic joints: the force normal "
            "to the axis, without the couple), located within each step, not from stored points",
            "float64",
            "simulate",
        ),
        _v(
            "peak_driver_torque",
            ("sample", "driver"),
            "N m",
            "continuous peak over the run of |driver_torque|, located within each step, not "
            "from stored points (NaN for slider drivers)",
            "float64",
            "simulate",
        ),
        _v(
            "peak_driver_force",
            ("sample", "driver"),
            "N",
            "continuous peak over the run of |driver_force| of slider drivers, located within "
            "each step, not from stored points (NaN for drivers of an angle)",
            "float64",
            "simulate",
        ),
        _v(
            "peak_contact_force",
            ("sample", "joint"),
            "N",
            "continuous peak over the run of the contact force (the link's |lambda|, then F_n), "
            "located within each step, not from stored points (joints with a contact law; NaN "
            "others)",
            "float64",
            "simulate",
        ),
        _v(
            "impact_count",
            ("sample", "joint"),
            "1",
            "impacts (located contact onsets) at joints with a contact law (-1 for the others)",
            "int32",
            "simulate",
        ),
        _v(
            "max_penetration",
            ("sample", "joint"),
            "m",
            "largest penetration under the contact law, continuous: located within each step, "
            "not from step ends or stored points (0 if never in contact; NaN others)",
            "float64",
            "simulate",
        ),
        _v(
            "free_flight_time",
            ("sample", "joint"),
            "s",
            "time the journal flew free inside the clearance (NaN for joints without a law)",
            "float64",
            "simulate",
        ),
        _v(
            "first_separation_time",
            ("sample", "joint"),
            "s",
            "first time the journal left the bearing wall (NaN if never)",
            "float64",
            "simulate",
            event_time=True,
        ),
        _v(
            "diverged_time",
            _S,
            "s",
            "first time the diverged flag was raised (NaN if never)",
            "float64",
            "simulate",
            event_time=True,
        ),
        _v(
            "singular_time",
            _S,
            "s",
            "first time the singular flag was raised (NaN if never)",
            "float64",
            "simulate",
            event_time=True,
        ),
        _v(
            "contact_lost_time",
            _S,
            "s",
            "first time the contact_lost flag was raised (NaN if never)",
            "float64",
            "simulate",
            event_time=True,
        ),
        _v(
            "solved_by",
            _S,
            "1",
            "what solved the sample's time integration ([simulate] retry_failed): the scene's "
            "settings, rtol/atol (or dt) / 10, / 100, radau at rtol/atol / 100, or nothing "
            "(unsolved: flagged, NaN)",
            "int8",
            "simulate",
            flag_values=np.array([0, 1, 2, 3, 4], dtype=np.int8),
            flag_meanings="as_written tightened_10 tightened_100 radau unsolved",
        ),
        _v(
            "requirement_met",
            ("sample", "requirement"),
            "1",
            "1 where the sample meets the requirement, 0 where it fails it (a failure bit in "
            "status fails every requirement; a NaN event time means never); limits, target and "
            "confidence of each requirement in the attributes",
            "int8",
            "requirement",
            flag_values=np.array([0, 1], dtype=np.int8),
            flag_meanings="failed met",
        ),
    )
}
"""Every ensemble variable, in the order they are written."""

COORDINATES: dict[str, dict[str, str]] = {
    "sample": {"long_name": "global sample index", "units": "1"},
    "body": {"long_name": "body name"},
    "dof": {"long_name": "coordinate of a body (x, y, theta)"},
    "joint": {"long_name": "joint name"},
    "xy": {"long_name": "global axis"},
    "mode": {"long_name": "mode number, ascending p", "units": "1"},
    "param": {"long_name": "sampled parameter path"},
    "param_units": {"long_name": "units of each sampled parameter"},
    "driver": {"long_name": "name of the driven body"},
    "time": {"long_name": "time", "units": "s", "standard_name": "time", "axis": "T"},
    "phase": {"long_name": "angle of the [modes] along driver from its angle0", "units": "rad"},
    "requirement": {"long_name": "requirement name ([[requirement]] name)"},
}
"""Attributes of the coordinate variables."""


def by_analysis(analysis: str) -> list[VariableSpec]:
    """The variables one analysis produces, in registry order."""
    if analysis not in ANALYSES:
        raise ValueError(f"analysis: must be one of {ANALYSES}, got {analysis!r}")
    return [spec for spec in VARIABLES.values() if spec.analysis == analysis]


def status_attributes() -> dict[str, Any]:
    """CF flag attributes of ``status`` (from :mod:`mcchain.status`)."""
    return {
        "flag_masks": FLAG_MASKS.copy(),
        "flag_meanings": FLAG_MEANINGS,
        "valid_min": STATUS_DTYPE(0),
        "valid_max": STATUS_DTYPE(int(FLAG_MASKS.sum())),
    }


def variable_attributes(name: str) -> dict[str, Any]:
    """All attributes written for variable ``name``."""
    attrs = VARIABLES[name].attributes()
    if name == "status":
        attrs.update(status_attributes())
    return attrs


# -- building ----------------------------------------------------------------------------


AXIS_OUTPUTS = {"time": "time", "cycle_phase": "phase"}
"""Solver outputs that are coordinate values (1-D, float64), and the dim each labels."""

STEPS_TAKEN = "steps_taken"
"""A solver output that is no ensemble variable: (sample,) int64, the integration steps each
sample took (fixed-step methods: the steps to t_end; rk45: the accepted ones). The run
machinery sums it into ``run.json``'s throughput (:mod:`mcchain.runner.executors`); it is not
stored (:func:`coerce_outputs` leaves it out)."""


def coerce_outputs(
    outputs: Mapping[str, Any],
    history_dtype: str = "float32",
    extra: Mapping[str, VariableSpec] | None = None,
) -> dict[str, np.ndarray]:
    """Cast a solver's arrays to their storage dtypes (the axis outputs, ``time`` and
    ``cycle_phase``, stay float64; :data:`STEPS_TAKEN` is left out). ``extra``: the scene's
    own variables (its ``[[output]]``s, :mod:`mcchain.ensemble.outputs`).

    Raises ``ValueError`` for an undeclared name or an array whose kind cannot be stored
    under its rule (a float for ``status``, a non-integer count).
    """
    if history_dtype not in ("float32", "float64"):
        raise ValueError(f"history_dtype: must be float32 or float64, got {history_dtype!r}")
    result: dict[str, np.ndarray] = {}
    for name, value in outputs.items():
        if name == STEPS_TAKEN:
            continue
        arr = np.asarray(value)
        if name in AXIS_OUTPUTS:
            result[name] = np.asarray(arr, dtype=np.float64)
            continue
        spec = VARIABLES.get(name) or (extra or {}).get(name)
        if spec is None:
            raise ValueError(f"{name}: not a declared ensemble variable")
        target = spec.storage_dtype(history_dtype)
        if spec.dtype in ("uint32", "int32", "int8"):
            if arr.dtype.kind not in "iub":
                raise ValueError(f"{name}: integer array expected, got {arr.dtype}")
            if arr.size and (arr.min() < np.iinfo(target).min or arr.max() > np.iinfo(target).max):
                raise ValueError(f"{name}: values out of range of {target}")
        elif spec.dtype == "bool":
            if arr.dtype.kind not in "biu":
                raise ValueError(f"{name}: boolean array expected, got {arr.dtype}")
        elif arr.dtype.kind not in "fiu":
            raise ValueError(f"{name}: floating-point array expected, got {arr.dtype}")
        result[name] = np.asarray(arr, dtype=target)
    return result


def model_coordinates(model: Model) -> dict[str, np.ndarray]:
    """Name coordinates of a model: body, dof, joint, xy, param, driver."""
    return {
        "body": np.array(model.body_names, dtype=object),
        "dof": np.array(DOF_NAMES, dtype=object),
        "joint": np.array(model.joint_names, dtype=object),
        "xy": np.array(XY_NAMES, dtype=object),
        "param": np.array(model.param_paths, dtype=object),
        "driver": np.array(model.driver_names, dtype=object),
    }


Variable = tuple[tuple[str, ...], np.ndarray, dict[str, Any]]
"""A netCDF variable as ``(dims, values, attributes)``, the triple xarray also takes."""


@dataclass(frozen=True)
class ChunkVariables:
    """One chunk of samples as the variables of a part file, in the order they are written.

    A run writes its part files from this, not from an :class:`xarray.Dataset`: importing
    xarray (with pandas and dask) took 0.4-0.6 s of every run's first write.

    Attributes:
        coords: coordinate variables by name.
        data_vars: data variables by name, in registry order.
        attrs: global attributes.
    """

    coords: dict[str, Variable]
    data_vars: dict[str, Variable]
    attrs: dict[str, Any]

    @property
    def sizes(self) -> dict[str, int]:
        """Dimension sizes in order of first use, data variables first (xarray's order)."""
        sizes: dict[str, int] = {}
        for dims, values, _ in [*self.data_vars.values(), *self.coords.values()]:
            for dim, n in zip(dims, values.shape, strict=True):
                sizes.setdefault(dim, n)
        return sizes

    def auxiliary_coordinates(self, name: str) -> list[str]:
        """Non-dimension coordinates that label data variable ``name`` (its CF
        ``coordinates`` attribute), e.g. ``param_units`` of ``parameters``."""
        dims, sizes = set(self.data_vars[name][0]), self.sizes
        return [c for c, (d, _, _) in self.coords.items() if c not in sizes and set(d) <= dims]

    def to_dataset(self) -> xr.Dataset:
        """The same variables as an :class:`xarray.Dataset`."""
        import xarray as xr

        return xr.Dataset(self.data_vars, coords=self.coords, attrs=self.attrs)


def build_dataset(
    outputs: Mapping[str, Any],
    model: Model,
    *,
    start: int = 0,
    history_dtype: str = "float32",
    attrs: Mapping[str, Any] | None = None,
    labels: Mapping[str, Sequence[str]] | None = None,
    variable_attrs: Mapping[str, Mapping[str, Any]] | None = None,
    extra: Mapping[str, VariableSpec] | None = None,
) -> xr.Dataset:
    """The Dataset of one chunk of samples from a solver's output dict: the variables of
    :func:`chunk_variables` (same arguments, same errors) as an :class:`xarray.Dataset`."""
    return chunk_variables(
        outputs,
        model,
        start=start,
        history_dtype=history_dtype,
        attrs=attrs,
        labels=labels,
        variable_attrs=variable_attrs,
        extra=extra,
    ).to_dataset()


def chunk_variables(
    outputs: Mapping[str, Any],
    model: Model,
    *,
    start: int = 0,
    history_dtype: str = "float32",
    attrs: Mapping[str, Any] | None = None,
    labels: Mapping[str, Sequence[str]] | None = None,
    variable_attrs: Mapping[str, Mapping[str, Any]] | None = None,
    extra: Mapping[str, VariableSpec] | None = None,
) -> ChunkVariables:
    """The variables of one chunk of samples from a solver's output dict.

    Args:
        outputs: arrays keyed by variable name, sample axis first, plus ``status`` and,
            with time histories, a 1-D ``time``. ``parameters`` is taken from
            ``model.parameters`` when absent.
        model: the chunk's model (``model.nsample`` samples); gives the name coordinates.
        start: global index of the chunk's first sample (the ``sample`` coordinate).
        history_dtype: storage dtype of time histories.
        attrs: global attributes.
        labels: name coordinates of dims the model does not know (``requirement``: the
            requirements' names).
        variable_attrs: attributes added to a variable's registry ones, by name (the
            requirements' limits on ``requirement_met``).
        extra: the scene's own variables (default: the ``[[output]]``s the model carries,
            :mod:`mcchain.ensemble.outputs`), written after the registry's.

    Raises:
        ValueError: an undeclared name, a wrong rank, shape or dtype kind, or no ``status``.
    """
    outputs = dict(outputs)
    if extra is None:
        from mcchain.ensemble.outputs import model_output_variables

        extra = model_output_variables(model)
    if "parameters" not in outputs:
        outputs["parameters"] = np.asarray(model.parameters, dtype=np.float64).reshape(
            model.nsample, len(model.param_paths)
        )
    if "status" not in outputs:
        raise ValueError("status: missing from the solver output")
    arrays = coerce_outputs(outputs, history_dtype, extra)
    names = model_coordinates(model)
    for dim, given in (labels or {}).items():
        names[dim] = np.array(list(given), dtype=object)
    sizes: dict[str, int] = {"sample": model.nsample}
    sizes.update({dim: len(values) for dim, values in names.items()})
    for output, dim in AXIS_OUTPUTS.items():
        if output in arrays:
            if arrays[output].ndim != 1:
                raise ValueError(f"{output}: must be 1-D, got shape {arrays[output].shape}")
            sizes[dim] = arrays[output].shape[0]

    data_vars: dict[str, Variable] = {}
    used: set[str] = set()
    for name, spec in {**VARIABLES, **extra}.items():
        if name not in arrays:
            continue
        arr = arrays[name]
        if arr.ndim != len(spec.dims):
            raise ValueError(
                f"{name}: expected dims {spec.dims}, got an array of shape {arr.shape}"
            )
        for dim, n in zip(spec.dims, arr.shape, strict=True):
            expected = sizes.setdefault(dim, n)
            if n != expected:
                raise ValueError(f"{name}: dim {dim} has size {n}, expected {expected}")
        used.update(spec.dims)
        added = dict((variable_attrs or {}).get(name, {}))
        own = variable_attributes(name) if name in VARIABLES else spec.attributes()
        data_vars[name] = (spec.dims, arr, own | added)

    coords: dict[str, Variable] = {
        "sample": (
            ("sample",),
            np.arange(start, start + model.nsample, dtype=np.int64),
            dict(COORDINATES["sample"]),
        )
    }
    dims = ("body", "dof", "joint", "xy", "mode", "param", "driver", "time", "phase", "requirement")
    for dim in dims:
        if dim not in used:
            continue
        if dim == "mode":
            values: np.ndarray = np.arange(sizes["mode"], dtype=np.int32)
        elif dim == "time":
            values = arrays["time"]
        elif dim == "phase":
            values = arrays["cycle_phase"]
        else:
            values = names[dim]
        coords[dim] = ((dim,), values, dict(COORDINATES[dim]))
        if dim == "param":
            units = np.array([param_units(p) for p in model.param_paths], dtype=object)
            coords["param_units"] = (("param",), units, dict(COORDINATES["param_units"]))
    return ChunkVariables(coords, data_vars, dict(attrs or {}))


def validate_dataset(ds: xr.Dataset, history_dtype: str | None = None) -> None:
    """Check a Dataset against the registry: names, dims, dtypes, units and long_name.

    Args:
        ds: an ensemble or one chunk of it, as built or as read back by xarray.
        history_dtype: expected dtype of time histories; ``None`` accepts float32/float64.

    Raises:
        ValueError: naming the first variable that does not match.
    """
    if "status" not in ds.data_vars:
        raise ValueError("status: missing")
    from mcchain.ensemble.outputs import stored_output

    for name, var in ds.data_vars.items():
        spec = VARIABLES.get(str(name)) or stored_output(str(name), var.attrs)
        if spec is None:
            raise ValueError(f"{name}: not a declared ensemble variable")
        dims = tuple(str(d) for d in var.dims)
        if dims[:1] == (HISTORY_SAMPLE,):  # [storage] histories = "failed": a subset
            dims = ("sample", *dims[1:])
        if dims != spec.dims:
            raise ValueError(f"{name}: dims {tuple(var.dims)}, expected {spec.dims}")
        allowed: Sequence[np.dtype]
        if spec.dtype == "history" and history_dtype is None:
            allowed = (np.dtype(np.float32), np.dtype(np.float64))
        else:
            allowed = (spec.storage_dtype(history_dtype or "float32"),)
        if var.dtype not in allowed:
            raise ValueError(f"{name}: dtype {var.dtype}, expected {allowed[0]}")
        for key in ("units", "long_name"):
            if var.attrs.get(key) != spec.attributes()[key]:
                raise ValueError(f"{name}: attribute {key} is {var.attrs.get(key)!r}")
