"""What the slider-crank verdict's ``[[output]]`` feed costs a step (issue 37, item 6), before
and after a change of :mod:`mcchain.kernels.outputs`, side by side in one process.

rk45 on ``configs/slider-crank-requirement.toml`` with ``[storage] histories = "none"``, 1
thread, CPU ns per accepted sample-step, each variant once per repeat, alternating:

- **as shipped** (its two outputs) and **the contact-force output alone**
  (``pin_force_after_startup``), each with ``--before``'s ``cubic_window`` (its text swapped
  into the generated module) and with this tree's;
- **forces cut to the one it reads**: the contact-force output alone with the feed's joint
  forces reduced to the contact force, the text that sharing the peak tracking's force
  would leave (what sharing could save at most);
- **no [[output]]**.

Every variant's per-sample results (``pin_force_after_startup``, ``slider_error``, the
peaks, contact summaries, steps) are hashed: before and after must give the same bytes.

    python benchmarks/profile_output_feed.py --before main --samples 256 --repeats 8

Results (with the command and the load average) go to ``benchmarks/results/verdict/``.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numba

sys.path.insert(0, str(Path(__file__).resolve().parent))
from profile_verdict import REPO, light_scene, write_result

OUTPUTS = "mcchain/kernels/outputs.py"


def function_text(source: str, name: str) -> str:
    """The text of top-level function ``name`` in ``source`` (up to the next decorator)."""
    match = re.search(rf"^def {name}\(.*?(?=^@njit|\Z)", source, re.S | re.M)
    assert match is not None, name
    return match.group(0)


def results_digest(out: dict) -> str:
    """The first 16 hex digits of the SHA-256 of a solved chunk's arrays but ``time``."""
    digest = hashlib.sha256()
    for key in sorted(out):
        if key != "time":
            digest.update(key.encode() + out[key].tobytes())
    return digest.hexdigest()[:16]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="main", help="commit of the 'before' outputs.py")
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=8)
    args = parser.parse_args()
    command = "python benchmarks/profile_output_feed.py " + " ".join(sys.argv[1:])

    import mcchain.codegen.generate as generate
    import mcchain.codegen.output_blocks as output_blocks
    from mcchain.codegen.emitter import Emitter
    from mcchain.solvers import solve_chunk

    old_source = subprocess.run(["git", "show", f"{args.before}:{OUTPUTS}"], cwd=REPO,
                                check=True, capture_output=True, text=True).stdout  # fmt: skip
    old = function_text(old_source, "cubic_window")
    new = function_text((REPO / OUTPUTS).read_text("utf-8"), "cubic_window")

    class OneForce(Emitter):
        """The feed's joint forces cut to the contact-law joints' contact force."""

        def outputs(self, t: str = "t") -> None:
            self._load_contact_state("fm")
            for k, r in self.contact_row.items():
                self.emit(f"cf{k} = lam{r} if fm{k} == 0.0 else max(lam{r}, 0.0)")

    generate_source = generate.generate_source
    mode = {"cubic": "after", "forces": "all"}

    def patched(topo, variant, lmax=None, outputs=()):
        output_blocks.Emitter = OneForce if mode["forces"] == "one" else Emitter
        try:
            source = generate_source(topo, variant, lmax=lmax, outputs=outputs)
        finally:
            output_blocks.Emitter = Emitter
        if outputs and mode["cubic"] == "before" and old != new:
            assert source.count(new) == 1
            source = source.replace(new, old)
        return source

    generate.generate_source = patched
    # the variants differ in text, not in what the lane-text cache keys on: generate each
    generated_text = generate.generated_text
    generate.generated_text = lambda name, key, make: make()
    scene, model = light_scene(args.samples)
    alone = scene.model_copy(update={"output": [o for o in scene.output if o.relative_to is None]})
    none = scene.model_copy(update={"output": []})
    variants = {
        "as shipped, before": (scene, "before", "all"),
        "as shipped, after": (scene, "after", "all"),
        "contact-force output alone, before": (alone, "before", "all"),
        "contact-force output alone, after": (alone, "after", "all"),
        "contact-force output alone, after, forces cut to the one it reads": (
            alone,
            "after",
            "one",
        ),
        "no [[output]]": (none, "after", "all"),
    }
    numba.set_num_threads(1)
    modules = {}
    for name, (variant, cubic, forces) in variants.items():
        mode.update(cubic=cubic, forces=forces)
        generate._MODULES.clear()
        solve_chunk(model.select(0, 2), variant)  # generated, compiled or loaded
        modules[name] = dict(generate._MODULES)
    costs: dict[str, list[float]] = {name: [] for name in variants}
    digests: dict[str, set[str]] = {name: set() for name in variants}
    loads = []
    for _ in range(args.repeats):
        loads.append(os.getloadavg()[0])
        for name, (variant, _cubic, _forces) in variants.items():
            generate._MODULES.clear()
            generate._MODULES.update(modules[name])
            t0 = time.process_time()
            out = solve_chunk(model, variant)
            cpu = time.process_time() - t0
            costs[name].append(cpu / out["steps_taken"].sum() * 1e9)
            digests[name].add(results_digest(out))
    generate.generate_source = generate_source
    generate.generated_text = generated_text

    lines = [
        f"### CPU a step ({args.samples} samples, 1 thread; loads "
        f"{', '.join(f'{x:.1f}' for x in loads)}; before = {args.before})",
        "",
        "| variant | ns an accepted sample-step, each repeat | median | results (sha256) |",
        "|---|---|---|---|",
    ]
    for name, values in costs.items():
        each = ", ".join(f"{c:.0f}" for c in values)
        results = ", ".join(sorted(digests[name]))
        lines.append(f"| {name} | {each} | {statistics.median(values):.0f} | {results} |")
    for what in ("as shipped", "contact-force output alone"):
        ratios = [b / a for b, a in zip(costs[f"{what}, before"], costs[f"{what}, after"],
                                        strict=True)]  # fmt: skip
        lines.append(f"\n{what}: before / after, repeat by repeat: "
                     f"{', '.join(f'{r:.2f}' for r in ratios)}; median "
                     f"{statistics.median(ratios):.3f}")  # fmt: skip
    write_result(command, lines, "output_feed.md")


if __name__ == "__main__":
    main()
