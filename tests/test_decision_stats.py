"""The decision statistics against closed forms, scipy's binomial and by simulation.

Clopper–Pearson ends are beta quantiles and must agree with the binomial tail sums they
invert; coverage is summed exactly over the binomial distribution and checked by simulation
(no mechanism); the order-statistic bounds of a quantile are checked against a distribution
with a known quantile (the exponential) and against the verdict they are dual to.

The meaning of ``confidence`` (docs/scenes.md): each end of [lower_C, upper_C] is a
one-sided bound at C; a verdict is wrong with probability at most 1 − C.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from scipy import stats

from mcchain.decision.stats import (
    EMPTY,
    FAIL,
    PASS,
    UNDECIDED,
    clopper_pearson,
    clopper_pearson_arrays,
    family_confidence,
    one_sided_bounds,
    one_sided_bounds_arrays,
    quantile_bounds,
    quantile_bounds_samples_needed,
    quantile_interval,
    quantile_samples_needed,
    samples_to_decide,
    success_run_count,
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


def test_verdict__three_outcomes_and_the_empty_interval() -> None:
    assert verdict(0.0, 0.009, 0.01) == PASS
    assert verdict(0.0, 0.01, 0.01) == PASS  # the target itself is acceptable
    assert verdict(0.011, 0.03, 0.01) == FAIL
    assert verdict(0.01, 0.03, 0.01) == UNDECIDED  # lower bound at the target: not above it
    assert verdict(0.005, 0.02, 0.01) == UNDECIDED
    # an empty running intersection is no verdict, whichever side the target lies on
    assert verdict(0.02, 0.015, 0.01) == EMPTY
    assert verdict(0.02, 0.015, 0.017) == EMPTY
    assert verdict(0.02, 0.015, 0.5) == EMPTY


def test_success_run__closed_form_and_the_two_sided_figure() -> None:
    assert success_run_samples(0.01, 0.95) == pytest.approx(math.log(0.05) / math.log(0.99))
    # zero failures: the two-sided interval passes from ln(0.025)/ln(0.99) = 367.04 samples
    assert samples_to_decide(0, 10, 0.01, 0.95) == 368
    assert verdict(*clopper_pearson(0, 368, 0.95), 0.01) == PASS
    assert verdict(*clopper_pearson(0, 367, 0.95), 0.01) == UNDECIDED


def test_success_run__one_sided_count_is_where_the_bound_passes() -> None:
    """ln(0.05)/ln(0.99) = 298.07: 298 failure-free samples leave upper_C = 0.010002 above
    1 %, 299 pass; the count is the ceiling, checked against scipy's beta quantile."""
    assert success_run_count(0.01, 0.95) == 299 == math.ceil(success_run_samples(0.01, 0.95))
    assert stats.beta.ppf(0.95, 1, 298) > 0.01 >= stats.beta.ppf(0.95, 1, 299)
    assert verdict(*one_sided_bounds(0, 299, 0.95), 0.01) == PASS
    assert verdict(*one_sided_bounds(0, 298, 0.95), 0.01) == UNDECIDED
    one_sided = lambda k, n: one_sided_bounds(k, n, 0.95)  # noqa: E731
    assert samples_to_decide(0, 10, 0.01, 0.95, interval=one_sided) == 299
    assert samples_to_decide(0, 0, 0.01, 0.95, interval=one_sided) == 299
    # the count is the first that passes, also where the logarithm lands near a whole count
    # (1 - (1 - C)^(1/2) = p at n = 2, up to rounding)
    for p, c in ((1 - math.sqrt(0.05), 0.95), (0.3, 0.9), (1e-4, 0.99), (0.5, 0.5)):
        n = success_run_count(p, c)
        assert one_sided_bounds(0, n, c)[1] <= p
        assert n == 1 or one_sided_bounds(0, n - 1, c)[1] > p
    # the same count is where the quantile's upper bound first exists (the duality)
    assert quantile_bounds_samples_needed(0.99, 0.95) == 299


@pytest.mark.parametrize(("k", "n"), [(0, 1), (0, 50), (1, 10), (3, 300), (57, 64), (64, 64)])
def test_one_sided_bounds__each_end_inverts_one_binomial_tail(k: int, n: int) -> None:
    lo, hi = one_sided_bounds(k, n, 0.95)
    # P(X >= k | lower) = 1 - C and P(X <= k | upper) = 1 - C (each end alone)
    if k == 0:
        assert lo == 0.0
    else:
        assert stats.binom.sf(k - 1, n, lo) == pytest.approx(0.05, abs=TAIL_TOL)
    if k == n:
        assert hi == 1.0
    else:
        assert stats.binom.cdf(k, n, hi) == pytest.approx(0.05, abs=TAIL_TOL)
    assert (lo, hi) == pytest.approx(clopper_pearson(k, n, 0.9), rel=1e-12, abs=1e-300)
    arr = one_sided_bounds_arrays(np.array([k]), np.array([n]), 0.95)
    assert (float(arr[0][0]), float(arr[1][0])) == pytest.approx((lo, hi), rel=1e-14)
    assert one_sided_bounds(0, 0, 0.95) == (0.0, 1.0)
    with pytest.raises(ValueError, match="failures"):
        one_sided_bounds(3, 2, 0.95)


@pytest.mark.parametrize("p", [0.001, 0.0099, 0.01, 0.0101, 0.05, 0.5])
def test_one_sided_bounds__each_end_covers_at_c_and_verdicts_err_at_most_1_minus_c(
    p: float,
) -> None:
    """Summed exactly over Bin(n, p): P(upper_C >= p) >= C and P(lower_C <= p) >= C, so a
    wrong PASS (p > target) or a wrong FAIL (p <= target) has probability <= 1 − C, at p
    on either side of the target and at the target itself."""
    n, confidence, target = 400, 0.95, 0.01
    ks = np.arange(n + 1)
    lo, hi = one_sided_bounds_arrays(ks, np.full(n + 1, n), confidence)
    pmf = stats.binom.pmf(ks, n, p)
    assert float(np.sum(pmf[hi >= p])) >= confidence - 1e-12
    assert float(np.sum(pmf[lo <= p])) >= confidence - 1e-12
    wrong = pmf[hi <= target].sum() if p > target else pmf[lo > target].sum()
    assert wrong <= 1 - confidence + 1e-12


def test_family_confidence__bonferroni() -> None:
    assert family_confidence([0.95] * 4) == pytest.approx(0.8)
    assert family_confidence([0.99, 0.95]) == pytest.approx(0.94)
    assert family_confidence([0.95]) == pytest.approx(0.95)
    assert family_confidence([0.6] * 3) == pytest.approx(-0.2)  # nothing claimed


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


def test_samples_to_decide__one_sided_interval_held_rate(k: int = 4, n: int = 300) -> None:
    one_sided = lambda kk, nn: one_sided_bounds(kk, nn, 0.95)  # noqa: E731
    needed = samples_to_decide(k, n, 0.01, 0.95, interval=one_sided)
    at = int(needed)
    assert verdict(*one_sided(math.floor(at * k / n + 0.5), at), 0.01) == FAIL
    assert verdict(*one_sided(math.floor((at - 1) * k / n + 0.5), at - 1), 0.01) == UNDECIDED
    # the one-sided bounds are narrower: fewer samples than the two-sided interval needs
    assert needed < samples_to_decide(k, n, 0.01, 0.95)


def test_quantile_bounds__point_value_in_exact_arithmetic() -> None:
    """n = 100, q = 0.07: 100 q is 7 exactly for the decimal the user wrote, x_(7); the
    binary 0.07 makes ceil(100 q) 8 in floating point (the bug)."""
    x = np.arange(1.0, 101.0)
    assert math.ceil(100 * 0.07) == 8  # what the floating point gave
    assert quantile_bounds(x, 0.07, 0.95).value == 7.0
    assert quantile_bounds(x, 1 - Fraction("0.07"), 0.95).value == 93.0
    assert quantile_interval(x, 0.07, 0.95).value == 7.0
    for q in (0.01, 0.1, 0.29, 0.57, 0.99):
        expected = math.ceil(Fraction(str(q)) * 100)
        assert quantile_bounds(x, q, 0.95).value == float(expected)


@pytest.mark.parametrize("seed", range(6))
def test_quantile_bounds__upper_bound_at_limit_iff_the_verdict_passes(seed: int) -> None:
    """The order-statistic bounds are the duals of the binomial ones: for a ``max`` limit L
    and level 1 − target, upper <= L exactly when upper_C(#{x > L} of n) <= target; for a
    ``min`` limit at level target, lower >= L exactly when the same count below L passes.
    Continuous draws and integer ones (ties at the limit)."""
    rng = np.random.default_rng(seed)
    n, target, confidence = int(rng.integers(300, 2000)), float(rng.choice([0.01, 0.02])), 0.95
    for x in (rng.normal(size=n), rng.poisson(3.0, size=n).astype(float)):
        q_max = quantile_bounds(x, 1 - Fraction(str(target)), confidence)
        q_min = quantile_bounds(x, target, confidence)
        for limit in np.r_[np.quantile(x, [0.9, 0.98, 0.99, 0.995, 1.0]), np.unique(x)[-4:]]:
            k = int(np.sum(x > limit))
            passes = verdict(*one_sided_bounds(k, n, confidence), target) == PASS
            assert (q_max.upper <= limit) == passes, (limit, k)
        for limit in np.r_[np.quantile(x, [0.0, 0.005, 0.01, 0.1]), np.unique(x)[:4]]:
            k = int(np.sum(x < limit))
            passes = verdict(*one_sided_bounds(k, n, confidence), target) == PASS
            assert (q_min.lower >= limit) == passes, (limit, k)


def test_quantile_bounds__each_bound_covers_at_c() -> None:
    """Exponential draws, ξ_q = −ln(1 − q): each one-sided bound holds in >= C of many
    seeds (and the pair, a (2C − 1) interval, in >= 2C − 1)."""
    q, confidence, n, trials = 0.9, 0.95, 400, 4000
    xi = -math.log(1 - q)
    rng = np.random.default_rng(11)
    below, above = [], []
    for _ in range(trials):
        res = quantile_bounds(rng.exponential(size=n), q, confidence)
        below.append(res.lower <= xi)
        above.append(xi <= res.upper)
    slack = 3.1 * math.sqrt(confidence * (1 - confidence) / trials)
    assert np.mean(below) >= confidence - slack
    assert np.mean(above) >= confidence - slack


def test_scipy_stats_free__bounds_cdf_and_ranks_bit_for_bit() -> None:
    """The verdict does not import scipy.stats (0.3-1 s): its beta quantiles, binomial cdf
    and mid-ranks are the same bits as scipy.stats' on every count tried."""
    from scipy import stats

    from mcchain.decision.allocation import mid_ranks
    from mcchain.decision.stats import _beta_bound_arrays, _beta_bounds, binom_cdf

    for n in (1, 2, 7, 299, 1000, 4096):
        k = np.arange(n + 1)
        for q in (0.01, 0.07, 0.5, 0.95, 0.999):
            np.testing.assert_array_equal(binom_cdf(k, n, q), stats.binom.cdf(k, n, q))
        for tail in (0.05, 0.025, 0.005):
            lower, upper = _beta_bound_arrays(k, np.full(k.shape, n), tail)
            ref_lower = np.where(k > 0, stats.beta.ppf(tail, np.maximum(k, 1), n - k + 1), 0.0)
            ref_upper = np.where(k < n, stats.beta.ppf(1 - tail, k + 1, np.maximum(n - k, 1)), 1.0)
            np.testing.assert_array_equal(lower, ref_lower)
            np.testing.assert_array_equal(upper, ref_upper)
            assert _beta_bounds(int(k[n // 2]), n, tail) == (lower[n // 2], upper[n // 2])
    rng = np.random.default_rng(5)
    for x in (rng.integers(0, 9, 500).astype(float), rng.random(300), np.array([2.0])):
        np.testing.assert_array_equal(mid_ranks(x), stats.rankdata(x, method="average"))
