"""What ``[[output]]`` costs: the same run with and without outputs, side by side.

Each case solves one chunk of samples (``mcchain.solvers.solve_chunk``, the kernels warm)
as written, with outputs that the state gives (a windowed force peak, a position's max) and
with ``relative_to = "ideal"`` (the ideal copy integrated alongside); the variants alternate
in one process, ``--repeats`` times, and the table gives each one's best and median time and
its ratio to the run without outputs (the machine is shared: ratios of one run only; the
best runs are the least disturbed by other jobs, the chart shows theirs).

    python benchmarks/bench_outputs.py [--repeats 3] [--samples 128]

Writes ``benchmarks/results/outputs/outputs.md`` and ``outputs.png``.
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "outputs"
sys.path.insert(0, str(REPO))

FORCE_AND_POSITION = """
[[output]]
name = "pin_force_late"
of = "joint_force"
joint = "{joint}"
component = "magnitude"
reduce = "max"
window = [{w0}, {w1}]
[[output]]
name = "x_max"
of = "position"
body = "{body}"
component = "x"
reduce = "max"
"""
RELATIVE = """
[[output]]
name = "error"
of = "position"
body = "{body}"
component = "{component}"
relative_to = "ideal"
reduce = "max_abs"
"""
# (label, config, [simulate] keys or None (as shipped), samples divisor, body, joint,
#  component of the relative output, window)
CASES = [
    ("slider-crank, contact law, rk45 lanes", "configs/slider-crank-requirement.toml", None, 1,
     "slider", "B", "x", (0.002, 0.024)),
    ("four-bar, link, rk4 lanes", "configs/fourbar-clearance.toml",
     't_end = 0.5\ndt = 1e-4\noutput_dt = 1e-3\nmethod = "rk4"', 1, "rocker", "B",
     "magnitude", (0.1, 0.5)),
    ("slider-crank, contact law, rk4 loop", "configs/slider-crank-requirement.toml",
     't_end = 0.004\ndt = 1e-7\noutput_dt = 1e-5\nmethod = "rk4"\nkernels = "loop"', 16,
     "slider", "B", "x", (0.001, 0.004)),
]  # fmt: skip


def scene_text(config: str, simulate: str | None, extra: str) -> str:
    """The config without its requirements and sampling count changes, [simulate] replaced
    when given, plus ``extra`` tables."""
    text = (REPO / config).read_text()
    text = text.split("[[requirement]]")[0]
    if simulate is not None:
        text = re.sub(r"(?ms)^\[simulate\]\n.*?(?=^\[)", "", text + "\n[end]\n")
        text = text.replace("\n[end]\n", "") + f"\n[simulate]\n{simulate}\n"
    return text + extra


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--samples", type=int, default=128)
    args = parser.parse_args()
    from mcchain.scene import compile_model, load_scene_text
    from mcchain.solvers import solve_chunk

    rows = []
    for label, config, simulate, divisor, body, joint, component, window in CASES:
        samples = max(args.samples // divisor, 4)
        variants = {
            "none": "",
            "force + position": FORCE_AND_POSITION.format(
                body=body, joint=joint, w0=window[0], w1=window[1]
            ),
            "relative_to ideal": RELATIVE.format(body=body, component=component),
        }
        jobs = {}
        for name, extra in variants.items():
            scene = load_scene_text(scene_text(config, simulate, extra))
            model = compile_model(scene, nsample=samples)
            solve_chunk(model.select(0, 4), scene)  # compile / load the kernels
            jobs[name] = (scene, model)
        times: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(args.repeats):
            for name, (scene, model) in jobs.items():
                t0 = time.perf_counter()
                solve_chunk(model, scene)
                times[name].append(time.perf_counter() - t0)
        base_best, base_median = min(times["none"]), statistics.median(times["none"])
        for name, values in times.items():
            best, median = min(values), statistics.median(values)
            rows.append((label, samples, name, best, median, best / base_best,
                         median / base_median))  # fmt: skip
            ratios = f"ratio {best / base_best:5.2f} / {median / base_median:5.2f}"
            print(f"{label:40s} {name:18s} best {best:7.2f} s  median {median:7.2f} s  "
                  f"{ratios}", flush=True)  # fmt: skip
    write(rows, args)


def write(rows: list[tuple], args: argparse.Namespace) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    lines = [
        "# What `[[output]]` costs",
        "",
        f"`python benchmarks/bench_outputs.py --repeats {args.repeats} --samples {args.samples}`"
        f" ({time.strftime('%Y-%m-%d')}, 2 shared cores; one chunk solved in-process, kernels "
        "warm, the variants alternating; ratio = time / the same run without outputs).",
        "",
        "Variants: `none`, the scene as shipped; `force + position`, a joint force's windowed",
        "max (values only: the four-point cubic) and a body point's max (the Hermite with its",
        "rate); `relative_to ideal`, one position output relative to the ideal mechanism (its",
        "copy integrated alongside: about the mechanism's own integration again). The outputs",
        "are fed per lane in scalar code at every accepted state (their signal, then the",
        "reduction), which is what the middle variant costs.",
        "",
        "| case | samples | outputs | best, s | median, s | ratio (best) | ratio (median) |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, samples, name, best, median, r_best, r_median in rows:
        lines.append(
            f"| {label} | {samples} | {name} | {best:.2f} | {median:.2f} | {r_best:.2f} | "
            f"{r_median:.2f} |"
        )
    (OUT / "outputs.md").write_text("\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = sorted({r[0] for r in rows}, key=[r[0] for r in rows].index)
    names = sorted({r[2] for r in rows}, key=[r[2] for r in rows].index)
    fig, ax = plt.subplots(figsize=(8, 3.5))
    width = 0.8 / len(names)
    for j, name in enumerate(names):
        ratios = [next(r[5] for r in rows if r[0] == lab and r[2] == name) for lab in labels]
        ax.bar([i + j * width for i in range(len(labels))], ratios, width, label=name)
    ax.set_xticks([i + width for i in range(len(labels))], labels, fontsize=8)
    ax.axhline(1.0, color="k", lw=0.5)
    ax.set_ylabel("time / without outputs (best runs)")
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title("[[output]] cost, side by side")
    fig.tight_layout()
    fig.savefig(OUT / "outputs.png", dpi=120)
    print(OUT / "outputs.md")


if __name__ == "__main__":
    main()
