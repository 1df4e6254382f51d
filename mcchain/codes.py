"""The integer codes of the compiled model (joint kinds, driver and load laws, the ground).

A leaf module (numpy-free): :mod:`mcchain.parameters` and :mod:`mcchain.model` both read
these codes, and the model reads the parameter table, so the codes live below both.
:mod:`mcchain.model` re-exports every name.
"""

from __future__ import annotations

from enum import IntEnum

GROUND = -1
"""Body index of the fixed ground body (r = 0, θ = 0)."""


class JointKind(IntEnum):
    """The kind of a joint, as stored in ``Model.joint_kind``; each knows its constraint rows.

    * ``IDEAL``: ideal revolute joint, Φ = d = 0 (two rows);
    * ``CLEARANCE``: revolute joint with radial clearance c, Φ = |d| − c = 0 (one row);
    * ``PRISMATIC``: ideal prismatic (sliding) joint along the unit axis u fixed in body a,
      Φ = (n·d, θ_b − θ_a − θ_0) with n = A_a Ω u the axis' normal (two rows).
    """

    IDEAL = 0
    CLEARANCE = 1
    PRISMATIC = 2

    @property
    def rows(self) -> int:
        """Number of constraint rows of a joint of this kind."""
        return _JOINT_ROWS[self]


_JOINT_ROWS = {JointKind.IDEAL: 2, JointKind.CLEARANCE: 1, JointKind.PRISMATIC: 2}

JOINT_IDEAL = int(JointKind.IDEAL)
"""``JointKind.IDEAL`` as a plain int, for numba kernels (they read int module globals)."""
JOINT_CLEARANCE = int(JointKind.CLEARANCE)
"""``JointKind.CLEARANCE`` as a plain int, for numba kernels."""
JOINT_PRISMATIC = int(JointKind.PRISMATIC)
"""``JointKind.PRISMATIC`` as a plain int, for numba kernels."""

DRIVER_CONSTANT = 0
"""``Model.driver_law`` of θ0 + ω t."""
DRIVER_HARMONIC = 1
"""``Model.driver_law`` of θ0 + ω t + A (sin(2π f t + φ) − sin φ)."""
DRIVER_TABLE = 2
"""``Model.driver_law`` of a cubic spline through a table (θ0 = f(0), ω = 0)."""
DRIVER_LAWS = {"constant": DRIVER_CONSTANT, "harmonic": DRIVER_HARMONIC, "table": DRIVER_TABLE}
"""``[[driver]] law`` -> ``Model.driver_law`` code."""
LOAD_CONSTANT = 0
"""``Model.force_law`` of a constant load."""
LOAD_HARMONIC = 1
"""``Model.force_law`` of a load times sin(2π f t + φ)."""
LOAD_TABLE = 2
"""``Model.force_law`` of a load times a cubic spline through a table of factors."""
LOAD_LAWS = {"constant": LOAD_CONSTANT, "harmonic": LOAD_HARMONIC, "table": LOAD_TABLE}
"""``[[force]] law`` -> ``Model.force_law`` code."""
