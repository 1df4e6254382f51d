"""The decision statistics against closed forms and by simulation of binomials.

Clopper–Pearson ends are beta quantiles and must agree with the binomial tail sums they
invert; coverage is checked by simulation (no mechanism); the order-statistic interval of a
quantile is checked against a distribution with a known quantile (the exponential).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from mcchain.decision.stats import (
    FAIL,
    PASS,
    UNDECIDED,
    clopper_pearson,
    clopper_pearson_arrays,
    quantile_interval,
    quantile_samples_needed,
    samples_to_decide,
    success_run_samples,
    verdict,
)

TAIL_TOL = 1e-9
"""Tail sums at an interval's end equal (1 - C)/2 to the beta quantile's accuracy."""


@pytest.mark.parametrize(("k", "n"), [(1, 10), (3, 300), (57, 64), (250, 1000)])
def test_clopper_pearson__ends_invert_the_binomial_tails(k: int, n: int) -> None:
    lo, hi = clopper_pearson(k, n, 0.95)
    # P(X >= k | p_lower) = 0.025 and P(X <= k | p_upper) = 0.025
    assert stats.binom.sf(k - 1, n, lo) == pytest.approx(0.025, abs=TAIL_TOL)
    assert stats.binom.cdf(k, n, hi) == pytest.approx(0.025, abs=TAIL_TOL)


def test_clopper_pearson__zero_and_all_failures_closed_form() -> None:
    n = 300
    lo, hi = clopper_pearson(0, n, 0.95)
    assert lo == 0.0
    assert hi == pytest.approx(1 - 0.025 ** (1 / n), rel=1e-12)
    lo, hi = clopper_pearson(n, n, 0.95)
    assert hi == 1.0
    assert lo == pytest.approx(0.025 ** (1 / n), rel=1e-12)
    assert clopper_pearson(0, 0, 0.95) == (0.0, 1.0)


def test_clopper_pearson__arrays_equal_scalars() -> None:
    k = np.array([0, 1, 5, 99, 100])
    n = np.array([100, 100, 100, 100, 100])
    lo, hi = clopper_pearson_arrays(k, n, 0.9)
    for i in range(k.size):
        assert (lo[i], hi[i]) == pytest.approx(
            clopper_pearson(int(k[i]), int(n[i]), 0.9), rel=1e-14
        )


@pytest.mark.parametrize("p", [0.001, 0.01, 0.05, 0.3])
def test_clopper_pearson__coverage_by_simulation(p: float) -> None:
    """The exact interval covers the true p in at least C of 20,000 simulated experiments
    (binomial draws; the lower bound of a one-sided 99.9 % check on the observed share)."""
    rng = np.random.default_rng(12345)
    n, trials, confidence = 200, 20_000, 0.95
    k = rng.binomial(n, p, size=trials)
    lo, hi = clopper_pearson_arrays(k, np.full(trials, n), confidence)
    covered = np.mean((lo <= p) & (p <= hi))
    # the exact coverage, summed over the binomial distribution, is >= C
    ks = np.arange(n + 1)
    los, his = clopper_pearson_arrays(ks, np.full(n + 1, n), confidence)
    exact = float(np.sum(stats.binom.pmf(ks, n, p)[(los <= p) & (p <= his)]))
    assert exact >= confidence
    assert covered >= confidence - 3.1 * math.sqrt(confidence * (1 - confidence) / trials)


def test_verdict__three_outcomes() -> None:
    assert verdict(0.0, 0.009, 0.01) == PASS
    assert verdict(0.0, 0.01, 0.01) == PASS
    assert verdict(0.011, 0.03, 0.01) == FAIL
    assert verdict(0.005, 0.02, 0.01) == UNDECIDED


def test_success_run__closed_form_and_the_two_sided_figure() -> None:
    assert success_run_samples(0.01, 0.95) == pytest.approx(math.log(0.05) / math.log(0.99))
    # zero failures: the two-sided interval passes from ln(0.025)/ln(0.99) = 367.04 samples
    assert samples_to_decide(0, 10, 0.01, 0.95) == 368
    assert verdict(*clopper_pearson(0, 368, 0.95), 0.01) == PASS
    assert verdict(*clopper_pearson(0, 367, 0.95), 0.01) == UNDECIDED


@pytest.mark.parametrize(("k", "n"), [(3, 400), (15, 1000), (4, 200)])
def test_samples_to_decide__the_rate_held_decides_there_and_not_before(k: int, n: int) -> None:
    target, confidence = 0.01, 0.95
    needed = samples_to_decide(k, n, target, confidence)
    assert verdict(*clopper_pearson(k, n, confidence), target) == UNDECIDED
    rate = k / n
    at = int(needed)
    assert (
        verdict(*clopper_pearson(math.floor(at * rate + 0.5), at, confidence), target) != UNDECIDED
    )
    before = at - 1
    assert (
        verdict(*clopper_pearson(math.floor(before * rate + 0.5), before, confidence), target)
        == UNDECIDED
    )


def test_samples_to_decide__rate_at_the_target_never_decides() -> None:
    assert math.isnan(samples_to_decide(5, 500, 0.01, 0.95))


def test_quantile_interval__order_statistics_of_a_known_quantile() -> None:
    """Exponential draws: ξ_q = −ln(1 − q); the interval covers it in >= C of many seeds."""
    q, confidence, n = 0.99, 0.95, 1000
    xi = -math.log(1 - q)
    rng = np.random.default_rng(7)
    covered = []
    for _ in range(2000):
        res = quantile_interval(rng.exponential(size=n), q, confidence)
        covered.append(res.lower <= xi <= res.upper)
    assert np.mean(covered) >= confidence - 3.1 * math.sqrt(confidence * (1 - confidence) / 2000)
    x = rng.exponential(size=n)
    res = quantile_interval(x, q, confidence)
    assert res.value == np.sort(x)[math.ceil(n * q) - 1]
    assert res.lower <= res.value <= res.upper


def test_quantile_interval__too_few_samples_nan_and_count() -> None:
    needed = quantile_samples_needed(0.99, 0.95)
    assert needed == math.ceil(math.log(0.025) / math.log(0.99))  # 368
    short = quantile_interval(np.arange(needed - 1, dtype=float), 0.99, 0.95)
    assert math.isnan(short.upper) and not math.isnan(short.lower)
    enough = quantile_interval(np.arange(needed, dtype=float), 0.99, 0.95)
    assert enough.upper == needed - 1  # the largest sample
    assert enough.samples_needed == needed


def test_quantile_interval__infinite_failed_samples_allowed_nan_refused() -> None:
    x = np.r_[np.arange(999.0), np.inf]
    assert quantile_interval(x, 0.5, 0.95).value == 499.0
    with pytest.raises(ValueError, match="NaN"):
        quantile_interval(np.array([1.0, math.nan]), 0.5, 0.95)
