"""The two paths of ``[simulate]``: generated lanes against the loop kernels, side by side.

For chains of N bars (rk4): the time of a first run of a topology never seen (fresh
generated-code cache; numba's cache holds the statics and the loop kernels, compiled once
per installation, as after any first run), and the steady cost per instance-step once
everything is compiled. Each figure is one ``mcchain run`` in a fresh process, both paths
back to back, so their ratio is measured under the same machine load.

    python benchmarks/bench_loop.py [--sizes 2 4 8 16 32] [--samples 256]

Writes ``benchmarks/results/loop/loop.md`` and ``loop.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "loop"
sys.path.insert(0, str(REPO))

from mcchain.testing.scenes import straight_chain_text  # noqa: E402


def chain_scene(n: int, kernels: str, samples: int, t_end: float) -> str:
    """An N-bar chain released from rest, sampled masses, rk4 with the given path."""
    lengths = [0.3 + 0.02 * (k % 5) for k in range(n)]
    masses = [1.0 + 0.1 * (k % 3) for k in range(n)]
    text = straight_chain_text(lengths, masses).replace('name = "chain"', f'name = "chain{n}"')
    return text + (
        f'[sample]\ncount = {samples}\nseed = 1\n[sample.vary]\n"body.b0.mass" = '
        "{ uniform = [0.9, 1.1] }\n"
        f'[simulate]\nt_end = {t_end!r}\ndt = 1e-4\noutput_dt = 1e-2\nmethod = "rk4"\n'
        f'kernels = "{kernels}"\n'
    )


def run(scene: Path, env: dict[str, str], out: Path) -> tuple[float, dict]:
    """Wall time of one ``mcchain run`` in a fresh process, and its run.json."""
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "mcchain.cli", "run", str(scene), "--out", str(out), "--quiet"],
        env=env, check=True, capture_output=True, text=True,
    )  # fmt: skip
    wall = time.perf_counter() - t0
    folder = max(out.iterdir(), key=lambda p: p.stat().st_mtime)
    return wall, json.loads((folder / "run.json").read_text())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[2, 4, 8, 16, 32])
    parser.add_argument("--samples", type=int, default=256)
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="bench-loop-"))
    numba_cache = work / "numba"
    base = {**os.environ, "PYTHONPATH": str(REPO), "NUMBA_CACHE_DIR": str(numba_cache)}
    # once per installation: statics and the loop kernels (a 2-bar loop run compiles them)
    warm_scene = work / "warm.toml"
    warm_scene.write_text(chain_scene(2, "loop", 4, 0.01))
    run(warm_scene, {**base, "MCCHAIN_CACHE_DIR": str(work / "gen-warm")}, work / "runs")
    rows = []
    for n in args.sizes:
        row: dict[str, float | int] = {"N": n}
        for kernels in ("lanes", "loop"):
            gen = {**base, "MCCHAIN_CACHE_DIR": str(work / f"gen-{n}-{kernels}")}
            first = work / f"chain{n}-{kernels}-first.toml"
            first.write_text(chain_scene(n, kernels, 4, 0.01))
            row[f"{kernels}_first_s"], _ = run(first, gen, work / "runs")
            steady = work / f"chain{n}-{kernels}.toml"
            steady.write_text(chain_scene(n, kernels, args.samples, 0.5))
            _, record = run(steady, gen, work / "runs")
            row[f"{kernels}_steps_per_s"] = record["throughput"]["instance_steps_per_s"]
        row["speed_ratio"] = row["lanes_steps_per_s"] / row["loop_steps_per_s"]
        print(json.dumps(row), flush=True)
        rows.append(row)
    write(rows, args.samples)
    return 0


def write(rows: list[dict], samples: int) -> None:
    lines = [
        "# Lanes against loop kernels (rk4, chains of N bars)",
        "",
        f"One `mcchain run` per figure in a fresh process, both paths back to back; {samples} "
        "samples × 5,000 steps for the steady cost. *First run*: a topology never seen "
        "(empty generated-code cache; numba's cache already holds the statics and the loop "
        "kernels, as after any first run), 4 samples × 100 steps.",
        "",
        "| N | first run, lanes (s) | first run, loop (s) | lanes (instance-steps/s) | loop "
        "(instance-steps/s) | lanes / loop per step |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['N']} | {r['lanes_first_s']:.1f} | {r['loop_first_s']:.1f} | "
            f"{r['lanes_steps_per_s']:.3g} | {r['loop_steps_per_s']:.3g} | "
            f"{r['speed_ratio']:.1f}× |"
        )
    (OUT / "loop.md").write_text("\n".join(lines) + "\n")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 3.6), layout="constrained")
    left, right = fig.subplots(1, 2)
    n = [r["N"] for r in rows]
    for kernels, color in (("lanes", "C0"), ("loop", "C1")):
        left.plot(n, [r[f"{kernels}_first_s"] for r in rows], "o-", color=color, label=kernels)
        right.plot(n, [r[f"{kernels}_steps_per_s"] for r in rows], "o-", color=color,
                   label=kernels)  # fmt: skip
    left.set(xscale="log", yscale="log", xlabel="bars N", ylabel="first run of a topology [s]")
    right.set(xscale="log", yscale="log", xlabel="bars N", ylabel="instance-steps/s (warm)")
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    plain = FuncFormatter(lambda value, _: f"{value:g}")
    for ax in (left, right):
        ax.set_xticks(n, [str(x) for x in n])
        ax.xaxis.set_minor_formatter(NullFormatter())  # no "3×10⁰" between the sizes
        ax.yaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
        ax.yaxis.set_major_formatter(plain)
        ax.yaxis.set_minor_formatter(plain)
        ax.legend(frameon=False)
        ax.grid(alpha=0.3)
    fig.suptitle("rk4: generated lanes against the loop kernels")
    fig.savefig(OUT / "loop.png", dpi=100)


if __name__ == "__main__":
    raise SystemExit(main())
