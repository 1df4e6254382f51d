"""The lane kernels on 2 threads: blocks of lane groups against one queue shared by the
threads, the same compiled kernel, alternating in one process.

The lanes take their work (rk4: lane groups; rk45: samples) from ``queue[0]``
(:func:`mcchain.kernels.config.take_next`). Run as before this change, each block of
``--per-thread`` blocks per thread (:func:`mcchain.solvers.threads.over_samples`; rk4 had
4, rk45 2) gets a queue of its own starting at the block's first item; run as now, one
queue for every thread (:func:`mcchain.solvers.threads.on_every_thread`). The arguments are
captured from one ``simulate`` call: ``--kernel rk4``, bench_speed's run (the clearance
double pendulum, 10,000 samples, 2,000 steps of 0.1 ms); ``--kernel rk45``, one 1,024-sample
chunk of the slider-crank requirement verdict (``configs/slider-crank-requirement.toml``,
histories ``"none"``). Wall time per round; the figure is the median (quartiles) of the
rounds' queue / blocks ratios, with every output array of the two compared bit for bit.

    python benchmarks/bench_queue.py [--kernel rk4|rk45] [--rounds 14] [--per-thread N]

Prints its figures (readings: benchmarks/results/roofline/reading.md).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np


def _lanes_argument(kernel: str) -> int:
    """The position of ``lanes`` among the kernel's arguments after ``g_start, g_stop``
    (templates._ERK_ARGS, templates._ADAPTIVE_ARGS)."""
    from mcchain.codegen import templates

    text = templates._ERK_ARGS if kernel == "rk4" else templates._ADAPTIVE_ARGS
    return [name.strip() for name in text.split(",")].index("lanes")


def _captured(kernel: str) -> tuple[Any, int, tuple[Any, ...]]:
    """The kernel, its count of groups and its arguments but the queue, from one
    ``simulate`` call of this tree."""
    import mcchain.solvers.simulate as simulate_module

    captured: dict[str, Any] = {}
    real = simulate_module.on_every_thread

    def capture(kernel: Callable[..., Any], count: int, *args: Any) -> None:
        if count >= captured.get("count", 0):  # the run's own call, not a shared ideal's
            captured.update(entry=kernel, count=count, args=args[:-1])
        real(kernel, count, *args)

    simulate_module.on_every_thread = capture
    try:
        if kernel == "rk4":
            from mcchain.testing.scenes import DOUBLE_PENDULUM, model_of, straight_chain_text

            text = straight_chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4})
            model = model_of(text, nsample=10_000)
            sim = dict(t_end=0.2, dt=1e-4, output_dt=1e-2, method="rk4", kernels="lanes")
            simulate_module.simulate(model, sim)
        else:
            from profile_verdict import light_scene

            from mcchain.solvers import solve_chunk

            scene, model = light_scene(1024)
            solve_chunk(model, scene)
    finally:
        simulate_module.on_every_thread = real
    return captured["entry"], captured["count"], captured["args"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kernel", choices=("rk4", "rk45"), default="rk4")
    parser.add_argument("--rounds", type=int, default=14)
    parser.add_argument("--per-thread", type=int, default=None, help="blocks (4 rk4, 2 rk45)")
    args = parser.parse_args(argv)
    if args.rounds < 2:
        parser.error("--rounds: at least 2 (quartiles)")
    import numba

    from mcchain.solvers.threads import on_every_thread, over_samples

    sys.path.insert(0, os.path.dirname(__file__))
    entry, count, kernel_args = _captured(args.kernel)
    per_thread = args.per_thread or (4 if args.kernel == "rk4" else 2)
    # rk4's queue holds lane groups, rk45's samples
    scale = 1 if args.kernel == "rk4" else int(kernel_args[_lanes_argument(args.kernel)])
    numba.set_num_threads(2)

    def fresh() -> list[Any]:
        return [np.copy(a) if isinstance(a, np.ndarray) else a for a in kernel_args]

    def blocks(copies: list[Any]) -> None:
        def block(start: int, stop: int, *rest: Any) -> None:
            entry(start, stop, *rest, np.array([start * scale], np.int64))

        over_samples(block, count, *copies, min_block=1, per_thread=per_thread)

    def queue(copies: list[Any]) -> None:
        on_every_thread(entry, count, *copies, np.array([0], np.int64))

    runs = {"blocks": blocks, "queue": queue}
    times: dict[str, list[float]] = {name: [] for name in runs}
    outputs: dict[str, list[Any]] = {}
    for r in range(args.rounds):
        for name in list(runs) if r % 2 == 0 else list(runs)[::-1]:
            outputs[name] = fresh()  # the kernels' arrays as captured, outside the time
            t0 = time.perf_counter()
            runs[name](outputs[name])
            times[name].append(time.perf_counter() - t0)
    same = all(
        np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
        for a, b in zip(outputs["blocks"], outputs["queue"], strict=True)
        if isinstance(a, np.ndarray)
    )
    ratios = [q / b for b, q in zip(times["blocks"], times["queue"], strict=True)]
    q1, median, q3 = statistics.quantiles(ratios, n=4, method="inclusive")
    print(
        f"`python benchmarks/bench_queue.py --kernel {args.kernel} --rounds {args.rounds} "
        f"--per-thread {per_thread}`; 2 threads, load average {os.getloadavg()[0]:.1f}\n\n"
        f"blocks ({per_thread} per thread): median {statistics.median(times['blocks']):.3f} s; "
        f"one queue: median {statistics.median(times['queue']):.3f} s\n"
        f"queue / blocks, the rounds' ratios: median {median:.3f} (quartiles {q1:.3f}-{q3:.3f})"
        f"\nevery output array identical: {same}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
