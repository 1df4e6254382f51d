"""The tolerance allocation before and after bounds valid over every cut tried: how often it
claims a range on a parameter without influence, and how far its bound lies from the exact
one on the offset bar.

* Claim rate: synthetic ensembles (no mechanism): x uniform on [0, 1], each sample failing
  with probability 1.05 x target whatever x (a parameter without influence: every range
  claimed is wrong). 40 seeds (the issue's count) and ``--seeds`` seeds for a tight rate,
  with its exact 95 % interval; the box over two such parameters; and a parameter with
  influence, P(fail | x) = 2.1 t (1 − x), where ranges of large x pass legitimately (wrong:
  the range claimed fails above the target in truth).
* The offset bar (a bar pinned 0.5 m from its centre of mass, m = 2 kg, J ~ U[0.05, 0.15]
  kg m², p = √(m g a/(J + m a²)) <= 4.078727 rad/s: exact P(fail) = 0.3968; target 0.05):
  ``mcchain run`` of 4,096 samples (seed 11), the allocated J >= bound before and after,
  beside the exact 0.08651 kg m²; and the mean bound over 40 closed-form ensembles.

    python benchmarks/bench_allocation.py [--seeds 2000] [--before 995158e]

"Before" is ``mcchain/decision/requirements.py::allocate`` as it was at ``--before`` (read
with ``git show``). Writes ``benchmarks/results/allocation/bench.md``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from at_commit import module_at

from mcchain.decision.allocation import allocate, allocate_box
from mcchain.decision.stats import clopper_pearson
from mcchain.testing.closed_forms import bar_pulsation, pinned_bar_allocation, pinned_bar_exceedance

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "allocation"
M, A, J_LOW, J_HIGH = 2.0, 0.5, 0.05, 0.15
LIMIT = 4.078727090947326
TARGET = 0.05
CONFIDENCE = 0.95

Claim = Callable[[np.ndarray, np.ndarray, float], tuple[bool, float, float]]
"""(x, failed, target) -> (a range claimed, its low, its high)."""


def before(commit: str) -> Claim:
    module = module_at(commit, "mcchain/decision/requirements.py")

    def claim(x: np.ndarray, failed: np.ndarray, target: float) -> tuple[bool, float, float]:
        a = module.allocate(x, (~failed).astype(float), target, CONFIDENCE)
        if math.isnan(a.bound):
            return False, math.nan, math.nan
        return (True, 0.0, a.bound) if a.side == "upper" else (True, a.bound, 1.0)

    return claim


def after(x: np.ndarray, failed: np.ndarray, target: float) -> tuple[bool, float, float]:
    r = allocate(x, failed, target, CONFIDENCE, (0.0, 1.0))
    return r.passes, r.low, r.high


def rate(count: int, total: int) -> str:
    lo, hi = clopper_pearson(count, total, CONFIDENCE)
    return f"{count} of {total} = {100 * count / total:.2f} % [{100 * lo:.2f}, {100 * hi:.2f}]"


def claim_rates(method: Claim, n: int, target: float, seeds: int, p_of_x) -> tuple[int, int]:  # type: ignore[no-untyped-def]
    """(claims, wrong claims) over ``seeds`` ensembles of ``n`` samples."""
    claims = wrong = 0
    for seed in range(seeds):
        rng = np.random.default_rng([20261128, seed])
        x = rng.random(n)
        failed = rng.random(n) < p_of_x(x)
        ok, low, high = method(x, failed, target)
        if ok:
            claims += 1
            wrong += float(np.mean(p_of_x(np.linspace(low, high, 2001)))) > target
    return claims, wrong


def offset_bar_run(seed: int = 11, count: int = 4096) -> Path:
    from mcchain.cli import main
    from mcchain.testing.factory import bar_scene_dict, toml_text

    doc = bar_scene_dict(
        mass=M,
        sample={"count": count, "seed": seed,
                "vary": {"body.bar.inertia": {"uniform": [J_LOW, J_HIGH]}}},
        equilibrium=False,
    )  # fmt: skip
    doc["requirement"] = [{"name": "pulsation", "output": "omega", "select": {"mode": 0},
                           "max": LIMIT, "target": TARGET}]  # fmt: skip
    work = Path(tempfile.mkdtemp(prefix="bench-allocation-"))
    (work / "bar.toml").write_text(toml_text(doc))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["run", str(work / "bar.toml"), "--out", str(work / "runs"), "--quiet"]) == 0
    return Path(out.getvalue().strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2000)
    parser.add_argument("--before", default="995158e")
    args = parser.parse_args()
    methods = {f"before ({args.before})": before(args.before), "after": after}
    lines = [
        "# Tolerance allocation: claim rate and bound, before and after",
        "",
        f"`python benchmarks/bench_allocation.py --seeds {args.seeds} --before {args.before}`; "
        f"confidence {CONFIDENCE} (one-sided: a claim is wrong with probability at most "
        f"{1 - CONFIDENCE:.2f} by construction after)",
        "",
        "## Claims on a parameter without influence (P(fail) = 1.05 x target, every claim wrong)",
        "",
        "| method | samples | target | 40 seeds | all seeds, rate [95 % interval] |",
        "| --- | --- | --- | --- | --- |",
    ]
    flat = lambda t: lambda x: np.full_like(x, 1.05 * t)  # noqa: E731
    for n, t in ((4096, 0.01), (1000, 0.05)):
        for name, method in methods.items():
            first, _ = claim_rates(method, n, t, 40, flat(t))
            total, _ = claim_rates(method, n, t, args.seeds, flat(t))
            row = f"| {name} | {n} | {t} | {first} of 40 | {rate(total, args.seeds)} |"
            lines.append(row)
            print(row, flush=True)
    boxes = 0
    box_seeds = min(args.seeds, 1000)
    for seed in range(box_seeds):
        rng = np.random.default_rng([7, seed])
        x = rng.random((1000, 2))
        failed = rng.random(1000) < 1.05 * TARGET
        boxes += allocate_box(x, failed, TARGET, CONFIDENCE, np.array([[0.0, 1.0]] * 2)).passes
    lines += ["", f"Box over two parameters without influence (1,000 samples, target {TARGET}): "
              f"{rate(boxes, box_seeds)} claimed.", ""]  # fmt: skip
    lines += [
        "## A parameter with influence: P(fail | x) = 2.1 t (1 − x), t = 0.05, 2,000 samples",
        "",
        "| method | claims | wrong claims (exact P(fail) of the range > t) |",
        "| --- | --- | --- |",
    ]
    slope = lambda x: 2.1 * TARGET * (1 - x)  # noqa: E731
    seeds = min(args.seeds, 1000)
    for name, method in methods.items():
        claims, wrong = claim_rates(method, 2000, TARGET, seeds, slope)
        lines.append(f"| {name} | {rate(claims, seeds)} | {rate(wrong, seeds)} |")
        print(lines[-1], flush=True)

    exact = pinned_bar_allocation(LIMIT, TARGET, M, A, J_LOW, J_HIGH)
    p_exact = float(pinned_bar_exceedance(LIMIT, M, A, J_LOW, J_HIGH))
    import mcchain as mc

    run = offset_bar_run()
    with mc.open_run(run) as ds:
        J = ds["parameters"].values[:, 0]
        failed = ds["requirement_met"].values[:, 0] == 0
    old = methods[f"before ({args.before})"](J, failed, TARGET)
    new = allocate(J, failed, TARGET, CONFIDENCE, (J_LOW, J_HIGH))
    j_star = J_LOW + p_exact * (J_HIGH - J_LOW)

    def conditional(b: float) -> float:
        return (j_star - b) / (J_HIGH - b)

    gaps = {name: [] for name in methods}
    for seed in range(40):
        Jr = np.random.default_rng([3, seed]).uniform(J_LOW, J_HIGH, 4096)
        fr = bar_pulsation(M, Jr, A) > LIMIT
        for name, method in methods.items():
            ok, low, _ = method(Jr, fr, TARGET)
            gaps[name].append(low - exact if ok else math.nan)
    lines += [
        "",
        f"## Offset bar, J ~ U[{J_LOW}, {J_HIGH}] kg m2, target {TARGET}: the allocated J >= b",
        "",
        f"`mcchain run` of 4,096 samples, seed 11: {int(failed.sum())} failed (exact P(fail) "
        f"{p_exact:.4f}); exact allocation b* = {exact:.5f} kg m2 "
        f"(P(fail) for J >= b* is {TARGET})",
        "",
        "| method | b (kg m2) | b − b* | exact P(fail) for J >= b | samples kept | "
        "mean b − b* over 40 closed-form ensembles |",
        "| --- | --- | --- | --- | --- | --- |",
        f"| before | {old[1]:.5f} | {old[1] - exact:+.5f} | {conditional(old[1]):.4f} | "
        f"{int(np.sum(J >= old[1]))} | {np.nanmean(gaps[f'before ({args.before})']):+.5f} |",
        f"| after | {new.low:.5f} | {new.low - exact:+.5f} | {conditional(new.low):.4f} | "
        f"{new.samples_kept} | {np.nanmean(gaps['after']):+.5f} |",
        "",
        f"after: p_upper {new.p_upper:.4f} over every cut tried (side {new.side}); the range "
        f"kept is {100 * (J_HIGH - new.low) / (J_HIGH - exact):.1f} % of the exact one's width.",
    ]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
