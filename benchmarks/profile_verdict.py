"""Where the compute of a slider-crank verdict goes (issue 37, item 6): rk45 on
``configs/slider-crank-requirement.toml`` with ``[storage] histories = "none"``, in process.

1. **steps**: per sample (``--samples``, 1 thread) the accepted and rejected steps, the
   right-hand-side evaluations, the impacts and free flight (a least-squares fit of the steps
   on them), and the same run with a coarser ``output_dt`` (the steps then no longer end on
   every 10 µs output time: how many steps the scene's grid takes, and how far the
   per-sample values move: the impacts make them sensitive to the step sequence).
2. **per step**: CPU seconds per accepted sample-step as shipped, without the relative
   output, and without any ``[[output]]`` (1 thread, alternating).
3. **threads**: one chunk of 1,024 samples on 2 threads, each block of lane groups with its
   wall and its thread's CPU seconds (a static split that leaves a thread idle would show).

    python benchmarks/profile_verdict.py --samples 256

Results (with the command and the load average) go to ``benchmarks/results/verdict/``.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

import numba
import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "configs" / "slider-crank-requirement.toml"
RESULTS = REPO / "benchmarks" / "results" / "verdict"


def light_scene(samples: int):
    from mcchain.scene import compile_model, load_scene_text

    text = SCENE.read_text(encoding="utf-8").replace(
        "\n[sample]", '\n[storage]\nhistories = "none"\n\n[sample]'
    )
    scene = load_scene_text(text)
    return scene, compile_model(scene, nsample=samples)


def steps_part(scene, model) -> list[str]:
    from mcchain.solvers import _Ideal
    from mcchain.solvers.outputs import simulate_outputs
    from mcchain.solvers.statics import assemble

    numba.set_num_threads(1)
    start = assemble(model)
    ideal = _Ideal(model, scene)
    timed = [o for o in scene.output if o.at is None]

    def run(sim):
        status = start.status | ideal.status(False)
        t0 = time.thread_time()
        out = simulate_outputs(model, timed, sim, start.q, start.v, ideal.start(False), status,
                               diagnostics=True, histories=False)  # fmt: skip
        return out, time.thread_time() - t0

    run(scene.simulate.model_copy(update={"t_end": 5 * scene.simulate.dt}))  # warm
    out, cpu = run(scene.simulate)
    n = model.nsample
    steps, rejected, evals = out["steps"], out["rejected_steps"], out["evaluations"]
    joint = model.joint_names.index("B")
    impacts, flight = out["impact_count"][:, joint], out["free_flight_time"][:, joint]
    fit = np.linalg.lstsq(np.vstack([np.ones(n), impacts, flight * 1e3]).T, steps, rcond=None)
    a, b, c = fit[0]
    lines = [
        f"### 1. steps ({n} samples, 1 thread, load {os.getloadavg()[0]:.1f})",
        "",
        f"- kernel CPU {cpu:.2f} s: {cpu / n * 1e3:.2f} ms a sample, "
        f"{cpu / steps.sum() * 1e9:.0f} ns an accepted sample-step, "
        f"{cpu / evals.sum() * 1e9:.0f} ns an evaluation",
        f"- accepted steps a sample: mean {steps.mean():.0f}, p10 {np.percentile(steps, 10):.0f},"
        f" median {np.median(steps):.0f}, p90 {np.percentile(steps, 90):.0f}, max {steps.max()}",
        f"- rejected: {rejected.sum() / (steps.sum() + rejected.sum()) * 100:.1f} % of attempts;"
        f" evaluations a sample {evals.mean():.0f}",
        f"- output times: {len(np.arange(0, scene.simulate.t_end, scene.simulate.output_step))}"
        f" + t_end (output_dt {scene.simulate.output_step:g} s): no step is longer",
        f"- impacts a sample {np.mean(impacts):.1f} (max {np.max(impacts)}); free flight "
        f"{np.mean(flight) * 1e3:.2f} ms of {scene.simulate.t_end * 1e3:g} ms",
        f"- fit: steps = {a:.0f} + {b:.1f} a impact + {c:.1f} a ms of free flight",
        "",
        "| output_dt (s) | steps a sample | rejected | CPU (s) | as written / this | max "
        "\\|Δ slider_error\\| (m) | max relative Δ peak_contact_force |",
        "|---|---|---|---|---|---|---|",
        f"| {scene.simulate.output_step:g} (as written) | {steps.mean():.0f} | "
        f"{rejected.sum() / (steps.sum() + rejected.sum()) * 100:.1f} % | {cpu:.2f} | 1.00 | "
        "0 | 0 |",
    ]
    for output_dt in (1e-4, 1e-3):
        other, cpu2 = run(scene.simulate.model_copy(update={"output_dt": output_dt}))
        s2, r2 = other["steps"], other["rejected_steps"]
        pk, pk2 = out["peak_contact_force"][:, joint], other["peak_contact_force"][:, joint]
        lines.append(
            f"| {output_dt:g} | {s2.mean():.0f} | {r2.sum() / (s2.sum() + r2.sum()) * 100:.1f} % | "
            f"{cpu2:.2f} | {cpu / cpu2:.2f} | "
            f"{np.nanmax(np.abs(other['slider_error'] - out['slider_error'])):.2g} | "
            f"{np.nanmax(np.abs(pk2 / pk - 1)):.2g} |"
        )
    return lines


def per_step_part(scene, model, repeats: int) -> list[str]:
    from mcchain.solvers import solve_chunk

    numba.set_num_threads(1)
    variants = {
        "as shipped (two outputs, one relative to the ideal)": scene,
        "without the relative output": scene.model_copy(
            update={"output": [o for o in scene.output if o.relative_to is None]}
        ),
        "no [[output]]": scene.model_copy(update={"output": []}),
    }
    for variant in variants.values():
        solve_chunk(model.select(0, 2), variant)
    costs: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(repeats):
        for name, variant in variants.items():
            t0 = time.process_time()
            out = solve_chunk(model, variant)
            costs[name].append((time.process_time() - t0) / out["steps_taken"].sum() * 1e9)
    lines = [
        f"### 2. CPU a step ({model.nsample} samples, 1 thread, load {os.getloadavg()[0]:.1f};"
        f" each of {repeats} repeats)",
        "",
        "| variant | ns an accepted sample-step |",
        "|---|---|",
    ]
    lines += [f"| {n} | {', '.join(f'{c:.0f}' for c in cs)} |" for n, cs in costs.items()]
    return lines


def threads_part(scene, model) -> list[str]:
    import mcchain.solvers.simulate as simulate_module
    import mcchain.solvers.threads as threads_module
    from mcchain.solvers import solve_chunk

    numba.set_num_threads(2)
    solve_chunk(model.select(0, 2), scene)
    blocks: list[tuple[int, int, int, float, float, float]] = []
    # blocks of items (over_samples), or one call a thread on a shared queue (rk45's lanes)
    originals = {n: getattr(threads_module, n) for n in ("over_samples", "on_every_thread")}

    def timed(original):
        def run(kernel, count, *args, **keywords):
            def block(start, stop, *rest):
                t0, c0 = time.perf_counter(), time.thread_time()
                kernel(start, stop, *rest)
                blocks.append((threading.get_ident(), start, stop, t0, time.perf_counter(),
                               time.thread_time() - c0))  # fmt: skip

            original(block, count, *args, **keywords)

        return run

    for name, original in originals.items():
        setattr(simulate_module, name, timed(original))
    try:
        t0, c0 = time.perf_counter(), os.times()
        solve_chunk(model, scene)
        wall, cpu = time.perf_counter() - t0, os.times().user - c0.user
    finally:
        for name, original in originals.items():
            setattr(simulate_module, name, original)
    names = {ident: k for k, ident in enumerate(dict.fromkeys(b[0] for b in blocks))}
    lines = [
        f"### 3. threads: one chunk of {model.nsample} samples, 2 threads (load "
        f"{os.getloadavg()[0]:.1f}): wall {wall:.2f} s, process user CPU {cpu:.2f} s",
        "",
        "| thread | items (lane groups or samples) | start (s) | end (s) | wall (s) | CPU (s) |",
        "|---|---|---|---|---|---|",
    ]
    for ident, start, stop, b0, b1, bcpu in blocks:
        lines.append(
            f"| {names[ident]} | {start}:{stop} | {b0 - t0:.3f} | {b1 - t0:.3f} | "
            f"{b1 - b0:.3f} | {bcpu:.3f} |"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    command = "python benchmarks/profile_verdict.py " + " ".join(sys.argv[1:])
    scene, model = light_scene(args.samples)
    lines = steps_part(scene, model)
    lines += ["", *per_step_part(scene, model, args.repeats)]
    _, chunk = light_scene(1024)
    lines += ["", *threads_part(scene, chunk)]
    write_result(command, lines, "profile.md")


def write_result(command: str, lines: list[str], name: str) -> None:
    """Print ``lines`` under the command, the cores and the time, and append them to ``name``
    in :data:`RESULTS` (the earlier runs and the readings written under them are kept)."""
    from bench_speed import append_results

    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    text = f"`{command}` ({os.cpu_count()} cores, {when})\n\n" + "\n".join(lines) + "\n"
    print(text)
    append_results(RESULTS / name, f"## {when}\n\n{text}")


if __name__ == "__main__":
    main()
