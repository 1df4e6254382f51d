"""The sequential interval of ``[sample] until = "decided"``: a confidence sequence.

Simulated Bernoulli streams (no mechanism): a run that looks every ``batch`` samples and
stops at its first verdict must decide wrongly at most 1 − confidence of the time at
p = target ± 20 %, where the fixed-sample Clopper–Pearson interval used the same way does
not. Seeded, deterministic.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from mcchain.decision.sequential import (
    confidence_sequence,
    log_mixture_martingale,
    look_counts,
    mixture_prior,
    running_interval,
    sequential_bounds,
)

TARGET = 0.01
CONFIDENCE = 0.95
BATCH = 512
LOOKS = 128  # max_count = 65,536
STREAMS = 1000
SEED = 20261126


def first_verdicts(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per stream (rows): whether its first verdict was pass, and whether it was fail."""
    passed, failed = upper <= TARGET, lower > TARGET
    decided = passed | failed
    first = decided.argmax(axis=1)
    rows = np.arange(lower.shape[0])
    ever = decided.any(axis=1)
    return ever & passed[rows, first], ever & failed[rows, first]


def streams(p: float) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative failures and samples at each look of ``STREAMS`` Bernoulli(p) streams."""
    rng = np.random.default_rng([SEED, round(p * 1e6)])
    failures = rng.binomial(BATCH, p, size=(STREAMS, LOOKS)).cumsum(axis=1)
    samples = np.broadcast_to(BATCH * np.arange(1, LOOKS + 1), failures.shape)
    return failures, samples


@pytest.mark.parametrize("factor", [0.8, 1.2])
def test_sequential__wrong_decisions_stay_below_one_minus_confidence(factor: float) -> None:
    p = factor * TARGET
    failures, samples = streams(p)
    lower, upper = running_interval(failures, samples, CONFIDENCE, TARGET)
    passed, failed = first_verdicts(lower, upper)
    wrong = (passed if p > TARGET else failed).mean()
    right = (failed if p > TARGET else passed).mean()
    assert wrong <= 1 - CONFIDENCE
    assert right > 0.9  # and it does decide, mostly rightly, within max_count


def test_sequential__holds_the_true_p_at_every_look_where_fixed_intervals_do_not() -> None:
    """At p = target (the hardest case) the running interval keeps p at every look in at
    least ``confidence`` of the streams; the Clopper–Pearson interval, recomputed at each
    look, loses it far more often than 1 − confidence."""
    failures, samples = streams(TARGET)
    lower, upper = running_interval(failures, samples, CONFIDENCE, TARGET)
    lost = ((lower > TARGET) | (upper < TARGET)).any(axis=1).mean()
    assert lost <= 1 - CONFIDENCE
    alpha = 1 - CONFIDENCE
    cp_lower = np.where(
        failures > 0, stats.beta.ppf(alpha / 2, np.maximum(failures, 1), samples - failures + 1), 0
    )
    cp_upper = stats.beta.ppf(1 - alpha / 2, failures + 1, samples - failures)
    naive_lost = ((cp_lower > TARGET) | (cp_upper < TARGET)).any(axis=1).mean()
    assert naive_lost > 2 * (1 - CONFIDENCE)


def test_confidence_sequence__bounds_are_where_the_martingale_reaches_one_over_alpha() -> None:
    k = np.array([0, 1, 5, 40, 512, 3])
    n = np.array([512, 512, 1024, 4096, 512, 3])
    lower, upper = confidence_sequence(k, n, CONFIDENCE, TARGET)
    prior = mixture_prior(TARGET)
    level = np.log(1 / (1 - CONFIDENCE))
    assert np.all(lower <= k / n) and np.all(k / n <= upper)
    assert lower[0] == 0.0 and upper[4] == 1.0 and upper[5] == 1.0
    inner = (k > 0) & (k < n)
    for bound in (lower[inner & (k > 0)], upper[k < n]):
        assert bound.size
    np.testing.assert_allclose(
        log_mixture_martingale(k[k > 0], n[k > 0], lower[k > 0], prior), level, rtol=1e-9
    )
    np.testing.assert_allclose(
        log_mixture_martingale(k[k < n], n[k < n], upper[k < n], prior), level, rtol=1e-9
    )
    # Wider than the fixed-sample interval: the price of looking at will.
    cp_upper = stats.beta.ppf(1 - (1 - CONFIDENCE) / 2, k[1:4] + 1, n[1:4] - k[1:4])
    assert np.all(upper[1:4] > cp_upper)


def test_sequential_bounds__the_running_intersection_over_the_looks() -> None:
    assert list(look_counts(1100, 512)) == [512, 1024, 1100]
    assert list(look_counts(1024, 512)) == [512, 1024]
    # the counts an extended run was judged at before it grew join the looks, once each
    assert list(look_counts(1300, 512, [200, 512, 1100, 1300])) == [200, 512, 1024, 1100, 1300]
    rng = np.random.default_rng(3)
    failed = rng.random(1500) < 0.02
    lower, upper = sequential_bounds(failed, 512, CONFIDENCE, TARGET)
    looks = np.array([512, 1024, 1500])
    k = np.array([failed[:m].sum() for m in looks])
    lo, hi = confidence_sequence(k, looks, CONFIDENCE, TARGET)
    assert (lower, upper) == (lo.max(), hi.min())
