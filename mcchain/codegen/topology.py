"""The structure of a model that generated code depends on, and the packed parameters.

* :class:`Topology`: the hashable structure of a :class:`~mcchain.model.Model` (which bodies
  each joint, driver, force and spring connects, and the joint kinds).
* :func:`pack_parameters`: the per-sample parameters as ``P`` (nslot, nsample), float64,
  sample innermost; the slot of each named quantity is fixed by :meth:`Topology.slots`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from mcchain.model import (
    DRIVER_HARMONIC,
    GROUND,
    LOAD_CONSTANT,
    LOAD_HARMONIC,
    JointKind,
    Model,
    constraint_rows,
)
from mcchain.parameters import Slot, packed_slots


@dataclass(frozen=True, repr=False)
class Topology:
    """The structure of a model that generated code depends on (never parameter values; of
    them only whether a contact joint has friction at all, :attr:`joint_friction`).

    Constraint rows follow :func:`mcchain.model.constraint_rows`: joints in order (2 rows
    ideal, 1 clearance), then drivers.
    """

    nbody: int
    joint_a: tuple[int, ...]
    joint_b: tuple[int, ...]
    joint_kind: tuple[int, ...]
    driver_body: tuple[int, ...]
    force_body: tuple[int, ...]
    spring_a: tuple[int, ...]
    spring_b: tuple[int, ...]
    joint_model: tuple[int, ...] = ()
    # Per joint, read by contact joints only: the law's code ([joint.contact] law is not
    # sampled: a literal of the text) and 1 where some sample's Coulomb μ is not 0 (the
    # text of a joint without has no friction terms). (): the law a parameter of the lanes,
    # friction everywhere.
    joint_law: tuple[int, ...] = ()
    joint_friction: tuple[int, ...] = ()
    driver_law: tuple[int, ...] = ()
    force_law: tuple[int, ...] = ()
    driver_joint: tuple[int, ...] = ()
    # Table laws: per driver / load, (knots, ascending coefficients) of its spline, or ()
    driver_tables: tuple[tuple[tuple[float, ...], ...], ...] = ()
    load_tables: tuple[tuple[tuple[float, ...], ...], ...] = ()
    # An ideal copy after the mechanism (Model.reference): the mechanism's own counts, or ()
    reference: tuple[int, ...] = ()

    def __repr__(self) -> str:
        # The contact fields only when a joint uses the law, the driver laws only when one is
        # not constant: the text of every generated module without them (it starts with this
        # repr) is unchanged by their addition.
        names = [f.name for f in fields(self)]
        if not self.contact_joints:
            names = [n for n in names if n not in ("joint_model", "joint_law", "joint_friction")]
        if not self.harmonic_drivers:
            names = [n for n in names if n != "driver_law"]
        if not self.harmonic_loads:
            names = [n for n in names if n != "force_law"]
        if not self.slider_drivers:
            names = [n for n in names if n != "driver_joint"]
        if not any(self.driver_tables):
            names = [n for n in names if n != "driver_tables"]
        if not any(self.load_tables):
            names = [n for n in names if n != "load_tables"]
        if not self.reference:
            names = [n for n in names if n != "reference"]
        items = ", ".join(f"{n}={getattr(self, n)!r}" for n in names)
        return f"Topology({items})"

    @classmethod
    def from_model(cls, model: Model) -> Topology:
        def t(a: np.ndarray) -> tuple[int, ...]:
            return tuple(int(x) for x in np.asarray(a).reshape(-1))

        return cls(
            nbody=model.nbody,
            joint_a=t(model.joint_body_a),
            joint_b=t(model.joint_body_b),
            joint_kind=t(model.joint_kind),
            driver_body=t(model.driver_body),
            force_body=t(model.force_body),
            spring_a=t(model.spring_body_a),
            spring_b=t(model.spring_body_b),
            # 1 where the joint may use the contact law: whether from the start or after the
            # link lets go (model contact or auto) is a parameter of the lanes.
            joint_model=tuple(int(m != 0) for m in np.asarray(model.joint_model).reshape(-1)),
            joint_law=t(model.joint_contact_law),
            joint_friction=_friction(model),
            driver_law=t(model.driver_law),
            force_law=t(model.force_law),
            driver_joint=t(model.driver_joint),
            driver_tables=_tables(model.driver_table_size, model.driver_table_knots,
                                  model.driver_table_coef),
            load_tables=_tables(model.force_table_size, model.force_table_knots,
                                model.force_table_coef),
            reference=t(model.reference),
        )  # fmt: skip

    @property
    def ndof(self) -> int:
        return 3 * self.nbody

    @property
    def njoint(self) -> int:
        return len(self.joint_kind)

    @property
    def ndriver(self) -> int:
        return len(self.driver_body)

    @property
    def joint_row(self) -> tuple[int, ...]:
        joint_row, _ = constraint_rows(np.asarray(self.joint_kind, dtype=np.int64), self.ndriver)
        return tuple(int(r) for r in joint_row)

    @property
    def driver_row(self) -> tuple[int, ...]:
        _, driver_row = constraint_rows(np.asarray(self.joint_kind, dtype=np.int64), self.ndriver)
        return tuple(int(r) for r in driver_row)

    @property
    def ncon(self) -> int:
        return sum(JointKind(k).rows for k in self.joint_kind) + self.ndriver

    @property
    def ground_revolutes(self) -> tuple[int, ...]:
        """Ideal revolute joints between the ground and one body: the determinant of their
        2×2 block of B M⁻¹ Bᵀ is a per-sample constant (the fixed-step lanes compute it once:
        mcchain.codegen.kinematics.ConstraintKinematics.ground_revolutes)."""
        return tuple(
            k
            for k, kind in enumerate(self.joint_kind)
            if kind == JointKind.IDEAL
            and (self.joint_a[k] == GROUND) != (self.joint_b[k] == GROUND)
        )

    @property
    def clearance_rows(self) -> tuple[int, ...]:
        return tuple(
            r
            for r, kind in zip(self.joint_row, self.joint_kind, strict=True)
            if kind == JointKind.CLEARANCE
        )

    @property
    def own_bodies(self) -> int:
        """The mechanism's own bodies (all, but in a model with an ideal copy after them,
        ``Model.reference``: its energy and step control leave the copy out)."""
        return self.reference[0] if self.reference else self.nbody

    @property
    def own_forces(self) -> int:
        """The mechanism's own loads (see :attr:`own_bodies`)."""
        return self.reference[3] if self.reference else len(self.force_body)

    @property
    def own_springs(self) -> int:
        """The mechanism's own spring-dampers (see :attr:`own_bodies`)."""
        return self.reference[4] if self.reference else len(self.spring_a)

    def own_row(self, r: int) -> bool:
        """Whether constraint row ``r`` is the mechanism's own (see :attr:`own_bodies`)."""
        if not self.reference or r < self.reference[5]:
            return True
        return r in self.driver_row[: self.reference[2]]

    @property
    def contact_joints(self) -> tuple[int, ...]:
        """The joints that may use the contact law (model contact or auto)."""
        return tuple(k for k, m in enumerate(self.joint_model) if m != 0)

    def friction(self, k: int) -> bool:
        """Whether contact joint ``k`` may have friction (some sample's μ is not 0)."""
        return not self.joint_friction or self.joint_friction[k] != 0

    def law(self, k: int) -> int | None:
        """The contact law's code of joint ``k`` (:data:`mcchain.contact.LAW_CODES`), or None
        where the lanes read it from their parameters."""
        return self.joint_law[k] if self.joint_law else None

    @property
    def harmonic_drivers(self) -> tuple[int, ...]:
        """The drivers of law harmonic."""
        return tuple(d for d, law in enumerate(self.driver_law) if law == DRIVER_HARMONIC)

    @property
    def slider_drivers(self) -> dict[int, int]:
        """Driver -> the prismatic joint it moves, for the slider drivers."""
        return {d: k for d, k in enumerate(self.driver_joint) if k >= 0}

    @property
    def harmonic_loads(self) -> tuple[int, ...]:
        """The forces of law harmonic."""
        return tuple(f for f, law in enumerate(self.force_law) if law == LOAD_HARMONIC)

    @property
    def varying_loads(self) -> tuple[int, ...]:
        """The forces that vary in time (law harmonic or table): no potential."""
        return tuple(f for f, law in enumerate(self.force_law) if law != LOAD_CONSTANT)

    def packed(self) -> list[Slot]:
        """The rows of ``P``, in order (:func:`mcchain.parameters.packed_slots`)."""
        return packed_slots(
            self.joint_kind,
            self.nbody,
            self.ndriver,
            len(self.force_body),
            len(self.spring_a),
            self.joint_model,
            self.driver_law,
            self.force_law,
            self.driver_joint,
        )

    def slots(self) -> dict[str, int]:
        """Row of ``P`` holding each named per-sample quantity."""
        return {slot.name: i for i, slot in enumerate(self.packed())}


def _friction(model: Model) -> tuple[int, ...]:
    """Per joint, 1 where some sample's μ is not 0 (NaN counts as friction)."""
    mu = np.asarray(model.joint_contact_friction, dtype=np.float64).reshape(-1, model.njoint)
    return tuple(int(np.any(mu[:, k] != 0.0)) for k in range(model.njoint))


def _tables(
    size: np.ndarray, knots: np.ndarray, coef: np.ndarray
) -> tuple[tuple[tuple[float, ...], ...], ...]:
    """Per item, (knots, coefficients) of its table's spline as tuples of floats, or ()."""
    out: list[tuple[tuple[float, ...], ...]] = []
    for i, n in enumerate(np.asarray(size).reshape(-1)):
        n = int(n)
        if n == 0:
            out.append(())
            continue
        out.append(
            (tuple(float(x) for x in knots[i, :n]), tuple(float(x) for x in coef[i, : 4 * (n - 1)]))
        )
    return tuple(out)


def pack_parameters(model: Model, topology: Topology | None = None) -> np.ndarray:
    """The parameters of every sample as ``P`` (nslot, nsample), sample innermost."""
    topo = topology or Topology.from_model(model)
    slots = topo.packed()
    P = np.empty((len(slots), model.nsample), dtype=np.float64)
    for row, slot in enumerate(slots):
        arr = np.asarray(getattr(model, slot.field), dtype=np.float64)
        if arr.ndim == len(slot.at):  # a topology array (no sample axis): the same for all
            arr = arr[np.newaxis]
        index: tuple[slice | int, ...] = (slice(None), *slot.at)
        column = arr[index]
        P[row] = np.broadcast_to(1.0 / column if slot.inverse else column, (model.nsample,))
    return P
