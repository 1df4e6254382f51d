"""Extending a fixed-count run until it decides: how often the verdict is a wrong PASS.

A user runs ``n0`` samples; while the verdict is undecided, ``mcchain run --extend RUN
--samples n0`` and looks again, up to ``--looks`` looks. Each sample fails with probability
p = ``--ratio`` x target (a wrong PASS is any PASS: p is above the target). Simulated with
Bernoulli draws (the verdict depends on the failure counts only), ``--runs`` times:

* **before**: every look judged by the fixed-count interval (exact one-sided bounds at C,
  :func:`mcchain.decision.stats.one_sided_bounds`), what ``--extend`` reported before;
* **after**: the first look (the fixed-count run as it was) by those bounds, every look after
  an extension by the confidence sequence over the looks n0, 2 n0, ...
  (:func:`mcchain.decision.sequential.running_interval`), what ``--extend`` reports now.

Nominal: a verdict wrong with probability at most 1 - C. "after" can exceed it only through
its first look (the fixed-count verdict the user read before extending) plus the sequence's
own 1 - C: a bound of 2 (1 - C), whatever the number of extensions.

    python benchmarks/bench_extend.py [--runs 20000] [--n0 256] [--looks 40] [--ratio 1.02]

Writes ``benchmarks/results/extend/bench.md`` and ``bench.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from mcchain.decision.sequential import running_interval
from mcchain.decision.stats import one_sided_bounds_arrays

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "extend"


def first_decision(
    lower: np.ndarray, upper: np.ndarray, target: float
) -> tuple[np.ndarray, np.ndarray]:
    """(nrun,) the verdict at the first deciding look (1 pass, -1 fail, 0 none) and that
    look's index (-1: none)."""
    passed, failed = upper <= target, lower > target
    decided = passed | failed
    first = np.argmax(decided, axis=1)
    rows = np.arange(lower.shape[0])
    out = np.where(passed[rows, first], 1, np.where(failed[rows, first], -1, 0))
    return np.where(decided.any(axis=1), out, 0), np.where(decided.any(axis=1), first, -1)


def simulate(
    runs: int, n0: int, looks: int, p: float, target: float, confidence: float, seed: int
) -> dict[str, dict[str, Any]]:
    rng = np.random.default_rng(seed)
    k = np.cumsum(rng.binomial(n0, p, size=(runs, looks)), axis=1)
    n = np.broadcast_to(n0 * np.arange(1, looks + 1), k.shape)
    cp_lo, cp_hi = one_sided_bounds_arrays(k, n, confidence)
    cs_lo, cs_hi = running_interval(k.astype(float), n.astype(float), confidence, target)
    after_lo = np.concatenate([cp_lo[:, :1], cs_lo[:, 1:]], axis=1)
    after_hi = np.concatenate([cp_hi[:, :1], cs_hi[:, 1:]], axis=1)
    out = {}
    for name, (lo, hi) in {"before": (cp_lo, cp_hi), "after": (after_lo, after_hi)}.items():
        decision, at = first_decision(lo, hi, target)
        samples = np.where(at >= 0, (at + 1) * n0, looks * n0)
        out[name] = {
            "wrong_pass": float(np.mean(decision == 1)),
            "fail": float(np.mean(decision == -1)),
            "undecided": float(np.mean(decision == 0)),
            "samples": float(np.mean(samples)),
            "by_look": np.array([np.mean((decision == 1) & (at <= j)) for j in range(looks)]),
        }
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20000)
    parser.add_argument("--n0", type=int, default=256)
    parser.add_argument("--looks", type=int, default=40)
    parser.add_argument("--ratio", type=float, default=1.02)
    parser.add_argument("--target", type=float, default=0.01)
    parser.add_argument("--confidence", type=float, default=0.95)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    p = args.ratio * args.target
    res = simulate(args.runs, args.n0, args.looks, p, args.target, args.confidence, args.seed)
    se = {k: np.sqrt(v["wrong_pass"] * (1 - v["wrong_pass"]) / args.runs) for k, v in res.items()}
    lines = [
        "# Extending a fixed-count run until it decides: wrong PASS rate",
        "",
        f"`python benchmarks/bench_extend.py --runs {args.runs} --n0 {args.n0} --looks "
        f"{args.looks} --ratio {args.ratio} --target {args.target} --confidence "
        f"{args.confidence} --seed {args.seed}`",
        "",
        f"p = {args.ratio} x target {args.target} (every PASS is wrong); {args.n0} samples, "
        f"then extended by {args.n0} while undecided, at most {args.looks} looks "
        f"({args.n0 * args.looks} samples); {args.runs} simulated users. Nominal: 1 - C = "
        f"{1 - args.confidence:.3g}; after: at most 2 (1 - C) = {2 * (1 - args.confidence):.3g} "
        "(the fixed-count first look plus the sequence).",
        "",
        "| --extend judged by | wrong PASS (± 1 s.e.) | FAIL | undecided at the last look | "
        "mean samples |",
        "|---|---|---|---|---|",
    ]
    for name, words in (
        ("before", "Clopper-Pearson at every look (before)"),
        ("after", "Clopper-Pearson at n0, then the confidence sequence (now)"),
    ):
        r = res[name]
        lines.append(
            f"| {words} | {100 * r['wrong_pass']:.2f} % (± {100 * se[name]:.2f}) | "
            f"{100 * r['fail']:.2f} % | {100 * r['undecided']:.2f} % | {r['samples']:.0f} |"
        )
    text = "\n".join(lines) + "\n"
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench.md").write_text(text, encoding="utf-8")
    print(text)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    counts = args.n0 * np.arange(1, args.looks + 1)
    for name, style in (("before", "-r"), ("after", "-b")):
        ax.plot(counts, 100 * res[name]["by_look"], style, label=f"{name}")
    ax.axhline(100 * (1 - args.confidence), color="k", ls=":", label="nominal 1 - C")
    ax.set_xlabel("samples when the user stops extending (at most)")
    ax.set_ylabel("wrong PASS so far, % of users")
    ax.set_title(f"p = {args.ratio} x target, extended by {args.n0} until decided")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "bench.png", dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
