"""The structure of a model that generated code depends on, and the packed parameters.

* :class:`Topology`: the hashable structure of a :class:`~mcchain.model.Model` (which bodies
  each joint, driver, force and spring connects, and the joint kinds).
* :func:`pack_parameters`: the per-sample parameters as ``P`` (nslot, nsample), float64,
  sample innermost; the slot of each named quantity is fixed by :meth:`Topology.slots`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mcchain.model import JOINT_CLEARANCE, JOINT_IDEAL, Model


@dataclass(frozen=True)
class Topology:
    """The structure of a model that generated code depends on (never parameter values).

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
        )

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
        rows, r = [], 0
        for kind in self.joint_kind:
            rows.append(r)
            r += 2 if kind == JOINT_IDEAL else 1
        return tuple(rows)

    @property
    def driver_row(self) -> tuple[int, ...]:
        first = sum(2 if k == JOINT_IDEAL else 1 for k in self.joint_kind)
        return tuple(first + i for i in range(self.ndriver))

    @property
    def ncon(self) -> int:
        return sum(2 if k == JOINT_IDEAL else 1 for k in self.joint_kind) + self.ndriver

    @property
    def clearance_rows(self) -> tuple[int, ...]:
        return tuple(
            r
            for r, kind in zip(self.joint_row, self.joint_kind, strict=True)
            if kind == JOINT_CLEARANCE
        )

    def slots(self) -> dict[str, int]:
        """Row of ``P`` holding each named per-sample quantity."""
        names = ["gx", "gy"]
        for b in range(self.nbody):
            names += [f"m{b}", f"J{b}", f"im{b}", f"iJ{b}"]
        for k, kind in enumerate(self.joint_kind):
            names += [f"sax{k}", f"say{k}", f"sbx{k}", f"sby{k}"]
            if kind == JOINT_CLEARANCE:
                names.append(f"cl{k}")
        for d in range(self.ndriver):
            names += [f"th0_{d}", f"om{d}"]
        for f in range(len(self.force_body)):
            names += [f"fpx{f}", f"fpy{f}", f"fx{f}", f"fy{f}", f"tq{f}"]
        for s in range(len(self.spring_a)):
            names += [f"spax{s}", f"spay{s}", f"spbx{s}", f"spby{s}", f"k{s}", f"l0{s}", f"cd{s}"]
        return {n: i for i, n in enumerate(names)}


def pack_parameters(model: Model, topology: Topology | None = None) -> np.ndarray:
    """The parameters of every sample as ``P`` (nslot, nsample), sample innermost."""
    topo = topology or Topology.from_model(model)
    slots = topo.slots()
    n = model.nsample
    P = np.empty((len(slots), n), dtype=np.float64)

    def put(name: str, column: np.ndarray) -> None:
        P[slots[name]] = np.broadcast_to(np.asarray(column, dtype=np.float64), (n,))

    def col(arr: np.ndarray, *index: int) -> np.ndarray:
        a = np.asarray(arr, dtype=np.float64)
        where: tuple[Any, ...] = (slice(None), *index)
        return a[where]

    put("gx", col(model.gravity, 0))
    put("gy", col(model.gravity, 1))
    for b in range(topo.nbody):
        m = col(model.body_mass, b)
        J = col(model.body_inertia, b)
        put(f"m{b}", m)
        put(f"J{b}", J)
        put(f"im{b}", 1.0 / m)
        put(f"iJ{b}", 1.0 / J)
    for k, kind in enumerate(topo.joint_kind):
        put(f"sax{k}", col(model.joint_point_a, k, 0))
        put(f"say{k}", col(model.joint_point_a, k, 1))
        put(f"sbx{k}", col(model.joint_point_b, k, 0))
        put(f"sby{k}", col(model.joint_point_b, k, 1))
        if kind == JOINT_CLEARANCE:
            put(f"cl{k}", col(model.joint_clearance, k))
    for d in range(topo.ndriver):
        put(f"th0_{d}", col(model.driver_angle0, d))
        put(f"om{d}", col(model.driver_omega, d))
    for f in range(len(topo.force_body)):
        put(f"fpx{f}", col(model.force_point, f, 0))
        put(f"fpy{f}", col(model.force_point, f, 1))
        put(f"fx{f}", col(model.force_value, f, 0))
        put(f"fy{f}", col(model.force_value, f, 1))
        put(f"tq{f}", col(model.force_torque, f))
    for s in range(len(topo.spring_a)):
        put(f"spax{s}", col(model.spring_point_a, s, 0))
        put(f"spay{s}", col(model.spring_point_a, s, 1))
        put(f"spbx{s}", col(model.spring_point_b, s, 0))
        put(f"spby{s}", col(model.spring_point_b, s, 1))
        put(f"k{s}", col(model.spring_stiffness, s))
        put(f"l0{s}", col(model.spring_rest_length, s))
        put(f"cd{s}", col(model.spring_damping, s))
    return P
