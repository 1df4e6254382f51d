"""A slider-crank verdict end to end (issue 37, item 6): ``mcchain run`` of
``configs/slider-crank-requirement.toml`` with ``[storage] histories = "none"`` at
``--samples`` (4,096), warm, before and after, side by side in one run.

``before`` is the tree of ``--before`` (a commit, exported with ``git archive`` into
``--work``, kept there so that its kernels stay cached between invocations), ``after`` this
tree. Each runs the scene once first at 64 samples, unmeasured (its kernels compiled or
loaded into the cache), then ``--repeats`` times, alternating, timed from the command's
start to its exit with the 1-minute load average beside each run (the machine is shared);
ratios are of medians and repeat by repeat. The ensembles of the first repeat are compared
variable by variable: the bitwise equal ones are listed, the others with their largest
difference. ``wall - compute`` (median of each run's) is what a run spends outside its chunk
loop — the interpreter's start, imports, kernel loads, merge, the verdict read back — the
figure a loaded machine disturbs least. After each run, ``mcchain verdict`` of its folder,
``mcchain export --requirements`` of it and ``mcchain confirm`` of a range (:data:`CONFIRM`)
from it (the same tree) are timed too: the designer's steps after a run (the verdict table;
the allocation and what-if files; a fresh run inside a cut range, its verdict).
``--threads`` is passed to ``mcchain run`` (the machine's 2 cores by default).
``--bytecode``: the runs keep their compiled bytecode (in
``--work``), as an installed package has it, where the environment sets
``PYTHONDONTWRITEBYTECODE`` (then each run compiles mcchain's hundred modules from source).

    python benchmarks/bench_verdict.py --before main --repeats 3

Results go to ``benchmarks/results/verdict/``: the table, with the command, appended to
``verdict.md`` (the earlier runs and their readings kept), the last run's JSON in
``verdict.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_light import REPO, export_tree, mcchain_run, scene_with
from bench_speed import append_results

RESULTS = REPO / "benchmarks" / "results" / "verdict"


def per_sample_values(path: Path) -> dict[str, np.ndarray]:
    """Every variable of ``path`` without a time axis (the per-sample ones, coordinates)."""
    import netCDF4

    with netCDF4.Dataset(path) as nc:
        nc.set_auto_maskandscale(False)
        return {
            name: np.asarray(var[:])
            for name, var in nc.variables.items()
            if "time" not in var.dimensions
        }


def compare(before: Path, after: Path) -> list[str]:
    """Lines: the variables bitwise equal, and each other one's largest |difference|."""
    a, b = per_sample_values(before), per_sample_values(after)
    same, lines = [], []
    for name in sorted(a.keys() | b.keys()):
        x, y = a.get(name), b.get(name)
        if x is None or y is None:
            lines.append(f"- `{name}`: only {'after' if x is None else 'before'}")
        elif x.dtype.kind == "O" or y.dtype.kind == "O":
            (same if repr(x) == repr(y) else lines).append(f"`{name}`")
        elif x.shape == y.shape and x.tobytes() == y.tobytes():
            same.append(f"`{name}`")
        elif x.shape != y.shape:
            lines.append(f"- `{name}`: shape {x.shape} before, {y.shape} after")
        else:
            d = np.abs(x.astype(np.float64) - y.astype(np.float64))
            differ = int(np.count_nonzero(~((x == y) | (np.isnan(x) & np.isnan(y)))))
            lines.append(
                f"- `{name}`: {differ} of {x.size} values differ, max |difference| "
                f"{np.nanmax(d):.3g} (median of the values {np.nanmedian(np.abs(x)):.3g})"
            )
    return [f"bitwise equal: {', '.join(same)}", *lines]


CONFIRM = ("--requirement", "slider-accuracy", "--range", "joint.B.clearance=:1.5e-4")
"""The confirmation timed after each run: the slider's accuracy inside clearances up to
0.15 mm (299 fresh samples: the success-run count at 1 % and 95 %)."""


def read_seconds(tree: Path, folder: Path, *command_args: str) -> float:
    """Wall seconds of ``mcchain <command_args> folder`` run from ``tree`` (exit 0, 1 or 4:
    a verdict's codes)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    command = [sys.executable, "-m", "mcchain.cli", *command_args, str(folder)]
    t0 = time.perf_counter()
    proc = subprocess.run(command, env=env, capture_output=True, text=True, cwd=tree)
    seconds = time.perf_counter() - t0
    if proc.returncode not in (0, 1, 4):
        raise RuntimeError(f"{command}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return seconds


def run_variants(args: argparse.Namespace, work: Path) -> tuple[list[dict], list[str]]:
    tree = work / f"tree-{args.before[:10]}"
    before = tree if tree.exists() else export_tree(args.before, work)
    scene = scene_with("none", work)
    variants = {"before": before, "after": REPO}
    extra = ["--threads", str(args.threads), "--no-background-compile"]
    for name, root in variants.items():  # warm: compile or load every kernel once
        mcchain_run(root, scene, 64, work / f"warm-{name}-{time.time_ns()}", extra)
    rows: list[dict] = []
    check: list[str] = []
    for r in range(args.repeats):
        order = list(variants) if r % 2 == 0 else list(variants)[::-1]
        folders = {}
        for name in order:
            folders[name] = work / f"run-{name}-{r}-{time.time_ns()}"
            result = mcchain_run(variants[name], scene, args.samples, folders[name], extra)
            result.pop("stdout")
            result["verdict_wall"] = read_seconds(variants[name], folders[name], "verdict")
            result["export_wall"] = read_seconds(
                variants[name], folders[name], "export", "--requirements"
            )
            confirm_dir = ["--quiet", "--run-dir", str(folders[name] / "confirmed")]
            result["confirm_wall"] = read_seconds(
                variants[name], folders[name], "confirm", *CONFIRM, *confirm_dir
            )
            rows.append({"variant": name, "repeat": r, **result})
            t = result["timings"]
            print(
                f"  {name:6s} repeat {r}: {result['wall']:6.2f} s (prepare {t['prepare']:.2f}, "
                f"warmup {t['warmup']:.2f}, compute {t['compute']:.2f}, merge {t['merge']:.2f}),"
                f" load {result['load']:.2f}; mcchain verdict {result['verdict_wall']:.2f} s,"
                f" export --requirements {result['export_wall']:.2f} s,"
                f" confirm {result['confirm_wall']:.2f} s",
                flush=True,
            )
        if r == 0:
            check = compare(folders["before"] / "ensemble.nc", folders["after"] / "ensemble.nc")
            exported = sorted(  # confirm's scene copy names its run folder: not compared
                p.name
                for p in (folders["before"] / "export").iterdir()
                if not p.name.startswith("confirm-")
            )
            differ = [
                n
                for n in exported
                if (folders["before"] / "export" / n).read_bytes()
                != (folders["after"] / "export" / n).read_bytes()
            ]
            check.append(
                f"`export --requirements` files ({', '.join(exported)}): "
                + (f"differ: {', '.join(differ)}" if differ else "byte for byte the same")
            )
    return rows, check


def table(rows: list[dict], check: list[str], args: argparse.Namespace) -> str:
    keys = ("prepare", "warmup", "compute", "write", "merge")
    lines = [
        f"### {args.samples} samples, `mcchain run --threads {args.threads}` end to end, warm "
        "(median of the repeats; the 1-minute load average at each run's start)",
        "",
        "| variant | wall (s) | "
        + " | ".join(keys)
        + " | wall - compute | user CPU (s) | `mcchain verdict` (s) | `export --requirements`"
        " (s) | `confirm` (s) | loads |",
        "|---|---|" + "---|" * len(keys) + "---|---|---|---|---|---|",
    ]
    for name in ("before", "after"):
        mine = [r for r in rows if r["variant"] == name]
        med = [statistics.median(r["timings"].get(k, float("nan")) for r in mine) for k in keys]
        lines.append(
            f"| {name} | {statistics.median(r['wall'] for r in mine):.2f} | "
            + " | ".join(f"{m:.2f}" for m in med)
            + f" | {statistics.median(r['wall'] - r['timings']['compute'] for r in mine):.2f}"
            + f" | {statistics.median(r['cpu'] for r in mine):.1f}"
            + f" | {statistics.median(r['verdict_wall'] for r in mine):.2f}"
            + f" | {statistics.median(r['export_wall'] for r in mine):.2f}"
            + f" | {statistics.median(r['confirm_wall'] for r in mine):.2f} | "
            + ", ".join(f"{r['load']:.1f}" for r in mine)
            + " |"
        )
    wall = {
        n: statistics.median(r["wall"] for r in rows if r["variant"] == n)
        for n in ("before", "after")
    }
    pairs = []
    for r in sorted({row["repeat"] for row in rows}):
        w = {row["variant"]: row["wall"] for row in rows if row["repeat"] == r}
        pairs.append(f"{w['before'] / w['after']:.2f}")
    verdicts = {tuple(row["verdict"]) for row in rows}
    lines += [
        "",
        f"before / after (medians): {wall['before'] / wall['after']:.2f}; repeat by repeat: "
        f"{', '.join(pairs)}",
        "",
        "the verdict lines: " + ("the same in every run" if len(verdicts) == 1 else "DIFFER"),
        *(f"    {line}" for line in sorted(verdicts)[0]),
        "",
        "per-sample variables, first repeat, before against after:",
        "",
        *check,
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--before", default="main", help="commit of the 'before' tree")
    parser.add_argument("--work", default="/tmp/bench-verdict", help="trees and runs")
    parser.add_argument(
        "--bytecode",
        action="store_true",
        help="let the runs cache their bytecode (under --work) as an installed package does, "
        "where PYTHONDONTWRITEBYTECODE is set",
    )
    args = parser.parse_args()
    if args.bytecode:  # the children inherit it: each tree's modules compiled once, not per run
        os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
        os.environ["PYTHONPYCACHEPREFIX"] = str(Path(args.work) / "pycache")
    args.before = os.popen(f"git -C {REPO} rev-parse {args.before}").read().strip()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    command = "python benchmarks/bench_verdict.py " + " ".join(sys.argv[1:])
    rows, check = run_variants(args, work)
    text = table(rows, check, args)
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    header = (
        f"## bench_verdict, {when}\n\n"
        f"`{command}` ({os.cpu_count()} cores, {when}, before = {args.before[:10]})\n\n"
    )
    print(header + text)
    append_results(RESULTS / "verdict.md", header + text + "\n")
    (RESULTS / "verdict.json").write_text(
        json.dumps({"command": command, "runs": rows, "check": check}, indent=1), "utf-8"
    )


if __name__ == "__main__":
    main()
