"""What-if tolerances against fresh runs: P(fail) reweighted from one ensemble at narrowed
parameter ranges (``whatif.csv``) beside new runs sampled at those ranges.

The Flores slider-crank of ``configs/slider-crank-requirement.toml`` cut to one crank turn
(t_end = 12 ms), its piston pin's clearance U[0.1, 0.5] mm and restitution U[0.7, 0.95]
sampled as shipped, plus the crank speed N(523.6, 15) rad/s; requirement: the pin's peak
contact force below the median of a 256-sample pilot run (seed 1). The base ensemble
(``--samples``, seed 3) gives the reweighted rows; each narrowed distribution is then run
afresh (``--fresh`` samples, four times as many by default, seed 4) and its own P(fail)
compared: the fresh estimate must lie in the reweighted bounds (each end one-sided 95 %).
The fresh run has its own sampling error (its exact interval is shown); with four times the
samples it is half the base ensemble's.

    python benchmarks/bench_whatif.py [--samples 1024] [--fresh 4096]

Writes ``benchmarks/results/whatif/bench.md``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mcchain import execution, open_run
from mcchain.decision.stats import clopper_pearson
from mcchain.decision.whatif import whatifs

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
    result = execution.start_run(
        folder / f"{name}.toml", samples=samples, seed=seed, run_dir=folder / name, progress=False
    )
    return result.folder, time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1024)
    parser.add_argument("--fresh", type=int, default=None, help="default: 4 x --samples")
    args = parser.parse_args()
    fresh_count = args.fresh or 4 * args.samples
    work = Path(tempfile.mkdtemp(prefix="bench-whatif-"))
    pilot, _ = run(work, "pilot", scene_text(1e30), 256, 1)
    with open_run(pilot) as ds:
        limit = float(np.median(ds["peak_contact_force"].sel(joint="B").values))
    base, base_s = run(work, "base", scene_text(limit), args.samples, 3)
    with open_run(base) as ds:
        rows = whatifs(ds)
    lines = [
        "# What-if tolerances against fresh runs (slider-crank, one crank turn)",
        "",
        f"`python benchmarks/bench_whatif.py --samples {args.samples} --fresh {fresh_count}`: "
        f"limit {limit:.1f} N (median of a 256-sample pilot); base ensemble {args.samples} "
        f"samples, seed 3 ({base_s:.0f} s); each fresh run {fresh_count} samples, seed 4. "
        "Bounds: each end one-sided 95 %.",
        "",
        "| parameter | change | share | distribution | reweighted P(fail) [bounds] | samples "
        "(n_eff) | fresh P(fail) [its own bounds] | fresh inside reweighted |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for path, change, share in CHANGES:
        (row,) = [
            r
            for r in rows
            if (r.parameter, r.change) == (path, change) and abs(r.share - share) < 1e-9
        ]
        text = scene_text(limit, {path: row.distribution})
        fresh, _ = run(work, f"{change}-{path}", text, fresh_count, 4)
        with open_run(fresh) as ds:
            failed = ds["requirement_met"].values[:, 0] == 0
        k, n = int(failed.sum()), failed.size
        lo, hi = clopper_pearson(k, n, 0.9)  # each end one-sided 95 %
        inside = row.p_lower <= k / n <= row.p_upper
        lines.append(
            f"| {path} | {change} | {share:g} | `{row.distribution}` | {row.p_fail:.4f} "
            f"[{row.p_lower:.4f}, {row.p_upper:.4f}] | {row.samples} ({row.n_eff:.0f}) | "
            f"{k / n:.4f} [{lo:.4f}, {hi:.4f}] | {'yes' if inside else 'NO'} |"
        )
        print(lines[-1], flush=True)
    first = next(r for r in rows if r.change == "central" and r.share == 1.0)
    lines += [
        "",
        f"As sampled: P(fail) {first.p_fail:.4f} [{first.p_lower:.4f}, {first.p_upper:.4f}] "
        f"({first.samples} samples).",
    ]
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
