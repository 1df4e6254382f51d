"""Every parameter of a scene, defined once: one :class:`Parameter` row per (kind, key).

A row says everything the rest of mcchain needs to know about one scene key that a
``[sample.vary]`` path may name:

* ``kind``, ``key``, ``shape``: the path ``kind.name.key[i][j]`` and how many indices it takes
  (:mod:`mcchain.scene.paths` parses against these rows);
* ``field`` (and ``dof``): the :class:`~mcchain.model.Model` array it lands in and how the
  item and indices map to an index of that array (:meth:`Parameter.model_index`; the compiler
  writes scene values and sampled columns there, ``mcchain validate`` reads them back);
* ``domain``: the allowed values, checked on a distribution's support at load time and on
  every sampled value at compile time;
* ``units``: the CF units of its column of the ensemble's ``parameters``;
* ``slots``: the names of its rows in the lane kernels' packed parameter array ``P``, one per
  element (C order), ``{i}`` standing for the item's index; ``inverse_slots`` hold 1/value
  (packed after every plain slot of the item); ``packed_for`` limits a joint row to joints of
  one :class:`~mcchain.model.JointKind`. :func:`packed_slots` lays them out in the order the
  generated kernels read them.

Adding a parameter of an existing kind means: a row here, the key in the scene model
(:mod:`mcchain.scene.models`), its array in :class:`~mcchain.model.Model`, and the kernel that
reads it. This module imports numpy only (no numba, no pydantic), so the code generator can
use it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from mcchain.codes import DRIVER_HARMONIC, LOAD_HARMONIC, JointKind
from mcchain.contact import HERTZ_EXPONENT


@dataclass(frozen=True)
class Domain:
    """The allowed values of a parameter: ``> low`` (open) or ``>= low``, and ``<= high``
    when ``high`` is given."""

    low: float
    open_low: bool
    high: float | None = None

    @property
    def text(self) -> str:
        text = f"{'>' if self.open_low else '>='} {self.low!r}"
        return text if self.high is None else f"{text} and <= {self.high!r}"

    def contains(self, values: Any) -> Any:
        ok = values > self.low if self.open_low else values >= self.low
        return ok if self.high is None else ok & (values <= self.high)


POSITIVE = Domain(0.0, True)
NON_NEGATIVE = Domain(0.0, False)
UNIT_INTERVAL = Domain(0.0, True, 1.0)

CONTACT_JOINTS = "contact"
"""``packed_for`` of the contact-law rows: packed only for clearance joints whose model is
``contact`` or ``auto`` (:data:`mcchain.contact.MODEL_CODES`)."""
HARMONIC_DRIVERS = "harmonic"
"""``packed_for`` of the harmonic-law rows of drivers: packed only for drivers of that law."""
SLIDER_DRIVERS = "slider"
"""``packed_for`` of the rows of slider drivers: packed only for drivers of a prismatic joint."""
HARMONIC_LOADS = "harmonic load"
"""``packed_for`` of the harmonic-law rows of forces: packed only for forces of that law."""


@dataclass(frozen=True)
class Parameter:
    """One sampled-parameter key of one kind of scene item (see the module docstring).

    Attributes:
        kind: ``scene``, ``body``, ``joint``, ``driver``, ``force`` or ``spring``.
        key: the scene key (``mass``, ``points``, ...).
        shape: the key's array shape; ``()`` for a number.
        field: the Model array; a tuple gives one array per first index (``points[0|1]``
            land in ``joint_point_a`` / ``joint_point_b``).
        units: CF units.
        domain: allowed values, or None for any finite value.
        dof: for a body's state, the coordinate offset: the value lands in
            ``field[3 * body + dof + k]``.
        slots: packed slot names, one per element, ``{i}`` the item index.
        inverse_slots: packed slots holding 1 / value (after the item's plain slots).
        packed_for: pack the slots only for joints of this kind, or, with
            :data:`CONTACT_JOINTS`, only for joints that may use the contact law.
        unset: the Model value of an optional key the scene leaves out (None in the scene
            model); NaN where the compiler derives it (from positions, or the body's angle).
    """

    kind: str
    key: str
    shape: tuple[int, ...]
    field: str | tuple[str, ...]
    units: str
    domain: Domain | None = None
    dof: int | None = None
    slots: tuple[str, ...] = ()
    inverse_slots: tuple[str, ...] = ()
    packed_for: JointKind | str | None = None
    unset: float | None = None

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def elements(self) -> list[tuple[int, ...]]:
        """Every index into the key's array, in C order (``[()]`` for a number)."""
        return [tuple(int(i) for i in idx) for idx in np.ndindex(*self.shape)]

    def model_index(self, item: int, indices: tuple[int, ...]) -> tuple[str, tuple[int, ...]]:
        """The Model array and the index (without the sample axis) of element ``indices``
        of item ``item`` (0 for ``scene``)."""
        if isinstance(self.field, tuple):
            return self.field[indices[0]], (item, *indices[1:])
        if self.dof is not None:
            return self.field, (3 * item + self.dof + sum(indices),)
        if self.kind == "scene":
            return self.field, indices
        return self.field, (item, *indices)

    def field_shape(self, nitem: int) -> tuple[int, ...]:
        """Shape (without the sample axis) of the Model array for ``nitem`` items."""
        if isinstance(self.field, tuple):
            return (nitem, *self.shape[1:])
        if self.dof is not None:
            return (3 * nitem,)
        if self.kind == "scene":
            return self.shape
        return (nitem, *self.shape)

    def scene_value(self, item: Any) -> Any:
        """The key's value in a scene item (a pydantic model), None when not given; a dotted
        key (``contact.stiffness``) reads the sub-table (absent: None)."""
        *tables, key = self.key.split(".")
        for table in tables:
            item = getattr(item, table)
            if item is None:
                return None
        return getattr(item, key)

    def read(self, model: Any, item: int, sample: int = 0) -> np.ndarray:
        """The value of item ``item`` in ``model`` (a Model) at ``sample``, shaped ``shape``."""
        values = []
        for idx in self.elements:
            name, at = self.model_index(item, idx)
            arr = getattr(model, name)
            values.append(arr[(sample % arr.shape[0], *at)])
        return np.asarray(values, dtype=np.float64).reshape(self.shape)


_P = Parameter
_AB = ("joint_point_a", "joint_point_b")
_SAB = ("spring_point_a", "spring_point_b")
_NAN = math.nan

# fmt: off
TABLE: tuple[Parameter, ...] = (
    # Rows of one kind are in packed order (the generated kernels' slot order).
    # kind     key                 shape   Model field              units      domain
    _P("scene", "gravity",          (2,),   "gravity",               "m s-2",   None,
      slots=("gx", "gy")),
    _P("body",  "mass",             (),     "body_mass",             "kg",      POSITIVE,
      slots=("m{i}",), inverse_slots=("im{i}",)),
    _P("body",  "inertia",          (),     "body_inertia",          "kg m2",   POSITIVE,
      slots=("J{i}",), inverse_slots=("iJ{i}",)),
    _P("body",  "position",         (2,),   "q0",                    "m",       None, dof=0,
      unset=_NAN),
    _P("body",  "angle",            (),     "q0",                    "rad",     None, dof=2,
      unset=_NAN),
    _P("body",  "velocity",         (2,),   "v0",                    "m s-1",   None, dof=0),
    _P("body",  "angular_velocity", (),     "v0",                    "rad s-1", None, dof=2),
    _P("joint", "points",           (2, 2), _AB,                     "m",       None,
      slots=("sax{i}", "say{i}", "sbx{i}", "sby{i}")),
    # A sampled clearance makes a clearance joint: it must stay > 0 (|d| = 0 is singular).
    _P("joint", "clearance",        (),     "joint_clearance",       "m",       POSITIVE,
      slots=("cl{i}",), packed_for=JointKind.CLEARANCE),
    _P("joint", "eccentricity",     (),     "joint_eccentricity",    "rad",     None,
      unset=_NAN),
    # A prismatic joint: its sliding axis in the first body's frame (made unit when compiled)
    # and the relative angle θ_b − θ_a it holds (unset: as written or placed).
    _P("joint", "axis",             (2,),   "joint_axis",            "1",       None,
      slots=("ux{i}", "uy{i}"), packed_for=JointKind.PRISMATIC, unset=_NAN),
    _P("joint", "relative_angle",   (),     "joint_relative_angle",  "rad",     None,
      slots=("rel{i}",), packed_for=JointKind.PRISMATIC, unset=_NAN),
    # The contact law of a clearance joint (``[joint.contact]``); K unset: from the materials.
    _P("joint", "contact.stiffness", (),   "joint_contact_stiffness", "N m-1.5", POSITIVE,
      slots=("K{i}",), packed_for=CONTACT_JOINTS, unset=_NAN),
    _P("joint", "contact.exponent", (),    "joint_contact_exponent", "1",       POSITIVE,
      slots=("mx{i}",), packed_for=CONTACT_JOINTS, unset=HERTZ_EXPONENT),
    _P("joint", "contact.restitution", (), "joint_contact_restitution", "1",    UNIT_INTERVAL,
      slots=("er{i}",), packed_for=CONTACT_JOINTS, unset=1.0),
    _P("joint", "contact.friction", (),    "joint_contact_friction", "1",       NON_NEGATIVE,
      slots=("mu{i}",), packed_for=CONTACT_JOINTS, unset=0.0),
    _P("joint", "contact.radius", (),      "joint_contact_radius", "m",         NON_NEGATIVE,
      slots=("R{i}",), packed_for=CONTACT_JOINTS, unset=0.0),
    _P("driver", "angle0",          (),     "driver_angle0",         "rad",     None,
      slots=("th0_{i}",), unset=_NAN),
    _P("driver", "omega",           (),     "driver_omega",          "rad s-1", None,
      slots=("om{i}",), unset=0.0),
    # A slider driver (``joint``): s0 + v t; s0 unset: as written or placed
    _P("driver", "displacement0",   (),     "driver_displacement0",  "m",       None,
      slots=("s0_{i}",), packed_for=SLIDER_DRIVERS, unset=_NAN),
    _P("driver", "speed",           (),     "driver_speed",          "m s-1",   None,
      slots=("spd{i}",), packed_for=SLIDER_DRIVERS, unset=0.0),
    # law = "harmonic": θ0 + ω t + A (sin(2π f t + φ) − sin φ)
    _P("driver", "amplitude",       (),     "driver_amplitude",      "rad",     None,
      slots=("amp{i}",), packed_for=HARMONIC_DRIVERS, unset=0.0),
    _P("driver", "frequency",       (),     "driver_frequency",      "Hz",      POSITIVE,
      slots=("frq{i}",), packed_for=HARMONIC_DRIVERS, unset=0.0),
    _P("driver", "phase",           (),     "driver_phase",          "rad",     None,
      slots=("pha{i}",), packed_for=HARMONIC_DRIVERS, unset=0.0),
    _P("force", "point",            (2,),   "force_point",           "m",       None,
      slots=("fpx{i}", "fpy{i}")),
    _P("force", "value",            (2,),   "force_value",           "N",       None,
      slots=("fx{i}", "fy{i}"), unset=0.0),
    _P("force", "torque",           (),     "force_torque",          "N m",     None,
      slots=("tq{i}",), unset=0.0),
    # law = "harmonic": value and torque times sin(2π f t + φ)
    _P("force", "frequency",        (),     "force_frequency",       "Hz",      POSITIVE,
      slots=("ffr{i}",), packed_for=HARMONIC_LOADS, unset=0.0),
    _P("force", "phase",            (),     "force_phase",           "rad",     None,
      slots=("fph{i}",), packed_for=HARMONIC_LOADS, unset=0.0),
    _P("spring", "points",          (2, 2), _SAB,                    "m",       None,
      slots=("spax{i}", "spay{i}", "spbx{i}", "spby{i}")),
    _P("spring", "stiffness",       (),     "spring_stiffness",      "N m-1",   NON_NEGATIVE,
      slots=("k{i}",)),
    _P("spring", "rest_length",     (),     "spring_rest_length",    "m",       NON_NEGATIVE,
      slots=("l0{i}",), unset=_NAN),
    _P("spring", "damping",         (),     "spring_damping",        "N s m-1", NON_NEGATIVE,
      slots=("cd{i}",)),
)
# fmt: on
"""Every sampled parameter; rows of one kind are in the order of their packed slots."""

PARAMETERS: dict[tuple[str, str], Parameter] = {(p.kind, p.key): p for p in TABLE}
"""The rows by (kind, key)."""


def unset_value(kind: str, key: str) -> float:
    """The value a scene key takes when the scene leaves it out (its row's ``unset``): the
    one statement of that default, read by the scene model and the Model."""
    value = PARAMETERS[kind, key].unset
    if value is None:
        raise KeyError(f"{kind}.{key} has no default")
    return value


KINDS: tuple[str, ...] = tuple(dict.fromkeys(p.kind for p in TABLE))
"""The kinds, in packed order: scene, body, joint, driver, force, spring."""


def rows_of(kind: str) -> list[Parameter]:
    """The rows of one kind, in table order."""
    return [p for p in TABLE if p.kind == kind]


def param_units(path: str) -> str:
    """CF units of a sampled parameter path (``body.bar.mass`` -> ``kg``), ``1`` if unknown."""
    parts = [part.strip('"') for part in path.split("[", 1)[0].split(".")]
    key = parts[-1] if parts[0] == "scene" else ".".join(parts[2:])
    row = PARAMETERS.get((parts[0], key))
    return row.units if row is not None else "1"


class Slot(NamedTuple):
    """One row of the packed parameter array ``P``: its name, where its value comes from
    (Model array and the element's index without the sample axis) and whether it holds
    1 / value."""

    name: str
    field: str
    at: tuple[int, ...]
    inverse: bool


def packed_slots(
    joint_kind: Sequence[int],
    nbody: int,
    ndriver: int,
    nforce: int,
    nspring: int,
    joint_model: Sequence[int] | None = None,
    driver_law: Sequence[int] | None = None,
    force_law: Sequence[int] | None = None,
    driver_joint: Sequence[int] | None = None,
) -> list[Slot]:
    """The rows of ``P`` for a topology, in order: kinds in table order, then items in order;
    per item, every row's plain slots in table order, then the inverse slots.

    A joint row with ``packed_for`` is packed only for joints of that kind (or, for
    :data:`CONTACT_JOINTS`, whose ``joint_model`` is not the link; default: every joint is);
    a driver row with :data:`HARMONIC_DRIVERS` only for drivers whose ``driver_law`` is
    harmonic, a force row with :data:`HARMONIC_LOADS` only for forces whose ``force_law`` is,
    a driver row with :data:`SLIDER_DRIVERS` only for drivers of a prismatic joint
    (``driver_joint`` ≥ 0) (default: none is).
    """
    contact = [m != 0 for m in joint_model] if joint_model is not None else []
    contact += [False] * (len(joint_kind) - len(contact))
    harmonic = [law == DRIVER_HARMONIC for law in driver_law] if driver_law is not None else []
    harmonic += [False] * (ndriver - len(harmonic))
    waving = [law == LOAD_HARMONIC for law in force_law] if force_law is not None else []
    waving += [False] * (nforce - len(waving))
    slider = [k >= 0 for k in driver_joint] if driver_joint is not None else []
    slider += [False] * (ndriver - len(slider))
    counts = {"scene": 1, "body": nbody, "joint": len(joint_kind), "driver": ndriver}
    counts |= {"force": nforce, "spring": nspring}
    out: list[Slot] = []
    for kind in KINDS:
        rows = rows_of(kind)
        for i in range(counts[kind]):
            plain: list[Slot] = []
            inverse: list[Slot] = []
            for row in rows:
                if row.packed_for == CONTACT_JOINTS:
                    if not contact[i]:
                        continue
                elif row.packed_for == HARMONIC_DRIVERS:
                    if not harmonic[i]:
                        continue
                elif row.packed_for == HARMONIC_LOADS:
                    if not waving[i]:
                        continue
                elif row.packed_for == SLIDER_DRIVERS:
                    if not slider[i]:
                        continue
                elif row.packed_for is not None and int(joint_kind[i]) != row.packed_for:
                    continue
                for names, target, inv in (
                    (row.slots, plain, False),
                    (row.inverse_slots, inverse, True),
                ):
                    if not names:
                        continue
                    for template, idx in zip(names, row.elements, strict=True):
                        field, at = row.model_index(i, idx)
                        target.append(Slot(template.format(i=i), field, at, inv))
            if kind == "joint" and contact[i]:
                # The law and the model (contact or auto) are data too: one module serves
                # them all. Their Model arrays have no sample axis (topology); the start
                # mode's has one.
                plain += [
                    Slot(f"lw{i}", "joint_contact_law", (i,), False),
                    Slot(f"md{i}", "joint_model", (i,), False),
                    # the mode it starts in, per sample (mcchain.contact.START_LINK, ...)
                    Slot(f"fs{i}", "joint_start", (i,), False),
                ]
            out += plain + inverse
    return out


def packed_slot_names(
    joint_kind: Sequence[int],
    nbody: int,
    ndriver: int,
    nforce: int,
    nspring: int,
    joint_model: Sequence[int] | None = None,
    driver_law: Sequence[int] | None = None,
    force_law: Sequence[int] | None = None,
    driver_joint: Sequence[int] | None = None,
) -> list[str]:
    """The names of the rows of ``P`` (see :func:`packed_slots`), in order."""
    slots = packed_slots(
        joint_kind,
        nbody,
        ndriver,
        nforce,
        nspring,
        joint_model,
        driver_law,
        force_law,
        driver_joint,
    )
    return [s.name for s in slots]
