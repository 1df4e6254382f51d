"""Time to first result: cold and warm starts of the CLI, for two commits side by side.

Usage::

    python benchmarks/bench_startup.py [--before REF] [--after REF] [--quick]

Each commit is checked out in a temporary git worktree and run with this interpreter
(``PYTHONPATH`` = the worktree), every command in a fresh process. "Cold" = empty numba and
generated-code caches (``NUMBA_CACHE_DIR``, ``MCCHAIN_CACHE_DIR`` in a new folder); each later
row reuses the caches the rows above it filled, as a user's session would:

1. the Quick start's main job (``configs/clearance-sweep.toml``), cold, then warm. A cold
   statics run may run its kernels interpreted while a background process compiles them
   (``mcchain.compiled.first_run``): the row "kernels cached" is the time from the cold run's start
   until that process is done, and every row waits for it before the next starts;
2. the first statics run of another joint mix (the ideal double pendulum, no simulation);
3. a new simulation topology each: the double pendulum (rk4), the four-bar with its
   clearance joint under the contact law (rk45), a 32-bar chain (rk4);
4. ``mcchain validate`` of the Quick start's scene, warm.

Every command runs with its stdin and stderr on a pseudo-terminal, as at a user's terminal
(where alone a cold first run starts its background compile).

The two commits run row by row (one right after the other), each with its own caches, so
that both see the same machine load. ``--quick`` leaves out the 32-bar chain. Writes
``benchmarks/results/startup/startup.md`` and ``startup.png`` (ratios are measured in one
run: absolute times drift on a shared machine).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "startup"
GOALS: dict[str, float | None] = {
    "quick start, cold": 15.0,
    "quick start, cold: kernels cached": None,
    "quick start, warm": 1.5,
    "other joint mix (statics), cold": 10.0,
    "double pendulum (rk4), cold": 8.0,
    "four-bar, contact law (rk45), cold": 8.0,
    "32-bar chain (rk4), cold": 20.0,
    "validate, warm": 0.5,
}


def _worktree(ref: str, parent: Path) -> Path:
    sha = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", ref],
        check=True, capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip
    path = parent / f"tree-{sha}"
    subprocess.run(
        ["git", "-C", str(REPO), "worktree", "add", "--detach", "-f", str(path), ref],
        check=True, capture_output=True,
    )  # fmt: skip
    return path


def _scenes(tree: Path, folder: Path, quick: bool) -> dict[str, list[str]]:
    """The command line (after ``mcchain``) of every row, scene files written to ``folder``."""
    configs = tree / "configs"
    pendulum = (configs / "double-pendulum.toml").read_text()
    statics = folder / "double-pendulum-statics.toml"
    statics.write_text(pendulum.split("[simulate]")[0].replace('"double-pendulum"', '"dp-statics"'))
    rows = {
        "quick start, cold": ["run", str(configs / "clearance-sweep.toml")],
        "quick start, warm": ["run", str(configs / "clearance-sweep.toml")],
        "other joint mix (statics), cold": ["run", str(statics)],
        "double pendulum (rk4), cold": ["run", str(configs / "double-pendulum.toml")],
        "four-bar, contact law (rk45), cold": ["run", str(configs / "fourbar-clearance.toml")],
    }
    if not quick:
        sys.path.insert(0, str(REPO))
        from mcchain.testing.factory import chain_scene_text

        chain = folder / "chain32.toml"
        chain.write_text(
            chain_scene_text(
                32, (), seed=1, equilibrium=False, modes=False,
                simulate={"t_end": 0.05, "dt": 1e-4, "output_dt": 1e-2, "method": "rk4"},
            )
        )  # fmt: skip
        rows["32-bar chain (rk4), cold"] = ["run", str(chain)]
    rows["validate, warm"] = ["validate", str(configs / "clearance-sweep.toml")]
    return rows


def _time(tree: Path, cache: Path, work: Path, args: list[str]) -> tuple[float, float, str]:
    """Seconds of the command, seconds until the kernels it compiles are in the cache (a
    background compile included: mcchain.compiled.first_run), and its output."""
    env = dict(os.environ)
    env.update(
        PYTHONPATH=str(tree),
        NUMBA_CACHE_DIR=str(cache / "numba"),
        MCCHAIN_CACHE_DIR=str(cache / "generated"),
    )
    env.pop("MCCHAIN_INTERPRET_COLD", None)
    cmd = [sys.executable, "-m", "mcchain.cli", *args]
    if args[0] == "run":
        cmd += ["--quiet", "--out", str(work / "runs")]
        if "fourbar" in args[1]:
            cmd += ["--samples", "4"]  # the compile is the point, not the 1000 samples
    t0 = time.perf_counter()
    code, out, err = _in_terminal(cmd, work, env)
    seconds = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"{' '.join(args)} failed in {tree}:\n{err[-2000:]}")
    wait = (  # trees before issue 36: mcchain.compile_ahead; older ones: no such
        "try:\n    from mcchain.compiled.background import wait_background as w\n"
        "except ImportError:\n    from mcchain.compile_ahead import wait_background as w\nw()"
    )
    subprocess.run([sys.executable, "-c", wait], env=env, capture_output=True)
    return seconds, time.perf_counter() - t0, out + err


def _in_terminal(cmd: list[str], cwd: Path, env: dict[str, str]) -> tuple[int, str, str]:
    """Run ``cmd`` with its stdin and stderr on a pseudo-terminal, as a user at a terminal
    runs it (a cold first run starts its background compile only there:
    ``mcchain.compiled.background.why_not_background``); its exit code, stdout and stderr."""
    import pty
    import threading

    env = {k: v for k, v in env.items() if k not in ("CI", "SLURM_JOB_ID", "PBS_JOBID")}
    master, slave = pty.openpty()
    chunks: list[bytes] = []

    def drain() -> None:
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # the terminal's other end closed
                return
            if not data:
                return
            chunks.append(data)

    reader = threading.Thread(target=drain, daemon=True)
    reader.start()
    try:
        proc = subprocess.run(
            cmd, cwd=cwd, env=env, stdin=slave, stdout=subprocess.PIPE, stderr=slave, text=True
        )
    finally:
        os.close(slave)
        reader.join(timeout=5)
        os.close(master)
    err = b"".join(chunks).decode(errors="replace").replace("\r\n", "\n")
    return proc.returncode, proc.stdout, err


def measure(trees: dict[str, Path], parent: Path, quick: bool) -> dict[str, dict[str, float]]:
    """Seconds of every row for each commit (checked out in ``trees``), row by row: each
    row runs for one commit right after the other, so both see the same machine load (it
    drifts by 30 % within minutes). Each commit has its own caches."""
    caches = {ref: Path(tempfile.mkdtemp(prefix="cache-", dir=parent)) for ref in trees}
    works = {ref: Path(tempfile.mkdtemp(prefix="work-", dir=parent)) for ref in trees}
    rows = {ref: _scenes(tree, works[ref], quick) for ref, tree in trees.items()}
    seconds: dict[str, dict[str, float]] = {ref: {} for ref in trees}
    for name in next(iter(rows.values())):
        for ref, tree in trees.items():
            args = rows[ref][name]
            if name == "validate, warm":
                _time(tree, caches[ref], works[ref], args)  # load its kernels once
            seconds[ref][name], cached, output = _time(tree, caches[ref], works[ref], args)
            print(f"  {ref}, {name}: {seconds[ref][name]:.2f} s", flush=True)
            if name == "quick start, cold":
                seconds[ref]["quick start, cold: kernels cached"] = cached
                print(f"  {ref}, kernels cached after {cached:.2f} s", flush=True)
                print("   ", " / ".join(re.findall(r"^(?:wall|end to end|note).*$", output, re.M)))
    return seconds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="HEAD~1", help="the earlier commit")
    parser.add_argument("--after", default="HEAD", help="the later commit")
    parser.add_argument("--quick", action="store_true", help="leave out the 32-bar chain")
    args = parser.parse_args(argv)
    parent = Path(tempfile.mkdtemp(prefix="mcchain-startup-"))
    labels = {}
    trees = {}
    try:
        for ref in (args.before, args.after):
            trees[ref] = _worktree(ref, parent)
            labels[ref] = trees[ref].name.removeprefix("tree-")
            print(f"{ref}: {labels[ref]}", flush=True)
        results = measure(trees, parent, args.quick)
    finally:
        for tree in parent.glob("tree-*"):
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree)])
    before, after = results[args.before], results[args.after]
    b, a = labels[args.before], labels[args.after]
    lines = [
        f"| what | {b}, s | {a}, s | {b} / {a} | goal, s |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name in after:
        goal = GOALS[name]
        lines.append(
            f"| {name} | {before[name]:.2f} | {after[name]:.2f} | "
            f"{before[name] / after[name]:.2f}× | {'—' if goal is None else f'≤ {goal:g}'} |"
        )
    table = "\n".join(lines)
    print(table)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "startup.md").write_text(
        f"# Start-up times: {b} against {a}\n\n"
        f"`python benchmarks/bench_startup.py --before {args.before} --after {args.after}"
        f"{' --quick' if args.quick else ''}`, on {os.cpu_count()} cores, the two commits "
        "row by row (each row of one right after the same row of the other; each commit "
        "reuses the caches its rows above filled).\n\n" + table + "\n"
    )
    _chart(before, after, b, a)
    return 0


def _chart(before: dict[str, float], after: dict[str, float], b: str, a: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = list(after)
    y = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(9.5, 0.6 * len(names) + 1.2))
    ax.barh(y - 0.2, [before[n] for n in names], 0.4, label=b, color="0.6")
    ax.barh(y + 0.2, [after[n] for n in names], 0.4, label=a, color="C0")
    goals = [(GOALS[n], i) for i, n in enumerate(names) if GOALS[n] is not None]
    ax.scatter(*zip(*goals, strict=True), marker="|", s=300, color="C3", label="goal")
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("wall time of the command, s (log)")
    ax.set_title("Time to first result: cold and warm starts")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))  # clear of the bars and goals
    fig.tight_layout()
    fig.savefig(OUT / "startup.png", dpi=120)


if __name__ == "__main__":
    raise SystemExit(main())
