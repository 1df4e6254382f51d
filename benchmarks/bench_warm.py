"""What a warm run's kernel warm-up spends its time on, for two source trees side by side.

    python benchmarks/bench_warm.py --before REF [--after REF] [--rounds 3]

Runs ``mcchain run`` on the Flores slider-crank with ``method = "radau"`` (4 samples, 2 ms:
``bench_speed.radau_scene``), warm (each tree with its own caches, warmed first), in a fresh
process that times, inside the run: every numba cache load (``Cache.load_overload``) and
every first import of a ``scipy`` package, each as before the warm-up (``prepare``) or in it.
The trees alternate round by round; each figure is the best of the rounds. Writes
``benchmarks/results/speed/warm.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench_speed import OUT, _env, export, radau_scene

PROBE = r"""
import builtins, json, sys, time
import numba.core.caching as caching

events = []  # (kind, name, seconds, end time)
load = caching.Cache.load_overload

def timed_load(self, sig, target_context):
    t0 = time.perf_counter()
    try:
        return load(self, sig, target_context)
    finally:
        events.append(("numba", getattr(self, "_name", "?"), time.perf_counter() - t0,
                       time.perf_counter()))

caching.Cache.load_overload = timed_load
real_import = builtins.__import__
depth = [0]

def timed_import(name, *args, **kwargs):
    if depth[0] or not name.startswith("scipy") or name in sys.modules:
        return real_import(name, *args, **kwargs)
    depth[0] += 1
    t0 = time.perf_counter()
    try:
        return real_import(name, *args, **kwargs)
    finally:
        depth[0] -= 1
        events.append(("import", name, time.perf_counter() - t0, time.perf_counter()))

builtins.__import__ = timed_import
warm_at = []
for module in ("mcchain.runner.executors", "mcchain.parallel"):  # after / before h-runner
    try:
        mod = __import__(module, fromlist=["warm_model"])
    except ImportError:
        continue
    original = mod.warm_model
    def marked(model, original=original):
        warm_at.append(time.perf_counter())
        return original(model)
    mod.warm_model = marked
    break
scene, folder = sys.argv[1], sys.argv[2]
sys.argv = ["mcchain", "run", scene, "--run-dir", folder, "--quiet", "--no-background-compile"]
from mcchain.cli import main
main()
timings = json.load(open(folder + "/run.json"))["timings"]
start = warm_at[0] if warm_at else 0.0
end = start + timings.get("warmup", 0.0)
out = {"timings": timings, "prepare": {"numba": 0.0, "import": 0.0},
       "warmup": {"numba": 0.0, "import": 0.0}, "loads": 0, "imports": []}
for kind, name, seconds, t in events:
    phase = "warmup" if start <= t <= end else "prepare" if t < start else None
    if phase is None:
        continue
    out[phase][kind] += seconds
    if phase == "warmup":
        if kind == "numba":
            out["loads"] += 1
        else:
            out["imports"].append(f"{name} {seconds:.2f} s")
print(json.dumps(out))
"""


def probe(tree: Path, cache: Path, scene: Path, work: Path) -> dict[str, Any]:
    folder = work / f"warm-{os.getpid()}-{len(list(work.iterdir()))}"
    out = subprocess.run([sys.executable, "-c", PROBE, str(scene), str(folder)], cwd=tree,
                         env=_env(tree, cache), capture_output=True, text=True)  # fmt: skip
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    result = json.loads(out.stdout.splitlines()[-1])
    result["load"] = os.getloadavg()[0]
    return dict(result)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True)
    parser.add_argument("--after", default="HEAD")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--work", type=Path, default=None)
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-warm-"))
    trees = {"before": export(args.before, work), "after": export(args.after, work)}
    caches = {k: work / f"cache-{k}" for k in trees}
    scene = radau_scene(work)
    rows: dict[str, list[dict[str, Any]]] = {k: [] for k in trees}
    for name, tree in trees.items():  # warm the caches (compiles are not timed)
        probe(tree, caches[name], scene, work)
    for r in range(args.rounds):
        for name, tree in trees.items() if r % 2 == 0 else reversed(trees.items()):
            rows[name].append(probe(tree, caches[name], scene, work))
            print(name, json.dumps(rows[name][-1]), flush=True)
    text = report(rows, args)
    print(text)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "warm.md").write_text(text)
    return 0


def report(rows: dict[str, list[dict[str, Any]]], args: argparse.Namespace) -> str:
    def best(name: str, get: Any) -> float:
        return min(float(get(r)) for r in rows[name])

    figures = [
        ("end to end (run.json total), s", lambda r: r["timings"]["total"]),
        ("prepare, s", lambda r: r["timings"].get("prepare", 0.0)),
        ("kernel warm-up (run.json warmup), s", lambda r: r["timings"].get("warmup", 0.0)),
        ("… of which numba cache loads, s", lambda r: r["warmup"]["numba"]),
        ("… of which first scipy imports, s", lambda r: r["warmup"]["import"]),
        ("scipy imports before the warm-up, s", lambda r: r["prepare"]["import"]),
        ("compute, s", lambda r: r["timings"].get("compute", 0.0)),
    ]
    loads = ", ".join(f"{r['load']:.1f}" for name in rows for r in rows[name])
    lines = [
        "# Warm start: where a warm radau run's warm-up goes",
        "",
        f"`python benchmarks/bench_warm.py --before {args.before} --after {args.after} "
        f'--rounds {args.rounds}` (Flores slider-crank, `method = "radau"`, 4 samples, '
        f"2 ms; best of the rounds, trees alternating); load averages {loads}.",
        "",
        "| figure | before | after | goal |",
        "|---|---|---|---|",
    ]

    def cell(name: str, label: str, get: Any) -> str:
        probed = any(r["loads"] or r["prepare"]["numba"] for r in rows[name])
        if ("numba" in label or "scipy" in label) and not probed:
            return "–"  # the run's kernels loaded out of this process's sight
        return f"{best(name, get):.2f}"

    for label, get in figures:
        goal = "≤ 0.3 s" if label.startswith("kernel warm-up") else ""
        cells = " | ".join(cell(name, label, get) for name in ("before", "after"))
        lines.append(f"| {label} | {cells} | {goal} |")
    last = rows["after"][-1]
    lines += [
        "",
        "–: no numba cache load was seen in the probed process (the tree ran its kernels "
        "where the probe does not see them); its run.json timings stand.",
        f"After: {last['loads']} numba cache loads in the warm-up; its first imports: "
        + (", ".join(last["imports"]) or "none")
        + ".",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
