"""Per-sample status bits, shared by kernels, solvers and the ensemble.

Kernels never raise: they OR these bits into a per-sample ``status`` array (uint32) and fill
the sample's outputs with NaN. Kernels use the plain ``int`` constants below (numba reads
module globals as compile-time constants); Python code decodes them with :class:`Status`,
whose members carry the human message and the CF ``flag_meanings`` word.
"""

from __future__ import annotations

import enum

import numpy as np

ASSEMBLY_FAILED = 1
EQUILIBRIUM_NOT_CONVERGED = 2
SINGULAR = 4
DIVERGED = 8
CONTACT_LOST = 16
UNSTABLE_EQUILIBRIUM = 32
CONTACT_STEP_TOO_LARGE = 64

STATUS_DTYPE = np.uint32


class Status(enum.IntFlag):
    """Failure and warning bits of one sample; ``describe`` gives the messages."""

    ASSEMBLY_FAILED = ASSEMBLY_FAILED
    EQUILIBRIUM_NOT_CONVERGED = EQUILIBRIUM_NOT_CONVERGED
    SINGULAR = SINGULAR
    DIVERGED = DIVERGED
    CONTACT_LOST = CONTACT_LOST
    UNSTABLE_EQUILIBRIUM = UNSTABLE_EQUILIBRIUM
    CONTACT_STEP_TOO_LARGE = CONTACT_STEP_TOO_LARGE

    @property
    def meaning(self) -> str:
        """The CF ``flag_meanings`` word of a single flag."""
        return (self.name or "").lower()

    @property
    def message(self) -> str:
        """A one-line human explanation of a single flag."""
        return _MESSAGES[Status(self.value)]

    @classmethod
    def describe(cls, bits: int) -> list[str]:
        """Messages of every flag set in ``bits``."""
        return [flag.message for flag in cls if bits & flag.value]


_MESSAGES = {
    Status.ASSEMBLY_FAILED: "initial positions could not be projected onto the constraints",
    Status.EQUILIBRIUM_NOT_CONVERGED: "Newton did not reach the equilibrium tolerance",
    Status.SINGULAR: "constraint Jacobian B or the KKT matrix is rank-deficient",
    Status.DIVERGED: "non-finite state or constraint error past tolerance",
    Status.CONTACT_LOST: "a clearance joint needs λ ≤ 0 (continuous contact broken)",
    Status.UNSTABLE_EQUILIBRIUM: "an eigenpulsation has p² < 0 (unstable equilibrium)",
    Status.CONTACT_STEP_TOO_LARGE: "the fixed step is too large for a contact's stiffness "
    "(use rk45 or a smaller dt)",
}

FAILURE_BITS = (
    ASSEMBLY_FAILED | EQUILIBRIUM_NOT_CONVERGED | SINGULAR | DIVERGED | CONTACT_STEP_TOO_LARGE
)
"""Bits after which a sample's values are NaN; the others are warnings."""

FLAG_MASKS = np.array([flag.value for flag in Status], dtype=STATUS_DTYPE)
FLAG_MEANINGS = " ".join(flag.meaning for flag in Status)


def counts(status: np.ndarray) -> dict[str, int]:
    """How many samples carry each flag, plus ``ok`` (no flag at all)."""
    status = np.asarray(status)
    result = {"ok": int(np.count_nonzero(status == 0))}
    for flag in Status:
        result[flag.meaning] = int(np.count_nonzero(status & flag.value))
    return result
