"""The ideal counterpart of a mechanism: the same instance with every clearance joint ideal.

``[[output]] relative_to = "ideal"`` subtracts from a quantity the same quantity of the same
instance (same sampled parameters, drivers, loads, times) with every clearance joint made an
ideal pin. Where that is computed:

* at the equilibrium, by the statics of :func:`ideal_model` (same sample, own equilibrium);
* in a time history, by integrating it **in the same run, with the same method and the same
  steps**: :func:`with_ideal_copy` appends the ideal mechanism to the model as more bodies,
  joints, drivers, loads and springs (a second, disconnected mechanism), and every kernel
  integrates both at once. The copy starts from its own assembled state (or its own
  equilibrium); the model's ``reference`` tells the kernels which part is the mechanism, so
  that its energy, its max |Φ| and the adaptive step control (``rk45``) leave the copy out,
  and the lanes order the copy's rows of S apart: the mechanism's own history is that of a
  run without the copy, bit for bit on the lanes and the loop kernels (to rounding with
  generalized-α and radau, which solve both in one system), and the copy takes the
  mechanism's steps.

This was chosen over a position analysis of the ideal mechanism at each step end (exact
where the ideal mechanism is fully driven, zero degrees of freedom, and cheaper there: a
Newton solve per step end instead of the copy's stages): the copy works for every
mechanism (a pendulum, a four-bar with a free rocker) and every method by construction,
is as accurate as the mechanism's own integration (4e-15 m against the closed-form ideal
slider-crank at rk45's rtol 1e-13), and costs about the mechanism's own integration again:
1.9–2.5× the run without it on the shipped slider-crank and four-bar
(benchmarks/results/outputs).

Where the ideal mechanism is the same for every sample (:func:`shared_ideal`: no sampled
parameter reaches it, as a tolerance sweep of the clearances) and the relative outputs are
positions or angles, ``rk45`` integrates it once per chunk instead, alone and tighter, and
the lanes read it from a table (:func:`tabulated_plan`; every chunk computes the same table
from the same start, so the run does not depend on the chunking). The mechanism's own
integration is unchanged; the output moves by the copy's own integration error.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from mcchain.codes import OUTPUT_ANGLE, OUTPUT_POSITION, OUTPUT_TABULATED_REFERENCE
from mcchain.contact import START_LINK
from mcchain.model import GROUND, JointKind, Model, constraint_rows
from mcchain.solvers.output_plan import OutputPlan
from mcchain.status import FAILURE_BITS

_ITEMS = {
    "body": ("body_mass", "body_inertia"),
    "joint": (
        "joint_point_a", "joint_point_b", "joint_clearance", "joint_eccentricity",
        "joint_contact_stiffness", "joint_contact_exponent", "joint_contact_restitution",
        "joint_contact_friction", "joint_contact_radius", "joint_start", "joint_axis",
        "joint_relative_angle",
    ),
    "driver": (
        "driver_angle0", "driver_omega", "driver_amplitude", "driver_frequency",
        "driver_phase", "driver_displacement0", "driver_speed",
    ),
    "force": ("force_point", "force_value", "force_torque", "force_frequency", "force_phase"),
    "spring": (
        "spring_point_a", "spring_point_b", "spring_stiffness", "spring_rest_length",
        "spring_damping",
    ),
}  # fmt: skip
"""Per-sample fields (*, nitem, ...) by the item their second axis runs over."""
_TOPOLOGY = {
    "body": (),
    "joint": ("joint_kind", "joint_model", "joint_contact_law", "joint_written"),
    "driver": ("driver_law", "driver_table_size", "driver_table_knots", "driver_table_coef"),
    "force": ("force_law", "force_table_size", "force_table_knots", "force_table_coef"),
    "spring": (),
}
"""Topology fields (nitem, ...) copied as they are."""
_BODIES = {
    "joint": ("joint_body_a", "joint_body_b"),
    "driver": ("driver_body",),
    "force": ("force_body",),
    "spring": ("spring_body_a", "spring_body_b"),
}
"""Topology fields holding body indices (shifted in the copy; the ground stays)."""


def ideal_model(model: Model) -> Model:
    """``model`` with every clearance joint ideal (two rows, no contact law), the same
    samples, parameters and start positions (to be assembled anew)."""
    kind = np.where(
        model.joint_kind == JointKind.CLEARANCE, int(JointKind.IDEAL), model.joint_kind
    ).astype(np.int64)
    joint_row, driver_row = constraint_rows(kind, model.ndriver)
    zeros = np.zeros(model.njoint, dtype=np.int64)
    start = np.full((1, model.njoint), float(START_LINK))
    return replace(
        model,
        joint_kind=kind,
        joint_row=joint_row,
        driver_row=driver_row,
        joint_model=zeros,
        joint_contact_law=zeros.copy(),
        joint_written=zeros.copy(),
        joint_start=start,
        joint_contact_start=("seated",) * model.njoint,  # no contact law: as assembled
        joint_eccentricity=np.full_like(np.asarray(model.joint_eccentricity), np.nan),
        reference=np.zeros(0, dtype=np.int64),
        meta=dict(model.meta),
    )


def with_ideal_copy(model: Model, ideal: Model) -> Model:
    """``model`` followed by ``ideal`` (:func:`ideal_model` of it) as a second, disconnected
    mechanism: its bodies, joints, drivers, loads and springs after the model's, their
    body indices shifted; rows by :func:`mcchain.model.constraint_rows` (the model's joints,
    the copy's, then the model's drivers, the copy's). ``reference`` records the split.
    ``q0``/``v0`` are the two start states side by side (the copy's from ``ideal``)."""
    nb = model.nbody
    changes: dict[str, Any] = {}
    for names in _ITEMS.values():
        for name in names:
            a = np.asarray(getattr(model, name))
            b = np.asarray(getattr(ideal, name))
            n = max(a.shape[0], b.shape[0])
            a = np.broadcast_to(a, (n, *a.shape[1:]))
            b = np.broadcast_to(b, (n, *b.shape[1:]))
            changes[name] = np.ascontiguousarray(np.concatenate([a, b], axis=1))
    for names in _TOPOLOGY.values():
        for name in names:
            changes[name] = np.concatenate(
                [np.asarray(getattr(model, name)), np.asarray(getattr(ideal, name))], axis=0
            )
    for name_list in _BODIES.values():
        for name in name_list:
            a = np.asarray(getattr(model, name))
            b = np.asarray(getattr(ideal, name))
            changes[name] = np.concatenate([a, np.where(b == GROUND, GROUND, b + nb)])
    joints = np.asarray(model.driver_joint)
    ideal_joints = np.asarray(ideal.driver_joint)
    changes["driver_joint"] = np.concatenate(
        [joints, np.where(ideal_joints < 0, -1, ideal_joints + model.njoint)]
    ).astype(np.int64)
    joint_row, driver_row = constraint_rows(changes["joint_kind"], 2 * model.ndriver)
    changes["joint_row"], changes["driver_row"] = joint_row, driver_row
    for name in ("q0", "v0"):
        a, b = np.asarray(getattr(model, name)), np.asarray(getattr(ideal, name))
        n = max(a.shape[0], b.shape[0])
        changes[name] = np.concatenate(
            [np.broadcast_to(a, (n, a.shape[1])), np.broadcast_to(b, (n, b.shape[1]))], axis=1
        )
    # the two start states are placed before the copy is made (simulate_outputs): the
    # journals stay where they are
    changes["joint_contact_start"] = ("seated",) * (2 * model.njoint)
    own_rows = int(np.sum([JointKind(int(k)).rows for k in model.joint_kind]))
    changes["reference"] = np.array(
        [nb, model.njoint, model.ndriver, model.nforce, model.nspring, own_rows], dtype=np.int64
    )
    for kind in ("body", "joint", "driver", "force", "spring"):
        names = getattr(model, f"{kind}_names")
        changes[f"{kind}_names"] = (*names, *(f"ideal:{name}" for name in names))
    return replace(model, **changes)


def main_part(model: Model, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The solver's arrays of a model with an ideal copy (:func:`with_ideal_copy`) cut back
    to the mechanism's own bodies, joints and drivers (their axes after sample and time)."""
    nb, nj, nd = (int(x) for x in model.reference[:3])
    out: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        axis = _ITEM_AXIS.get(name)
        if axis is None:
            out[name] = value
            continue
        kind, position = axis
        keep = {"body": nb, "joint": nj, "driver": nd}[kind]
        index = [slice(None)] * value.ndim
        index[position] = slice(0, keep)
        out[name] = np.ascontiguousarray(value[tuple(index)])
    return out


_ITEM_AXIS = {
    "q": ("body", 2),
    "v": ("body", 2),
    "joint_force": ("joint", 2),
    "contact_force": ("joint", 2),
    "joint_moment": ("joint", 2),
    "penetration": ("joint", 2),
    "contact_mode": ("joint", 2),
    "driver_torque": ("driver", 2),
    "driver_force": ("driver", 2),
    "peak_joint_force": ("joint", 1),
    "peak_driver_torque": ("driver", 1),
    "peak_driver_force": ("driver", 1),
    "peak_contact_force": ("joint", 1),
    "impact_count": ("joint", 1),
    "max_penetration": ("joint", 1),
    "free_flight_time": ("joint", 1),
    "first_separation_time": ("joint", 1),
}
"""Where each solver array of a time history has its body/joint/driver axis."""

REFERENCE_RTOL = 1e-12
"""``rtol`` of the one integration of a shared ideal mechanism (or the scene's, if tighter)."""
REFERENCE_ATOL = 1e-14
"""``atol`` of it, m and rad (or the scene's, if tighter)."""
KNOTS_PER_OUTPUT_STEP = 4
"""Knots of a tabulated reference per ``output_dt`` at first (doubled until its interpolant
is accurate enough: :data:`INTERPOLATION_SHARE`)."""
MAX_KNOTS = 1 << 20
"""Knots past which a reference is not tabulated (the ideal copy is integrated instead)."""
INTERPOLATION_SHARE = 1e-2
"""The interpolation error allowed on a tabulated reference, as a share of the scene's
``atol``: the cubic Hermite's, h⁴ max|f⁗| / 384, estimated from the knots' fourth
differences."""
TABULATED_KINDS = (OUTPUT_POSITION, OUTPUT_ANGLE)
"""Output kinds whose ideal quantity and rate a tabulated reference holds (their rate is
in the state; the others keep the ideal copy)."""


def shared_ideal(ideal: Model, q: np.ndarray, v: np.ndarray, status: np.ndarray) -> bool:
    """Whether the ideal mechanism (:func:`ideal_model`) is the same for every sample: the
    parameters its lane kernels read (:func:`mcchain.codegen.topology.pack_parameters` of its
    topology) and its start state ``q``, ``v`` (nsample, 3 nbody) equal, bit for bit, over
    the samples without a failure bit in ``status`` (at least one). No sampled parameter
    then reaches it (a clearance, a contact law's restitution); a sampled length, mass,
    load or driver speed does."""
    from mcchain.codegen.topology import Topology, pack_parameters

    alive = (status & FAILURE_BITS) == 0
    if not alive.any():
        return False
    columns = np.vstack([pack_parameters(ideal, Topology.from_model(ideal)), q.T, v.T])
    columns = columns[:, alive]
    return bool((columns.view(np.uint64) == columns[:, :1].view(np.uint64)).all())


def tabulated_plan(
    ideal: Model, q: np.ndarray, v: np.ndarray, sim: Any, plan: OutputPlan
) -> OutputPlan | None:
    """``plan`` with the ideal mechanism's quantities in tables (``ref`` =
    :data:`~mcchain.codes.OUTPUT_TABULATED_REFERENCE`, the knots after the data columns:
    :func:`mcchain.kernels.outputs.reference_signal`), from one integration of ``ideal``
    (a model of one sample, start state ``q``, ``v`` (1, 3 nbody), as ``sim`` says but by rk45 at
    :data:`REFERENCE_RTOL`/:data:`REFERENCE_ATOL` or the scene's if tighter, stored every knot).
    None (integrate the ideal copy instead) for a relative output of another kind than
    :data:`TABULATED_KINDS`, per-sample data rows that differ, a failed integration, or
    too many knots."""
    key = _table_key(ideal, q, v, sim, plan)
    try:
        return _TABLES[key]
    except KeyError:  # (not a test then a read: a chunk of another run may clear it meanwhile)
        pass
    table = _tabulated(ideal, q, v, sim, plan)
    _TABLES.clear()  # one run's table: every chunk of the run asks for the same
    _TABLES[key] = table
    return table


_TABLES: dict[str, OutputPlan | None] = {}
"""The last table made (:func:`tabulated_plan`), by :func:`_table_key` of what made it."""


def _table_key(ideal: Model, q: np.ndarray, v: np.ndarray, sim: Any, plan: OutputPlan) -> str:
    """A digest of everything a table is made from: the ideal mechanism's parameters as its
    kernels read them, its start, the settings and the plan."""
    import hashlib

    from mcchain.codegen.topology import Topology, pack_parameters

    digest = hashlib.sha256()
    topology = Topology.from_model(ideal)
    for part in (pack_parameters(ideal, topology), q, v, plan.spec, plan.data[:1]):
        digest.update(np.ascontiguousarray(part).tobytes())
    digest.update(repr(topology).encode())
    digest.update(sim.model_dump_json().encode())
    return digest.hexdigest()


def _tabulated(
    ideal: Model, q: np.ndarray, v: np.ndarray, sim: Any, plan: OutputPlan
) -> OutputPlan | None:
    from mcchain.kernels.outputs import REFERENCE_HEAD, REFERENCE_WIDTH, reference_knots
    from mcchain.solvers.simulate import simulate

    relative = [k for k in range(len(plan.names)) if plan.spec[k, 3] >= 0]
    if any(int(plan.spec[k, 0]) not in TABULATED_KINDS for k in relative):
        return None
    data = plan.data
    if data.shape[0] > 1 and not (data == data[:1]).all():
        return None
    t_end = float(sim.t_end)
    knots = KNOTS_PER_OUTPUT_STEP * max(1, math.ceil(t_end / sim.output_step))
    while knots <= MAX_KNOTS:
        settings = sim.model_copy(
            update={"perturb": {}, "method": "rk45", "output_dt": t_end / knots,
                    "rtol": min(sim.rtol, REFERENCE_RTOL), "atol": min(sim.atol, REFERENCE_ATOL)}
        )  # fmt: skip
        run = simulate(ideal, settings, q, v, history_dtype=np.float64)
        if run["status"][0] & FAILURE_BITS:
            return None
        tables = []
        for k in relative:
            table = np.zeros((len(run["time"]), REFERENCE_WIDTH))
            table[:, 0] = run["time"]
            kind, body = int(plan.spec[k, 0]), int(plan.spec[k, 2])  # the same body in it
            qh = run["q"][0].reshape(len(run["time"]), -1)
            vh = run["v"][0].reshape(len(run["time"]), -1)
            reference_knots(qh, vh, body, data[0, k, 0], data[0, k, 1], kind, table)
            tables.append(table)
        if all(_interpolation_error(t) <= INTERPOLATION_SHARE * sim.atol for t in tables):
            break
        knots *= 2
    else:
        return None
    width = REFERENCE_HEAD + REFERENCE_WIDTH * len(run["time"])
    tabulated = np.zeros((1, len(plan.names), width))
    tabulated[0, :, : data.shape[2]] = data[0]
    spec = plan.spec.copy()
    for k, table in zip(relative, tables, strict=True):
        spec[k, 3] = OUTPUT_TABULATED_REFERENCE
        tabulated[0, k, 5] = len(table)
        tabulated[0, k, 6] = t_end / knots
        tabulated[0, k, REFERENCE_HEAD:] = table.reshape(-1)
    return OutputPlan(plan.names, spec, tabulated, plan.relative)


def _interpolation_error(table: np.ndarray) -> float:
    """The cubic Hermite's error on the knots of ``table`` (uniform in t), estimated as
    max |Δ⁴f| / 384 of x and y (rounding counted: at least 64 ulp of the largest value)."""
    values = table[:, 1:3]
    if len(values) < 5:
        return math.inf
    fourth = np.abs(np.diff(values, n=4, axis=0)).max()
    return max(fourth / 384.0, 64.0 * np.finfo(float).eps * float(np.abs(values).max()))


__all__ = [
    "ideal_model",
    "main_part",
    "shared_ideal",
    "tabulated_plan",
    "with_ideal_copy",
]
