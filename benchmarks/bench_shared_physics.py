"""Lanes and loop kernels before and after a change of the physics' source, side by side.

Issue 28 item 1 moved each joint's, driver's and force's arithmetic into straight-line
functions of ``mcchain/kernels/`` that the loop kernels call and the lane generator inlines.
This script measures that the generated lanes (rk4, rk45) and the loop kernels kept their
speed: the same scenes run from two source trees (``--before``, ``--after``: each a checkout
of the package), alternating tree by tree in fresh processes, each tree with its own warm
caches; the figure is ``run.json``'s compute-only instance-steps per second.

    python benchmarks/bench_shared_physics.py --before /tmp/main --after . [--repeats 3]

Writes ``benchmarks/results/shared_physics/bench.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "shared_physics"
sys.path.insert(0, str(REPO))

from mcchain.testing.scenes import LOADED_TEXT  # noqa: E402

SLIDER_CRANK = (REPO / "configs" / "slider-crank-flores.toml").read_text()

# (label, scene text, [simulate] keys, samples): a driven clearance double pendulum with a
# force, a couple and two spring-dampers; the Flores slider-crank (prismatic joint, contact
# law at the piston pin). The loop kernels integrate with rk4 only.
CASES = [
    ("loaded, rk4 lanes", LOADED_TEXT, 't_end = 0.2\ndt = 1e-5\nmethod = "rk4"\n'
     'kernels = "lanes"', 128),
    ("loaded, rk45 lanes", LOADED_TEXT, 't_end = 0.5\ndt = 1e-5\nmethod = "rk45"\n'
     'rtol = 1e-9\natol = 1e-12\nkernels = "lanes"', 128),
    ("loaded, rk4 loop", LOADED_TEXT, 't_end = 0.1\ndt = 1e-5\nmethod = "rk4"\n'
     'kernels = "loop"', 16),
    ("slider-crank contact, rk45 lanes", SLIDER_CRANK, 't_end = 0.024\ndt = 1e-7\n'
     'output_dt = 1e-5\nmethod = "rk45"\nrtol = 1e-7\natol = 1e-10\nkernels = "lanes"', 32),
    ("slider-crank contact, rk4 loop", SLIDER_CRANK, 't_end = 0.001\ndt = 1e-7\n'
     'output_dt = 1e-5\nmethod = "rk4"\nkernels = "loop"', 8),
]  # fmt: skip


def scene_text(text: str, simulate: str) -> str:
    """``text`` with its [simulate] table (if any) replaced by ``simulate``'s keys."""
    text = re.sub(r"(?ms)^\[simulate\]\n.*?(?=^\[)", "", text + "\n[end]\n")
    return text.replace("\n[end]\n", "") + f"\n[simulate]\n{simulate}\n"


def run(tree: Path, scene: Path, samples: int, cache: Path, out: Path) -> float:
    """Instance-steps per second (compute only) of one ``mcchain run`` from ``tree``."""
    env = {**os.environ, "PYTHONPATH": str(tree), "MCCHAIN_CACHE_DIR": str(cache)}
    folder = out / f"run-{time.monotonic_ns()}"
    subprocess.run(
        [sys.executable, "-m", "mcchain.cli", "run", str(scene), "--samples", str(samples),
         "--run-dir", str(folder), "--quiet", "--no-background-compile", "--threads", "1"],
        env=env, check=True, capture_output=True, text=True, cwd=tree,
    )  # fmt: skip
    record = json.loads((folder / "run.json").read_text())
    return float(record["throughput"]["instance_steps_per_s"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="source tree before")
    parser.add_argument("--after", type=Path, default=REPO, help="source tree after")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="", help="run only cases whose label has this")
    parser.add_argument("--work", type=Path, help="work folder (its caches are reused)")
    parser.add_argument("--title", default="a run", help="the new section's title")
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-shared-"))
    work.mkdir(parents=True, exist_ok=True)
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    rows = []
    for label, text, simulate, samples in CASES:
        if args.only not in label:
            continue
        scene = work / (re.sub(r"\W+", "-", label) + ".toml")
        scene.write_text(scene_text(text, simulate))
        for side, tree in trees.items():  # warm: compile (or load) the kernels once
            run(tree, scene, 4, work / f"cache-{side}", work)
        speeds: dict[str, list[float]] = {"before": [], "after": []}
        for _ in range(args.repeats):  # alternating, so both see the same machine load
            for side, tree in trees.items():
                speeds[side].append(run(tree, scene, samples, work / f"cache-{side}", work))
        ratio = statistics.median(speeds["after"]) / statistics.median(speeds["before"])
        best = max(speeds["after"]) / max(speeds["before"])
        row = {"case": label, "samples": samples, **speeds, "ratio": ratio, "best": best}
        print(json.dumps(row), flush=True)
        rows.append(row)
    write(rows, args.repeats, args.title)
    return 0


def write(rows: list[dict], repeats: int, title: str) -> None:
    """A new section on top of ``bench.md`` (earlier rounds are kept below it)."""
    OUT.mkdir(parents=True, exist_ok=True)
    head = "# Lanes and loop kernels before and after: one source of the physics (issue 28)"
    lines = [
        head,
        "",
        f"## {title}",
        "",
        "Each figure is one `mcchain run --threads 1` in a fresh process (compute-only "
        f"instance-steps/s from run.json), {repeats} per tree, the trees alternating; kernels "
        "compiled before timing. Ratios after/before (> 1: faster after) of the medians and "
        "of the best runs (the best is the run least slowed by other jobs on the shared "
        "machine). Generated by `python benchmarks/bench_shared_physics.py --before <tree> "
        "--after <tree>`.",
        "",
        "| case | samples | before (instance-steps/s) | after (instance-steps/s) "
        "| median ratio | best ratio |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        before = ", ".join(f"{x:.3g}" for x in r["before"])
        after = ", ".join(f"{x:.3g}" for x in r["after"])
        lines.append(
            f"| {r['case']} | {r['samples']} | {before} | {after} | {r['ratio']:.3f} "
            f"| {r['best']:.3f} |"
        )
    path = OUT / "bench.md"
    earlier = path.read_text().removeprefix(head).lstrip("\n") if path.exists() else ""
    path.write_text("\n".join(lines) + "\n\n" + earlier)


if __name__ == "__main__":
    raise SystemExit(main())
