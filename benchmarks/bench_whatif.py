"""What-if tolerances against fresh runs: P(fail) reweighted from one ensemble at narrowed
parameter ranges (``whatif.csv``) beside new runs sampled at those ranges.

The Flores slider-crank of ``configs/slider-crank-requirement.toml`` cut to one crank turn
(t_end = 12 ms), its piston pin's clearance U[0.1, 0.5] mm and restitution U[0.7, 0.95]
sampled as shipped, plus the crank speed N(523.6, 15) rad/s; requirement: the pin's peak
contact force below the median of a 256-sample pilot run (seed 1). The base ensemble
(``--samples``, seeds 3, 4, ... for ``--bases`` ensembles) gives the reweighted rows; each
narrowed distribution is then run afresh (``--fresh`` samples, four times as many by
default, seed 1000) and its own P(fail) compared: the fresh estimate must lie in the
reweighted bounds (each end one-sided 95 %: a 90 % interval), counted over the base
ensembles. The fresh run has its own sampling error (its exact interval is shown); with four
times the samples it is half a base ensemble's.

    python benchmarks/bench_whatif.py [--samples 1024] [--fresh 4096] [--bases 10]

Writes ``benchmarks/results/whatif/bench.md``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mcchain import open_run
from mcchain.decision.stats import one_sided_bounds
from mcchain.decision.whatif import whatifs
from mcchain.runner import plan

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "whatif"
CLEARANCE = '"joint.B.clearance" = { uniform = [1e-4, 5e-4] } # m'
RESTITUTION = '"joint.B.contact.restitution" = { uniform = [0.7, 0.95] }'
OMEGA = '"driver.crank.omega" = { normal = [523.5987755982989, 15.0] }'
CHANGES = (
    ("joint.B.clearance", "lower", 0.5),
    ("joint.B.clearance", "central", 0.5),
    ("joint.B.contact.restitution", "upper", 0.4),
    ("driver.crank.omega", "sigma", 0.3),
)
"""The narrowed distributions run afresh: (parameter, change, share)."""


def scene_text(limit: float, vary: dict[str, str] | None = None) -> str:
    text = (REPO / "configs" / "slider-crank-requirement.toml").read_text(encoding="utf-8")
    lines = []
    for line in text.splitlines():
        key = line.split("=")[0].strip()
        if key == "t_end":
            line = "t_end = 0.012"
        elif key == "max":
            line = f"max = {limit!r}"
        elif line.startswith(RESTITUTION):
            line = RESTITUTION + "\n" + OMEGA
        lines.append(line)
    text = "\n".join(lines) + "\n"
    for path, table in (vary or {}).items():
        old = {
            "joint.B.clearance": CLEARANCE,
            "joint.B.contact.restitution": RESTITUTION,
            "driver.crank.omega": OMEGA,
        }[path]
        text = text.replace(old, f'"{path}" = {table}')
    return text


def run(folder: Path, name: str, text: str, samples: int, seed: int) -> tuple[Path, float]:
    (folder / f"{name}.toml").write_text(text, encoding="utf-8")
    t0 = time.perf_counter()
    result = plan.start_run(
        folder / f"{name}.toml", samples=samples, seed=seed, run_dir=folder / name, progress=False
    )
    return result.folder, time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1024)
    parser.add_argument("--fresh", type=int, default=None, help="default: 4 x --samples")
    parser.add_argument("--bases", type=int, default=10, help="base ensembles (seeds 3, 4, ...)")
    args = parser.parse_args()
    fresh_count = args.fresh or 4 * args.samples
    work = Path(tempfile.mkdtemp(prefix="bench-whatif-"))
    pilot, _ = run(work, "pilot", scene_text(1e30), 256, 1)
    with open_run(pilot) as ds:
        limit = float(np.median(ds["peak_contact_force"].sel(joint="B").values))
    bases = []
    for b in range(args.bases):
        base, base_s = run(work, f"base{b}", scene_text(limit), args.samples, 3 + b)
        with open_run(base) as ds:
            bases.append(whatifs(ds))

    def pick(rows: list, path: str, change: str, share: float):  # type: ignore[no-untyped-def]
        return next(
            r
            for r in rows
            if (r.parameter, r.change) == (path, change) and abs(r.share - share) < 1e-9
        )

    lines = [
        "# What-if tolerances against fresh runs (slider-crank, one crank turn)",
        "",
        f"`python benchmarks/bench_whatif.py --samples {args.samples} --fresh {fresh_count} "
        f"--bases {args.bases}`: limit {limit:.1f} N (median of a 256-sample pilot); "
        f"{args.bases} base ensembles of {args.samples} samples (seeds 3..{2 + args.bases}, "
        f"{base_s:.0f} s each); each fresh run {fresh_count} samples, seed 1000. Bounds: each "
        "end one-sided 95 % (a 90 % interval). The first base ensemble's row, then how many of "
        "the base ensembles' bounds hold the fresh estimate.",
        "",
        "| parameter | change | share | distribution | reweighted P(fail) [bounds], base 1 | "
        "samples (n_eff) | fresh P(fail) [its own bounds] | fresh inside, of the bases |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    total = inside_total = 0
    for path, change, share in CHANGES:
        row = pick(bases[0], path, change, share)
        text = scene_text(limit, {path: row.distribution})
        fresh, _ = run(work, f"{change}-{path}", text, fresh_count, 1000)
        with open_run(fresh) as ds:
            failed = ds["requirement_met"].values[:, 0] == 0
        k, n = int(failed.sum()), failed.size
        lo, hi = one_sided_bounds(k, n, 0.95)
        held = [
            r.p_lower <= k / n <= r.p_upper for r in (pick(b, path, change, share) for b in bases)
        ]
        total += len(held)
        inside_total += sum(held)
        lines.append(
            f"| {path} | {change} | {share:g} | `{row.distribution}` | {row.p_fail:.4f} "
            f"[{row.p_lower:.4f}, {row.p_upper:.4f}] | {row.samples} ({row.n_eff:.0f}) | "
            f"{k / n:.4f} [{lo:.4f}, {hi:.4f}] | {sum(held)} of {len(held)} |"
        )
        print(lines[-1], flush=True)
    first = next(r for r in bases[0] if r.change == "central" and r.share == 1.0)
    lines += [
        "",
        f"In all: the fresh estimate lies inside the reweighted bounds in {inside_total} of "
        f"{total} comparisons ({100 * inside_total / total:.0f} %; a 90 % interval, and the "
        "fresh estimate has its own sampling error).",
        "",
        f"As sampled (base 1): P(fail) {first.p_fail:.4f} [{first.p_lower:.4f}, "
        f"{first.p_upper:.4f}] ({first.samples} samples).",
    ]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
