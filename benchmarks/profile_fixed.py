"""What a warm verdict run spends outside its chunk loop (issue 37, item 6), in CPU seconds.

    python benchmarks/profile_fixed.py [--before REF] [--samples 64] [--rounds 5]

Two tables, each figure the median over ``--rounds`` fresh processes (CPU seconds of the
process, which a loaded machine disturbs far less than wall seconds; the 1-minute load
average is printed beside them):

1. **the import floor**: the packages a warm run of the shipped requirement scene
   (``configs/slider-crank-requirement.toml``, ``[storage] histories = "none"``) imports,
   one step after the other in one process: the interpreter alone, numpy, pydantic, the
   scene's models, numba, numba's target context (the registries its first cached load
   installs, which import scipy.linalg), netCDF4, the runner and solvers, the generated-code
   modules, the verdict's modules (scipy.special);
2. **the run's phases**: ``mcchain run`` of that scene in a process that wraps the run's
   steps with timers (the CLI's own code, unchanged): the scene read before the run's
   clock (``compiled/first_run.choose``), the thread check (numba's import), the scene's
   compile and checks (numba's first cached loads), the warm-up, each chunk, the merge, the
   verdict lines; CPU and wall seconds of each, and what the process spent before and after
   the CLI's ``main``.

``--before``: a commit (exported into ``--work`` with ``git archive``) measured beside this
tree, the two alternating round by round. Each tree runs once unmeasured first (its kernels
loaded or compiled into the cache). Appends a dated section to
``benchmarks/results/verdict/fixed.md``; ``--bytecode`` as in ``bench_verdict.py``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_light import REPO, export_tree, scene_with
from bench_speed import append_results

RESULTS = REPO / "benchmarks" / "results" / "verdict"

IMPORT_STEPS = [
    ("numpy", "import numpy"),
    ("pydantic", "import pydantic"),
    ("the scene's models (mcchain.scene)", "import mcchain.scene"),
    ("numba", "import numba"),
    (
        "numba's target context (its registries; scipy.linalg)",
        "from numba.core.registry import cpu_target; cpu_target.target_context.refresh()",
    ),
    ("netCDF4", "import netCDF4"),
    (
        "mcchain's runner and solvers",
        "import mcchain.solvers.statics, mcchain.runner.plan, mcchain.runner.job, "
        "mcchain.runner.store, mcchain.runner.executors, mcchain.runner.observers",
    ),
    ("mcchain's generated-code modules", "import mcchain.codegen.native, mcchain.codegen.generate"),
    ("the verdict's modules (scipy.special)", "import mcchain.decision.summary"),
]

FLOOR = """
import json, os, sys, time
marks = [time.process_time()]
for code in json.loads(sys.argv[1]):
    exec(code)
    marks.append(time.process_time())
print(json.dumps(marks), flush=True)
os._exit(0)  # as the CLI exits (mcchain.cli.console_main): no teardown module by module
"""

ORDER = [
    ("choose", "the scene read before the run's clock (`first_run.choose`)"),
    ("start_run", "`start_run`: everything from the run's clock to its end"),
    ("_check_threads", "  the thread check (numba's import)"),
    ("prepare_job", "  the scene loaded, compiled and checked (`prepare_job`)"),
    ("check_scene", "    the statics check (numba's first cached loads)"),
    ("Kernels.after_checks", "  `Kernels.after_checks`"),
    ("create_run", "  the run folder and its provenance (`create_run`)"),
    ("Kernels.warm", "  the warm-up (`Kernels.warm`)"),
    ("solve_coerced", "  the chunks (`solve_coerced`, the compute)"),
    ("Store.merge", "  the merge"),
    ("RetryCounts.on_merged", "  the retry counts"),
    ("VerdictLines.on_merged", "  the verdict lines"),
    ("Store.complete", "  run.json completed"),
    ("outside", "the process outside the CLI's `main` (start, CLI import, exit)"),
    ("process", "**the whole process**"),
]
"""The rows of the phases' table, in the order a run reaches them (indent: nested)."""

PHASES = {
    "mcchain.compiled.first_run": ["choose"],
    "mcchain.runner.plan": ["start_run", "_check_threads"],
    "mcchain.runner.job": ["prepare_job"],
    "mcchain.solvers.statics": ["check_scene"],
    "mcchain.runner.runs": ["create_run"],
    "mcchain.compiled.ready": ["Kernels.after_checks", "Kernels.warm"],
    "mcchain.runner.executors": ["solve_coerced"],
    "mcchain.runner.store": ["Store.merge", "Store.complete"],
    "mcchain.runner.observers": ["RetryCounts.on_merged", "VerdictLines.on_merged"],
}
"""Module -> the functions (``Class.method``) timed, wrapped when their module is first
imported (so that no import moves)."""

RUN = """
import functools, importlib.abc, json, os, sys, time
T0, C0 = time.perf_counter(), time.process_time()
PHASES = json.loads(os.environ.pop("PROFILE_FIXED_PHASES"))
EVENTS = []

def wrap(owner, attr, label):
    inner = owner.__dict__[attr]

    @functools.wraps(inner)
    def timed(*args, **kwargs):
        w, c = time.perf_counter(), time.process_time()
        try:
            return inner(*args, **kwargs)
        finally:
            EVENTS.append([label, time.perf_counter() - w, time.process_time() - c])

    setattr(owner, attr, timed)

class Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name not in PHASES:
            return None
        for finder in sys.meta_path:
            if finder is not self and hasattr(finder, "find_spec"):
                spec = finder.find_spec(name, path, target)
                if spec is not None:
                    break
        else:
            return None
        execute = spec.loader.exec_module

        def exec_module(module):
            execute(module)
            for label in PHASES[name]:
                *owners, attr = label.split(".")
                owner = module
                for part in owners:
                    owner = getattr(owner, part)
                wrap(owner, attr, label)

        spec.loader.exec_module = exec_module
        return spec

sys.meta_path.insert(0, Finder())
sys.argv = ["mcchain", *sys.argv[1:]]
from mcchain.cli import commands, main
commands._may_interpret = True  # as console_main sets it
with open(os.devnull, "w") as sink:
    stdout, sys.stdout = sys.stdout, sink
    code = main()
    sys.stdout = stdout
EVENTS.append(["main", time.perf_counter() - T0, time.process_time() - C0])
print(json.dumps({"code": code, "events": EVENTS}))
sys.stdout.flush()
os._exit(0)
"""


def cpu_of_child(command: list[str], env: dict[str, str]) -> tuple[str, float, float]:
    """stdout, wall and CPU (user + system) seconds of a child process, started in its tree
    (``env["PYTHONPATH"]``): ``python -c`` puts its working folder first on ``sys.path``,
    and started in this repository, a child would import this tree's mcchain whatever
    ``PYTHONPATH`` says (until 2026-11-29 14:13 UTC, the "before" columns measured this
    tree)."""
    before = os.times()
    t0 = time.perf_counter()
    done = subprocess.run(
        command, env=env, capture_output=True, text=True, check=True, cwd=env["PYTHONPATH"]
    )
    wall = time.perf_counter() - t0
    after = os.times()
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    return done.stdout, wall, cpu


def floor_round(env: dict[str, str]) -> list[float]:
    """CPU seconds of the interpreter (before the first step, and its exit) and of each
    import step, in one fresh process."""
    codes = json.dumps([code for _, code in IMPORT_STEPS])
    out, _, cpu = cpu_of_child([sys.executable, "-c", FLOOR, codes], env)
    marks = json.loads(out)
    return [cpu - (marks[-1] - marks[0]), *(b - a for a, b in itertools.pairwise(marks))]


def phases_round(env: dict[str, str], scene: Path, samples: int, folder: Path) -> dict:
    """{step: [CPU, wall, calls]} of one ``mcchain run`` in a fresh process."""
    env = {**env, "PROFILE_FIXED_PHASES": json.dumps(PHASES)}
    command = [sys.executable, "-c", RUN, "run", str(scene), "--samples", str(samples)]
    command += ["--run-dir", str(folder), "--threads", "2", "--no-background-compile"]
    out, process_wall, process_cpu = cpu_of_child(command, env)
    summed: dict[str, list[float]] = {}
    for label, w, c in json.loads(out.splitlines()[-1])["events"]:
        total = summed.setdefault(label, [0.0, 0.0, 0])
        total[0] += c
        total[1] += w
        total[2] += 1
    main = summed.pop("main")
    summed["outside"] = [process_cpu - main[0], process_wall - main[1], 1]
    summed["process"] = [process_cpu, process_wall, 1]
    return summed


def nested(text: str) -> str:
    """A row's label with its two-space indents shown as dots (markdown drops spaces)."""
    depth = (len(text) - len(text.lstrip(" "))) // 2
    return "· " * depth + text.lstrip(" ")


def median_of(rounds: list[dict], key: str, index: int) -> float:
    return statistics.median(r[key][index] for r in rounds if key in r)


def tables(trees: list[str], floors: dict, phases: dict, samples: int) -> list[str]:
    """The two tables' lines, a CPU column per tree (and the wall seconds of the last)."""
    floor_names = ["the interpreter (`python -c`, site) and its exit"]
    floor_names += [name for name, _ in IMPORT_STEPS]
    heads = " | ".join(f"CPU (s), {t}" for t in trees)
    lines = [
        "### the import floor: CPU seconds of each step, in this order, in one process",
        "",
        f"| step | {heads} |",
        "|---|" + "---|" * len(trees),
    ]
    medians = {t: [statistics.median(col) for col in zip(*floors[t], strict=True)] for t in trees}
    for i, name in enumerate(floor_names):
        lines.append(f"| {name} | " + " | ".join(f"{medians[t][i]:.3f}" for t in trees) + " |")
    lines.append("| **sum** | " + " | ".join(f"**{sum(medians[t]):.3f}**" for t in trees) + " |")
    last = trees[-1]
    lines += [
        "",
        f"### `mcchain run` at {samples} samples: the timed steps (nested steps are part of "
        "the one above them)",
        "",
        f"| step | calls | {heads} | wall (s), {last} |",
        "|---|---|" + "---|" * (len(trees) + 1),
    ]
    for key, text in ORDER:
        if not all(any(key in r for r in phases[t]) for t in trees):
            continue
        calls = int(median_of(phases[last], key, 2))
        cpus = " | ".join(f"{median_of(phases[t], key, 0):.3f}" for t in trees)
        wall = median_of(phases[last], key, 1)
        lines.append(f"| {nested(text)} | {calls} | {cpus} | {wall:.3f} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--before", default=None, help="a commit measured beside this tree")
    parser.add_argument("--bytecode", action="store_true", help="as in bench_verdict.py")
    parser.add_argument("--work", default=None, help="trees and run folders (default: temporary)")
    args = parser.parse_args()
    work = Path(args.work or tempfile.mkdtemp(prefix="profile-fixed-"))
    work.mkdir(parents=True, exist_ok=True)
    roots = {"this tree": REPO}
    if args.before is not None:
        commit = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", args.before],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
        tree = work / f"tree-{commit[:10]}"
        roots = {f"before ({commit[:10]})": tree if tree.exists() else export_tree(commit, work)}
        roots["after"] = REPO
    envs = {}
    for name, root in roots.items():
        env = {**os.environ, "PYTHONPATH": str(root)}
        if args.bytecode:
            env.pop("PYTHONDONTWRITEBYTECODE", None)
            env["PYTHONPYCACHEPREFIX"] = str(work / "pycache")
        envs[name] = env
    scene = scene_with("none", work)
    trees = list(roots)
    for name in trees:  # unmeasured: kernels loaded once, with --bytecode the bytecode written
        floor_round(envs[name])
        phases_round(envs[name], scene, args.samples, work / f"warm-{time.time_ns()}")
    load0 = os.getloadavg()[0]
    floors: dict[str, list[list[float]]] = {t: [] for t in trees}
    phases: dict[str, list[dict]] = {t: [] for t in trees}
    for r in range(args.rounds):  # the trees alternate, round by round
        for name in trees if r % 2 == 0 else trees[::-1]:
            floors[name].append(floor_round(envs[name]))
            folder = work / f"run-{r}-{time.time_ns()}"
            phases[name].append(phases_round(envs[name], scene, args.samples, folder))
    load1 = os.getloadavg()[0]
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    command = "python benchmarks/profile_fixed.py " + " ".join(sys.argv[1:])
    lines = [
        f"## profile_fixed, {when}",
        "",
        f"`{command}` ({os.cpu_count()} cores, {when}, load {load0:.1f} -> {load1:.1f}; "
        f"medians of {args.rounds} fresh processes a tree)",
        "",
        *tables(trees, floors, phases, args.samples),
    ]
    text = "\n".join(lines)
    print(text)
    append_results(RESULTS / "fixed.md", text + "\n")


if __name__ == "__main__":
    main()
