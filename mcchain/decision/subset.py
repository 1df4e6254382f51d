"""Rare failure probabilities by subset simulation (Au & Beck 2001), on mcchain's batches.

A target of 1e-4 needs ~3e4 failure-free samples just to be shown, and far more to be
estimated. Subset simulation writes P(F) as a product of conditional probabilities of
nested events F_1 ⊃ F_2 ⊃ ... ⊃ F_m = F, each about ``p0`` = 0.1, and estimates each from
samples that Markov chains spread over the previous event.

Method (:func:`subset_simulation`), in the standard-normal space of the sampled parameters
(parameter j = its distribution's inverse CDF of Φ(u_j), :func:`parameters_of`):

1. Level 0: N independent standard-normal points, their responses r (the output's margin
   beyond the limit: failure is r > 0; a failed instance, NaN, is +inf, i.e. a failure, and
   is counted in ``undefined``).
2. While fewer than p0 N points fail: the next event is {r >= b}, b the (p0 N)-th largest
   response, or {r > b} where points tie at b (an integer, boolean or saturated output):
   both shares are counted and the one nearer p0 is taken, so a level's probability P_j is
   the share of its points in the next event, never assumed to be p0. Every point in the
   event seeds a Markov chain; the N states of the next level are shared out ⌊N/m⌋ per
   chain, the remainder one each to seeds drawn uniformly. A step proposes v = ρ u + σ ξ,
   ξ standard normal, ρ = √(1 − σ²) per coordinate (the conditional sampling of
   Papaioannou et al., Prob. Eng. Mech. 2015, which leaves the standard normal invariant),
   and keeps it if its response is in the event, else the chain stays. σ starts at the
   seeds' spread per coordinate times a scale adapted after every step towards 44 % of the
   candidates kept (carried from level to level). Each step moves all chains at once: one
   batch of the kernels.
3. Where no event lies between the level's points and failure (all share one response, or
   the next event is the failure event itself: a boolean output), thresholds cannot rise:
   the level grows, N more points at a time (independent draws at level 0, the chains
   continued above), until p0 N of its points fail or ``max_levels`` N responses are spent,
   with a warning. A boolean output is then plain Monte Carlo, as it must be.
4. P(F) = Π P_j · (failures among the last level's points)/(its points). With no failure,
   0 and an approximate upper bound (``p_upper``).

Its coefficient of variation: Au & Beck's (2001, eqs. 27–29), δ_j² = (1 − P_j)/(N P_j)
(1 + γ_j) per level, γ_j from the correlation of the indicator along the chains (chains of
unequal length weighted by their pairs), δ = √(Σ δ_j²), neglects the correlation between
levels; the lineage c.o.v. (:func:`lineage_cov`) sees it where the last level's failures
descend from few level-0 points. ``cov`` is the larger of the two; Σ δ_j (levels fully
correlated) is ``cov_upper``. Measured over 100 seeds (N = 1000,
``benchmarks/bench_subset_cases.py``): a plateau output, an integer output, a boolean at
P = 1e-3 and a series system of two regions lie within 3 stated c.o.v. of the exact value
in 94, 99, 100 and 98 of 100 seeds (textbook subset simulation, which assumed p0 per level:
1, 2, 0 and 30 of 100, at 0.20, 0.14, 10⁻¹⁸ and 0.92 times the exact value; OpenTURNS'
``SubsetSampling``: 40, 34, 60 and 36 of 100, at 0.59, 0.37, 0.84 and 0.92).

Several failure modes (a requirement with ``min`` and ``max``; a response of k columns):
one subset simulation per mode, each following its own margin, combined as Σ P(F_j) q_j
(:func:`combine_modes`). Given as the single maximum of margins of very different scales,
a second region is hidden from the intermediate levels (they follow the larger margins of
the other): no single-margin subset simulation sees it (ours and OpenTURNS' lie within 3
c.o.v. in 38 and 36 of 100 seeds on such a case, ``series-max``).

OpenTURNS' ``SubsetSampling`` (measured side by side, the ``bench`` extra) is not the
engine: it assumes p0 per level (biased on ties as the table shows), has no failure modes,
and draws from a process-wide generator, so a run would not be the pure function of
(scene, seed) that every mcchain result is.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

LEVEL_PROBABILITY = 0.1
"""p0: the conditional probability of each intermediate level (Au & Beck's choice)."""

MAX_LEVELS = 20
"""Levels at most (P down to p0^19 = 1e-19); the last level estimates whatever it finds."""

TARGET_ACCEPTANCE = 0.44
"""The share of chain candidates the proposal's scale is adapted towards."""

METHOD = (
    "subset simulation (Au & Beck 2001), adaptive conditional sampling, p0 = 0.1, levels at "
    "their counted share"
)
"""How the CSV names the method."""

Response = Callable[[np.ndarray], np.ndarray]
"""``response(u) -> r``: u (n, d) standard-normal points, r (n,) margins (failure: r > 0)."""


@dataclass
class SubsetResult:
    """What :func:`subset_simulation` found.

    Attributes:
        p_fail: the estimate of P(r > 0) (0 when the last level found no failure).
        cov: its estimated coefficient of variation δ, the larger of ``cov_levels`` and
            ``cov_lineage`` (see the module docstring).
        cov_upper: Σ δ_j, the c.o.v. if the levels' estimates were fully correlated (Au &
            Beck 2001, §5), at least ``cov``.
        cov_levels: Au & Beck's δ = √(Σ δ_j²) (levels taken as uncorrelated).
        cov_lineage: the δ from the failures' level-0 ancestors (:func:`lineage_cov`).
        p_upper: with ``p_fail`` = 0 (no failure at the last level, at the level cap or
            where the thresholds stopped rising), an approximate one-sided ``confidence``
            upper bound: the product of the levels reached times 1 − (1 − C)^(1/m), m the
            last level's chains; NaN otherwise.
        samples_spent: responses evaluated (kernel solves).
        undefined: responses that were NaN (failed instances), counted as failures.
        levels: levels m (1: plain Monte Carlo found p0 N failures at once).
        per_level: N.
        thresholds: the intermediate thresholds b_1 .. b_(m−1) (margins; level j keeps the
            points with r >= b_j), then 0 (the failure event r > 0).
        level_probabilities: P_1 .. P_m, each the share of the level's points in the next
            event, counted (p0 only when no point ties at the threshold).
        level_covs: δ_1 .. δ_m.
        acceptance: per level after the first, the share of chain steps that moved.
        warnings: what the user must know (ties, a stall, NaN responses, the level cap).
        failure_points: the last level's failing points (standard-normal space).
        modes: with several failure modes, each mode's own result (the fields above then
            combine them: :func:`combine_modes`); [] for one.
    """

    p_fail: float
    cov: float
    cov_upper: float
    samples_spent: int
    levels: int
    per_level: int
    p_upper: float = math.nan
    undefined: int = 0
    cov_levels: float = math.inf
    cov_lineage: float = math.inf
    failure_points: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    modes: list[SubsetResult] = field(default_factory=list)
    thresholds: list[float] = field(default_factory=list)
    level_probabilities: list[float] = field(default_factory=list)
    level_covs: list[float] = field(default_factory=list)
    acceptance: list[float] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def _gamma(indicator: np.ndarray, p: float, chains: list[np.ndarray] | None) -> float:
    """γ of Au & Beck (eq. 29) for chains of unequal lengths: the indicator's correlation
    along the chains, lag k weighted by the share of states with a partner k steps on,
    Σ_c (L_c − k)₊ / N (which is 1 − k/ns for equal chains). 0 for independent points."""
    if chains is None or p <= 0.0 or p >= 1.0:
        return 0.0
    n = indicator.size
    r0 = p * (1.0 - p)
    lengths = np.array([len(c) for c in chains])
    longest = int(lengths.max())
    # The chains' indicators side by side, one row each, False past a chain's end: a pair
    # (i, i + k) counts only where both are in the chain. Counts are integers: the same
    # sums, hence the same γ, as chain by chain.
    along = np.zeros((lengths.size, longest), dtype=bool)
    along[np.arange(longest) < lengths[:, None]] = indicator[np.concatenate(chains)]
    gamma = 0.0
    for k in range(1, longest):
        count = int(np.maximum(lengths - k, 0).sum())
        joint = int(np.count_nonzero(along[:, :-k] & along[:, k:])) / count
        gamma += 2.0 * (count / n) * (joint - p * p) / r0
    return max(gamma, 0.0)


def _delta2(p: float, n: int, gamma: float) -> float:
    return math.inf if p <= 0.0 else (1.0 - p) / (n * p) * (1.0 + gamma)


def next_event(r: np.ndarray, nc: int, p0: float) -> tuple[float, int] | None:
    """The next intermediate event {r >= threshold} and how many points lie in it.

    The (p0 N)-th largest response b is the textbook threshold; where points tie at b the
    event {r >= b} holds more than p0 N of them and {r > b} fewer. Both are candidates
    (their shares counted, never assumed), the one whose share is nearer p0 (in log) wins;
    an event that holds every point (no progress) or none is not a candidate. None when
    neither is (every point has the same response: the thresholds cannot rise)."""
    n = r.size
    b = float(-np.partition(-r, nc - 1)[nc - 1])  # the nc-th largest
    candidates = []
    for threshold in (b, float(np.nextafter(b, np.inf))):
        count = int(np.sum(r >= threshold))
        if 0 < count < n:
            candidates.append((abs(math.log(count / (n * p0))), threshold, count))
    if not candidates:
        return None
    _, threshold, count = min(candidates)
    return threshold, count


def subset_simulation(
    response: Response,
    ndim: int,
    *,
    per_level: int = 1000,
    p0: float = LEVEL_PROBABILITY,
    seed: int = 0,
    max_levels: int = MAX_LEVELS,
    confidence: float = 0.95,
) -> SubsetResult:
    """P(some margin of response(U) > 0) for U standard normal in ``ndim`` dimensions
    (module docstring).

    Args:
        response: the batch response (:data:`Response`): (n,) margins, or (n, k) margins of
            k failure modes (failure: any > 0); NaN is a failed instance: it counts as a
            failure and in ``undefined``.
        ndim: dimensions d >= 1.
        per_level: N, samples per level; p0 N must be a whole number >= 1.
        p0: the aimed conditional probability of each intermediate level.
        seed: seeds the Philox generator of every random number drawn here (mode j of k > 1
            draws from the stream [seed, j]).
        max_levels: levels at most.
        confidence: of ``p_upper`` when no failure is found.
    """
    nc = round(p0 * per_level)
    if ndim < 1 or nc < 1 or not math.isclose(nc, p0 * per_level) or nc >= per_level:
        raise ValueError(
            f"per_level: p0 N must be a whole number in [1, N), got N = {per_level}, p0 = {p0}"
        )

    def mode_response(j: int | None) -> Callable[[np.ndarray], np.ndarray]:
        def respond(u: np.ndarray) -> np.ndarray:
            r = np.asarray(response(u), dtype=np.float64).reshape(len(u), -1)
            if j is None and r.shape[1] > 1:
                raise _Modes(r.shape[1])
            return r[:, 0 if j is None else j]

        return respond

    args = (ndim, per_level, p0, nc, max_levels, confidence)
    try:
        return _one_mode(mode_response(None), np.random.Philox(seed), *args)
    except _Modes as found:
        k = found.count
    results, last = [], []
    for j in range(k):
        stream = np.random.Philox(np.random.SeedSequence([seed, j]))
        result = _one_mode(mode_response(j), stream, *args)
        # every mode's margins at this run's last-level failures (for the overlap)
        failures = result.failure_points
        margins = np.asarray(response(failures), dtype=np.float64).reshape(len(failures), k)
        result.samples_spent += len(failures)
        results.append(result)
        last.append(margins)
    return combine_modes(results, last)


class _Modes(Exception):
    """The response has several columns (failure modes): run one subset simulation each."""

    def __init__(self, count: int) -> None:
        super().__init__(count)
        self.count = count


def combine_modes(results: list[SubsetResult], last_margins: list[np.ndarray]) -> SubsetResult:
    """P(F_1 ∪ ... ∪ F_k) from one subset simulation per mode: Σ_j P(F_j) q_j, q_j the share
    of run j's last-level failures in no earlier mode (F_j ∩ no F_i, i < j; 1 for disjoint
    modes such as a requirement's two limits); δ² = Σ_j (P_j q_j / P)² (δ_j² + (1 − q_j)/
    (n_j q_j)), the runs being independent. Each mode's levels follow its own margin, so a
    mode whose margins are small beside another's is not lost (the single max of the
    margins hides it from the intermediate levels)."""
    parts, var, var_upper = [], 0.0, 0.0
    for j, (result, r) in enumerate(zip(results, last_margins, strict=True)):
        # r: every mode's margins at run j's last-level failures (NaN: failed in each mode)
        earlier = np.any(np.where(np.isnan(r[:, :j]), np.inf, r[:, :j]) > 0.0, axis=1)
        n_fail = len(r)
        q = float(np.mean(~earlier)) if n_fail else 1.0
        part = result.p_fail * q
        extra = (1.0 - q) / (n_fail * q) if n_fail and q > 0 else 0.0
        parts.append(part)
        var += part * part * (result.cov**2 + extra) if part > 0 else 0.0
        var_upper += part * part * (result.cov_upper**2 + extra) if part > 0 else 0.0
    total = math.fsum(parts)
    combined = SubsetResult(
        total,
        math.sqrt(var) / total if total > 0 else math.inf,
        math.sqrt(var_upper) / total if total > 0 else math.inf,
        sum(r.samples_spent for r in results),
        max(r.levels for r in results),
        results[0].per_level,
        undefined=sum(r.undefined for r in results),
        modes=results,
    )
    combined.cov_levels = combined.cov_lineage = combined.cov
    if total == 0.0:
        combined.p_upper = math.fsum(r.p_upper for r in results)
    for j, mode in enumerate(results):
        combined.warnings += [f"mode {j + 1}: {w}" for w in mode.warnings]
    return combined


def _one_mode(
    margin_of: Callable[[np.ndarray], np.ndarray],
    bit_generator: np.random.BitGenerator,
    ndim: int,
    per_level: int,
    p0: float,
    nc: int,
    max_levels: int,
    confidence: float,
) -> SubsetResult:
    """Subset simulation of one margin (module docstring)."""
    rng = np.random.Generator(bit_generator)
    result = SubsetResult(0.0, math.inf, math.inf, 0, 0, per_level)

    def margins(u: np.ndarray) -> np.ndarray:
        r = margin_of(u)
        failed = np.isnan(r)
        result.undefined += int(failed.sum())
        result.samples_spent += len(u)
        return np.where(failed, np.inf, r)

    u = rng.standard_normal((per_level, ndim))
    r = margins(u)
    eve = np.arange(per_level)  # each point's level-0 ancestor
    distinct = np.unique(r).size
    if distinct < per_level // 2:
        result.warnings.append(
            f"the output is discrete or saturated ({distinct} distinct values among the "
            f"{per_level} points of level 1): each level holds its counted share of points, "
            f"not p0 = {p0:g}"
        )
    chains: list[np.ndarray] | None = None  # the chain layout of the current points
    p_fail, delta2 = 1.0, 0.0
    state = {"scale": 1.0}  # the proposal's scale, adapted from level to level
    budget = max_levels * per_level
    below = -math.inf  # the current level's event: r >= below
    for level in range(max_levels):
        failures = int(np.sum(r > 0.0))
        event = None if failures >= nc or level == max_levels - 1 else next_event(r, nc, p0)
        if event is not None and event[0] > 0.0:
            event = None  # the next event is the failure event itself: no level between
        if event is None and failures < nc and level < max_levels - 1:
            # no threshold between the points (all share one response): more points of the
            # same level, until p0 N fail or the budget is spent
            result.warnings.append(
                f"the thresholds stopped rising at level {level + 1}: no response lies between "
                f"its points' {float(np.max(r[r <= 0.0], initial=-np.inf)):.6g} and failure (a "
                "plateau or a discrete output): that level grows until p0 N of its points fail "
                "or the budget of max_levels N solves is spent (plain Monte Carlo at level 1)"
            )
            u, r, eve, chains = _extend_level(
                u, r, eve, chains, below, per_level, nc, budget, rng, margins, state
            )
            failures = int(np.sum(r > 0.0))
        if event is None:
            threshold, count, indicator = 0.0, failures, r > 0.0
        else:
            threshold, count = event
            indicator = r >= threshold
        p_level = count / r.size
        d2 = _delta2(p_level, r.size, _gamma(indicator, p_level, chains))
        result.thresholds.append(threshold)
        result.level_probabilities.append(p_level)
        result.level_covs.append(math.sqrt(d2))
        p_fail *= p_level
        delta2 += d2
        if event is None:
            break
        seeds = np.flatnonzero(indicator)
        u, r, chains, moved_share, parent = _grow_chains(
            u[seeds], r[seeds], threshold, per_level, rng, margins, state
        )
        eve = eve[seeds][parent]
        below = threshold
        result.acceptance.append(moved_share)
    result.levels = len(result.level_probabilities)
    result.failure_points = u[r > 0.0]
    result.p_fail = p_fail
    result.cov_levels = math.sqrt(delta2) if p_fail > 0 else math.inf
    result.cov_lineage = lineage_cov(eve, r > 0.0)
    result.cov = max(result.cov_levels, result.cov_lineage)
    result.cov_upper = max(math.fsum(result.level_covs), result.cov) if p_fail > 0 else math.inf
    if p_fail == 0.0:
        reached = math.prod(result.level_probabilities[:-1])
        m = len(chains) if chains is not None else r.size
        result.p_upper = reached * -math.expm1(math.log1p(-confidence) / m)
        result.warnings.append(
            f"no failure found: P(fail) < {result.p_upper:.3g} (approximate one-sided "
            f"{100 * confidence:g} % bound: the levels reached times the bound of the last "
            "level's failure share, its chains taken as the independent draws)"
        )
    if result.undefined:
        result.warnings.append(
            f"{result.undefined} of {result.samples_spent} responses were NaN (failed "
            "instances): counted as failures"
        )
    return result


def lineage_cov(eve: np.ndarray, failed: np.ndarray) -> float:
    """The c.o.v. from the failures' level-0 ancestors ("Eves"): δ² = Σ_e s_e² − 1/n₀,
    s_e the share of the last level's failures descending from point e of level 0, n₀ the
    level-0 points. It treats the level-0 points as independent clusters of everything
    grown from them, so it sees what Au & Beck's per-level sum neglects: failures that
    all descend from a few ancestors (for plain Monte Carlo it is the binomial c.o.v.,
    √((1 − p)/(n p)), exactly). inf without failures."""
    k = int(failed.sum())
    if k == 0:
        return math.inf
    n0 = int(eve.max()) + 1 if eve.size else 1
    shares = np.bincount(eve[failed], minlength=n0) / k
    return math.sqrt(max(float(np.sum(shares * shares)) - 1.0 / n0, 0.0))


def _extend_level(
    u: np.ndarray,
    r: np.ndarray,
    eve: np.ndarray,
    chains: list[np.ndarray] | None,
    below: float,
    batch: int,
    nc: int,
    budget: int,
    rng: np.random.Generator,
    margins: Callable[[np.ndarray], np.ndarray],
    state: dict[str, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray] | None]:
    """More points of the current level, ``batch`` at a time, until ``nc`` fail or the
    solves reach ``budget``: independent draws at level 0 (new ancestors), else every chain
    continued from its last state (in {r >= below})."""
    spent = [0]

    def counted(x: np.ndarray) -> np.ndarray:
        spent[0] += len(x)
        return margins(x)

    total = batch
    while int(np.sum(r > 0.0)) < nc and total + batch <= budget:
        if chains is None:
            new_u = rng.standard_normal((batch, u.shape[1]))
            u, r = np.concatenate([u, new_u]), np.concatenate([r, counted(new_u)])
            eve = np.arange(r.size)
        else:
            last = np.array([c[-1] for c in chains])
            more_u, more_r, more, _, parent = _grow_chains(
                u[last], r[last], below, batch + len(chains), rng, counted, state
            )
            keep = np.concatenate([c[1:] for c in more])  # the first state repeats the seed
            offset = r.size
            index_of = np.full(more_r.size, -1)
            index_of[keep] = offset + np.arange(keep.size)
            chains = [
                np.concatenate([c, index_of[m[1:]]]) for c, m in zip(chains, more, strict=True)
            ]
            u = np.concatenate([u, more_u[keep]])
            r = np.concatenate([r, more_r[keep]])
            eve = np.concatenate([eve, eve[last][parent[keep]]])
        total += batch
    return u, r, eve, chains


def _grow_chains(
    u0: np.ndarray,
    r0: np.ndarray,
    threshold: float,
    total: int,
    rng: np.random.Generator,
    margins: Callable[[np.ndarray], np.ndarray],
    state: dict[str, float],
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], float, np.ndarray]:
    """Markov chains from every seed in ``u0`` (m, d), kept in {r >= threshold}, ``total``
    states in all (the seeds included): each chain gets ⌊total/m⌋ states and the remainder
    goes one each to seeds drawn uniformly. Returns the points (total, d), their
    responses, each chain's point indices in order, the share of steps that moved and each
    point's seed (an index into ``u0``)."""
    m, d = u0.shape
    lengths = np.full(m, total // m)
    lengths[rng.choice(m, total - int(lengths.sum()), replace=False)] += 1
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    u = np.empty((total, d))
    r = np.empty(total)
    u[starts], r[starts] = u0, r0
    current, current_r = u0.copy(), r0.copy()
    moves = steps = 0
    scale = state["scale"]
    # Adaptive conditional sampling (Papaioannou et al. 2015): v = ρ u + √(1 − ρ²) ξ keeps
    # the standard normal invariant, so every candidate is solved; σ = √(1 − ρ²) per
    # dimension starts at the seeds' spread and is scaled after each step towards 44 %
    # of the candidates accepted.
    sigma0 = np.minimum(np.std(u0, axis=0), 1.0) if m > 1 else np.ones(d)
    for step in range(1, int(lengths.max())):
        active = np.flatnonzero(lengths > step)
        sigma = np.minimum(scale * np.maximum(sigma0, 1e-3), 1.0)
        rho = np.sqrt(1.0 - sigma**2)
        candidate = rho * current[active] + sigma * rng.standard_normal((active.size, d))
        candidate_r = margins(candidate)
        inside = candidate_r >= threshold
        current[active] = np.where(inside[:, None], candidate, current[active])
        current_r[active] = np.where(inside, candidate_r, current_r[active])
        u[starts[active] + step] = current[active]
        r[starts[active] + step] = current_r[active]
        accepted = int(inside.sum())
        moves += accepted
        steps += active.size
        scale *= math.exp((accepted / active.size - TARGET_ACCEPTANCE) / math.sqrt(step))
    state["scale"] = scale
    chains = [np.arange(a, a + n) for a, n in zip(starts, lengths, strict=True)]
    parent = np.repeat(np.arange(m), lengths)
    return u, r, chains, moves / steps if steps else 0.0, parent


def parameters_of(u: np.ndarray, distributions: Sequence[object]) -> np.ndarray:
    """The sampled parameters (n, nparam) at standard-normal points ``u`` (n, nparam):
    column j is distribution j's inverse CDF of Φ(u_j) (the map a design's uniforms take)."""
    from scipy.special import ndtr

    from mcchain.scene.sampling import ppf

    uniform = np.clip(ndtr(np.asarray(u, dtype=np.float64)), 2.0**-53, 1.0 - 2.0**-53)
    out = np.empty_like(uniform)
    for j, dist in enumerate(distributions):
        out[:, j] = ppf(dist, uniform[:, j])  # type: ignore[arg-type]
    return out
