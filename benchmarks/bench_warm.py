"""What a warm run's kernel warm-up spends its time on, for two source trees side by side.

    python benchmarks/bench_warm.py --before REF [--after REF] [--rounds 3]

Runs ``mcchain run`` on the Flores slider-crank (4 samples, 2 ms) with ``method = "radau"``
(``bench_speed.radau_scene``) and as shipped (``rk45``), and on the README's quick start
(``configs/clearance-sweep.toml``), warm (each tree with its own caches,
warmed first), in a fresh process that times inside the run, in wall and CPU seconds: the
warm-up (``Kernels.warm``), every numba cache load in it (``Dispatcher._compile_for_args``,
with the index check and unpickling and the dispatcher's own work around the load), every LLVM
library load (numba's and the generated lane kernels', with the parse of the bitcode numba
keeps beside the object code to link it into later compiles), every
first import in it (top-level imports only) and the scipy imports before it; the size of
the numba cache files it loaded. The trees and scenes alternate round by round; each figure
is the best of the rounds. Then the floor: a minimal cached ``@njit`` function's load in a
fresh process (numba's import, the first load, which initialises numba's target context,
and each further load). Appends a dated section to ``benchmarks/results/speed/warm.md``
(the earlier ones stay: each says what it compared).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench_speed import OUT, REPO, _env, append_results, export, radau_scene

PROBE = r"""
import builtins, collections, json, sys, time
import numba.core.caching as caching
import numba.core.codegen as codegen
import numba.core.dispatcher as dispatcher

parts = collections.defaultdict(lambda: [0, 0.0, 0.0])  # label: calls, wall, CPU (thread)
phase = ["prepare"]

def timed(owner, name, label):
    f = getattr(owner, name)
    def g(*a, **k):
        if phase[0] != "warmup":
            return f(*a, **k)
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            return f(*a, **k)
        finally:
            p = parts[label]
            p[0] += 1; p[1] += time.perf_counter() - t0; p[2] += time.thread_time() - c0
    setattr(owner, name, g)

timed(dispatcher.Dispatcher, "_compile_for_args", "dispatcher")
timed(caching.Cache, "_load_overload", "load")  # numba's own load and mcchain's light one
timed(caching.IndexDataCacheFile, "_load_index", "index")
timed(caching.IndexDataCacheFile, "_load_data", "unpickle")
timed(codegen.CPUCodegen, "unserialize_library", "llvm")
timed(codegen.ll, "parse_bitcode", "bitcode")
loaded_bytes = [0]
load_data = caching.IndexDataCacheFile._load_data

def sized(self, name):
    if phase[0] == "warmup":
        import os
        loaded_bytes[0] += os.path.getsize(os.path.join(self._cache_path, name))
    return load_data(self, name)

caching.IndexDataCacheFile._load_data = sized
real_import = builtins.__import__
depth = [0]
imports = {"prepare": [], "warmup": []}

def timed_import(name, *args, **kwargs):
    if depth[0] or name in sys.modules or phase[0] not in imports:
        return real_import(name, *args, **kwargs)
    depth[0] += 1
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        return real_import(name, *args, **kwargs)
    finally:
        depth[0] -= 1
        imports[phase[0]].append((name, time.perf_counter() - t0, time.thread_time() - c0))

builtins.__import__ = timed_import
import mcchain.compiled.ready as ready
warm = ready.Kernels.warm
cpu = {}

def timed_warm(self, first, scene, solve):
    phase[0] = "warmup"
    c0 = time.process_time()
    try:
        warm(self, first, scene, solve)
    finally:
        cpu["warmup"] = time.process_time() - c0
        phase[0] = "compute"

ready.Kernels.warm = timed_warm
scene, folder = sys.argv[1], sys.argv[2]
sys.argv = ["mcchain", "run", scene, "--run-dir", folder, "--quiet", "--no-background-compile"]
from mcchain.cli import main
try:
    main()
except SystemExit as exc:
    if exc.code:
        raise
timings = json.load(open(folder + "/run.json"))["timings"]
def total(kind, phase_name, pick):
    return sum(x[pick] for x in imports[phase_name] if x[0].startswith(kind))
out = {"timings": timings, "warmup_cpu": cpu.get("warmup", 0.0), "parts": dict(parts),
       "loaded_mb": loaded_bytes[0] / 1e6,
       "imports": [x for x in imports["warmup"] if x[1] > 0.005],
       "import_cpu": sum(x[2] for x in imports["warmup"]),
       "scipy_before_cpu": total("scipy", "prepare", 2),
       "scipy_optimize": "scipy.optimize" in sys.modules}
print(json.dumps(out))
"""

FLOOR = r"""
import json, sys, time
c0 = time.process_time()
import numba
c1 = time.process_time()
sys.path.insert(0, sys.argv[1])
import tiny
c2 = time.process_time()
tiny.f0(1.0)
c3 = time.process_time()
for i in range(1, tiny.N):
    getattr(tiny, f"f{i}")(1.0)
c4 = time.process_time()
hits = sum(sum(getattr(tiny, f"f{i}").stats.cache_hits.values()) for i in range(tiny.N))
print(json.dumps({"numba import": c1 - c0, "first load": c3 - c2,
                  "each further load": (c4 - c3) / (tiny.N - 1), "hits": hits}))
"""

TINY_FUNCTIONS = 21


def probe(tree: Path, cache: Path, scene: Path, work: Path) -> dict[str, Any]:
    folder = work / f"warm-{os.getpid()}-{len(list(work.iterdir()))}"
    out = subprocess.run([sys.executable, "-c", PROBE, str(scene), str(folder)], cwd=tree,
                         env=_env(tree, cache), capture_output=True, text=True)  # fmt: skip
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    result = json.loads(out.stdout.splitlines()[-1])
    result["load"] = os.getloadavg()[0]
    return dict(result)


def floor(work: Path) -> dict[str, float]:
    """A minimal cached function's load, in CPU seconds (the first call compiles them)."""
    folder = work / "floor"
    folder.mkdir(exist_ok=True)
    text = f"from numba import njit\n\nN = {TINY_FUNCTIONS}\n"
    for i in range(TINY_FUNCTIONS):
        text += f"\n\n@njit(cache=True)\ndef f{i}(x):\n    return x + {i}.0\n"
    (folder / "tiny.py").write_text(text)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(folder / "cache")}
    for _ in range(2):  # the first run compiles
        out = subprocess.run([sys.executable, "-c", FLOOR, str(folder)], env=env, check=True,
                             capture_output=True, text=True)  # fmt: skip
    result = json.loads(out.stdout.splitlines()[-1])
    assert result.pop("hits") == TINY_FUNCTIONS, "the floor's functions did not load"
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
    scenes = {"radau": radau_scene(work), "rk45": work / "slider-crank-rk45.toml"}
    scenes["rk45"].write_text(
        scenes["radau"].read_text().replace('method = "radau"', 'method = "rk45"')
    )
    scenes["quick start"] = REPO / "configs" / "clearance-sweep.toml"
    rows: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for name, tree in trees.items():  # warm the caches (compiles are not timed)
        for scene in scenes.values():
            probe(tree, caches[name], scene, work)
    for r in range(args.rounds):
        order = list(trees.items()) if r % 2 == 0 else list(reversed(trees.items()))
        for method, scene in scenes.items():
            for name, tree in order:
                rows.setdefault((method, name), []).append(probe(tree, caches[name], scene, work))
                print(method, name, json.dumps(rows[method, name][-1]), flush=True)
    floors = [floor(work) for _ in range(args.rounds)]
    for ref in ("before", "after"):  # a folder: its commit, as the result names it
        if Path(getattr(args, ref)).is_dir():
            head = subprocess.run(["git", "-C", getattr(args, ref), "rev-parse", "--short", "HEAD"],
                                  capture_output=True, text=True).stdout.strip()  # fmt: skip
            setattr(args, ref, f"{getattr(args, ref)} (at {head or 'no commit'})")
    text = report(rows, floors, args)
    print(text)
    append_results(OUT / "warm.md", text)
    return 0


def _part(r: dict[str, Any], label: str) -> float:
    return float(r["parts"].get(label, [0, 0.0, 0.0])[2])


def _count(r: dict[str, Any], label: str) -> int:
    return int(r["parts"].get(label, [0])[0])


FIGURES: list[tuple[str, Any]] = [
    ("warm-up (run.json warmup), wall s", lambda r: r["timings"].get("warmup", 0.0)),
    ("warm-up, CPU s", lambda r: r["warmup_cpu"]),
    ("… numba cache loads (count)", lambda r: _count(r, "dispatcher")),
    ("… numba cache loads, CPU s", lambda r: _part(r, "dispatcher")),
    ("… … numba cache files loaded, MB", lambda r: r.get("loaded_mb", 0.0)),
    ("… … index check and unpickle, CPU s", lambda r: _part(r, "index") + _part(r, "unpickle")),
    (
        "… … dispatcher around the load (numba's target context refresh, where done), CPU s",
        lambda r: _part(r, "dispatcher") - _part(r, "load"),
    ),
    ("… LLVM library loads, numba's and the lane kernels' (count)", lambda r: _count(r, "llvm")),
    ("… LLVM library loads, CPU s", lambda r: _part(r, "llvm")),
    ("… … parse of the bitcode kept for linking, CPU s", lambda r: _part(r, "bitcode")),
    ("… first imports, CPU s", lambda r: r["import_cpu"]),
    ("scipy imports before the warm-up, CPU s", lambda r: r["scipy_before_cpu"]),
    ("compute, wall s", lambda r: r["timings"].get("compute", 0.0)),
    ("end to end (run.json total), wall s", lambda r: r["timings"]["total"]),
]


def report(
    rows: dict[tuple[str, str], list[dict[str, Any]]],
    floors: list[dict[str, float]],
    args: argparse.Namespace,
) -> str:
    loads = ", ".join(f"{r['load']:.1f}" for runs in rows.values() for r in runs)
    methods = sorted({m for m, _ in rows}, key=["radau", "rk45", "quick start"].index)
    head = " | ".join(f"{m} {n}" for m in methods for n in ("before", "after"))
    lines = [
        f"## Warm start: where a warm run's kernel warm-up goes ({datetime.date.today()})",
        "",
        f"`python benchmarks/bench_warm.py --before {args.before} --after {args.after} "
        f'--rounds {args.rounds}` (Flores slider-crank, 4 samples, 2 ms, `method = "radau"` '
        "and as shipped, `rk45`; the quick start, `configs/clearance-sweep.toml`, 10,000 "
        "statics instances; best of the rounds, trees alternating; CPU seconds are the "
        f"process's or, for the parts, the main thread's); load averages {loads}.",
        "",
        f"| figure | {head} |",
        "|---|" + "---|" * (2 * len(methods)),
    ]
    for label, get in FIGURES:
        cells = []
        for m in methods:
            for n in ("before", "after"):
                best = min(float(get(r)) for r in rows[m, n])
                cells.append(f"{best:.0f}" if "(count)" in label else f"{best:.3f}")
        lines.append(f"| {label} | {' | '.join(cells)} |")
    lines += ["", "First imports in the warm-up (last round; wall s, CPU s):", ""]
    for (m, n), runs in rows.items():
        found = ", ".join(f"{name} {w:.2f}/{c:.2f}" for name, w, c in runs[-1]["imports"])
        optimize = "imported" if runs[-1]["scipy_optimize"] else "never imported"
        lines.append(f"- {m} {n}: {found or 'none over 5 ms'} (scipy.optimize {optimize})")
    lines += [
        "",
        f"Floor: a minimal cached `@njit` function (`x + 1.0`), {TINY_FUNCTIONS} of them, in "
        "a fresh process; CPU s, best of the rounds:",
        "",
        "| numba import | first load (numba's target context) | each further load |",
        "|---|---|---|",
        "| " + " | ".join(f"{min(f[k] for f in floors):.4f}" for k in floors[0]) + " |",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
