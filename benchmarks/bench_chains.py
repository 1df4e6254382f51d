"""Chains of N = 2 … 32 bars: mcchain rk4 against MuJoCo's rollout and scipy, per instance-step.

Issue #3 targets: cost growing no faster than N^1.1; ≥ 40× MuJoCo's RK4 rollout on the
double pendulum (N = 2). MuJoCo is optional (``pip install mujoco``); without it its column is
empty. Everything runs side by side in one process:

    python benchmarks/bench_chains.py [--quick]

Writes ``benchmarks/results/chains/chains.png`` and ``bench.md``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from integrators import main

OUT = Path(__file__).resolve().parent / "results" / "chains"

if __name__ == "__main__":
    raise SystemExit(main([*sys.argv[1:], "--only", "chains", "--out", str(OUT)]))
