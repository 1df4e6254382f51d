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


IN_PROCESS = """
import sys, time, tomllib
from mcchain.scene import compile_model, load_scene_text
from mcchain.testing.comparisons import simulate_float64
text, samples, repeats = open(sys.argv[1]).read(), int(sys.argv[2]), int(sys.argv[3])
model = compile_model(load_scene_text(text), nsample=samples)
settings = tomllib.loads(text)["simulate"]
simulate_float64(model, settings)  # compile or load the kernels
best = min(
    (lambda t0: (simulate_float64(model, settings), time.process_time() - t0)[1])(
        time.process_time())
    for _ in range(repeats)
)
print(best)
"""
"""Best CPU time (s) of ``repeats`` simulate calls in one process (one numba thread), after a
warm-up call: CPU time, unlike wall time, does not count the time other jobs hold the core."""


def run_in_process(tree: Path, scene: Path, samples: int, cache: Path, repeats: int) -> float:
    """Best CPU time (s) of ``repeats`` runs of ``scene`` in one fresh process from ``tree``:
    the best of several in-process runs is far less disturbed by other jobs than one run."""
    env = {**os.environ, "PYTHONPATH": str(tree), "MCCHAIN_CACHE_DIR": str(cache),
           "NUMBA_NUM_THREADS": "1"}  # fmt: skip
    result = subprocess.run(
        [sys.executable, "-c", IN_PROCESS, str(scene), str(samples), str(repeats)],
        env=env, check=True, capture_output=True, text=True, cwd=tree,
    )  # fmt: skip
    return float(result.stdout.split()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="source tree before")
    parser.add_argument("--after", type=Path, default=REPO, help="source tree after")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="", help="run only cases whose label has this")
    parser.add_argument("--work", type=Path, help="work folder (its caches are reused)")
    parser.add_argument("--title", default="a run", help="the new section's title")
    parser.add_argument(
        "--in-process", type=int, default=0, metavar="R",
        help="time R simulate calls per process (best CPU time; figures in runs per CPU second)",
    )  # fmt: skip
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
                cache = work / f"cache-{side}"
                if args.in_process:  # a speed: runs per second
                    cpu = run_in_process(tree, scene, samples, cache, args.in_process)
                    speeds[side].append(1.0 / cpu)
                else:
                    speeds[side].append(run(tree, scene, samples, cache, work))
        ratio = statistics.median(speeds["after"]) / statistics.median(speeds["before"])
        best = max(speeds["after"]) / max(speeds["before"])
        row = {"case": label, "samples": samples, **speeds, "ratio": ratio, "best": best}
        print(json.dumps(row), flush=True)
        rows.append(row)
    write(rows, args.repeats, args.title, args.in_process)
    return 0


def write(rows: list[dict], repeats: int, title: str, in_process: int = 0) -> None:
    """A new section on top of ``bench.md`` (earlier rounds are kept below it)."""
    OUT.mkdir(parents=True, exist_ok=True)
    head = "# Lanes and loop kernels before and after: one source of the physics (issue 28)"
    unit = "runs per CPU s" if in_process else "instance-steps/s"
    lines = [
        head,
        "",
        f"## {title}",
        "",
        (
            f"Each figure is the best of {in_process} simulate calls in one fresh process "
            "(1 numba thread; runs per CPU second, after a warm-up call)"
            if in_process
            else "Each figure is one `mcchain run --threads 1` in a fresh process (compute-only "
            "instance-steps/s from run.json)"
        )
        + f", {repeats} per tree, the trees alternating; kernels "
        "compiled before timing. Ratios after/before (> 1: faster after) of the medians and "
        "of the best runs (the best is the run least slowed by other jobs on the shared "
        "machine). Generated by `python benchmarks/bench_shared_physics.py --before <tree> "
        "--after <tree>`.",
        "",
        f"| case | samples | before ({unit}) | after ({unit}) | median ratio | best ratio |",
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
