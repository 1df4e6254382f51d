"""Statistics of a pass/fail decision: pure functions of counts and samples (no I/O).

**What ``confidence`` means** (one meaning, in fixed-count and ``until`` runs alike): a
requirement's confidence C makes two one-sided statements. ``lower_C`` is a lower bound of
P(fail) and ``upper_C`` an upper bound, each holding with probability at least C. The
verdict is PASS iff upper_C <= target, FAIL iff lower_C > target, else undecided: each
verdict is wrong with probability at most 1 − C. The pair [lower_C, upper_C] is a two-sided
interval at level 2C − 1 (90 % for C = 95 %).

* :func:`one_sided_bounds`: (lower_C, upper_C) by the exact (Clopper–Pearson) beta
  quantiles, each end one-sided at C (independent draws, ``design = "random"``).
* :func:`clopper_pearson`: the exact two-sided interval at level C (each tail (1 − C)/2);
  ``clopper_pearson(k, n, 2C − 1)`` is ``one_sided_bounds(k, n, C)``.
* :func:`verdict`: ``pass`` when the upper end is at most the target, ``fail`` when the lower
  end is above it, :data:`EMPTY` when the lower end is above the upper one (a running
  intersection of a confidence sequence that came out empty), else ``undecided``.
* :func:`quantile_bounds`: a quantile of the samples with its one-sided order-statistic
  bounds at C (distribution-free, independent draws); :func:`quantile_interval` the two-sided
  interval of the earlier meaning.
* :func:`samples_to_decide`: how many samples the observed failure rate implies to reach a
  verdict by a given interval; :func:`success_run_samples`: the zero-failure figure
  n = ln(1 − C)/ln(1 − p) (not rounded), :func:`success_run_count` the count, rounded up.
* :func:`family_confidence`: the Bonferroni statement over several verdicts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from scipy.special import betaincinv

PASS = "pass"
FAIL = "fail"
UNDECIDED = "undecided"
EMPTY = "empty"
"""The verdict of an interval whose lower end lies above its upper end: the running
intersection of a confidence sequence emptied (the looks contradict each other: a
probability <= 1 − C event, or samples that are not independent draws). No verdict."""
VERDICTS = (PASS, FAIL, UNDECIDED, EMPTY)


def binom_cdf(k: np.ndarray, n: np.ndarray | int, p: float) -> np.ndarray:
    """P(Bin(n, p) <= k) for integers ``k`` >= 0 and counts ``n`` (broadcast with ``k``):
    ``scipy.stats.binom.cdf``, bit for bit (the boost ufunc it evaluates), without importing
    ``scipy.stats`` (slow to import: benchmarks/results/verdict/verdict.md;
    Clopper-Pearson's ``beta.ppf`` is ``scipy.special.betaincinv`` likewise). Falls back to
    ``scipy.stats`` where a scipy lacks that ufunc; tests compare the two."""
    try:
        from scipy.special._ufuncs import _binom_cdf
    except ImportError:
        from scipy import stats

        return np.asarray(stats.binom.cdf(k, n, p))
    return np.asarray(_binom_cdf(np.floor(k), n, p))


def _alpha(confidence: float) -> float:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: must be in (0, 1), got {confidence!r}")
    return 1.0 - float(confidence)


def _counts(failures: int, samples: int) -> tuple[int, int]:
    k, n = int(failures), int(samples)
    if n < 0 or not 0 <= k <= max(n, 0):
        raise ValueError(f"failures: must be in [0, samples], got {k} of {n}")
    return k, n


def _beta_bounds(k: int, n: int, tail: float) -> tuple[float, float]:
    """Beta(tail; k, n − k + 1) (0 when k = 0) and Beta(1 − tail; k + 1, n − k) (1 when
    k = n): the exact binomial bounds with ``tail`` outside each."""
    if n == 0:
        return 0.0, 1.0
    lower = 0.0 if k == 0 else float(betaincinv(k, n - k + 1, tail))
    upper = 1.0 if k == n else float(betaincinv(k + 1, n - k, 1 - tail))
    return lower, upper


def one_sided_bounds(failures: int, samples: int, confidence: float) -> tuple[float, float]:
    """(lower_C, upper_C): the exact one-sided bounds of a failure probability at C each.

    Args:
        failures: samples that failed, 0 <= failures <= samples.
        samples: samples drawn; 0 gives the uninformative (0, 1).
        confidence: C in (0, 1): P(p >= lower_C) >= C and P(p <= upper_C) >= C for every
            true p (independent draws).

    Returns:
        lower_C = Beta(1 − C; k, n − k + 1) quantile (0 when k = 0) and upper_C =
        Beta(C; k + 1, n − k) quantile (1 when k = n). With k = 0, upper_C = 1 − (1 − C)^(1/n).
    """
    return _beta_bounds(*_counts(failures, samples), _alpha(confidence))


def one_sided_bounds_arrays(
    failures: np.ndarray, samples: np.ndarray, confidence: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`one_sided_bounds` element by element over arrays of counts (samples >= 1)."""
    return _beta_bound_arrays(failures, samples, _alpha(confidence))


def clopper_pearson(failures: int, samples: int, confidence: float) -> tuple[float, float]:
    """The exact two-sided interval (p_lower, p_upper) of a failure probability at level C.

    Each tail holds (1 − C)/2: ``clopper_pearson(k, n, 2C − 1)`` equals
    :func:`one_sided_bounds` ``(k, n, C)``, the pair a verdict at confidence C reads.

    Args:
        failures: samples that failed, 0 <= failures <= samples.
        samples: samples drawn; 0 gives the uninformative (0, 1).
        confidence: two-sided confidence C in (0, 1); each tail holds (1 − C)/2.
    """
    return _beta_bounds(*_counts(failures, samples), _alpha(confidence) / 2)


def _beta_bound_arrays(
    failures: np.ndarray, samples: np.ndarray, tail: float
) -> tuple[np.ndarray, np.ndarray]:
    k = np.asarray(failures, dtype=np.float64)
    n = np.asarray(samples, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        lower = np.where(k > 0, betaincinv(np.maximum(k, 1), n - k + 1, tail), 0.0)
        upper = np.where(k < n, betaincinv(k + 1, np.maximum(n - k, 1), 1 - tail), 1.0)
    return lower, upper


def clopper_pearson_arrays(
    failures: np.ndarray, samples: np.ndarray, confidence: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`clopper_pearson` element by element over arrays of counts (samples >= 1)."""
    return _beta_bound_arrays(failures, samples, _alpha(confidence) / 2)


def verdict(p_lower: float, p_upper: float, target: float) -> str:
    """``pass`` if p_upper <= target, ``fail`` if p_lower > target, :data:`EMPTY` if
    p_lower > p_upper (no interval: no verdict), else ``undecided``."""
    if p_lower > p_upper:
        return EMPTY
    if p_upper <= target:
        return PASS
    if p_lower > target:
        return FAIL
    return UNDECIDED


def family_confidence(confidences: Sequence[float]) -> float:
    """The probability, at least, that every one of several verdicts holds together:
    1 − Σ(1 − C_i) (Bonferroni; no assumption on how the requirements depend on each other;
    may be <= 0, then nothing is claimed for the family)."""
    return 1.0 - float(sum(1.0 - float(c) for c in confidences))


def success_run_samples(target: float, confidence: float) -> float:
    """The success-run figure n = ln(1 − C)/ln(1 − p) (not rounded): failure-free samples
    that show P(fail) <= p at confidence C, the count from which
    :func:`one_sided_bounds` ``(0, n, C)`` passes (:func:`success_run_count`)."""
    alpha = _alpha(confidence)
    if not 0.0 < target < 1.0:
        raise ValueError(f"target: must be in (0, 1), got {target!r}")
    return math.log(alpha) / math.log1p(-target)


def success_run_count(target: float, confidence: float) -> int:
    """The smallest n with upper_C(0 of n) = 1 − (1 − C)^(1/n) <= target: ⌈ln(1 − C)/ln(1 −
    p)⌉, checked against the bound itself (298 for p = 1 %, C = 95 %)."""
    n = max(math.ceil(success_run_samples(target, confidence)), 1)
    while n > 1 and one_sided_bounds(0, n - 1, confidence)[1] <= target:
        n -= 1  # the logarithms rounded the figure up past a whole count
    while one_sided_bounds(0, n, confidence)[1] > target:
        n += 1
    return n


Interval = Callable[[int, int], tuple[float, float]]
"""An interval of a failure probability from (failures, samples): (lower, upper)."""


def samples_to_decide(
    failures: int,
    samples: int,
    target: float,
    confidence: float,
    limit: int = 1 << 40,
    *,
    interval: Interval | None = None,
) -> float:
    """The smallest sample count N at which the observed failure rate k/n, held, decides.

    Args:
        failures, samples: the counts observed.
        target, confidence: the requirement's.
        limit: the largest N searched (NaN beyond).
        interval: ``(k, n) -> (lower, upper)``, the interval that decides; default the
            two-sided Clopper–Pearson at ``confidence`` (:func:`clopper_pearson`). A verdict
            at confidence C passes ``lambda k, n: one_sided_bounds(k, n, C)``; an ``until``
            run its confidence sequence.

    Returns:
        With k = 0: the smallest N at which N failure-free samples pass. Else the smallest N
        with ⌊N k/n + ½⌋ failures whose interval lies wholly below the target (rate below
        it) or above it (rate above). NaN when the rate equals the target (no N decides) or
        N would exceed ``limit``. Already decided counts return ``samples``.
    """
    k, n = _counts(failures, samples)
    if interval is None:

        def interval(kk: int, nn: int) -> tuple[float, float]:
            return clopper_pearson(kk, nn, confidence)

    if n > 0 and verdict(*interval(k, n), target) not in (UNDECIDED, EMPTY):
        return float(n)
    rate = k / n if n else 0.0
    if rate == target:
        return math.nan

    def decided(count: int) -> bool:
        if count < 1:
            return False
        lo, hi = interval(min(math.floor(count * rate + 0.5), count), count)
        return hi <= target if rate < target else lo > target

    hi = max(n, 1)
    while not decided(hi):
        hi *= 2
        if hi > limit:
            return math.nan
    lo = hi // 2 if hi > max(n, 1) else 0
    # bisection: the rounding of N·rate makes `decided` nearly, not strictly, monotone; the
    # answer is a planning figure, exact to the sample where it is monotone
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if decided(mid):
            hi = mid
        else:
            lo = mid
    return float(hi)


@dataclass(frozen=True)
class QuantileInterval:
    """A sample quantile and its distribution-free bounds.

    Attributes:
        probability: the quantile's level q (0 < q < 1).
        value: the inverse empirical CDF at q, x_(⌈n q⌉) (a sample value; ⌈n q⌉ in exact
            arithmetic on the decimal q); NaN without samples.
        lower, upper: order statistics x_(r), x_(s) with P(x_(r) <= ξ_q) >= 1 − tail and
            P(ξ_q <= x_(s)) >= 1 − tail for any continuous distribution; NaN where no order
            statistic is extreme enough. :func:`quantile_bounds`: tail = 1 − C (each end
            one-sided at C); :func:`quantile_interval`: tail = (1 − C)/2.
        samples_needed: the count from which both ends exist, max(⌈ln(tail)/ln q⌉,
            ⌈ln(tail)/ln(1 − q)⌉).
    """

    probability: float
    value: float
    lower: float
    upper: float
    samples_needed: int


def _exact(q: float | Fraction) -> Fraction:
    """q as the decimal it was written as: 0.07 is 7/100, so 100 × 0.07 is exactly 7 (the
    binary 0.07 is 0.0700000000000000067, whose ceiling of 100 q is 8)."""
    return q if isinstance(q, Fraction) else Fraction(repr(float(q)))


def quantile_samples_needed(probability: float, confidence: float) -> int:
    """Samples from which the two-sided order-statistic interval of :func:`quantile_interval`
    has both ends: the upper end needs q^n <= α/2, the lower one (1 − q)^n <= α/2."""
    return _samples_needed(float(probability), _alpha(confidence) / 2)


def quantile_bounds_samples_needed(probability: float, confidence: float) -> int:
    """Samples from which both one-sided bounds of :func:`quantile_bounds` exist: q^n <= 1 − C
    and (1 − q)^n <= 1 − C (298 for q = 0.99 at C = 0.95)."""
    return _samples_needed(float(probability), _alpha(confidence))


def _samples_needed(q: float, tail: float) -> int:
    return int(
        max(math.ceil(math.log(tail) / math.log(q)), math.ceil(math.log(tail) / math.log1p(-q)))
    )


def _order_bounds(
    values: np.ndarray, probability: float | Fraction, tail: float, needed: int
) -> QuantileInterval:
    x = np.sort(np.asarray(values, dtype=np.float64).ravel())
    if np.isnan(x).any():
        raise ValueError("values: NaN is not allowed (place failed samples at ±inf)")
    exact = _exact(probability)
    q = float(exact)
    if not 0 < exact < 1:
        raise ValueError(f"probability: must be in (0, 1), got {q!r}")
    n = x.size
    if n == 0:
        return QuantileInterval(q, math.nan, math.nan, math.nan, needed)
    value = float(x[max(math.ceil(n * exact) - 1, 0)])
    cdf = binom_cdf(np.arange(n + 1), n, q)  # cdf[j] = P(Bin(n, q) <= j)
    # lower end x_(r): P(x_(r) > ξ_q) = P(Bin <= r - 1) <= tail; largest such r >= 1
    ok_lower = np.flatnonzero(cdf[:n] <= tail)  # index j = r - 1
    lower = float(x[ok_lower[-1]]) if ok_lower.size else math.nan
    # upper end x_(s): P(x_(s) < ξ_q) = P(Bin >= s) = 1 - cdf[s - 1] <= tail; smallest s <= n
    ok_upper = np.flatnonzero(cdf[:n] >= 1 - tail)  # index j = s - 1
    upper = float(x[ok_upper[0]]) if ok_upper.size else math.nan
    return QuantileInterval(q, value, lower, upper, needed)


def quantile_bounds(
    values: np.ndarray, probability: float | Fraction, confidence: float
) -> QuantileInterval:
    """The ``probability`` quantile of ``values`` with its one-sided bounds at C.

    ``values`` may hold ±inf (a failed sample counted on the failing side, an event that
    never happened at +inf); NaN is not allowed. ``lower`` is x_(r), r the largest with
    P(Bin(n, q) <= r − 1) <= 1 − C; ``upper`` is x_(s), s the smallest with
    P(Bin(n, q) <= s − 1) >= C (1-based). For a ``max`` requirement at level q = 1 − target,
    ``upper <= max`` exactly when the verdict passes (the bounds are the order-statistic
    duals of :func:`one_sided_bounds`).

    Args:
        probability: q in (0, 1); a float is read as the decimal it prints as, a
            :class:`fractions.Fraction` as is.
    """
    q = float(_exact(probability))
    tail = _alpha(confidence)
    return _order_bounds(values, probability, tail, _samples_needed(q, tail))


def quantile_interval(
    values: np.ndarray, probability: float, confidence: float
) -> QuantileInterval:
    """The ``probability`` quantile of ``values`` with its two-sided order-statistic interval
    at level C (each end with (1 − C)/2 outside; see :func:`quantile_bounds`)."""
    q = float(_exact(probability))
    tail = _alpha(confidence) / 2
    return _order_bounds(values, probability, tail, _samples_needed(q, tail))
