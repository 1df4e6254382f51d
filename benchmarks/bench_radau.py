"""``radau`` before and after the compiled Radau, on the Flores slider-crank with an
impacting piston pin (:func:`mcchain.testing.scenes.flores_pin_text`: 5000 rpm, clearance
0.1 mm, model auto, rtol 1e-11, atol 1e-13).

"Before" is the tree at ``--before`` (a git revision: scipy's ``solve_ivp(method="Radau")``
calling the accelerations from Python at every evaluation), extracted with ``git archive``
into a temporary folder; "after" is this tree. Each run is a fresh process that integrates a
short warm-up first (compiles or loads the kernels), then times ``simulate`` alone; the two
trees alternate ``--repeats`` times (the machine is shared: compare the ratios). The old
path needs minutes per run, so the side-by-side uses ``--t-end`` (default 16 ms: the link
lets go at 9.9 ms, four impacts at 14.9-15.5 ms); the whole 30 ms (six impacts) is timed
on this tree only, ``--full`` times. ::

    python benchmarks/bench_radau.py [--before add2da8] [--repeats 2] [--t-end 0.016]

Writes ``benchmarks/results/radau/bench.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

from mcchain.testing.scenes import flores_pin_text

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "radau"

CHILD = """
import json, sys, time
import numpy as np
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers.simulate import simulate
from mcchain.solvers.statics import assemble

def run(text):
    scene = load_scene_text(text)
    model = compile_model(scene)
    start = assemble(model)
    t0 = time.perf_counter()
    out = simulate(model, scene.simulate, q_start=start.q, v_start=start.v,
                   status=start.status, history_dtype=np.float64, diagnostics=True)
    return time.perf_counter() - t0, out

run({warm!r})  # compile or load the kernels
seconds, out = run({text!r})
print(json.dumps(dict(seconds=seconds, steps=int(out["steps"][0]),
                      evaluations=int(out["evaluations"][0]), status=int(out["status"][0]),
                      impacts=int(out["impact_count"][0, 2]))))
"""


def extract(revision: str, folder: Path) -> Path:
    """The tree of ``revision`` in ``folder`` (git archive)."""
    archive = folder / "tree.tar"
    subprocess.run(
        ["git", "-C", str(REPO), "archive", "-o", str(archive), revision, "mcchain", "configs"],
        check=True,
    )
    with tarfile.open(archive) as tar:
        tar.extractall(folder / "tree", filter="data")
    return folder / "tree"


def timed(tree: Path, t_end: float, cache: Path) -> dict[str, float]:
    """One run of the child script on ``tree``; its JSON line."""
    env = dict(os.environ, PYTHONPATH=str(tree), MCCHAIN_CACHE_DIR=str(cache))
    code = CHILD.format(warm=flores_pin_text(t_end=5e-4), text=flores_pin_text(t_end=t_end))
    code += f"\nimport mcchain; assert mcchain.__file__.startswith({str(tree)!r})\n"
    done = subprocess.run(  # run in the tree: `python -c` imports from its folder first
        [sys.executable, "-c", code], env=env, cwd=tree, check=True, capture_output=True,
        text=True,
    )  # fmt: skip
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="add2da8", help="git revision of the old radau")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--t-end", type=float, default=0.016)
    parser.add_argument("--full", type=int, default=2, help="timed runs of the whole 30 ms")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-radau-"))
    trees = {"before": extract(args.before, work), "after": REPO}
    # one cache for both trees (numba's is keyed by source path, the native one by text)
    cache = Path(os.environ.get("MCCHAIN_CACHE_DIR", work / "cache"))
    caches = {name: cache for name in trees}
    rows: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
    for r in range(args.repeats):
        for name, tree in trees.items():
            result = timed(tree, args.t_end, caches[name])
            print(name, r, result, flush=True)
            rows[name].append(result)
    full = []
    for r in range(args.full):
        result = timed(REPO, 0.03, caches["after"])
        print("after, 30 ms", r, result, flush=True)
        full.append(result)

    def line(label: str, runs: list[dict[str, float]], t_end: float) -> str:
        seconds = [run["seconds"] for run in runs]
        first = runs[0]
        return (
            f"| {label} | {t_end * 1e3:g} | {first['steps']} | {first['evaluations']} | "
            f"{first['impacts']} | {' / '.join(f'{s:.2f}' for s in seconds)} | "
            f"{statistics.median(seconds):.2f} |"
        )

    ratios = [
        b["seconds"] / a["seconds"] for b, a in zip(rows["before"], rows["after"], strict=True)
    ]
    OUT.mkdir(parents=True, exist_ok=True)
    text = "\n".join(
        [
            "# radau: scipy's solve_ivp against the compiled Radau",
            "",
            "`python benchmarks/bench_radau.py "
            f"--before {args.before} --repeats {args.repeats} --t-end {args.t_end:g}` "
            "(2 shared cores; runs alternate; `simulate` alone, kernels compiled or loaded "
            "beforehand). Scene: `mcchain.testing.scenes.flores_pin_text` (Flores "
            "slider-crank, piston pin 0.1 mm under Lankarani-Nikravesh e = 0.9, model auto), "
            "rtol 1e-11, atol 1e-13, one instance.",
            "",
            "| tree | t_end (ms) | accepted steps | evaluations | impacts | seconds per run | "
            "median |",
            "| --- | --- | --- | --- | --- | --- | --- |",
            line(f"before ({args.before}, scipy)", rows["before"], args.t_end),
            line("after (compiled)", rows["after"], args.t_end),
            line("after (compiled)", full, 0.03),
            "",
            "Before / after, run by run (alternating): "
            + ", ".join(f"{x:.1f}x" for x in ratios)
            + ".",
            "",
        ]
    )
    (OUT / "bench.md").write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
