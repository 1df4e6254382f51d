"""Method coefficients as data: Butcher tableaux and generalized-α parameters.

Identities (order conditions, the embedded pair, first same as last) are tested in
``tests/test_simulate_methods.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SAFETY = 0.9
"""Adaptive step control: the new step is ``SAFETY · err^(-1/(q+1))`` times the old one (q the
order of the error estimate), kept below the step that would just meet the tolerance."""

MIN_FACTOR = 0.2
"""Adaptive step control: smallest ratio of a new step to the one before (after a rejection)."""

MAX_FACTOR = 5.0
"""Adaptive step control: largest ratio of a new step to the one before (also the ratio when
the error estimate is exactly zero)."""

CAP_MARGIN = 1.0 + 1e-6
"""Adaptive step control: an error norm at most (MAX_FACTOR / SAFETY · CAP_MARGIN)^-(q+1)
takes the ratio MAX_FACTOR without the power err^(-1/(q+1)), which there is above MAX_FACTOR
/ SAFETY by the margin, a million times its rounding: the same ratio, one ``pow`` fewer a
step on the steps with a small error (the steps cut short to land on an output time)."""

KEEP_MARGIN = 1.0 + 1e-9
"""Adaptive step control: a step cut short to land on an output time keeps the controller's
step h unless the cut step's proposal h_cut · SAFETY · err^(-1/(q+1)) exceeds it, which it
cannot where err ≥ KEEP_MARGIN · (SAFETY h_cut / h)^(q+1): the margin covers the rounding
of that bound, of the power and of the product (a few ulps) a million times over, so the
kept step is the same without the power: most landed steps of a fine output grid."""


@dataclass(frozen=True)
class Tableau:
    """Explicit Runge–Kutta tableau: stages c, matrix A (strictly lower), weights b.

    ``b_error`` (embedded pairs): b − b̂, the weights of the local error estimate; ``order``
    is the order of b, ``error_order`` the order of b̂.
    """

    name: str
    c: np.ndarray
    A: np.ndarray
    b: np.ndarray
    order: int
    b_error: np.ndarray | None = None
    error_order: int | None = None

    @property
    def nstage(self) -> int:
        return len(self.c)


RK4 = Tableau(
    name="rk4",
    c=np.array([0.0, 0.5, 0.5, 1.0]),
    A=np.array(
        [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
    ),
    b=np.array([1.0, 2.0, 2.0, 1.0]) / 6.0,
    order=4,
)
"""The classical fourth-order Runge–Kutta method."""

_DP_B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
_DP_BHAT = np.array(
    [5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]
)
DOPRI5 = Tableau(
    name="dopri5",
    c=np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0]),
    A=np.array(
        [
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0, 0.0],
            [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0, 0.0],
            [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0, 0.0],
            [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0, 0.0],
            [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0],
        ]
    ),
    b=_DP_B,
    order=5,
    b_error=_DP_B - _DP_BHAT,
    error_order=4,
)
"""Dormand–Prince 5(4), first same as last (the last stage is the next step's first)."""


@dataclass(frozen=True)
class GeneralizedAlpha:
    """Generalized-α coefficients (Chung & Hulbert; Arnold & Brüls 2007) from ρ∞ ∈ [0, 1]."""

    rho_inf: float
    alpha_m: float
    alpha_f: float
    gamma: float
    beta: float

    @classmethod
    def from_rho(cls, rho_inf: float) -> GeneralizedAlpha:
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        gamma = 0.5 + af - am
        beta = 0.25 * (gamma + 0.5) ** 2
        return cls(rho_inf, am, af, gamma, beta)


PEAK_WIDTH = 5
"""Numbers the continuous peak tracking (:mod:`mcchain.kernels.peaks`) keeps per quantity:
its last four values at accepted states and its running peak. Here, with no numba, so that
the code generator lays out its rows without importing the kernels."""
PEAK_CLOCK = 5
"""... and per sample, shared by its quantities: the last four times and the count fed."""
