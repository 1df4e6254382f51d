"""What-if tolerances from one ensemble: P(fail) if one sampled parameter had a narrower
range or a smaller spread, from the samples already solved (``whatif.csv``, ``whatif.png``).

A designer's question after a FAIL is "how much tighter, on which parameter?". Each row
changes one parameter's distribution f into a narrower g, the others as sampled, and
reweights the stored samples by w = g(x)/f(x):

* ``central``, ``lower``, ``upper``: g is f cut to the central share s of its probability
  (quantiles (1 − s)/2 .. (1 + s)/2), to its lower share (below the s-quantile) or to its
  upper share; for a ``uniform`` that is a narrower uniform. The weights are 0 outside and
  1/s inside, so the reweighted estimate is the failure share of the samples inside, and
  given their count those samples are independent draws of g: the exact Clopper–Pearson
  bounds apply (each end one-sided at ``confidence``).
* ``sigma`` (``normal``, ``lognormal`` of the log, ``truncnormal`` with its bounds kept):
  g has the standard deviation scaled by s. The weights are bounded, w <= w_max (their value
  at the mean, σ/σ' times the ratio of the truncations' masses), so Y = w 1{fail}/w_max lies
  in [0, 1] with mean P_g(fail)/w_max. The estimate is Σ w 1{fail}/n (unbiased) and its
  bounds are the Chernoff–Hoeffding bounds of the mean of [0, 1] variables, {m : n KL(ȳ ‖ m)
  <= ln(1/α)} (a [0, 1] variable's moment generating function is at most a Bernoulli's of
  the same mean, so the binomial Chernoff bound holds): exact, never too narrow, for any
  weights and any failure region. Kish's effective sample size n_eff = (Σw)²/Σw² is reported
  beside them; the Clopper–Pearson interval at n_eff, tried first, is narrower but lost its
  coverage when the failures sit where the weights are large (near the mean):
  ``benchmarks/bench_whatif.py`` measures both on a closed form.

Every row is a statement on its own (each end one-sided at ``confidence``); reading the
table for the widest range that passes is a search, and ``mcchain confirm RUN --requirement
NAME --range PATH=LOW:HIGH`` decides on fresh samples. The bounds assume independent draws
(``design = "random"``); for ``sobol``, ``lhs`` and ``saltelli`` the estimates stay
consistent (a quasi-random integral of the same weighted failure indicator) and the rows are
marked ``exact = false``. ``choice`` parameters get no rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.decision.allocation_table import failed_samples
from mcchain.decision.requirements import stored_requirements
from mcchain.decision.sampled import SampledParameter, sampled_parameters
from mcchain.decision.stats import one_sided_bounds

if TYPE_CHECKING:
    from mcchain.ensemble.per_sample import StoredEnsemble
    from mcchain.scene.study import Distribution

SHARES = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1)
"""s of every row: the share of probability kept, or of the standard deviation."""
RANGE_CHANGES = ("central", "lower", "upper")
SIGMA = "sigma"
SIGMA_KINDS = ("normal", "lognormal", "truncnormal")
BISECTIONS = 60

WHATIF_COLUMNS = (
    "requirement",
    "parameter",
    "unit",
    "change",
    "share",
    "low",
    "high",
    "distribution",
    "samples",
    "n_eff",
    "failures",
    "p_fail",
    "p_lower",
    "p_upper",
    "confidence",
    "target",
    "meets_target",
    "method",
    "exact",
)
"""Columns of ``whatif.csv`` (docs/scenes.md)."""
METHODS = {
    "range": "clopper-pearson on the samples inside",
    SIGMA: "chernoff bound of bounded importance weights",
}


@dataclass(frozen=True)
class WhatIf:
    """P(fail) under one changed distribution: a row of ``whatif.csv``.

    Attributes:
        change: ``central``, ``lower``, ``upper`` (a cut range) or ``sigma``.
        share: s (module docstring).
        low, high: the new distribution's range, parameter units (±inf: unbounded).
        distribution: the new distribution as a TOML inline table.
        samples: samples used (inside the range; all for ``sigma``); n_eff: Kish's.
        failures: failures among them.
        p_fail, p_lower, p_upper: the estimate and its bounds, each one-sided at
            ``confidence``.
    """

    requirement: str
    parameter: str
    unit: str
    change: str
    share: float
    low: float
    high: float
    distribution: str
    samples: int
    n_eff: float
    failures: int
    p_fail: float
    p_lower: float
    p_upper: float
    confidence: float
    target: float
    exact: bool

    @property
    def meets_target(self) -> bool:
        return self.p_upper <= self.target

    @property
    def method(self) -> str:
        return METHODS[SIGMA if self.change == SIGMA else "range"]

    def row(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in WHATIF_COLUMNS}


# -- statistics ------------------------------------------------------------------------------
def kl_bernoulli(p: float | np.ndarray, q: float | np.ndarray) -> np.ndarray:
    """KL(Bernoulli(p) ‖ Bernoulli(q)), element by element (0 log 0 = 0)."""
    p, q = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(p > 0, p * np.log(p / q), 0.0)
        b = np.where(p < 1, (1 - p) * np.log((1 - p) / (1 - q)), 0.0)
    return np.asarray(a + b)


def chernoff_bounds(mean: float, n: int, confidence: float) -> tuple[float, float]:
    """One-sided ``confidence`` bounds (lower, upper) of the mean of n independent [0, 1]
    variables whose average is ``mean``: the m where n KL(mean ‖ m) = ln(1/(1 − C)) on each
    side (bisection; the bounds never claim too much)."""
    if n <= 0:
        return 0.0, 1.0
    level = -math.log1p(-confidence)
    y = min(max(float(mean), 0.0), 1.0)
    p = np.float64(y)

    def below_level(m: float) -> bool:
        """n KL(y ‖ m) <= level: :func:`kl_bernoulli`'s operations on float64 scalars (the
        same values, without its arrays: 120 evaluations a bound pair)."""
        q = np.float64(m)
        a = p * np.log(p / q) if p > 0 else 0.0
        b = (1 - p) * np.log((1 - p) / (1 - q)) if p < 1 else 0.0
        return bool(n * (a + b) <= level)

    with np.errstate(divide="ignore", invalid="ignore"):
        lo, hi = y, 1.0  # upper bound: KL rises from 0 at y to +inf at 1
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if below_level(mid) else (lo, mid)
        upper = hi if y < 1.0 else 1.0
        lo2, hi2 = 0.0, y  # lower bound
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo2 + hi2)
            lo2, hi2 = (lo2, mid) if below_level(mid) else (mid, hi2)
    lower = lo2 if y > 0.0 else 0.0
    return lower, upper


def range_estimate(
    failed: np.ndarray, inside: np.ndarray, confidence: float
) -> tuple[int, int, float, float, float]:
    """(samples, failures, p_fail, p_lower, p_upper) of the samples ``inside`` a cut range:
    the exact bounds, each one-sided at ``confidence``."""
    n = int(inside.sum())
    k = int(np.sum(failed & inside))
    if n == 0:
        return 0, 0, math.nan, 0.0, 1.0
    lo, hi = one_sided_bounds(k, n, confidence)
    return n, k, k / n, lo, hi


def weighted_estimate(
    failed: np.ndarray, weights: np.ndarray, w_max: float, confidence: float
) -> tuple[float, float, float, float]:
    """(p_fail, p_lower, p_upper, n_eff) for importance weights bounded by ``w_max``
    (module docstring): Σ w 1{fail}/n and w_max times the Chernoff bounds of the mean of
    w 1{fail}/w_max."""
    w = np.asarray(weights, dtype=np.float64)
    n = w.size
    y = float(np.sum(w * failed)) / n
    lo, hi = chernoff_bounds(y / w_max, n, confidence)
    n_eff = float(w.sum() ** 2 / np.sum(w * w)) if np.any(w > 0) else 0.0
    return y, w_max * lo, min(1.0, w_max * hi), n_eff


# -- changed distributions ---------------------------------------------------------------------
def _quantile_range(dist: Distribution, change: str, share: float) -> tuple[float, float]:
    """The new range (parameter units) of a cut change, from the sampling distribution's
    quantiles."""
    from mcchain.scene.sampling import ppf

    lo_q, hi_q = {
        "central": ((1 - share) / 2, (1 + share) / 2),
        "lower": (0.0, share),
        "upper": (1 - share, 1.0),
    }[change]
    support = dist.bounds() or (-math.inf, math.inf)
    low = support[0] if lo_q <= 0 else float(ppf(dist, np.array([lo_q]))[0])
    high = support[1] if hi_q >= 1 else float(ppf(dist, np.array([hi_q]))[0])
    return low, high


def _toml_number(x: float) -> str:
    """A computed TOML number with 12 significant digits (a quantile's last bits are
    noise); :func:`_written` for a number as the scene wrote it."""
    return format(float(x), ".12g")


def _written(x: float) -> str:
    return repr(float(x))


def range_distribution(dist: Distribution, low: float, high: float) -> str:
    """The distribution cut to [low, high] as a TOML inline table: a narrower ``uniform``
    for a uniform, else the distribution with ``within``."""
    if dist.kind == "uniform" and dist.within is None:
        return f"{{ uniform = [{_toml_number(low)}, {_toml_number(high)}] }}"
    args = ", ".join(_written(a) for a in dist.args)
    if math.isinf(low) and math.isinf(high):
        within = dist.within
    else:
        within = [low, high]
    extra = ""
    if within is not None:
        extra = f", within = [{_toml_number(within[0])}, {_toml_number(within[1])}]"
    return f"{{ {dist.kind} = [{args}]{extra} }}"


def sigma_weights(
    dist: Distribution, x: np.ndarray, share: float
) -> tuple[np.ndarray, float, list[float]]:
    """Weights g/f at ``x`` when the standard deviation (of the log for ``lognormal``) is
    scaled by ``share``, their supremum over the support, and the new distribution's args."""
    from mcchain.scene.sampling import cdf

    args = list(dist.args)
    mean, sigma = args[0], args[1]
    new = [mean, sigma * share, *args[2:]]
    z_of = (lambda v: np.log(v)) if dist.kind == "lognormal" else (lambda v: v)
    support = dist.bounds()
    # mass of each distribution on the support (truncnormal's own bounds and `within`)
    if support is None:
        mass_f = mass_g = 1.0
    else:
        ends = np.array(support, dtype=np.float64)
        base = "normal" if dist.kind == "truncnormal" else dist.kind
        mass_f = float(np.diff(cdf(base, args[:2], ends))[0])
        mass_g = float(np.diff(cdf(base, new[:2], ends))[0])

    def weight(v: np.ndarray) -> np.ndarray:
        z = (z_of(np.asarray(v, dtype=np.float64)) - mean) / sigma
        return np.asarray(np.exp(-0.5 * z * z * (1.0 / share**2 - 1.0)) / share * mass_f / mass_g)

    w = weight(x)
    # the weight falls with |z|: its largest value is at the support's point nearest the mean
    centre = math.exp(mean) if dist.kind == "lognormal" else mean
    if support is not None:
        centre = min(max(centre, support[0]), support[1])
    return w, float(weight(np.array([centre]))[0]), new


def whatif_rows(
    requirement: Any, parameter: SampledParameter, failed: np.ndarray, exact: bool
) -> list[WhatIf]:
    """Every change of one parameter for one requirement (module docstring)."""
    dist = parameter.distribution
    if dist is None or dist.kind == "choice":
        return []
    c, t = requirement.confidence, requirement.target
    x = parameter.values
    rows = []

    def add(change: str, s: float, low: float, high: float, text: str, numbers: tuple) -> None:
        n, n_eff, k, p, lo, hi = numbers
        rows.append(
            WhatIf(
                requirement.name,
                parameter.path,
                parameter.units,
                change,
                s,
                low,
                high,
                text,
                n,
                n_eff,
                k,
                p,
                lo,
                hi,
                c,
                t,
                exact,
            )
        )

    for change in RANGE_CHANGES:
        for s in SHARES:
            low, high = _quantile_range(dist, change, s)
            inside = (x >= low) & (x <= high)
            n, k, p, lo, hi = range_estimate(failed, inside, c)
            add(
                change,
                s,
                low,
                high,
                range_distribution(dist, low, high),
                (n, float(n), k, p, lo, hi),
            )
    if dist.kind in SIGMA_KINDS:
        support = dist.bounds() or (-math.inf, math.inf)
        for s in SHARES:
            w, w_max, new = sigma_weights(dist, x, s)
            p, lo, hi, n_eff = weighted_estimate(failed, w, w_max, c)
            args = ", ".join(_written(a) for a in new)
            within = ""
            if dist.within is not None:
                within = f", within = [{_written(dist.within[0])}, {_written(dist.within[1])}]"
            add(
                SIGMA,
                s,
                support[0],
                support[1],
                f"{{ {dist.kind} = [{args}]{within} }}",
                (x.size, n_eff, int(np.sum(failed)), p, lo, hi),
            )
    return rows


def whatifs(ds: StoredEnsemble) -> list[WhatIf]:
    """Every requirement's what-if rows over every sampled parameter."""
    from mcchain.decision.sampled import EXACT_DESIGNS, design_of

    exact = design_of(ds) in EXACT_DESIGNS
    params = sampled_parameters(ds)
    rows = []
    for requirement in stored_requirements(ds) if params else []:
        failed = failed_samples(ds, requirement)
        for parameter in params:
            rows += whatif_rows(requirement, parameter, failed, exact)
    return rows


def write_whatif(ds: StoredEnsemble, folder: Path) -> list[Path]:
    """``whatif.csv`` and ``whatif.png`` into ``folder`` (nothing without sampled
    parameters)."""
    from mcchain.decision.tables import write_csv

    rows = whatifs(ds)
    if not rows:
        return []
    csv_path, png_path = folder / "whatif.csv", folder / "whatif.png"
    write_csv(csv_path, WHATIF_COLUMNS, [r.row() for r in rows])
    from mcchain.viz.figures import save
    from mcchain.viz.report_whatif import whatif_figure

    tmp = save(whatif_figure(rows), folder / "whatif.partial.png")
    tmp.replace(png_path)  # atomic: a reader never sees half a PNG
    return [csv_path, png_path]


def kish_clopper_pearson(
    failed: np.ndarray, weights: np.ndarray, confidence: float
) -> tuple[float, float, float]:
    """The self-normalised estimate Σ w 1{fail}/Σ w with the Clopper–Pearson bounds at Kish's
    n_eff (non-integer counts: the beta quantiles), each end one-sided at ``confidence``: the
    common approximation this module measures against (``benchmarks/bench_whatif.py``)."""
    from scipy import stats  # here, not at the top: the export never calls this function

    w = np.asarray(weights, dtype=np.float64)
    p = float(np.sum(w * failed) / w.sum())
    n_eff = float(w.sum() ** 2 / np.sum(w * w))
    k = p * n_eff
    lo = 0.0 if k <= 0 else float(stats.beta.ppf(1 - confidence, k, n_eff - k + 1))
    hi = 1.0 if k >= n_eff else float(stats.beta.ppf(confidence, k + 1, n_eff - k))
    return p, lo, hi
