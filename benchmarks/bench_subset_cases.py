"""Subset simulation on rare-event closed forms: ours, the version before the tie fixes, and
OpenTURNS' ``SubsetSampling``, 100 seeds each (no mechanism: synthetic responses).

Cases (:mod:`mcchain.testing.rare_events`): a plateau output, an integer output, a boolean
with P = 1e-3, a series system of two failure regions whose margins differ in scale by 100
(as two failure modes, and as the single maximum of the two margins). Per engine and case:
the mean estimate over the exact value, the spread of the estimates (std / exact), the
median stated c.o.v., the share of seeds whose estimate lies within 3 stated c.o.v. of the
exact value (|p̂ − p| <= 3 δ̂ p̂, the error bar a user reads; a zero estimate is outside), the
zero estimates, and the mean number of responses evaluated.

    python benchmarks/bench_subset_cases.py [--seeds 100] [--per-level 1000] [--before COMMIT]

``--before COMMIT`` runs ``mcchain/decision/subset.py`` as it was at that commit (read with
``git show``, default 995158e) on the single-margin cases. OpenTURNS (``pip install
openturns``, the ``bench`` extra) is skipped when absent. Writes
``benchmarks/results/subset/cases.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from at_commit import module_at

from mcchain.decision.subset import subset_simulation
from mcchain.testing.rare_events import CASES, RareCase

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "subset"

Engine = Callable[[RareCase, int, int], tuple[float, float, int]]
"""(case, seed, N) -> (estimate, stated c.o.v., responses evaluated)."""


def ours(case: RareCase, seed: int, per_level: int) -> tuple[float, float, int]:
    r = subset_simulation(case.response, case.ndim, per_level=per_level, seed=seed)
    return r.p_fail, r.cov, r.samples_spent


def before(commit: str) -> Engine:
    """The subset simulation of ``commit`` (one margin only)."""
    module = module_at(commit, "mcchain/decision/subset.py")

    def run(case: RareCase, seed: int, per_level: int) -> tuple[float, float, int]:
        r = module.subset_simulation(case.response, case.ndim, per_level=per_level, seed=seed)
        return r.p_fail, r.cov, r.samples_spent

    return run


def openturns_engine() -> Engine | None:
    try:
        import openturns as ot
    except ImportError:
        return None
    ot.Log.Show(ot.Log.NONE)

    def run(case: RareCase, seed: int, per_level: int) -> tuple[float, float, int]:
        ot.RandomGenerator.SetSeed(seed)
        function = ot.PythonFunction(
            case.ndim, 1, func_sample=lambda x: np.asarray(case.response(np.asarray(x)))[:, None]
        )
        vector = ot.CompositeRandomVector(function, ot.RandomVector(ot.Normal(case.ndim)))
        algo = ot.SubsetSampling(ot.ThresholdEvent(vector, ot.Greater(), 0.0))
        algo.setMaximumOuterSampling(1)  # one block of N per level
        algo.setBlockSize(per_level)
        algo.setConditionalProbability(0.1)
        algo.run()
        result = algo.getResult()
        return (
            result.getProbabilityEstimate(),
            result.getCoefficientOfVariation(),
            function.getEvaluationCallsNumber(),
        )

    return run


def table_row(engine: str, case: RareCase, runs: list[tuple[float, float, int]], s: float) -> str:
    p = np.array([r[0] for r in runs])
    cov = np.array([r[1] for r in runs])
    with np.errstate(invalid="ignore"):
        within = np.abs(p - case.exact) <= 3 * cov * p
    finite = cov[np.isfinite(cov)]
    return (
        f"| {engine} | {case.name} | {case.exact:.4g} | {p.mean() / case.exact:.3g} | "
        f"{p.std(ddof=1) / case.exact:.3f} | {np.median(finite) if finite.size else np.inf:.3f} "
        f"| {int(within.sum())} % | {int(np.sum(p == 0))} | "
        f"{np.mean([r[2] for r in runs]):,.0f} | {s:.1f} |"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--per-level", type=int, default=1000)
    parser.add_argument("--before", default="995158e")
    args = parser.parse_args()
    engines: list[tuple[str, Engine, bool]] = [("mcchain (this commit)", ours, True)]
    if args.before:
        engines.append((f"mcchain before ({args.before})", before(args.before), False))
    ot_engine = openturns_engine()
    if ot_engine is not None:
        engines.append(("OpenTURNS SubsetSampling", ot_engine, False))
    lines = [
        "# Subset simulation on rare-event closed forms",
        "",
        f"`python benchmarks/bench_subset_cases.py --seeds {args.seeds} --per-level "
        f"{args.per_level}` (N = {args.per_level} per level, p0 = 0.1; "
        f"within: |p̂ − p| <= 3 δ̂ p̂, of {args.seeds} seeds)",
        "",
        "| engine | case | exact P | mean / exact | spread / exact | median stated c.o.v. | "
        "within 3 c.o.v. | zero estimates | responses | wall s |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, engine, modes in engines:
        for case in CASES.values():
            if case.name == "series" and not modes:
                continue  # one margin only: the series system is the `series-max` row
            t0 = time.perf_counter()
            runs = [engine(case, seed, args.per_level) for seed in range(args.seeds)]
            row = table_row(name, case, runs, time.perf_counter() - t0)
            row = row.replace(" % |", f" of {args.seeds} |", 1) if args.seeds != 100 else row
            lines.append(row)
            print(row, flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "cases.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines[:6]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
