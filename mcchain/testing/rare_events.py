"""Rare-event closed forms for subset simulation (tests and ``benchmarks/bench_subset_cases.py``).

Each case is a batch response on standard-normal points u (n, d): the margin of a
requirement (failure: margin > 0; NaN: a failed instance), with its exact failure
probability. They are built to break the assumptions of textbook subset simulation:

* ``plateau``: y = max(u₁ − 1.5, 0) (saturated: 0 for 93 % of the points, like
  ``free_flight_time`` = 0), failure y > 2, i.e. u₁ > 3.5;
* ``integer``: y = ⌊2 u₁⌋ (an integer output, like ``impact_count``), failure y >= 7 (limit
  6), i.e. u₁ >= 3.5;
* ``boolean``: y = 1 where u₁ > Φ⁻¹(1 − 10⁻³), else 0 (like ``stable`` = false), failure
  y > 0, P = 10⁻³ exactly;
* ``series``: two failure regions whose margins differ in scale by 100, u₁ − 3.5 and
  (u₂ − 3.7)/100, given as two failure modes (two columns, as ``mcchain rare`` gives a
  requirement's ``max`` and ``min`` sides); P = 1 − Φ(3.5) Φ(3.7);
* ``series-max``: the same system as one margin, their maximum: the intermediate levels
  follow the larger margins of the second region and never lead to the first (at N = 1000
  per level, a point of level 1 lands in it in about one run in five), which no
  single-margin subset simulation can see.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

BOOLEAN_P = 1e-3
BOOLEAN_Z = float(stats.norm.isf(BOOLEAN_P))
SERIES_P = float(1 - stats.norm.cdf(3.5) * stats.norm.cdf(3.7))


@dataclass(frozen=True)
class RareCase:
    """A response with a known failure probability.

    Attributes:
        name: the case's name.
        ndim: dimensions of u.
        response: margins at standard-normal points (n, ndim) -> (n,), or (n, k) for k
            failure modes.
        exact: P(margin > 0).
    """

    name: str
    ndim: int
    response: Callable[[np.ndarray], np.ndarray]
    exact: float


def _plateau(u: np.ndarray) -> np.ndarray:
    return np.maximum(u[:, 0] - 1.5, 0.0) - 2.0


def _integer(u: np.ndarray) -> np.ndarray:
    return np.floor(2.0 * u[:, 0]) - 6.0


def _boolean(u: np.ndarray) -> np.ndarray:
    return (u[:, 0] > BOOLEAN_Z).astype(np.float64)  # margin: y - 0


def _series(u: np.ndarray) -> np.ndarray:
    return np.stack([u[:, 0] - 3.5, (u[:, 1] - 3.7) / 100.0], axis=1)


def _series_max(u: np.ndarray) -> np.ndarray:
    return np.max(_series(u), axis=1)


CASES = {
    case.name: case
    for case in (
        RareCase("plateau", 2, _plateau, float(stats.norm.sf(3.5))),
        RareCase("integer", 2, _integer, float(stats.norm.sf(3.5))),
        RareCase("boolean", 2, _boolean, BOOLEAN_P),
        RareCase("series", 2, _series, SERIES_P),
        RareCase("series-max", 2, _series_max, SERIES_P),
    )
}
"""The cases by name."""
