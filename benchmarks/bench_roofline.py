"""A roofline of every kernel path: flops and bytes per unit of work counted in the optimised
LLVM IR of the kernels, the measured time, the fraction of this machine's measured peak.

    python benchmarks/bench_roofline.py [--repeats 7] [--only rk4,rk45] [--skip-peaks]

Three fresh processes, so that nothing one does disturbs the others:

1. ``--count``: fresh numba and lane-kernel caches, every kernel compiled with a counter in
   each basic block of its optimised IR (:mod:`ircount`: what is counted and how), each path
   run once on a few samples, one thread: flops and bytes per instance-step (per instance
   for statics and modes). Compiling everything cold takes minutes.
2. ``--time``: the ordinary compiled kernels (the user's caches), each path run ``--repeats``
   times on 1 thread (best CPU time: other jobs on the shared machine stretch wall time)
   and 2 threads (best wall time).
3. the ceilings (:mod:`peak`): FMA loop, add/mul loop, dgemm, L1 and memory bandwidth.

Paths: the generated lanes (``rk4``, ``rk4-projection``, ``rk45``) and the generic loop
kernels (``kernels = "loop"``: ``rk4``; ``generalized-alpha``, which has no lanes) on the
clearance double pendulum (the MuJoCo comparison scene) and the Flores slider-crank (contact
law at the piston pin), and the statics (Newton equilibrium) and modes (eigenpulsations)
kernels on the clearance four-bar. Writes ``benchmarks/results/roofline/roofline.md``,
``roofline.json`` and ``roofline.png``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "results" / "roofline"
CONFIGS = ROOT / "configs"


@dataclass(frozen=True)
class KernelPath:
    name: str  # the path: method and kernels
    scene: str  # scene label
    unit: str  # "instance-step" or "instance"
    count_samples: int  # samples of the counting run
    time_samples: int  # samples of the timed runs


PATHS = [
    KernelPath("rk4 lanes", "double pendulum", "instance-step", 16, 4096),
    KernelPath("rk4-projection lanes", "double pendulum", "instance-step", 16, 4096),
    KernelPath("rk45 lanes", "double pendulum", "instance-step", 16, 4096),
    KernelPath("rk4 loop", "double pendulum", "instance-step", 4, 256),
    KernelPath("generalized-alpha loop", "double pendulum", "instance-step", 4, 256),
    KernelPath("rk4 lanes", "slider-crank", "instance-step", 16, 512),
    KernelPath("rk45 lanes", "slider-crank", "instance-step", 16, 512),
    KernelPath("rk4 loop", "slider-crank", "instance-step", 4, 64),
    KernelPath("statics", "four-bar", "instance", 64, 20000),
    KernelPath("modes", "four-bar", "instance", 64, 20000),
]


# ---------------------------------------------------------------------------------------------
# The work of each path (run inside the counting or timing process)


def _slider_crank(n: int) -> tuple[Any, Any, Any]:
    from mcchain.scene import compile_model, load_scene_text
    from mcchain.solvers.statics import assemble

    text = (CONFIGS / "slider-crank-flores.toml").read_text()
    scene = load_scene_text(re.sub(r"count = \d+", f"count = {n}", text))
    model = compile_model(scene)
    return scene, model, assemble(model)


def _double_pendulum(n: int) -> Any:
    from mcchain.testing.scenes import DOUBLE_PENDULUM, model_of
    from mcchain.testing.scenes import straight_chain_text as chain_text

    return model_of(chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4}), nsample=n)


def work(path: KernelPath, n: int) -> Callable[[], float]:
    """A call that runs ``path`` on ``n`` samples and returns its units of work (summed
    instance-steps, or instances)."""
    from mcchain.solvers.simulate import simulate

    method, _, kernels = path.name.partition(" ")
    if path.scene == "double pendulum":
        model = _double_pendulum(n)
        steps = 2000 if method != "generalized-alpha" else 200
        if kernels == "loop":
            steps //= 10
        sim = dict(t_end=1e-4 * steps, dt=1e-4, output_dt=1e-2, method=method, rtol=1e-8,
                   atol=1e-10, kernels=kernels)  # fmt: skip

        def run() -> float:
            out = simulate(model, sim, diagnostics=True)
            return float(np.sum(out["steps"]))

        return run
    if path.scene == "slider-crank":
        scene, model, start = _slider_crank(n)
        sim = dict(scene.simulate.model_dump(), t_end=0.004, method=method, kernels=kernels)
        if method == "rk4":
            sim["dt"] = 1e-6
            if kernels == "loop":
                sim["t_end"] = 4e-4

        def run() -> float:
            out = simulate(model, sim, q_start=start.q, v_start=start.v, status=start.status,
                           diagnostics=True)  # fmt: skip
            return float(np.sum(out["steps"]))

        return run
    from mcchain.scene import compile_model, load_scene
    from mcchain.solvers.statics import assemble, solve_equilibrium, solve_modes

    scene = load_scene(CONFIGS / "fourbar-clearance-statics.toml")
    model = compile_model(scene, nsample=n)
    start = assemble(model)
    if path.name == "statics":
        return lambda: (solve_equilibrium(model, start.q, start.status, scene.equilibrium), n)[1]
    equilibrium = solve_equilibrium(model, start.q, start.status, scene.equilibrium)
    return lambda: (solve_modes(model, equilibrium, shapes=True), n)[1]


def _selected(only: str) -> list[KernelPath]:
    keys = [k for k in only.split(",") if k]
    return [p for p in PATHS if not keys or any(k in f"{p.name} {p.scene}" for k in keys)]


def count(only: str) -> list[dict[str, Any]]:
    """Per path: IR counts per unit (this process must have fresh caches)."""
    import ircount

    ircount.install()
    import numba

    numba.set_num_threads(1)
    rows = []
    for path in _selected(only):
        run = work(path, path.count_samples)
        run()  # compiles (instrumented)
        ircount.reset()
        units = run()
        t = ircount.totals()
        rows.append({
            "path": path.name, "scene": path.scene, "unit": path.unit, "units": units,
            "flops": t.flops / units, "fma": t.fma / units, "vector_flops": t.vector_flops / units,
            "libm": t.libm / units, "load_bytes": t.load_bytes / units,
            "store_bytes": t.store_bytes / units,
        })  # fmt: skip
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    return rows


def timed(only: str, repeats: int) -> list[dict[str, Any]]:
    """Per path: best time per unit on 1 thread (CPU) and 2 threads (wall)."""
    import numba

    rows = []
    for path in _selected(only):
        run = work(path, path.time_samples)
        run()  # compile or load
        row: dict[str, Any] = {"path": path.name, "scene": path.scene}
        for threads in (1, 2):
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
            best = math.inf
            for _ in range(repeats):
                c0, t0 = time.process_time(), time.perf_counter()
                units = run()
                spent = time.process_time() - c0 if threads == 1 else time.perf_counter() - t0
                best = min(best, spent / units)
            row[f"ns_{threads}"] = best * 1e9
        row["load"] = os.getloadavg()[0]
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    return rows


# ---------------------------------------------------------------------------------------------
# Orchestration, table, chart


def _child(args: list[str], env: dict[str, str]) -> Any:
    out = subprocess.run([sys.executable, __file__, *args], env=env, capture_output=True,
                         text=True)  # fmt: skip
    if out.returncode:
        sys.stderr.write(out.stderr)
        raise SystemExit(f"{' '.join(args)} failed")
    return json.loads(out.stdout)


def table(counts: list[dict], times: list[dict], peaks: dict[str, Any]) -> str:
    def peak(threads: int) -> float:
        return float(peaks[f"fma_{threads}"])

    lines = [
        "| path | scene | unit | flops / unit | in vectors | bytes / unit (L1) | flop / byte "
        "| ns / unit, 1 thread | GFLOP/s | % of FMA peak | ns / unit, 2 threads | GFLOP/s "
        "| % of FMA peak |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in counts:
        t = next((x for x in times if (x["path"], x["scene"]) == (c["path"], c["scene"])), None)
        nbytes = c["load_bytes"] + c["store_bytes"]
        cells = [c["path"], c["scene"], c["unit"], f"{c['flops']:,.0f}",
                 f"{100 * c['vector_flops'] / max(c['flops'], 1):.0f} %", f"{nbytes:,.0f}",
                 f"{c['flops'] / nbytes:.2f}"]  # fmt: skip
        for threads in (1, 2):
            if t is None:
                cells += ["–", "–", "–"]
                continue
            ns = t[f"ns_{threads}"]
            gflops = c["flops"] / ns
            cells += [f"{ns:,.1f}", f"{gflops:.1f}", f"{100 * gflops / peak(threads):.0f} %"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def chart(counts: list[dict], times: list[dict], peaks: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 6), constrained_layout=True)
    x = np.logspace(-2.5, 1.5, 200)
    threads = 1  # CPU time: on the shared machine the 2-thread wall times count others' turns
    fma, mul_add = peaks[f"fma_{threads}"], peaks[f"mul_add_{threads}"]
    l1, memory = peaks[f"l1_{threads}"], peaks["memory"]  # memory: one thread's copy
    label = f"FMA peak {fma:.0f} GFLOP/s, L1 loads {l1:.0f} GB/s"
    ax.loglog(x, np.minimum(fma, l1 * x), "k-", lw=1.5, label=label)
    label = f"separate mul/add peak {mul_add:.0f} GFLOP/s"
    ax.loglog(x, np.minimum(mul_add, l1 * x), "k--", lw=1, label=label)
    ax.loglog(x, np.minimum(fma, memory * x), "k:", lw=1, label=f"memory {memory:.0f} GB/s")
    dgemm = max(d["gflops"] for d in peaks[f"dgemm_{threads}"])
    ax.axhline(dgemm, color="tab:gray", lw=1, ls="-.", label=f"NumPy dgemm {dgemm:.0f} GFLOP/s")
    markers = {"double pendulum": "o", "slider-crank": "s", "four-bar": "^"}
    colours = plt.get_cmap("tab10")
    names = sorted({c["path"] for c in counts})
    for c in counts:
        t = next((x for x in times if (x["path"], x["scene"]) == (c["path"], c["scene"])), None)
        if t is None:
            continue
        intensity = c["flops"] / (c["load_bytes"] + c["store_bytes"])
        gflops = c["flops"] / t[f"ns_{threads}"]
        ax.loglog(intensity, gflops, markers.get(c["scene"], "o"), ms=9,
                  color=colours(names.index(c["path"]) % 10),
                  label=f"{c['path']}, {c['scene']}")  # fmt: skip
    ax.set_xlabel("arithmetic intensity, flop per byte loaded or stored (L1)")
    ax.set_ylabel(f"GFLOP/s, {threads} thread (CPU time)")
    ax.set_title("mcchain kernels on one core of this machine: counted flops / measured time")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(True, which="both", alpha=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--only", default="", help="paths whose name or scene has one of these")
    parser.add_argument("--skip-peaks", action="store_true", help="reuse roofline.json's")
    parser.add_argument("--count", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--time", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--peaks", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(HERE))
    if args.count:
        print(json.dumps(count(args.only)))
        return 0
    if args.time:
        print(json.dumps(timed(args.only, args.repeats)))
        return 0
    if args.peaks:
        import peak

        print(json.dumps(peak.measure()))
        return 0
    OUT.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    commit = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=HERE, text=True,
                            capture_output=True).stdout.strip() or "unknown"  # fmt: skip
    env = dict(os.environ)
    sub = ["--only", args.only, "--repeats", str(args.repeats)]
    with tempfile.TemporaryDirectory(prefix="roofline-") as fresh:
        counts = _child(["--count", *sub], {**env, "MCCHAIN_CACHE_DIR": f"{fresh}/mcchain",
                                            "NUMBA_CACHE_DIR": f"{fresh}/numba"})  # fmt: skip
    load_before = os.getloadavg()[0]
    times = _child(["--time", *sub], env)
    previous = OUT / "roofline.json"
    if args.skip_peaks and previous.exists():
        peaks = json.loads(previous.read_text())["peaks"]
    else:
        peaks = _child(["--peaks"], env)
    (OUT / "roofline.json").write_text(json.dumps({"counts": counts, "times": times,
                                                    "peaks": peaks}, indent=1))  # fmt: skip
    text = report(counts, times, peaks, args, load_before, time.perf_counter() - started, commit)
    print(text)
    (OUT / "roofline.md").write_text(text)
    chart(counts, times, peaks, OUT / "roofline.png")
    return 0


def report(counts: list[dict], times: list[dict], peaks: dict[str, Any],
           args: argparse.Namespace, load: float, seconds: float, commit: str) -> str:  # fmt: skip
    """The Markdown of roofline.md: command, ceilings, what is counted, the table
    (``seconds``: how long the run took; ``commit``: the tree's when it started)."""
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    command = "python benchmarks/bench_roofline.py" + (f" --only {args.only}" if args.only else "")
    dgemm = {th: max(peaks[f"dgemm_{th}"], key=lambda d: d["gflops"]) for th in (1, 2)}
    ceilings = [
        "| ceiling | 1 thread | 2 threads |",
        "|---|---|---|",
        f"| FMA loop, GFLOP/s | {peaks['fma_1']:.1f} | {peaks['fma_2']:.1f} |",
        f"| mul + add loop (no FMA), GFLOP/s | {peaks['mul_add_1']:.1f} | "
        f"{peaks['mul_add_2']:.1f} |",
        f"| NumPy dgemm (n = 3000), GFLOP/s | {dgemm[1]['gflops']:.1f} ({dgemm[1]['coretype']}, "
        f"kernel {dgemm[1]['kernel']}) | {dgemm[2]['gflops']:.1f} ({dgemm[2]['coretype']}) |",
        f"| L1 loads, GB/s | {peaks['l1_1']:.0f} | {peaks['l1_2']:.0f} |",
        f"| memory (copy), GB/s | {peaks['memory']:.1f} | |",
    ]
    every = "; ".join(
        f"dgemm {d['threads']} thread(s), OPENBLAS_CORETYPE {d['coretype']}: {d['gflops']:.1f}"
        for th in (1, 2) for d in peaks[f"dgemm_{th}"]
    )  # fmt: skip
    return "\n".join(
        [
            "# Roofline of mcchain's kernel paths",
            "",
            f"`{command}` ({when}, the kernels of {commit}; {seconds / 60:.0f} min: every kernel "
            "compiled cold with counters, then timed). "
            f"Load average {load:.1f} when the timed runs started ({peaks.get('load', 0):.1f} at "
            "the ceilings'): the machine is shared (2 cores); the figures are best-of runs, "
            "the ceilings and the kernels on 1 thread on CPU time, the kernels on 2 threads on "
            "wall time (their 2-thread fraction of the peak is low when the machine is busy).",
            "",
            "## Ceilings (measured here: `benchmarks/peak.py`)",
            "",
            *ceilings,
            "",
            f"OPENBLAS_CORETYPE in the environment: {peaks.get('env_OPENBLAS_CORETYPE')}. {every}.",
            f"SIMD register: {peaks['simd_doubles']} doubles. The percentages below are of the FMA "
            "loop's peak (the machine's); code whose adds and multiplies are not fused cannot pass "
            "the mul + add line, half of it.",
            "",
            "## What is counted",
            "",
            "Flops and bytes per unit of work (instance-step: an accepted step of one sample; "
            "instance: one sample's statics or modes) are counted in the optimised LLVM IR the "
            "machine code is emitted from (`benchmarks/ircount.py`): every basic block of every "
            "kernel numba's code generator finalises (the generated lanes and numba's own kernels) "
            "increments a counter, and each block's content is read once: fadd, fsub, fmul, fdiv, "
            "frem and sqrt count 1 per element (a `<8 x double>` operation 8), fma 2 (1 with a "
            "zero addend: a product rounded on its own); negations, "
            "compares, selects, min/max, conversions are not flops; libm calls (sin, cos, hypot) "
            "are counted apart, not as flops. Bytes: every load and store at its type's size "
            "(work arrays live in L1; the compulsory traffic to memory is far smaller). rk45's "
            "figures include rejected attempts and the lanes computed while waiting.",
            "",
            "## Table",
            "",
            table(counts, times, peaks),
            "",
            "libm calls per unit (not in the flops): "
            + ", ".join(f"{c['path']} / {c['scene']} {c['libm']:.0f}" for c in counts if c["libm"]),
            "",
            "![roofline](roofline.png)",
            "",
        ]
    )


if __name__ == "__main__":
    raise SystemExit(main())
