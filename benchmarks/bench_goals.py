"""Issue 37's item 3, its two figures measured in pairs: rk4 lanes on the clearance double
pendulum against MuJoCo's RK4 rollout and against the dgemm peak, in the same moments.

On a shared machine the best of a few runs taken minutes apart moves by 1.3× with nothing
changed (benchmarks/results/roofline/reading.md), and ``bench_speed.py`` divides best-of
times taken at different moments. Here one process per thread count (its BLAS limited to
that many threads before NumPy loads) repeats rounds of three measurements, in an order
that rotates between rounds: ``simulate`` of the lanes (bench_speed's run: 10,000 samples,
2,000 steps of 0.1 ms, rk4 lanes), MuJoCo's rollout of the same chain (2,000 samples,
200 steps, the better of two calls; benchmarks/integrators.py) and one float64 matmul
(n = 3,000). Each round gives its own ratios; the figures are their median and quartiles
(and the best times' ratios beside them). One thread: process CPU time; two threads: wall
time (for all three alike).

    python benchmarks/bench_goals.py [--rounds 10] [--threads 1,2] [--flops 1128.09]

(``--flops``: flops per rk4 instance-step, from ``bench_roofline.py --count``.)
Prints a table and appends it to benchmarks/results/speed/goals.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "speed" / "goals.md"

ROUNDS = r"""
import json, os, sys, time
import numpy as np
import numba
sys.path.insert(0, "benchmarks")
from integrators import _mujoco_chain
from mcchain.solvers.simulate import simulate
from mcchain.testing.scenes import DOUBLE_PENDULUM, model_of, straight_chain_text

threads, rounds = int(sys.argv[1]), int(sys.argv[2])
numba.set_num_threads(threads)
clock = time.process_time if threads == 1 else time.perf_counter
n = 10_000
model = model_of(straight_chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4}), nsample=n)
sim = dict(t_end=0.2, dt=1e-4, output_dt=1e-2, method="rk4", kernels="lanes")
simulate(model.select(0, 64), sim)  # compiled (or loaded) before the rounds
size = 3000
a = np.random.default_rng(0).random((size, size))
b = a.T.copy()
a @ b


def lanes():
    t0 = clock()
    simulate(model, sim)
    return (clock() - t0) / (n * 2000) * 1e9


def mujoco():
    return _mujoco_chain(**DOUBLE_PENDULUM, dt=1e-4, nstep=200, nsample=2_000,
                         threads=threads, cpu=threads == 1)


def dgemm():
    t0 = clock()
    a @ b
    return 2 * size**3 / (clock() - t0) / 1e9


measures = {"lanes": lanes, "mujoco": mujoco, "dgemm": dgemm}
order = list(measures)
for r in range(rounds):
    row = {}
    for name in order[r % 3:] + order[:r % 3]:
        row[name] = measures[name]()
    row["load"] = os.getloadavg()[0]
    print(json.dumps(row), flush=True)
"""


def run(threads: int, rounds: int) -> list[dict[str, float]]:
    """The rounds of one process on ``threads`` threads (BLAS included)."""
    env = {
        **os.environ,
        "OPENBLAS_NUM_THREADS": str(threads),
        "OMP_NUM_THREADS": str(threads),
        "OPENBLAS_CORETYPE": os.environ.get("OPENBLAS_CORETYPE", "Haswell"),
        "PYTHONPATH": str(REPO),
    }
    out = subprocess.run(
        [sys.executable, "-c", ROUNDS, str(threads), str(rounds)],
        cwd=REPO, env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]


def _spread(values: list[float], fmt: str) -> str:
    """Median (quartiles) of ``values``."""
    q1, median, q3 = statistics.quantiles(values, n=4, method="inclusive")
    return f"{format(median, fmt)} ({format(q1, fmt)}-{format(q3, fmt)})"


def report(rows: dict[int, list[dict[str, float]]], flops: float, command: str) -> str:
    """The table of the rounds' ratios per thread count."""
    lines = [
        f"## Item 3 in pairs ({datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC)",
        "",
        f"`{command}`; flops per rk4 instance-step {flops:,.2f}; per round: lanes, MuJoCo "
        "and dgemm in a rotating order; median (quartiles) of the rounds' own figures, then "
        "the best times' ratio.",
        "",
        "| threads | rounds | rk4 lanes, ns | MuJoCo, ns | dgemm, GFLOP/s | MuJoCo / lanes "
        "| lanes / dgemm | best: MuJoCo / lanes, lanes / dgemm | load |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for threads, rs in rows.items():
        lanes = [r["lanes"] for r in rs]
        mujoco = [r["mujoco"] for r in rs]
        gemm = [r["dgemm"] for r in rs]
        times = [m / x for m, x in zip(mujoco, lanes, strict=True)]
        fraction = [flops / x / g * 100 for x, g in zip(lanes, gemm, strict=True)]
        best = (min(mujoco) / min(lanes), flops / min(lanes) / max(gemm) * 100)
        loads = [r["load"] for r in rs]
        lines.append(
            f"| {threads} | {len(rs)} | {_spread(lanes, '.1f')} | {_spread(mujoco, ',.0f')} "
            f"| {_spread(gemm, '.1f')} | {_spread(times, '.0f')}× | {_spread(fraction, '.0f')} % "
            f"| {best[0]:.0f}×, {best[1]:.0f} % | {min(loads):.1f}-{max(loads):.1f} |"
        )
    lines += ["", "Goals (issue 37, item 3): MuJoCo / lanes ≥ 150×, lanes / dgemm ≥ 50 %.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--flops", type=float, default=1128.09)
    args = parser.parse_args(argv)
    if args.rounds < 2:
        parser.error("--rounds: at least 2 (quartiles)")
    rows = {int(t): run(int(t), args.rounds) for t in args.threads.split(",")}
    command = (
        f"python benchmarks/bench_goals.py --rounds {args.rounds} --threads {args.threads} "
        f"--flops {args.flops}"
    )
    text = report(rows, args.flops, command)
    print(text)
    with OUT.open("a") as f:
        f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
