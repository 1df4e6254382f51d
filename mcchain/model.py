"""The compiled model: a scene as flat arrays that numba kernels read.

A :class:`Model` holds two kinds of arrays:

* **topology** (static for the whole ensemble, int64): which bodies each joint, driver,
  force and spring connects, the joint kind, and the first constraint row of each joint
  and driver. Index ``-1`` is the fixed ground body.
* **parameters** (float64) with a *leading sample axis* of size 1 or ``nsample``. A kernel
  reads sample ``s`` with the broadcast index ``a[s % a.shape[0]]``, so any scalar can vary
  per sample at no cost to the ones that do not.

Generalised coordinates: ``q = [X_1, Y_1, θ_1, …, X_n, Y_n, θ_n]`` (m, m,
rad). Constraint rows are ordered by joint (2 rows for an ideal joint, 1 for a clearance
joint), then by driver (1 row each); ``joint_row`` / ``driver_row`` give the first row.

Shapes are written ``(*, nbody)`` for a parameter with a leading sample axis of size 1 or
``nsample``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, NamedTuple

import numpy as np

from mcchain.codes import (
    DRIVER_CONSTANT,
    DRIVER_HARMONIC,
    DRIVER_LAWS,
    DRIVER_TABLE,
    GROUND,
    JOINT_CLEARANCE,
    JOINT_IDEAL,
    JOINT_PRISMATIC,
    LOAD_CONSTANT,
    LOAD_HARMONIC,
    LOAD_LAWS,
    LOAD_TABLE,
    JointKind,
)
from mcchain.contact import CONTACT, DEFAULT_START, MODEL_NAMES
from mcchain.parameters import TABLE

__all__ = [  # the codes are re-exported: they are the model's
    "DRIVER_CONSTANT",
    "DRIVER_HARMONIC",
    "DRIVER_LAWS",
    "DRIVER_TABLE",
    "GROUND",
    "JOINT_CLEARANCE",
    "JOINT_IDEAL",
    "JOINT_PRISMATIC",
    "LOAD_CONSTANT",
    "LOAD_HARMONIC",
    "LOAD_LAWS",
    "LOAD_TABLE",
    "PER_SAMPLE_FIELDS",
    "JointKind",
    "KernelModel",
    "Model",
    "constraint_rows",
    "joint_rows",
]


def joint_rows(joint_kind: np.ndarray) -> np.ndarray:
    """(njoint,) int64 number of constraint rows of each joint (:attr:`JointKind.rows`)."""
    table = np.array([JointKind(k).rows for k in range(len(JointKind))], dtype=np.int64)
    return table[np.asarray(joint_kind, dtype=np.int64).reshape(-1)]


def _i64(values: object = ()) -> np.ndarray:
    return np.asarray(values, dtype=np.int64).reshape(-1)


@dataclass(frozen=True, eq=False)
class Model:
    """A scene compiled to arrays, for ``nsample`` instances.

    Names (tuples of str) label the axes of the ensemble; arrays are documented with units
    and shapes. ``nbody``/``njoint``/... are derived from the topology arrays.

    Attributes:
        body_names: (nbody,) body names, in coordinate order.
        joint_names: (njoint,) joint names.
        driver_names: (ndriver,) the driven body's name for each driver.
        force_names: (nforce,) force names.
        spring_names: (nspring,) spring names.
        param_paths: (nparam,) sampled parameter paths (``kind.name.key[i]``).
        parameters: (nsample, nparam) the sampled values, one column per path.
        nsample: number of instances.
        joint_body_a: (njoint,) int64 bearing body index (``GROUND`` = -1).
        joint_body_b: (njoint,) int64 journal body index.
        joint_kind: (njoint,) int64 :class:`JointKind` values.
        joint_row: (njoint,) int64 first constraint row of each joint.
        joint_model: (njoint,) int64 model of a clearance joint in time histories
            (:data:`mcchain.contact.MODEL_CODES`: 0 link, 1 contact, 2 auto; 0 for ideal
            joints). Statics and modes always use the link.
        joint_contact_law: (njoint,) int64 contact law code (:data:`mcchain.contact.LAW_CODES`).
        joint_written: (njoint,) int64 where the scene writes the journal of a clearance
            joint of model contact or auto (both bodies' positions written or sampled, or
            ground), judged on the scene as written: 1 off its wall (free or pressed: kept
            where written, not a constraint of the assembly), 2 on it (seated: held on the
            wall); 0 for the others (assembly places them as the link).
        joint_contact_start: (njoint,) ``[joint.contact] start`` of each joint as a scene
            spells it (:data:`mcchain.contact.ContactStart`; "seated", the place assembly
            gives, for joints without a contact law): where
            :func:`mcchain.solvers.start.contact_start` puts a journal the file does not
            write; default "pressed" for model contact, "seated" for the others.
        joint_start: (*, njoint) the mode each contact-law joint starts its time history in
            (:data:`mcchain.contact.START_LINK`, ``START_LAW``, ``START_SEATED``), set from
            the start state by :func:`mcchain.solvers.start.start_modes`; default: the
            law for model contact, the link for the others.
        driver_body: (ndriver,) int64 driven body.
        driver_row: (ndriver,) int64 constraint row of each driver.
        force_body: (nforce,) int64 loaded body.
        spring_body_a, spring_body_b: (nspring,) int64 bodies a spring joins.
        gravity: (*, 2) m/s².
        body_mass: (*, nbody) kg.
        body_inertia: (*, nbody) centroidal moment of inertia, kg m².
        joint_point_a, joint_point_b: (*, njoint, 2) local attachment points on the bearing
            (a) and journal (b) bodies, m.
        joint_clearance: (*, njoint) radial clearance c, m (ignored for ideal joints).
        joint_eccentricity: (*, njoint) initial direction α of d, rad; NaN: from positions.
        joint_axis: (*, njoint, 2) unit sliding axis of a prismatic joint in the frame of
            its first body (the ground's: global); NaN for revolute joints.
        joint_relative_angle: (*, njoint) θ_b − θ_a held by a prismatic joint, rad; NaN
            for revolute joints.
        joint_contact_stiffness: (*, njoint) K of the contact law, N/m^exponent.
        joint_contact_exponent: (*, njoint) exponent m of the contact law.
        joint_contact_restitution: (*, njoint) coefficient of restitution e.
        joint_contact_friction: (*, njoint) Coulomb coefficient μ.
        joint_contact_radius: (*, njoint) journal radius R (friction's slip and moment arm), m.
        driver_law: (ndriver,) int64 :data:`DRIVER_LAWS` code of each driver.
        driver_joint: (ndriver,) int64 the prismatic joint a slider driver moves, −1 for a
            driver of a body's angle (whose ``driver_body`` is then ``GROUND`` for a slider).
        driver_displacement0, driver_speed: (*, ndriver) s0 (m) and v (m/s) of slider drivers
            (NaN and 0 for the others).
        driver_table_size, driver_table_knots, driver_table_coef: (ndriver,) int64 knots,
            (ndriver, nknot) s and (ndriver, 4 (nknot − 1)) ascending cubic coefficients of
            each table driver's spline (:mod:`mcchain.kernels.tables`; size 0 for the others);
            ``force_table_*`` the same for the loads' factors.
        driver_angle0: (*, ndriver) θ_0, rad.
        driver_omega: (*, ndriver) ω, rad/s.
        driver_amplitude, driver_frequency, driver_phase: (*, ndriver) A (rad), f (Hz) and
            φ (rad) of harmonic drivers (0 for constant ones).
        force_point: (*, nforce, 2) local application point, m.
        force_value: (*, nforce, 2) constant force, global frame, N.
        force_torque: (*, nforce) constant couple, N m (counter-clockwise positive).
        force_law: (nforce,) int64 :data:`LOAD_LAWS` code of each force.
        force_frequency, force_phase: (*, nforce) f (Hz) and φ (rad) of harmonic loads
            (value and torque times sin(2π f t + φ); 0 for constant ones).
        spring_point_a, spring_point_b: (*, nspring, 2) local attachment points, m.
        spring_stiffness: (*, nspring) N/m.
        spring_rest_length: (*, nspring) m.
        spring_damping: (*, nspring) N s/m, along the spring.
        q0: (*, 3 nbody) initial positions [X, Y, θ]*.
        v0: (*, 3 nbody) initial velocities.
        reference: (6,) int64 for a model that carries, after its mechanism, the same
            mechanism with every clearance joint ideal (``[[output]] relative_to``,
            :mod:`mcchain.solvers.ideal`): the mechanism's own nbody, njoint, ndriver, nforce,
            nspring and joint constraint rows (its energy, max |Φ| and step control leave the
            copy out); (0,) for every other model.
    """

    body_names: tuple[str, ...]
    joint_names: tuple[str, ...]
    driver_names: tuple[str, ...]
    force_names: tuple[str, ...]
    spring_names: tuple[str, ...]
    param_paths: tuple[str, ...]
    parameters: np.ndarray
    nsample: int
    joint_body_a: np.ndarray
    joint_body_b: np.ndarray
    joint_kind: np.ndarray
    joint_row: np.ndarray
    driver_body: np.ndarray
    driver_row: np.ndarray
    force_body: np.ndarray
    spring_body_a: np.ndarray
    spring_body_b: np.ndarray
    gravity: np.ndarray
    body_mass: np.ndarray
    body_inertia: np.ndarray
    joint_point_a: np.ndarray
    joint_point_b: np.ndarray
    joint_clearance: np.ndarray
    joint_eccentricity: np.ndarray
    driver_angle0: np.ndarray
    driver_omega: np.ndarray
    force_point: np.ndarray
    force_value: np.ndarray
    force_torque: np.ndarray
    spring_point_a: np.ndarray
    spring_point_b: np.ndarray
    spring_stiffness: np.ndarray
    spring_rest_length: np.ndarray
    spring_damping: np.ndarray
    q0: np.ndarray
    v0: np.ndarray
    meta: dict[str, object] = field(default_factory=dict)
    # The contact law (optional: None gives link joints, an unset law).
    joint_model: np.ndarray = None  # type: ignore[assignment]
    joint_contact_law: np.ndarray = None  # type: ignore[assignment]
    joint_contact_stiffness: np.ndarray = None  # type: ignore[assignment]
    joint_contact_exponent: np.ndarray = None  # type: ignore[assignment]
    joint_contact_restitution: np.ndarray = None  # type: ignore[assignment]
    joint_contact_friction: np.ndarray = None  # type: ignore[assignment]
    joint_contact_radius: np.ndarray = None  # type: ignore[assignment]
    joint_written: np.ndarray = None  # type: ignore[assignment]
    joint_start: np.ndarray = None  # type: ignore[assignment]
    joint_contact_start: tuple[str, ...] = ()  # not an array: no kernel reads it
    # Prismatic joints (optional: None gives no axis, as for revolute joints).
    joint_axis: np.ndarray = None  # type: ignore[assignment]
    joint_relative_angle: np.ndarray = None  # type: ignore[assignment]
    # Driver laws (optional: None gives constant-speed drivers).
    driver_law: np.ndarray = None  # type: ignore[assignment]
    driver_amplitude: np.ndarray = None  # type: ignore[assignment]
    driver_frequency: np.ndarray = None  # type: ignore[assignment]
    driver_phase: np.ndarray = None  # type: ignore[assignment]
    driver_joint: np.ndarray = None  # type: ignore[assignment]
    driver_displacement0: np.ndarray = None  # type: ignore[assignment]
    driver_speed: np.ndarray = None  # type: ignore[assignment]
    driver_table_size: np.ndarray = None  # type: ignore[assignment]
    driver_table_knots: np.ndarray = None  # type: ignore[assignment]
    driver_table_coef: np.ndarray = None  # type: ignore[assignment]
    force_table_size: np.ndarray = None  # type: ignore[assignment]
    force_table_knots: np.ndarray = None  # type: ignore[assignment]
    force_table_coef: np.ndarray = None  # type: ignore[assignment]
    # Load laws (optional: None gives constant loads).
    force_law: np.ndarray = None  # type: ignore[assignment]
    force_frequency: np.ndarray = None  # type: ignore[assignment]
    force_phase: np.ndarray = None  # type: ignore[assignment]
    # An ideal copy after the mechanism (optional: None gives none).
    reference: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        njoint = len(self.joint_names)
        ndriver = len(self.driver_names)
        nforce = len(self.force_names)
        # Topology arrays a scene without drivers' or loads' laws, prismatic joints or
        # contact leaves out ...
        defaults = {
            "force_law": np.zeros(nforce, dtype=np.int64),
            "driver_law": np.zeros(ndriver, dtype=np.int64),
            "driver_joint": np.full(ndriver, -1, dtype=np.int64),
            "driver_table_size": np.zeros(ndriver, dtype=np.int64),
            "driver_table_knots": np.zeros((ndriver, 0)),
            "driver_table_coef": np.zeros((ndriver, 0)),
            "force_table_size": np.zeros(nforce, dtype=np.int64),
            "force_table_knots": np.zeros((nforce, 0)),
            "force_table_coef": np.zeros((nforce, 0)),
            "joint_model": np.zeros(njoint, dtype=np.int64),
            "joint_contact_law": np.zeros(njoint, dtype=np.int64),
            "joint_written": np.zeros(njoint, dtype=np.int64),
            "reference": np.zeros(0, dtype=np.int64),
        }
        # ... and parameter arrays: the value of the unset key, from the parameter table.
        count = {"joint": njoint, "driver": ndriver, "force": nforce}
        for row in TABLE:
            if row.unset is None or row.kind not in count:
                continue
            names = row.field if isinstance(row.field, tuple) else (row.field,)
            shape = (1, *row.field_shape(count[row.kind]))
            defaults |= {name: np.full(shape, row.unset) for name in names}
        for name, value in defaults.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        if len(self.joint_contact_start) != njoint:  # a model built without a scene
            start = tuple(
                DEFAULT_START[MODEL_NAMES[int(m)]] for m in np.asarray(self.joint_model)[:njoint]
            )
            object.__setattr__(self, "joint_contact_start", start)
        if self.joint_start is None:  # the law from t = 0 for model contact, else the link
            start = (np.asarray(self.joint_model).reshape(-1) == CONTACT).astype(np.float64)
            object.__setattr__(self, "joint_start", start[np.newaxis, :njoint].copy())

    # -- sizes -----------------------------------------------------------------------------
    @property
    def nbody(self) -> int:
        return len(self.body_names)

    @property
    def ndof(self) -> int:
        """Number of coordinates, 3 nbody."""
        return 3 * self.nbody

    @property
    def njoint(self) -> int:
        return len(self.joint_names)

    @property
    def ndriver(self) -> int:
        return len(self.driver_names)

    @property
    def nforce(self) -> int:
        return len(self.force_names)

    @property
    def nspring(self) -> int:
        return len(self.spring_names)

    @property
    def ncon(self) -> int:
        """Number of constraint rows: :attr:`JointKind.rows` per joint, 1 per driver."""
        return int(joint_rows(self.joint_kind).sum()) + self.ndriver

    @property
    def nmode(self) -> int:
        """Nominal degrees of freedom, 3 nbody − ncon (modes reported per sample)."""
        return self.ndof - self.ncon

    @property
    def has_clearance(self) -> bool:
        return bool(np.any(self.joint_kind == JointKind.CLEARANCE))

    @property
    def has_slider_drivers(self) -> bool:
        """Whether a driver moves a prismatic joint (its output is a force, not a torque)."""
        return bool(np.any(np.asarray(self.driver_joint) >= 0))

    @property
    def has_prismatic(self) -> bool:
        """Whether any joint is prismatic."""
        return bool(np.any(self.joint_kind == JointKind.PRISMATIC))

    @property
    def has_reference(self) -> bool:
        """Whether the model carries an ideal copy of its mechanism (:attr:`reference`)."""
        return bool(np.asarray(self.reference).size)

    @property
    def has_contact(self) -> bool:
        """Whether a clearance joint may use the contact law in time histories."""
        return bool(np.any(self.joint_model != 0))

    # -- arrays for kernels ----------------------------------------------------------------
    def kernel_arrays(self) -> KernelModel:
        """The arrays as one :class:`KernelModel`, contiguous with the dtypes kernels expect."""
        values: dict[str, np.ndarray] = {}
        name: str
        for name in KernelModel._fields:
            arr = getattr(self, name)
            dtype = np.int64 if arr.dtype.kind in "iub" else np.float64
            values[name] = np.ascontiguousarray(arr, dtype=dtype)
        return KernelModel(**values)

    def kernel_model(self) -> Any:
        """What every kernel takes as ``km``: :meth:`kernel_arrays` as one numba structure
        (:mod:`mcchain.kernels.kernel_model`), sharing the arrays; the arrays themselves
        where the kernels run interpreted (their fields read the same way)."""
        from mcchain.kernels import config

        if config.INTERPRETED:
            return self.kernel_arrays()
        from mcchain.kernels.kernel_model import as_struct

        return as_struct(self.kernel_arrays())

    def constraint_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """Where B and S = B M⁻¹ Bᵀ may be non-zero, from the topology alone.

        Returns:
            ``cols`` (ncon, 6) int64: the coordinates each constraint row touches, ascending,
            −1 after the last (a joint's or slider driver's: both bodies' x, y, θ; an angle
            driver's: its body's θ); ``first`` (ncon,) int64: the first row that shares a
            coordinate with each row, so that row i of S (and of its LDLᵀ factor) is zero left
            of column ``first[i]``.
        """
        touched: list[list[int]] = [[] for _ in range(self.ncon)]

        def coordinates(*bodies: int) -> list[int]:
            return [3 * b + i for b in sorted(bodies) if b != GROUND for i in range(3)]

        for k in range(self.njoint):
            row = int(self.joint_row[k])
            for r in range(row, row + JointKind(int(self.joint_kind[k])).rows):
                touched[r] = coordinates(int(self.joint_body_a[k]), int(self.joint_body_b[k]))
        for d in range(self.ndriver):
            k = int(self.driver_joint[d])
            row = int(self.driver_row[d])
            if k >= 0:
                touched[row] = coordinates(int(self.joint_body_a[k]), int(self.joint_body_b[k]))
            else:
                touched[row] = [3 * int(self.driver_body[d]) + 2]
        cols = np.full((self.ncon, 6), -1, dtype=np.int64)
        first = np.zeros(self.ncon, dtype=np.int64)
        for i, row_cols in enumerate(touched):
            cols[i, : len(row_cols)] = row_cols
            mine = set(row_cols)
            first[i] = next(j for j in range(i + 1) if mine & set(touched[j]) or j == i)
        return cols, first

    def select(self, start: int, stop: int) -> Model:
        """The sub-model of samples ``start:stop`` (per-sample arrays sliced, others kept)."""
        return self.take(slice(start, stop))

    def take(self, index: slice | np.ndarray) -> Model:
        """The sub-model of the samples ``index`` picks (a slice, or an integer array in any
        order: ``mcchain check`` re-solves a spread subset); per-sample arrays are indexed,
        the others kept."""
        picked = np.arange(self.nsample)[index]
        changes: dict[str, object] = {"nsample": int(picked.size)}
        for f in fields(self):
            arr = getattr(self, f.name)
            if f.name == "parameters":
                changes[f.name] = arr[index]
            elif (
                (f.name in _PER_SAMPLE_FIELDS or f.name in _START_FIELDS)
                and isinstance(arr, np.ndarray)
                and arr.shape[0] == self.nsample
                and self.nsample > 1
            ):
                changes[f.name] = arr[index]
        return replace(self, **changes)  # type: ignore[arg-type]


KernelModel = NamedTuple(  # type: ignore[misc]
    "KernelModel",
    [
        (f.name, np.ndarray)
        for f in fields(Model)
        if f.type == "np.ndarray" and f.name != "parameters"
    ],
)
"""The arrays a numba kernel reads, in one (heterogeneous) named tuple: every array field of
:class:`Model` but ``parameters``, in its order (meanings and shapes there). Numba accepts a
NamedTuple of arrays as one argument (:mod:`mcchain.kernels.kernel_model` makes it one
structure), which keeps kernel signatures short."""
_START_FIELDS = frozenset({"joint_start"})
"""Per-sample arrays set from the start state (not parameters of the scene)."""

_PER_SAMPLE_FIELDS = frozenset(
    name for row in TABLE for name in (row.field if isinstance(row.field, tuple) else (row.field,))
)
PER_SAMPLE_FIELDS = _PER_SAMPLE_FIELDS
"""Names of the parameter arrays that carry a leading sample axis (size 1 or nsample)."""


def constraint_rows(joint_kind: np.ndarray, ndriver: int) -> tuple[np.ndarray, np.ndarray]:
    """First constraint row of each joint and of each driver.

    Args:
        joint_kind: (njoint,) :class:`JointKind` values.
        ndriver: number of drivers.

    Returns:
        ``(joint_row, driver_row)``, int64 arrays of shape (njoint,) and (ndriver,).
    """
    sizes = joint_rows(joint_kind)
    joint_row = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    first_driver_row = int(sizes.sum())
    driver_row = first_driver_row + np.arange(ndriver, dtype=np.int64)
    return joint_row[: len(sizes)], driver_row
