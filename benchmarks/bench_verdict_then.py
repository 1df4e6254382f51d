"""Issue 37, item 6, against the issue's start: the designer's 4,096-sample slider-crank
verdict as it ran then and as it runs now, side by side in one run.

``then`` is the tree of ``--before`` (default 5c52736, main before the issue's work) running
its own shipped ``configs/slider-crank-requirement.toml`` as it was (every history stored:
the 831 MB run of the issue's text); ``now`` is this tree running today's file with
``[storage] histories = "none"`` (the light run item 4 added). The two files differ in what
they ask (today's has three requirements and their outputs, among them the slider's error
against the ideal mechanism), so this is the designer's run then and now, not one scene
timed twice; ``bench_verdict.py`` pairs trees on one file. Each tree has its own caches in
``--work``, warmed by a 64-sample run; then ``--repeats`` runs of each, alternating, timed
from the command's start to its exit (``bench_speed.mcchain_run``), with the 1-minute load
average beside each run.

    python benchmarks/bench_verdict_then.py [--before 5c52736] [--repeats 5]

Appends its table, with the command, to ``benchmarks/results/verdict/verdict.md``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_light import scene_with
from bench_speed import REPO, append_results, export, mcchain_run

SCENE = Path("configs") / "slider-crank-requirement.toml"


def _joined(rows: list[dict], key: str, fmt: str) -> str:
    return ", ".join(format(row[key], fmt) for row in rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="5c52736", help="the tree of the issue's start")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--samples", type=int, default=4096)
    parser.add_argument("--work", type=Path, default=Path("/tmp/bench-verdict-then"))
    args = parser.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    then = export(args.before, args.work)
    variants = {
        f"then ({args.before}, its own file, every history)": (then, then / SCENE),
        'now (this tree, histories = "none")': (REPO, scene_with("none", args.work)),
    }
    caches = {name: args.work / f"cache-{i}" for i, name in enumerate(variants)}
    for name, (tree, scene) in variants.items():  # compiles and loads are not timed
        mcchain_run(tree, caches[name], scene, args.work, "--samples", "64")
    rows: dict[str, list[dict]] = {name: [] for name in variants}
    names = list(variants)
    for r in range(args.repeats):
        for name in names if r % 2 == 0 else names[::-1]:
            tree, scene = variants[name]
            result = mcchain_run(
                tree, caches[name], scene, args.work, "--samples", str(args.samples)
            )
            rows[name].append(result)
            print(f"  {name}: {result['wall']:.2f} s, {result['size_mb']:.1f} MB, "
                  f"load {result['load']:.2f}", flush=True)  # fmt: skip
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    command = "python benchmarks/bench_verdict_then.py " + " ".join(
        sys.argv[1:] if argv is None else argv
    )
    lines = [
        f"## bench_verdict_then, {when}",
        "",
        f"`{command}` ({os.cpu_count()} cores; {args.samples} samples, `mcchain run`, warm; "
        "medians of the repeats)",
        "",
        "| run | end to end (s) | compute (s) | ensemble.nc (MB) | each run (s) | loads |",
        "|---|---|---|---|---|---|",
    ]
    for name, rs in rows.items():
        lines.append(
            f"| {name} | {statistics.median(x['wall'] for x in rs):.2f} "
            f"| {statistics.median(x['timings']['compute'] for x in rs):.2f} "
            f"| {statistics.median(x['size_mb'] for x in rs):.1f} "
            f"| {_joined(rs, 'wall', '.2f')} | {_joined(rs, 'load', '.1f')} |"
        )
    walls = [statistics.median(x["wall"] for x in rs) for rs in rows.values()]
    lines += ["", f"then / now (medians): {walls[0] / walls[1]:.2f}", ""]
    text = "\n".join(lines)
    print(text)
    append_results(REPO / "benchmarks" / "results" / "verdict" / "verdict.md", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
