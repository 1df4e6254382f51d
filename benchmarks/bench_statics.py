"""Equilibrium + eigenpulsations per second: mcchain's batch kernels against a plain SciPy loop.

Issue #2 speed target: ≥ 100× the SciPy loop (``scipy.optimize.root`` + ``scipy.linalg.eigh``
per instance, :mod:`mcchain.testing.dense`) on 2 threads. Everything is measured in one run, side
by side; the SciPy loop runs on a subset of the samples (its rate per instance does not
depend on the count). Compile time is reported apart (numba ``cache=True``).

    python benchmarks/bench_statics.py [--counts 10000 100000] [--scipy-samples 200]

Prints a Markdown table and writes ``benchmarks/results/statics.png`` and ``statics.md``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numba
import numpy as np

from mcchain.scene import compile_model, load_scene
from mcchain.solvers import solve_chunk
from mcchain.solvers.statics import assemble
from mcchain.testing import dense as reference

ROOT = Path(__file__).resolve().parents[1]

SCENES = {
    "clearance bar": ROOT / "configs" / "clearance-sweep.toml",
    "clearance four-bar": ROOT / "configs" / "fourbar-clearance-statics.toml",
}
RESULTS = ROOT / "benchmarks" / "results"


def kernel_rate(scene, model, threads: int, repeats: int = 3) -> tuple[float, int]:
    """Best-of-``repeats`` samples per second of ``solve_chunk`` (assembly, equilibrium,
    modes) and the number of failed samples."""
    numba.set_num_threads(threads)
    best = np.inf
    failed = 0
    for _ in range(repeats):
        start = time.perf_counter()
        out = solve_chunk(model, scene)
        best = min(best, time.perf_counter() - start)
        failed = int(np.count_nonzero(out["status"] & 0b111))
    return model.nsample / best, failed


def scipy_rate(model, count: int) -> tuple[float, float]:
    """Samples per second of the SciPy loop on the first ``count`` samples, and its largest
    relative deviation from the kernels' eigenpulsations there."""
    sub = model.select(0, count)
    assembled = assemble(sub)
    start = time.perf_counter()
    omegas = [reference.statics(sub, s, assembled.q[s]).omega for s in range(count)]
    elapsed = time.perf_counter() - start
    return count / elapsed, np.asarray(omegas)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--scipy-samples", type=int, default=200)
    args = parser.parse_args(argv)
    RESULTS.mkdir(parents=True, exist_ok=True)
    max_threads = numba.config.NUMBA_NUM_THREADS
    rows = []
    for label, path in SCENES.items():
        scene = load_scene(path)
        start = time.perf_counter()
        solve_chunk(compile_model(scene, nsample=4), scene)  # compile or load from cache
        warmup = time.perf_counter() - start
        ref_model = compile_model(scene, nsample=args.scipy_samples)
        ref_rate, ref_omega = scipy_rate(ref_model, args.scipy_samples)
        kernel_omega = solve_chunk(ref_model, scene)["omega"]
        deviation = float(np.nanmax(np.abs(kernel_omega - ref_omega) / np.abs(ref_omega)))
        for count in args.counts:
            model = compile_model(scene, nsample=count)
            for threads in sorted({1, min(2, max_threads)}):
                rate, failed = kernel_rate(scene, model, threads)
                rows.append((label, count, threads, rate, ref_rate, failed, deviation, warmup))
    header = (
        "| scene | samples | threads | mcchain samples/s | SciPy loop samples/s | speed-up "
        "| failed | max rel. diff. of ω vs SciPy | first call (compile/cache), s |"
    )
    lines = [header, "|" + "---|" * 9]
    for label, count, threads, rate, ref_rate, failed, deviation, warmup in rows:
        lines.append(
            f"| {label} | {count:,} | {threads} | {rate:,.0f} | {ref_rate:,.0f} | "
            f"{rate / ref_rate:,.0f}× | {failed} | {deviation:.1e} | {warmup:.1f} |"
        )
    table = "\n".join(lines)
    print(table)
    (RESULTS / "statics.md").write_text(table + "\n")
    _chart(rows, RESULTS / "statics.png")
    return 0


def _chart(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4), layout="constrained")
    ax = fig.add_subplot()
    labels = [f"{r[0]}\n{r[1]:,} × {r[2]} thr" for r in rows]
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r[3] for r in rows], 0.4, label="mcchain (numba batch)")
    ax.bar(x + 0.2, [r[4] for r in rows], 0.4, label="SciPy loop (root + eigh)")
    ax.set_yscale("log")
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("equilibria + eigenpulsations per second")
    ax.legend()
    ax.set_title("Statics throughput, measured side by side")
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    raise SystemExit(main())
