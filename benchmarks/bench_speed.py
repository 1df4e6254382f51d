"""Issue 37's figures for two source trees side by side: rk4 lanes against MuJoCo, rk45
against rk4, warm start, and a 4,096-sample verdict end to end.

    python benchmarks/bench_speed.py --before REF [--after REF] [--rounds 3] [--only ...]

Each commit is exported to a temporary folder and run with this interpreter (``PYTHONPATH`` =
that folder), with its own caches, warmed first. Every figure is the best of its repeats in a
fresh process; the two trees alternate round by round so that both see the same machine load
(``uptime``'s 1-minute load average is printed with each round). Sections:

* ``mujoco``: rk4 lanes on the clearance double pendulum (10⁴ samples, 2,000 steps of
  1e-4 s) against ``mujoco.rollout`` (RK4, the ideal-joint double pendulum in minimal
  coordinates; ``pip install mujoco``), ns per instance-step, 2 threads (wall) and 1 thread
  (CPU); each round also measures the machine's peak beside them (``benchmarks/peak.py``'s
  NumPy dgemm, 2 and 1 BLAS threads), and with ``--flops BEFORE,AFTER`` (flops per
  instance-step of each tree's text: ``bench_roofline.py --count``) the lanes' GFLOP/s as
  a fraction of the peak measured in the same run (the best of each, and the median of
  the rounds' own fractions);
* ``adaptive``: the Flores slider-crank (``configs/slider-crank-flores.toml``, 512 samples,
  4 ms): rk45 as configured against rk4 at dt = 1e-6 s, ns per instance-step (accepted
  steps), 1 thread (CPU) and 2 threads (wall), and their ratio: of the best times, and the
  median of the repeats' own ratios (the two methods alternate, each repeat's pair timed in
  one moment of the shared machine);
* ``warm``: a warm ``mcchain run`` of the slider-crank with ``method = "radau"`` (4 samples,
  2 ms): end to end and its warm-up (run.json's ``warmup``: the kernel set's loads and the
  imports its first calls make; the kernel set's load alone, item 5, is bench_warm.py's);
* ``verdict``: a warm ``mcchain run`` of ``configs/slider-crank-requirement.toml`` (4,096
  samples, its verdict), end to end and its phases, 2 threads.

Appends its table to ``benchmarks/results/speed/speed.md`` (earlier runs and readings kept).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from peak import dgemm  # the ceilings' own dgemm, in a fresh process

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "speed"

KERNELS = r"""
import json, os, sys, time
import numpy as np
import numba
from mcchain.solvers.simulate import simulate
section, repeats = sys.argv[1], int(sys.argv[2])

def once(run, threads, units):
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    c0, t0 = time.process_time(), time.perf_counter()
    run()
    spent = time.process_time() - c0 if threads == 1 else time.perf_counter() - t0
    return spent / units * 1e9

def best(run, threads, units):
    return min(once(run, threads, units) for _ in range(repeats))

result = {}
if section == "mujoco":
    from mcchain.testing.scenes import DOUBLE_PENDULUM, model_of
    from mcchain.testing.scenes import straight_chain_text as chain_text
    n = 10_000
    model = model_of(chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4}), nsample=n)
    sim = dict(t_end=0.2, dt=1e-4, output_dt=1e-2, method="rk4", kernels="lanes")
    simulate(model.select(0, 64), sim)
    for th in (2, 1):
        result[f"rk4_{th}"] = best(lambda: simulate(model, sim), th, n * 2000)
else:
    from mcchain.scene import compile_model, load_scene_text
    from mcchain.solvers.statics import assemble
    text = open("configs/slider-crank-flores.toml").read().replace("count = 64", "count = 512")
    scene = load_scene_text(text)
    model = compile_model(scene)
    start = assemble(model)
    base = dict(scene.simulate.model_dump(), t_end=0.004, kernels="lanes")
    runs, steps = {}, {}
    for method, extra in (("rk4", {"dt": 1e-6}), ("rk45", {})):
        sim = dict(base, method=method, **extra)
        runs[method] = lambda sim=sim: simulate(model, sim, q_start=start.q, v_start=start.v,
                                                status=start.status, diagnostics=True)
        steps[method] = result[f"{method}_steps"] = float(np.sum(runs[method]()["steps"]))
    for th in (1, 2):  # the two methods alternate: each repeat's ratio in one moment
        times = {m: [] for m in runs}
        for r in range(repeats):
            for m in ("rk4", "rk45") if r % 2 == 0 else ("rk45", "rk4"):
                times[m].append(once(runs[m], th, steps[m]))
        for m in runs:
            result[f"{m}_{th}"] = min(times[m])
        result[f"ratio_{th}"] = [a / b for a, b in zip(times["rk45"], times["rk4"])]
result["load"] = os.getloadavg()[0]
print(json.dumps(result))
"""

MUJOCO = r"""
import json, math, os, sys, time
import numpy as np
sys.path.insert(0, "benchmarks")
from integrators import _mujoco_chain
from mcchain.testing.scenes import DOUBLE_PENDULUM
repeats = int(sys.argv[1])
out = {}
for th in (2, 1):
    out[f"mujoco_{th}"] = min(_mujoco_chain(**DOUBLE_PENDULUM, dt=1e-4, nstep=200, nsample=10_000,
                                            threads=th, cpu=th == 1) for _ in range(repeats))
out["load"] = os.getloadavg()[0]
print(json.dumps(out))
"""


def append_results(path: Path, text: str) -> None:
    """Append ``text`` (a section with its own heading) to the results file ``path``: the
    sections of earlier runs, and the readings written under them, are kept."""
    path.parent.mkdir(parents=True, exist_ok=True)
    earlier = path.read_text("utf-8") if path.exists() else ""
    path.write_text(earlier.rstrip("\n") + "\n\n" + text if earlier else text, "utf-8")


def export(ref: str, parent: Path) -> Path:
    """The tree of commit ``ref`` (or a folder as it is) in ``parent``."""
    if Path(ref).is_dir():
        return Path(ref).resolve()
    sha = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", ref], check=True,
                         capture_output=True, text=True).stdout.strip()  # fmt: skip
    tree = parent / f"tree-{sha}"
    if not tree.exists():
        tree.mkdir(parents=True)
        archive = subprocess.run(["git", "-C", str(REPO), "archive", sha], check=True,
                                 capture_output=True).stdout  # fmt: skip
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def _env(tree: Path, cache: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(tree), "MCCHAIN_CACHE_DIR": str(cache / "mcchain"),
            "NUMBA_CACHE_DIR": str(cache / "numba"), "MCCHAIN_INTERPRET_COLD": "0"}  # fmt: skip


def kernels(tree: Path, cache: Path, section: str, repeats: int) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", KERNELS, section, str(repeats)], cwd=tree,
                         env=_env(tree, cache), capture_output=True, text=True)  # fmt: skip
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    return json.loads(out.stdout.splitlines()[-1])


def mcchain_run(tree: Path, cache: Path, scene: Path, work: Path, *extra: str) -> dict[str, Any]:
    """End-to-end wall time of ``mcchain run`` and its run.json timings."""
    folder = work / f"run-{time.monotonic_ns()}"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mcchain.cli", "run", str(scene), "--run-dir",
                    str(folder), "--quiet", "--no-background-compile", *extra], cwd=tree,
                   env=_env(tree, cache), check=True, capture_output=True)  # fmt: skip
    wall = time.perf_counter() - t0
    record = json.loads((folder / "run.json").read_text())
    size = (folder / "ensemble.nc").stat().st_size if (folder / "ensemble.nc").exists() else 0
    return {"wall": wall, "timings": record.get("timings", {}), "size_mb": size / 1e6,
            "load": os.getloadavg()[0]}  # fmt: skip


def radau_scene(work: Path) -> Path:
    text = (REPO / "configs" / "slider-crank-flores.toml").read_text()
    text = text.replace('method = "rk45"', 'method = "radau"').replace("count = 64", "count = 4")
    text = re.sub(r"t_end = 0\.024", "t_end = 0.002", text)
    path = work / "slider-crank-radau.toml"
    path.write_text(text)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True)
    parser.add_argument("--after", default=str(REPO))
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--only", default="mujoco,adaptive,warm,verdict")
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument(
        "--flops", default=None, help="flops per instance-step of the before and after texts: B,A"
    )
    args = parser.parse_args(argv)
    sections = args.only.split(",")
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-speed-"))
    work.mkdir(parents=True, exist_ok=True)  # a --work folder not made yet
    trees = {"before": export(args.before, work), "after": export(args.after, work)}
    caches = {k: work / f"cache-{k}" for k in trees}
    radau = radau_scene(work)
    verdict = REPO / "configs" / "slider-crank-requirement.toml"
    results: dict[str, list[dict[str, Any]]] = {}

    def add(key: str, value: dict[str, Any]) -> None:
        results.setdefault(key, []).append(value)
        print(key, json.dumps(value), flush=True)

    for name, tree in trees.items():  # warm every cache first (compiles are not timed)
        if "warm" in sections:
            mcchain_run(tree, caches[name], radau, work)
        if "verdict" in sections:
            mcchain_run(tree, caches[name], verdict, work, "--samples", "64")
    for r in range(args.rounds):
        for name, tree in trees.items() if r % 2 == 0 else reversed(trees.items()):
            for section in ("mujoco", "adaptive"):
                if section in sections:
                    add(f"{section}:{name}", kernels(tree, caches[name], section, args.repeats))
            if "warm" in sections:
                add(f"warm:{name}", mcchain_run(tree, caches[name], radau, work))
            if "verdict" in sections:
                add(f"verdict:{name}", mcchain_run(tree, caches[name], verdict, work))
        if "mujoco" in sections:
            out = subprocess.run([sys.executable, "-c", MUJOCO, str(args.repeats)], cwd=REPO,
                                 env={**os.environ, "PYTHONPATH": str(REPO)},
                                 capture_output=True, text=True, check=True)  # fmt: skip
            add("mujoco:reference", json.loads(out.stdout.splitlines()[-1]))
            add(
                "peak",
                {f"dgemm_{th}": dgemm(th, None)["gflops"] for th in (2, 1)}
                | {"load": os.getloadavg()[0]},
            )
    text = report(results, args, trees)
    print(text)
    append_results(OUT / "speed.md", text)
    return 0


def _best(rows: list[dict[str, Any]], key: str) -> float:
    return min(float(r[key]) for r in rows)


def _peak_rows(results: dict[str, list[dict[str, Any]]], flops: str) -> list[str]:
    """Rows of the lanes' GFLOP/s against the dgemm peak measured in the same rounds:
    the best kernel time over the best dgemm, and the median of each round's own ratio
    (kernel rows of round r beside peak row r)."""
    counts = dict(zip(("before", "after"), map(float, flops.split(",")), strict=True))
    peaks = results["peak"]
    lines = []
    for th in (2, 1):
        best_peak = max(float(r[f"dgemm_{th}"]) for r in peaks)
        cells = []
        for k in ("before", "after"):
            rows = results[f"mujoco:{k}"]
            best = counts[k] / _best(rows, f"rk4_{th}")  # flops per ns = GFLOP/s
            per_round = [counts[k] / float(r[f"rk4_{th}"]) / float(p[f"dgemm_{th}"])
                         for r, p in zip(rows, peaks, strict=True)]  # fmt: skip
            cells.append(
                f"{best:.1f} GFLOP/s = {100 * best / best_peak:.0f} % "
                f"(rounds' median {100 * statistics.median(per_round):.0f} %)"
            )
        lines.append(f"| rk4 lanes / dgemm peak ({best_peak:.1f} GFLOP/s), {th} thread(s) | "
                     f"{cells[0]} | {cells[1]} | ≥ 50 % |")  # fmt: skip
    return lines


def report(results: dict[str, list[dict[str, Any]]], args: argparse.Namespace,
           trees: dict[str, Path]) -> str:  # fmt: skip
    lines = [
        f"## Issue 37: before and after, side by side ({datetime.date.today()})",
        "",
        f"`python benchmarks/bench_speed.py --before {args.before} --after {args.after} "
        f"--rounds {args.rounds} --repeats {args.repeats} --only {args.only}"
        + (f" --flops {args.flops}" if args.flops else "")
        + "`; best of each "
        "figure's repeats and rounds; load averages "
        + ", ".join(f"{r['load']:.1f}" for rows in results.values() for r in rows)
        + ".",
        "",
        "| figure | before | after | goal |",
        "|---|---|---|---|",
    ]
    if "mujoco:before" in results:
        ref = results["mujoco:reference"]
        for th in (2, 1):
            mj = _best(ref, f"mujoco_{th}")
            b, a = (_best(results[f"mujoco:{k}"], f"rk4_{th}") for k in ("before", "after"))
            lines.append(f"| rk4 lanes, clearance double pendulum, {th} thread(s), ns per "
                         f"instance-step | {b:.1f} | {a:.1f} | |")  # fmt: skip
            lines.append(f"| MuJoCo rollout ({mj:,.0f} ns) / rk4 lanes, {th} thread(s) | "
                         f"{mj / b:.0f}× | {mj / a:.0f}× | ≥ 150× |")  # fmt: skip
        if args.flops:
            lines += _peak_rows(results, args.flops)
    if "adaptive:before" in results:
        for th in (1, 2):
            cells = []
            for k in ("before", "after"):
                rows = results[f"adaptive:{k}"]
                r45, r4 = _best(rows, f"rk45_{th}"), _best(rows, f"rk4_{th}")
                paired = [x for r in rows for x in r.get(f"ratio_{th}", [])]
                median = f" (repeats' median {statistics.median(paired):.2f}×)" if paired else ""
                cells.append(f"{r45:.0f} / {r4:.0f} = {r45 / r4:.2f}×{median}")
            lines.append(f"| slider-crank, rk45 / rk4 ns per instance-step, {th} thread(s) | "
                         f"{cells[0]} | {cells[1]} | ≤ 3.0× |")  # fmt: skip
    if "warm:before" in results:
        for key, label in (
            ("wall", "end to end, s"),
            ("warmup", "warm-up (kernel loads, first calls' imports), s"),
        ):
            cells = []
            for k in ("before", "after"):
                rows = results[f"warm:{k}"]
                cells.append(min(r["wall"] if key == "wall" else r["timings"].get("warmup", 0)
                                 for r in rows))  # fmt: skip
            lines.append(f"| warm radau slider-crank, {label} | {cells[0]:.2f} | {cells[1]:.2f}"
                         " | |")  # fmt: skip
    if "verdict:before" in results:
        for key in ("wall", "prepare", "warmup", "compute", "merge"):
            cells = []
            for k in ("before", "after"):
                rows = results[f"verdict:{k}"]
                cells.append(min(r["wall"] if key == "wall" else r["timings"].get(key, 0)
                                 for r in rows))  # fmt: skip
            goal = "≤ 5 s" if key == "wall" else ""
            lines.append(f"| 4,096-sample verdict, {key}, s | {cells[0]:.2f} | {cells[1]:.2f}"
                         f" | {goal} |")  # fmt: skip
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
