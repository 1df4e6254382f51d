"""The tolerance allocation (:mod:`mcchain.decision.allocation`): its evidence against a
numerical integral of its definition, its claims on parameters without influence (many
seeded synthetic ensembles, no mechanism), its validity where the parameter does matter,
ties, zero and all failures, and the box over several parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from mcchain.decision.allocation import (
    ALL,
    allocate,
    allocate_box,
    log_evidence,
    pass_level,
    prior,
    reaches,
    upper_bound,
)

CONFIDENCE = 0.95
ALPHA = 1 - CONFIDENCE
SEEDS = 300
"""Synthetic ensembles per claim-rate test: the rate's standard error is about 1 %."""


def claimed(rate: float, seeds: int) -> float:
    """The largest claim rate a guarantee of ALPHA allows in ``seeds`` seeded ensembles:
    ALPHA plus three binomial standard errors."""
    return ALPHA + 3 * math.sqrt(ALPHA * (1 - ALPHA) / seeds) if rate else 0.0


@pytest.mark.parametrize(("s", "k", "p"), [(0, 300, 0.01), (3, 500, 0.02), (40, 4096, 0.012)])
def test_log_evidence__the_mixture_of_likelihood_ratios_integrated(
    s: int, k: int, p: float
) -> None:
    """W_k(p) = ∫₀ᵖ π(q) (q/p)^S ((1 − q)/(1 − p))^(k − S) dq / ∫₀ᵖ π(q) dq, π the Beta
    prior of mean p, against scipy's quad."""
    a, b = prior(p)

    def integrand(q: float) -> float:
        return float(stats.beta.pdf(q, a, b) * (q / p) ** s * ((1 - q) / (1 - p)) ** (k - s))

    numerator = integrate.quad(integrand, 0, p, limit=200, epsabs=0, epsrel=1e-11)[0]
    expected = math.log(numerator / stats.beta.cdf(p, a, b))
    assert float(log_evidence(s, k, p)) == pytest.approx(expected, rel=1e-7, abs=1e-9)


def test_upper_bound__the_evidence_reaches_the_level_there_and_beyond() -> None:
    level = pass_level(CONFIDENCE, 3)
    for s, k in [(0, 800), (5, 1000), (100, 4096), (93, 128), (10, 10)]:
        bound = upper_bound(s, k, CONFIDENCE, 3)
        if s == k:
            assert bound == 1.0
            continue
        assert float(log_evidence(s, k, bound)) == pytest.approx(level, abs=1e-6)
        above = np.linspace(bound, min(0.999, 3 * bound), 50)[1:]
        assert np.all(log_evidence(s, k, above) >= level)
        # above S/k and above the one-sided bound of one fixed test (the price of every cut)
        assert max(s / k, stats.beta.ppf(CONFIDENCE, s + 1, k - s)) < bound


@pytest.mark.parametrize("k", [1, 2, 10, 257, 4096])
@pytest.mark.parametrize("p", [1e-4, 0.01, 0.3, 0.5, 0.97])
@pytest.mark.parametrize("level", [pass_level(0.95, 3), pass_level(0.05, 1), 2e-6])
def test_reaches__the_full_evaluation_s_answer_where_the_share_failed_is_at_least_p(
    k: int, p: float, level: float
) -> None:
    """Every failure count 0..k: the same answers as evaluating the evidence everywhere; the
    prefixes it skips (S >= p k) have an evidence below 1 as computed, too."""
    s = np.arange(k + 1, dtype=np.float64)
    kept = np.full_like(s, k)
    evidence = log_evidence(s, kept, p)
    assert np.array_equal(reaches(s, kept, p, level), evidence >= level)
    skipped = s >= p * kept
    assert np.all(evidence[skipped] < 1e-9)


def test_reaches__a_level_near_zero_evaluates_every_prefix() -> None:
    s, k = np.array([0.0, 5.0, 50.0, 100.0]), np.array([100.0, 100.0, 100.0, 100.0])
    for level in (1e-7, 0.0, -4.0, -5.0):
        assert np.array_equal(reaches(s, k, 0.2, level), log_evidence(s, k, 0.2) >= level)
    # S >= p k: log W is -3.57 and -4.54 there (below 0, above -5)
    assert reaches(s, k, 0.2, -5.0).tolist() == [True, True, True, True]


@pytest.mark.parametrize(
    ("share", "ties"), [(0.0, False), (1.0, False), (0.9, True), (0.3, False), (0.012, True)]
)
def test_allocate__the_same_ranges_and_bounds_as_evaluating_every_prefix(
    share: float, ties: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The allocation with :func:`reaches` against the one that evaluates the evidence of
    every prefix at every bisection step: the same range and the same p_upper to the bit,
    on ensembles with no failure, all failures, ties, and shares far above and near the
    target, where the failures depend on the parameter."""
    import mcchain.decision.allocation as allocation

    def everywhere(s: np.ndarray, k: np.ndarray, p: float, level: float) -> np.ndarray:
        return np.asarray(log_evidence(s, k, p) >= level)

    for seed in range(4):
        rng = np.random.default_rng([37, seed])
        x = rng.random(2000)
        if ties:
            x = np.round(x, 2)
        failed = (
            rng.random(2000) < np.clip(share * 2 * x, 0.0, 1.0)
            if 0 < share < 1
            else (np.full(2000, share == 1.0))
        )
        fast = allocate(x, failed, 0.01, CONFIDENCE, (0.0, 1.0))
        with monkeypatch.context() as patch:
            patch.setattr(allocation, "reaches", everywhere)
            full = allocate(x, failed, 0.01, CONFIDENCE, (0.0, 1.0))
        assert fast == full


def test_upper_bound__zero_failures_need_more_than_the_success_run_figure() -> None:
    """The price of holding over every cut: with no failure, 643 samples pass at target
    0.01 over three chains (the success-run figure of one fixed test is 299)."""
    assert upper_bound(0, 642, CONFIDENCE, 3) > 0.01 >= upper_bound(0, 643, CONFIDENCE, 3)


def _claim_rate(p_of_x, target: float, n: int, seeds: int) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """Share of seeded ensembles (x uniform on [0, 1]) where a range is claimed, and where
    the range claimed has an exact failure probability above the target (a wrong claim)."""
    claims = wrong = 0
    for seed in range(seeds):
        rng = np.random.default_rng([20261128, seed])
        x = rng.random(n)
        failed = rng.random(n) < p_of_x(x)
        r = allocate(x, failed, target, CONFIDENCE, (0.0, 1.0))
        if r.passes:
            claims += 1
            grid = np.linspace(r.low, r.high, 2001)
            wrong += float(np.mean(p_of_x(grid))) > target
    return claims / seeds, wrong / seeds


@pytest.mark.parametrize(("target", "n"), [(0.05, 1000), (0.01, 2048)])
def test_allocate__no_influence_at_the_target_claims_at_most_one_minus_confidence(
    target: float, n: int
) -> None:
    """A parameter without influence at P(fail) = 1.05 x target: every range claimed is
    wrong; it happens in at most 1 − C of the ensembles (the rates over 2,000 ensembles:
    benchmarks/results/allocation)."""
    rate, wrong = _claim_rate(lambda x: np.full_like(x, 1.05 * target), target, n, SEEDS)
    assert rate == wrong
    assert rate <= claimed(rate, SEEDS)


def test_allocate__influence_claims_are_right_or_rare() -> None:
    """P(fail | x) = 2.1 t (1 − x): the whole range fails at 1.05 t, ranges of large x pass
    legitimately. Wrong claims (a range whose exact P(fail) is above t) stay within 1 − C;
    right ones are found in most ensembles."""
    target = 0.05
    rate, wrong = _claim_rate(lambda x: 2.1 * target * (1 - x), target, 2000, 200)
    assert wrong <= claimed(wrong, 200)
    assert rate > 0.9


def test_allocate__ties_are_kept_or_cut_together() -> None:
    """A parameter of five values (a choice): every kept set ends between two values."""
    rng = np.random.default_rng(4)
    x = rng.choice([1.0, 2.0, 3.0, 4.0, 5.0], size=5000)
    failed = (x == 5.0) & (rng.random(5000) < 0.5)
    r = allocate(x, failed, 0.01, CONFIDENCE, (1.0, 5.0))
    assert r.passes and r.side == "upper" and r.high == 4.0
    assert r.samples_kept == int(np.sum(x <= 4.0)) and r.failures == 0


def test_allocate__zero_and_all_failures_and_no_samples() -> None:
    x = np.linspace(0, 1, 1000)
    clean = allocate(x, np.zeros(1000, bool), 0.01, CONFIDENCE, (0.0, 1.0))
    assert clean.side == ALL and clean.passes and (clean.low, clean.high) == (0.0, 1.0)
    assert clean.samples_kept == 1000 and math.isnan(clean.bound)
    assert clean.p_upper == pytest.approx(upper_bound(0, 1000, CONFIDENCE, 3))
    dirty = allocate(x, np.ones(1000, bool), 0.01, CONFIDENCE)
    assert not dirty.passes and dirty.p_upper == 1.0
    empty = allocate(np.array([]), np.array([], bool), 0.01, CONFIDENCE, (0.0, 1.0))
    assert not empty.passes and empty.samples_kept == 0


def test_allocate_box__finds_the_corner_and_holds_out_half() -> None:
    """Failures where x0 > 0.9 or x1 < 0.05 (x uniform on the unit cube, x2 without
    influence): the box cuts those two faces, keeps x2 whole, and its bound comes from the
    odd samples alone."""
    rng = np.random.default_rng(9)
    x = rng.random((20_000, 3))
    failed = (x[:, 0] > 0.9) | (x[:, 1] < 0.05)
    box = allocate_box(x, failed, 0.01, CONFIDENCE, np.array([[0.0, 1.0]] * 3))
    assert box.passes and box.selection == box.verification == 10_000
    assert 0.8 < box.high[0] < 0.92 and 0.03 < box.low[1] < 0.15
    assert (box.low[2], box.high[2]) == (0.0, 1.0)
    odd = x[1::2]
    inside = np.all((odd >= box.low) & (odd <= box.high), axis=1)
    assert box.samples_kept == int(inside.sum())
    assert box.failures == int(failed[1::2][inside].sum())


def test_allocate_box__no_influence_claims_at_most_one_minus_confidence() -> None:
    target, seeds = 0.05, 200
    claims = 0
    for seed in range(seeds):
        rng = np.random.default_rng([7, seed])
        x = rng.random((1000, 2))
        failed = rng.random(1000) < 1.05 * target
        claims += allocate_box(x, failed, target, CONFIDENCE, np.array([[0.0, 1.0]] * 2)).passes
    assert claims / seeds <= claimed(claims, seeds)
