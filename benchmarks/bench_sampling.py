"""Scene compile time with sampling: 10⁵ samples of three parameters, per design.

What a run spends before any kernel: validating the scene, drawing the samples, checking each
against its parameter's domain and laying them out as model arrays. A wall-clock figure, so
it lives here and not in the tests (the tests check the values, not the time).

    python benchmarks/bench_sampling.py [--samples 100000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

from mcchain.scene import compile_model, load_scene_text
from mcchain.testing.factory import clearance_bar_text

DESIGNS = ("random", "sobol", "lhs")


def scene_text(count: int) -> str:
    return clearance_bar_text() + (
        f"\n[sample]\ncount = {count}\nseed = 7\n[sample.vary]\n"
        '"joint.O.clearance" = { uniform = [1e-4, 1e-3] }\n'
        '"body.bar.mass" = { normal = [2.0, 0.02] }\n'
        '"body.bar.angle" = { truncnormal = [-1.5707963267948966, 0.01, -1.6, -1.5] }\n'
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    scene = load_scene_text(scene_text(args.samples))
    compile_model(scene, nsample=10)  # the lazy imports, outside the timing
    print(f"| design | compile_model, {args.samples:,} samples (best of {args.repeat}) |")
    print("| --- | --- |")
    for design in DESIGNS:
        scene.sample.design = design  # type: ignore[union-attr]
        best = float("inf")
        for _ in range(args.repeat):
            start = time.perf_counter()
            model = compile_model(scene)
            best = min(best, time.perf_counter() - start)
        assert model.parameters.shape == (args.samples, 3)
        print(f"| {design} | {best:.3f} s |")


if __name__ == "__main__":
    main()
