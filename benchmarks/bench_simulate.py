"""Time integration: work-precision, stability map, constraint drift and speed per method.

Issue #3. The measurements live in ``benchmarks/integrators.py``; this script
runs them and writes the tables and charts to ``benchmarks/results/``:

    python benchmarks/bench_simulate.py [--quick] [--only work-precision,stability,drift,speed]

* work_precision.png: error vs radau (rtol 1e-12) against CPU time per instance, 3 scenes;
* stability.png: largest stable step vs clearance, with 2√2/p_max from the eigen step;
* drift.png: max |Φ| over time, rk4 with/without Baumgarte and rk4-projection;
* speed.png: ns per instance-step of each method, 10⁴ samples, 1 and 2 threads.
"""

from __future__ import annotations

import sys
from pathlib import Path

from integrators import main

OUT = Path(__file__).resolve().parent / "results" / "simulate"

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--only" not in args:
        args += ["--only", "work-precision,stability,drift,speed"]
    raise SystemExit(main([*args, "--out", str(OUT)]))
