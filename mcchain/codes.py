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

# -- [[output]]: what the kernels track per output (mcchain.kernels.outputs) -----------------
OUTPUT_POSITION = 0
"""An output of a body point's position (m): a vector, with its rate."""
OUTPUT_VELOCITY = 1
"""... of a body point's velocity (m/s): a vector, with its rate (the acceleration)."""
OUTPUT_ACCELERATION = 2
"""... of a body point's acceleration (m/s²): a vector, values only."""
OUTPUT_ANGLE = 3
"""... of a body's angle (rad), with its rate."""
OUTPUT_ANGULAR_VELOCITY = 4
"""... of a body's angular velocity (rad/s), with its rate."""
OUTPUT_JOINT_FORCE = 5
"""... of a joint's force on its journal body (N): a vector, values only."""
OUTPUT_CONTACT_FORCE = 6
"""... of a clearance joint's normal force (N), values only."""
OUTPUT_PENETRATION = 7
"""... of a contact-law joint's penetration δ = |d| − c (m), with its rate."""
OUTPUT_DRIVER = 8
"""... of a driver's torque (N m) or force (N), −λ of its row, values only."""
OUTPUT_KINDS = {
    "position": OUTPUT_POSITION,
    "velocity": OUTPUT_VELOCITY,
    "acceleration": OUTPUT_ACCELERATION,
    "angle": OUTPUT_ANGLE,
    "angular_velocity": OUTPUT_ANGULAR_VELOCITY,
    "joint_force": OUTPUT_JOINT_FORCE,
    "contact_force": OUTPUT_CONTACT_FORCE,
    "penetration": OUTPUT_PENETRATION,
    "driver_torque": OUTPUT_DRIVER,
    "driver_force": OUTPUT_DRIVER,
}
"""``[[output]] of`` -> kind code."""
OUTPUT_TABULATED_REFERENCE = -2
"""The ``ref`` of a ``relative_to = "ideal"`` output whose ideal mechanism is the same for
every sample: its quantity is read from a table in the output's data
(:func:`mcchain.kernels.outputs.reference_signal`), not from an ideal copy's items (≥ 0;
−1: no reference)."""
OUTPUT_WITH_RATE = (
    OUTPUT_POSITION,
    OUTPUT_VELOCITY,
    OUTPUT_ANGLE,
    OUTPUT_ANGULAR_VELOCITY,
    OUTPUT_PENETRATION,
)
"""The kinds whose rate the state gives: a cubic Hermite on each step; the others are
interpolated by the cubic through four step ends, as the peaks."""
OUTPUT_COMPONENTS = {"x": 0, "y": 1, "magnitude": 2}
"""``[[output]] component`` -> code (−1: a scalar quantity)."""
OUTPUT_REDUCTIONS = {
    "max": 0,
    "min": 1,
    "max_abs": 2,
    "rms": 3,
    "mean": 4,
    "range": 5,
    "first_time_above": 6,
    "first_time_below": 7,
}
"""``[[output]] reduce`` -> code."""
OUTPUT_WIDTH = 11
"""Numbers an output's running reduction keeps (mcchain.kernels.outputs): its last four
values, the rate at the last one, the largest and smallest values, the integrals of the value
and of its square, the first crossing time and the length of window covered; a sample's four
times and count are kept once, as the peaks' clock (PEAK_CLOCK). Here, with no numba, so
that the code generator lays out its rows without importing the kernels."""
