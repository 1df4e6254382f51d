"""Rare failure probabilities by subset simulation (Au & Beck 2001), on mcchain's batches.

A target of 1e-4 needs ~3e4 failure-free samples just to be shown, and far more to be
estimated. Subset simulation writes P(F) as a product of conditional probabilities of
nested events F_1 ⊃ F_2 ⊃ ... ⊃ F_m = F, each about ``p0`` = 0.1, and estimates each from
samples that Markov chains spread over the previous event.

Method (:func:`subset_simulation`), in the standard-normal space of the sampled parameters
(parameter j = its distribution's inverse CDF of Φ(u_j), :func:`parameters_of`):

1. Level 0: N independent standard-normal points, their responses r (the output's margin
   beyond the limit: failure is r > 0; a failed instance, NaN, is +inf, i.e. a failure).
2. While fewer than p0 N points fail: the threshold b is the (p0 N)-th largest response, the
   p0 N points above it seed p0 N Markov chains of 1/p0 states each (the seed is the first).
   A step proposes v = ρ u + σ ξ, ξ standard normal, ρ = √(1 − σ²) per coordinate (the
   conditional sampling of Papaioannou et al., Prob. Eng. Mech. 2015, which leaves the
   standard normal invariant: no rejection on the prior, unlike Au & Beck's component-wise
   Metropolis), and keeps it if its response is ≥ b, else the chain stays. σ starts at the
   seeds' spread per coordinate times a scale adapted after every step towards 44 % of the
   candidates kept (carried from level to level). Each step moves all chains at once: one
   batch of the kernels.
3. P(F) = p0^(m−1) · (failures among the last level's N points)/N.

Its coefficient of variation (Au & Beck 2001, eqs. 27–29): δ_j² = (1 − P_j)/(N P_j) (1 + γ_j)
per level, γ_j from the correlation of the indicator along the chains (0 at level 0), and
δ = √(Σ δ_j²) — which neglects the correlation between levels, so it is on the low side;
Σ δ_j (levels fully correlated) bounds it from above, and both are reported. Measured over
200 seeds (N = 1000), the spread of the estimates / the mean δ / the mean Σ δ_j: the pinned
bar (one parameter) at P = 1e-4 0.32 / 0.28 / 0.56, at 1e-6 0.40 / 0.35 / 0.87; a linear
limit state in two dimensions at 1e-4 0.30 / 0.28 / 0.56, at 1e-6 0.47 / 0.35 / 0.87.
(Au & Beck's component-wise Metropolis with unit spread, tried first, gave spreads of
0.46-0.82 at 1e-6 for δ ≈ 0.4, and a biased mean in one dimension.) Samples spent:
N + (m − 1)(N − p0 N).

No library was used: OpenTURNS' ``SubsetSampling`` and UQpy's ``SubsetSimulation`` are not
installed here, and both draw from their own random generators, so a run would not be the
pure function of (scene, seed) that every mcchain result is; the algorithm is short.
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

METHOD = "subset simulation (Au & Beck 2001), adaptive conditional sampling, p0 = 0.1"
"""How the CSV names the method."""

Response = Callable[[np.ndarray], np.ndarray]
"""``response(u) -> r``: u (n, d) standard-normal points, r (n,) margins (failure: r > 0)."""


@dataclass
class SubsetResult:
    """What :func:`subset_simulation` found.

    Attributes:
        p_fail: the estimate of P(r > 0).
        cov: its estimated coefficient of variation δ (see the module docstring).
        cov_upper: Σ δ_j, the c.o.v. if the levels' estimates were fully correlated: the
            true c.o.v. lies between ``cov`` and this (Au & Beck 2001, §5).
        samples_spent: responses evaluated (kernel solves).
        levels: levels m (1: plain Monte Carlo found p0 N failures at once).
        per_level: N.
        thresholds: the intermediate thresholds b_1 .. b_(m−1) (margins), then 0.
        level_probabilities: P_1 .. P_m.
        level_covs: δ_1 .. δ_m.
        acceptance: per level after the first, the share of chain steps that moved.
    """

    p_fail: float
    cov: float
    cov_upper: float
    samples_spent: int
    levels: int
    per_level: int
    thresholds: list[float] = field(default_factory=list)
    level_probabilities: list[float] = field(default_factory=list)
    level_covs: list[float] = field(default_factory=list)
    acceptance: list[float] = field(default_factory=list)


def _gamma(indicator: np.ndarray, p: float) -> float:
    """γ of Au & Beck (eq. 29) for an indicator laid out (chains, states)."""
    nc, ns = indicator.shape
    if ns < 2 or p <= 0.0 or p >= 1.0:
        return 0.0
    ind = indicator.astype(np.float64)
    r0 = p * (1.0 - p)
    gamma = 0.0
    for k in range(1, ns):
        rk = float(np.sum(ind[:, : ns - k] * ind[:, k:])) / (nc * (ns - k)) - p * p
        gamma += 2.0 * (1.0 - k / ns) * rk / r0
    return max(gamma, 0.0)


def _delta2(p: float, n: int, gamma: float) -> float:
    return math.inf if p <= 0.0 else (1.0 - p) / (n * p) * (1.0 + gamma)


def subset_simulation(
    response: Response,
    ndim: int,
    *,
    per_level: int = 1000,
    p0: float = LEVEL_PROBABILITY,
    seed: int = 0,
    max_levels: int = MAX_LEVELS,
) -> SubsetResult:
    """P(response(U) > 0) for U standard normal in ``ndim`` dimensions (module docstring).

    Args:
        response: the batch response (:data:`Response`); NaN counts as a failure.
        ndim: dimensions d >= 1.
        per_level: N, samples per level; p0 N and 1/p0 must be whole numbers.
        p0: the conditional probability of each intermediate level.
        seed: seeds the Philox generator of every random number drawn here.
        max_levels: levels at most.
    """
    nc = round(p0 * per_level)
    ns = round(1.0 / p0)
    if ndim < 1 or nc < 1 or nc * ns != per_level or not math.isclose(nc, p0 * per_level):
        raise ValueError(
            f"per_level: p0 N and 1/p0 must be whole numbers with N = (p0 N)(1/p0), "
            f"got N = {per_level}, p0 = {p0}"
        )
    rng = np.random.Generator(np.random.Philox(seed))

    def margins(u: np.ndarray) -> np.ndarray:
        r = np.asarray(response(u), dtype=np.float64).reshape(len(u))
        return np.where(np.isnan(r), np.inf, r)

    u = rng.standard_normal((per_level, ndim))
    r = margins(u)
    result = SubsetResult(0.0, math.inf, math.inf, per_level, 0, per_level)
    chains: np.ndarray | None = None  # the layout (nc, ns) of the current points, if chains
    p_fail, delta2 = 1.0, 0.0
    state = {"scale": 1.0}  # the proposal's scale, adapted from level to level
    for level in range(max_levels):
        failures = int(np.sum(r > 0.0))
        last = failures >= nc or level == max_levels - 1
        if last:
            threshold, p_level = 0.0, failures / per_level
            indicator = r > 0.0
        else:
            order = np.argsort(-r, kind="stable")
            threshold = float(r[order[nc - 1]])
            p_level = p0
            indicator = r >= threshold
        gamma = 0.0 if chains is None else _gamma(indicator[chains], p_level)
        d2 = _delta2(p_level, per_level, gamma)
        result.thresholds.append(threshold)
        result.level_probabilities.append(p_level)
        result.level_covs.append(math.sqrt(d2))
        p_fail *= p_level
        delta2 += d2
        if last:
            break
        seeds = order[:nc]
        u, r, moved_share, spent = _grow_chains(
            u[seeds], r[seeds], threshold, ns, rng, margins, state
        )
        chains = np.arange(per_level).reshape(nc, ns)
        result.samples_spent += spent
        result.acceptance.append(moved_share)
    result.p_fail = p_fail
    result.cov = math.sqrt(delta2) if p_fail > 0 else math.inf
    result.cov_upper = math.fsum(result.level_covs) if p_fail > 0 else math.inf
    result.levels = len(result.level_probabilities)
    return result


def _grow_chains(
    u0: np.ndarray,
    r0: np.ndarray,
    threshold: float,
    ns: int,
    rng: np.random.Generator,
    margins: Callable[[np.ndarray], np.ndarray],
    state: dict[str, float],
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Modified Metropolis chains of ``ns`` states from the seeds ``u0`` (nc, d), kept in
    {r >= threshold}; returns the points laid out chain by chain (nc ns, d), their
    responses, the share of steps that moved, and the responses evaluated."""
    nc, d = u0.shape
    u = np.empty((nc, ns, d))
    r = np.empty((nc, ns))
    u[:, 0], r[:, 0] = u0, r0
    moves = spent = 0
    scale = state["scale"]
    # Adaptive conditional sampling (Papaioannou et al. 2015): v = ρ u + √(1 − ρ²) ξ keeps
    # the standard normal invariant, so every candidate is solved; σ = √(1 − ρ²) per
    # dimension starts at the seeds' spread and is scaled after each step towards 44 %
    # of the candidates accepted.
    sigma0 = np.minimum(np.std(u0, axis=0), 1.0) if nc > 1 else np.ones(d)
    for step in range(1, ns):
        current, current_r = u[:, step - 1], r[:, step - 1]
        sigma = np.minimum(scale * np.maximum(sigma0, 1e-3), 1.0)
        rho = np.sqrt(1.0 - sigma**2)
        candidate = rho * current + sigma * rng.standard_normal((nc, d))
        candidate_r = margins(candidate)
        spent += nc
        inside = candidate_r >= threshold
        u[:, step] = np.where(inside[:, None], candidate, current)
        r[:, step] = np.where(inside, candidate_r, current_r)
        accepted = int(inside.sum())
        moves += accepted
        scale *= math.exp((accepted / nc - TARGET_ACCEPTANCE) / math.sqrt(step))
    state["scale"] = scale
    return u.reshape(nc * ns, d), r.reshape(nc * ns), moves / (nc * (ns - 1)), spent


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
