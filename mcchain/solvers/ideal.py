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
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from mcchain.contact import START_LINK
from mcchain.model import GROUND, JointKind, Model, constraint_rows

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

__all__ = ["ideal_model", "main_part", "with_ideal_copy"]
