"""Statistics of a pass/fail decision: pure functions of counts and samples (no I/O).

* :func:`clopper_pearson`: the exact (Clopper–Pearson) two-sided interval of a binomial
  proportion, from the beta quantiles: its coverage is at least ``confidence`` for every
  true probability when the samples are independent draws (``design = "random"``).
* :func:`verdict`: ``pass`` when the interval's upper end is at most the target, ``fail``
  when its lower end is above it, else ``undecided``. With the two-sided interval each
  verdict is wrong with probability at most (1 − confidence)/2.
* :func:`quantile_interval`: a quantile of the samples and its distribution-free
  order-statistic interval (valid for any continuous distribution, independent draws),
  with the sample count an interval needs when the samples are too few.
* :func:`samples_to_decide`: how many samples the observed failure rate implies to reach a
  verdict; :func:`success_run_samples`: the classical zero-failure figure
  n = ln(1 − C)/ln(1 − p).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PASS = "pass"
FAIL = "fail"
UNDECIDED = "undecided"
VERDICTS = (PASS, FAIL, UNDECIDED)


def _alpha(confidence: float) -> float:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: must be in (0, 1), got {confidence!r}")
    return 1.0 - float(confidence)


def clopper_pearson(failures: int, samples: int, confidence: float) -> tuple[float, float]:
    """The exact two-sided interval (p_lower, p_upper) of a failure probability.

    Args:
        failures: samples that failed, 0 <= failures <= samples.
        samples: samples drawn; 0 gives the uninformative (0, 1).
        confidence: two-sided confidence C in (0, 1); each tail holds (1 − C)/2.

    Returns:
        p_lower = Beta(α/2; k, n − k + 1) quantile (0 when k = 0) and p_upper =
        Beta(1 − α/2; k + 1, n − k) quantile (1 when k = n), α = 1 − C.
    """
    alpha = _alpha(confidence)
    k, n = int(failures), int(samples)
    if n < 0 or not 0 <= k <= max(n, 0):
        raise ValueError(f"failures: must be in [0, samples], got {k} of {n}")
    if n == 0:
        return 0.0, 1.0
    from scipy import stats as _stats  # lazily: 1-3 s to import; a run without
    # requirements never needs it

    lower = 0.0 if k == 0 else float(_stats.beta.ppf(alpha / 2, k, n - k + 1))
    upper = 1.0 if k == n else float(_stats.beta.ppf(1 - alpha / 2, k + 1, n - k))
    return lower, upper


def clopper_pearson_arrays(
    failures: np.ndarray, samples: np.ndarray, confidence: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`clopper_pearson` element by element over arrays of counts (samples >= 1)."""
    alpha = _alpha(confidence)
    k = np.asarray(failures, dtype=np.float64)
    n = np.asarray(samples, dtype=np.float64)
    from scipy import stats as _stats  # lazily (see clopper_pearson)

    with np.errstate(invalid="ignore"):
        lower = np.where(k > 0, _stats.beta.ppf(alpha / 2, np.maximum(k, 1), n - k + 1), 0.0)
        upper = np.where(k < n, _stats.beta.ppf(1 - alpha / 2, k + 1, np.maximum(n - k, 1)), 1.0)
    return lower, upper


def verdict(p_lower: float, p_upper: float, target: float) -> str:
    """``pass`` if p_upper <= target, ``fail`` if p_lower > target, else ``undecided``."""
    if p_upper <= target:
        return PASS
    if p_lower > target:
        return FAIL
    return UNDECIDED


def success_run_samples(target: float, confidence: float) -> float:
    """The success-run figure n = ln(1 − C)/ln(1 − p) (not rounded): failure-free samples
    that show P(fail) <= p with one-sided confidence C. The two-sided interval of
    :func:`clopper_pearson` needs ``success_run_samples(p, (1 + C)/2)`` of them to pass."""
    alpha = _alpha(confidence)
    if not 0.0 < target < 1.0:
        raise ValueError(f"target: must be in (0, 1), got {target!r}")
    return math.log(alpha) / math.log1p(-target)


def samples_to_decide(
    failures: int, samples: int, target: float, confidence: float, limit: int = 1 << 40
) -> float:
    """The smallest sample count N at which the observed failure rate k/n, held, decides.

    With k = 0: the N at which a failure-free run passes, ⌈ln((1 − C)/2)/ln(1 − p)⌉ (the
    two-sided interval's success-run figure). Else the smallest N with ⌊N k/n + ½⌋
    failures whose interval lies wholly below the target (rate below it) or above it (rate
    above). NaN when the rate equals the target (no N decides) or N would exceed ``limit``.
    Already decided counts return ``samples``.
    """
    k, n = int(failures), int(samples)
    if n > 0 and verdict(*clopper_pearson(k, n, confidence), target) != UNDECIDED:
        return float(n)
    if k == 0:
        return float(math.ceil(success_run_samples(target, (1 + confidence) / 2)))
    rate = k / n
    if rate == target:
        return math.nan

    def decided(count: int) -> bool:
        lo, hi = clopper_pearson(min(math.floor(count * rate + 0.5), count), count, confidence)
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
    """A sample quantile and its distribution-free interval.

    Attributes:
        probability: the quantile's level q (0 < q < 1).
        value: the inverse empirical CDF at q, x_(⌈n q⌉) (a sample value); NaN without samples.
        lower, upper: order statistics x_(r), x_(s) with P(x_(r) <= ξ_q <= x_(s)) >= C for
            any continuous distribution; NaN where no order statistic is extreme enough.
        samples_needed: the count from which both ends exist, max(⌈ln(α/2)/ln q⌉,
            ⌈ln(α/2)/ln(1 − q)⌉), α = 1 − C.
    """

    probability: float
    value: float
    lower: float
    upper: float
    samples_needed: int


def quantile_samples_needed(probability: float, confidence: float) -> int:
    """Samples from which the order-statistic interval of the ``probability`` quantile has
    both ends: the upper end needs q^n <= α/2, the lower one (1 − q)^n <= α/2."""
    tail = _alpha(confidence) / 2
    q = float(probability)
    return int(
        max(math.ceil(math.log(tail) / math.log(q)), math.ceil(math.log(tail) / math.log1p(-q)))
    )


def quantile_interval(
    values: np.ndarray, probability: float, confidence: float
) -> QuantileInterval:
    """The ``probability`` quantile of ``values`` with its order-statistic interval.

    ``values`` may hold ±inf (a failed sample counted on the failing side); NaN is not
    allowed (the caller decides where a failed sample goes). The interval's ends are the
    order statistics r (largest with P(Bin(n, q) <= r − 1) <= α/2) and s (smallest with
    P(Bin(n, q) <= s − 1) >= 1 − α/2), 1-based.
    """
    x = np.sort(np.asarray(values, dtype=np.float64).ravel())
    if np.isnan(x).any():
        raise ValueError("values: NaN is not allowed (place failed samples at ±inf)")
    q = float(probability)
    if not 0.0 < q < 1.0:
        raise ValueError(f"probability: must be in (0, 1), got {q!r}")
    tail = _alpha(confidence) / 2
    needed = quantile_samples_needed(q, confidence)
    n = x.size
    if n == 0:
        return QuantileInterval(q, math.nan, math.nan, math.nan, needed)
    value = float(x[max(math.ceil(n * q) - 1, 0)])
    from scipy import stats as _stats  # lazily (see clopper_pearson)

    cdf = _stats.binom.cdf(np.arange(n + 1), n, q)  # cdf[j] = P(Bin(n, q) <= j)
    # lower end x_(r): P(x_(r) > ξ_q) = P(Bin <= r - 1) <= tail; largest such r >= 1
    ok_lower = np.flatnonzero(cdf[:n] <= tail)  # index j = r - 1
    lower = float(x[ok_lower[-1]]) if ok_lower.size else math.nan
    # upper end x_(s): P(x_(s) < ξ_q) = P(Bin >= s) = 1 - cdf[s - 1] <= tail; smallest s <= n
    ok_upper = np.flatnonzero(cdf[:n] >= 1 - tail)  # index j = s - 1
    upper = float(x[ok_upper[0]]) if ok_upper.size else math.nan
    return QuantileInterval(q, value, lower, upper, needed)
