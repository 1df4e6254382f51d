"""What the driven crank costs the verdict's rk45 lanes: an upper bound on eliminating the
coordinates a driver and a ground joint prescribe (issue 37, item 6: the way left after the
stage's text, its schedule and its registers).

The Flores slider-crank of ``configs/slider-crank-requirement.toml`` (its requirements and
outputs left out, the piston pin on the contact law from t = 0 so that both scenes take the
same stage, ``histories = "none"``) against the same mechanism without its crank: the rod
pinned to ground by an ideal revolute where the crank pin starts, no driver. The crank's
three coordinates, its ground joint's two rows, the driver's row, one sine-cosine and one
joint's peak tracking are what the second scene does not have: 9 coordinates and 8 rows
against 6 and 5. Eliminated, the crank's motion would come back as a function of time (one
sine-cosine of θ₀ + ω t a stage, its pin's acceleration in the rod's rows) and its
reactions from its own three equations after the solve, so the gain is below the ratio
measured here. The two scenes' motions differ (the rod alone barely moves): the figure is
the cost of one right-hand-side evaluation, the kernel's CPU time over the evaluations its
diagnostics count.

``--samples`` samples (256), 1 thread, CPU time; the two scenes alternate over ``--rounds``
rounds (8), the figure the median of the rounds' ratios.

    python benchmarks/bench_prescribed.py [--samples 256] [--rounds 8]

Prints a table and appends it to benchmarks/results/verdict/prescribed.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import re
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "configs" / "slider-crank-requirement.toml"
RESULTS = REPO / "benchmarks" / "results" / "verdict" / "prescribed.md"


def scene_texts() -> dict[str, str]:
    """``crank``: the shipped slider-crank cut before its first requirement, the piston pin
    on the contact law, no histories; ``rod``: the same without the crank and its driver, the
    rod pinned where the crank pin starts (crank 0.05 m at angle0 = 0: (0.05, 0))."""
    text = SCENE.read_text("utf-8").split("[[requirement]]")[0]
    text = text.replace('model = "auto"', 'model = "contact"')
    text = text.replace("\n[sample]", '\n[storage]\nhistories = "none"\n\n[sample]')
    rod = re.sub(r'\[\[body\]\]\nname = "crank".*?\n\n', "", text, flags=re.S)
    rod = re.sub(r'\[\[joint\]\]\nname = "O".*?\n\n', "", rod, flags=re.S)
    rod = re.sub(r"\[\[driver\]\].*?\n\n", "", rod, flags=re.S)
    pin = 'bodies = ["crank", "rod"]\npoints = [[0.025, 0.0], [-0.06, 0.0]]'
    if pin not in rod or 'name = "crank"' in rod or "[[driver]]" in rod:
        raise SystemExit(f"{SCENE}: not the layout this benchmark cuts (crank, rod, slider)")
    rod = rod.replace(pin, 'bodies = ["ground", "rod"]\npoints = [[0.05, 0.0], [-0.06, 0.0]]')
    return {"crank": text, "rod": rod}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=8)
    args = parser.parse_args(argv)
    if args.rounds < 2 or args.samples < 8:
        parser.error("--rounds: at least 2; --samples: at least 8")
    import numba

    from mcchain.scene import compile_model, load_scene_text
    from mcchain.solvers.simulate import simulate
    from mcchain.solvers.statics import assemble

    numba.set_num_threads(1)
    runs = {}
    for name, text in scene_texts().items():
        scene = load_scene_text(text)
        model = compile_model(scene, nsample=args.samples)
        runs[name] = (scene, model, assemble(model))

    def run(name: str) -> tuple[float, dict]:
        scene, model, start = runs[name]
        t0 = time.thread_time()
        out = simulate(model, scene.simulate, start.q, start.v, status=start.status,
                       diagnostics=True, histories=False)  # fmt: skip
        return time.thread_time() - t0, out

    for name in runs:
        run(name)  # compiled or loaded, unmeasured
    cpu: dict[str, list[float]] = {name: [] for name in runs}
    counts: dict[str, tuple[int, int, int]] = {}
    for r in range(args.rounds):
        for name in list(runs) if r % 2 == 0 else list(runs)[::-1]:
            seconds, out = run(name)
            cpu[name].append(seconds)
            counts[name] = (int(out["evaluations"].sum()), int(out["steps"].sum()),
                            int(out["rejected_steps"].sum()))  # fmt: skip
    per_eval = {n: [c / counts[n][0] * 1e9 for c in cpu[n]] for n in runs}
    ratios = [a / b for a, b in zip(per_eval["crank"], per_eval["rod"], strict=True)]
    q1, median, q3 = statistics.quantiles(ratios, n=4, method="inclusive")
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"## bench_prescribed, {stamp}",
        "",
        f"`python benchmarks/bench_prescribed.py --samples {args.samples} --rounds "
        f"{args.rounds}` (1 thread, CPU time; load average {os.getloadavg()[0]:.1f})",
        "",
        "| scene | coordinates, rows of B | evaluations | accepted steps | rejected | "
        "ns an evaluation (median) |",
        "|---|---|---|---|---|---|",
    ]
    shape = {name: f"{model.ndof}, {model.ncon}" for name, (_, model, _) in runs.items()}
    for name in runs:
        ev, st, rj = counts[name]
        lines.append(f"| {name} | {shape[name]} | {ev:,} | {st:,} | {rj:,} | "
                     f"{statistics.median(per_eval[name]):.1f} |")  # fmt: skip
    lines += [
        "",
        f"crank / rod per evaluation, the rounds' ratios: median **{median:.2f}** "
        f"(quartiles {q1:.2f}-{q3:.2f})",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_speed import append_results

    append_results(RESULTS, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
