"""Where the slider-crank verdict's relative output (``slider_error``: the slider's x minus
the tabulated ideal's) spends its time a step (issue 37, item 6), and what a change of it
saves, side by side in one process.

rk45 on ``configs/slider-crank-requirement.toml`` with ``[storage] histories = "none"``, 1
thread, CPU ns per accepted sample-step, each variant once per repeat, alternating. The
variants are texts of the generated lane module, made from this tree's and edited:

- **as shipped** (this tree) and **before**: every change of ``changes`` put back as
  ``--before`` has it (today one: ``hermite_window``, ``--before``'s text: without the
  Bézier-hull shortcut and with the two divisions of a step inside the window); with
  several changes, each one put back alone too (what each one saves, paired);
- for scale (wrong values, the same steps: outputs do not steer the step): **no relative
  output** (``slider_error`` left out), **no [[output]]**.

Every variant's per-sample results are hashed (as shipped and before must agree, bit for
bit) and its accepted steps summed (equal for all: else the variant changed the stepping).

    python benchmarks/profile_verdict_feed.py --before main --samples 256 --repeats 10

Results (with the command and the load average) go to ``benchmarks/results/verdict/``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numba

sys.path.insert(0, str(Path(__file__).resolve().parent))
from profile_output_feed import OUTPUTS, function_text, results_digest
from profile_verdict import REPO, light_scene, write_result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="main", help="commit of the 'before' outputs.py")
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    command = "python benchmarks/profile_verdict_feed.py " + " ".join(sys.argv[1:])

    import mcchain.codegen.generate as generate
    from mcchain.solvers import solve_chunk

    old_source = subprocess.run(["git", "show", f"{args.before}:{OUTPUTS}"], cwd=REPO,
                                check=True, capture_output=True, text=True).stdout  # fmt: skip
    new_source = (REPO / OUTPUTS).read_text("utf-8")

    def function_back(name: str) -> Callable[[str], str]:
        """The text with ``--before``'s function ``name`` in place of this tree's."""
        old, new = function_text(old_source, name), function_text(new_source, name)
        return lambda source: source.replace(new, old) if new in source else source

    changes = {"hermite_window": function_back("hermite_window")}
    """Each change of this tree to the feed, as a function that puts it back in a text."""

    def all_back(source: str) -> str:
        for change in changes.values():
            source = change(source)
        return source

    generate_source = generate.generate_source
    edit = {"with": lambda s: s}

    edited: list[bool] = []

    def patched(topo, variant, lmax=None, outputs=()):
        source = generate_source(topo, variant, lmax=lmax, outputs=outputs)
        changed = edit["with"](source)
        edited.append(changed != source)
        return changed

    generate.generate_source = patched
    generated_text = generate.generated_text  # the variants differ in text, not in key
    generate.generated_text = lambda name, key, make: make()
    scene, model = light_scene(args.samples)
    alone = scene.model_copy(update={"output": [o for o in scene.output if o.relative_to is None]})
    none = scene.model_copy(update={"output": []})
    same = lambda s: s  # noqa: E731
    variants = {
        "as shipped": (scene, same),
        "before": (scene, all_back),
        **{
            f"as shipped, {name} as before": (scene, change)
            for name, change in changes.items()
            if len(changes) > 1
        },
        "no relative output": (alone, same),
        "no [[output]]": (none, same),
    }
    numba.set_num_threads(1)
    modules = {}
    for name, (variant, change) in variants.items():
        edit["with"] = change
        edited.clear()
        generate._MODULES.clear()
        solve_chunk(model.select(0, 2), variant)  # generated, compiled or loaded
        modules[name] = dict(generate._MODULES)
        if change is not same and not any(edited):  # an edit that no longer matches the text
            raise SystemExit(f"{name}: the edit left the generated text as it was")
    costs: dict[str, list[float]] = {name: [] for name in variants}
    digests: dict[str, set[str]] = {name: set() for name in variants}
    steps: dict[str, set[int]] = {name: set() for name in variants}
    loads = []
    for _ in range(args.repeats):
        loads.append(os.getloadavg()[0])
        for name, (variant, _change) in variants.items():
            generate._MODULES.clear()
            generate._MODULES.update(modules[name])
            t0 = time.process_time()
            out = solve_chunk(model, variant)
            cpu = time.process_time() - t0
            costs[name].append(cpu / out["steps_taken"].sum() * 1e9)
            steps[name].add(int(out["steps_taken"].sum()))
            digests[name].add(results_digest(out))
    generate.generate_source = generate_source
    generate.generated_text = generated_text

    base = statistics.median(costs["as shipped"])
    lines = [
        f"### CPU a step ({args.samples} samples, 1 thread; loads "
        f"{', '.join(f'{x:.1f}' for x in loads)}; before = {args.before})",
        "",
        "| variant | ns an accepted sample-step, each repeat | median | as shipped − this "
        "(median of the paired differences) | accepted steps | results (sha256) |",
        "|---|---|---|---|---|---|",
    ]
    for name, values in costs.items():
        each = ", ".join(f"{c:.0f}" for c in values)
        paired = statistics.median(a - b for a, b in zip(costs["as shipped"], values,
                                                          strict=True))  # fmt: skip
        results = ", ".join(sorted(digests[name]))
        lines.append(
            f"| {name} | {each} | {statistics.median(values):.0f} | {paired:+.0f} | "
            f"{', '.join(map(str, sorted(steps[name])))} | {results} |"
        )
    ratios = [b / a for b, a in zip(costs["before"], costs["as shipped"], strict=True)]
    lines.append(
        f"\nbefore / as shipped, repeat by repeat: {', '.join(f'{r:.2f}' for r in ratios)}; "
        f"median {statistics.median(ratios):.3f} (as shipped: median {base:.0f} ns)"
    )
    write_result(command, lines, "verdict_feed.md")


if __name__ == "__main__":
    main()
