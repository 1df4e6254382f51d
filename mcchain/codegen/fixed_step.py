"""The fixed-step kernel's stage rows (templates.ERK_KERNEL): where a stage's k goes, who reads it.

Stage s writes its k = (q', v') = (v, q̈) once, into rows of its own (kq{s}, kv{s}; the stage
loop's ``kw``); the next stage, and the turning loop before it, read the previous stage's
rows (``kr``); the step's combine forms the increment from the rows of all the stages, so
the stage stores each k once (its body is bound by its stores:
benchmarks/results/roofline/reading.md).
"""

from __future__ import annotations

from mcchain.codegen.layout import Layout
from mcchain.codegen.topology import Topology

FIXED_STEP_VARIANTS = ("rk4", "rk4-projection")
"""The variants whose module is the fixed-step kernel (templates.ERK_KERNEL)."""


def fixed_step_blocks(topo: Topology, nstage: int, lay: Layout) -> dict[str, str]:
    """Blocks ``load_stage_sub`` (the stage's state, from the previous stage's k),
    ``combine_coefs`` and ``combine`` (the step's new state) of the fixed-step kernel.

    The combine's rounding is stated, every row alike: the increment as a chain of fused
    multiply-adds from the first stage on, d = fma(b₃h, k₃, fma(b₂h, k₂, fma(b₁h, k₁,
    b₀h·k₀))), then the state plus it, q + d (one rounding a stage where the loop kernel,
    mcchain.kernels.explicit, rounds each product and each sum: a few ulp apart; the lanes'
    stages differ from the loop's by as much already). Written out as ``fma`` calls, the
    choice is the text's, not LLVM's (with ``fastmath={"contract"}`` a sum of products
    contracts row by row as its DAG combiner picks); fused, because it is the faster of the
    two stated forms (benchmarks/results/roofline/reading.md; tests/test_codegen_stage_rows.py).
    """
    ndof = topo.ndof
    load = []
    for i in range(ndof):
        load += [
            f"q{i} = {lay.at('q', i)} + ah * {lay.stage_at(i, 'kr')}",
            f"v{i} = {lay.at('v', i)} + ah * {lay.stage_at(ndof + i, 'kr')}",
        ]
    base = [lay.rows[f"kq{j}"] for j in range(nstage)]
    combine = []
    for x, shift in (("q", 0), ("v", ndof)):
        for i in range(ndof):
            ks = [f"W[{(base[j] + shift + i) * lay.lmax} + l]" for j in range(nstage)]
            total = f"bh0 * {ks[0]}"  # an fma's addend: no contraction can take it
            for j in range(1, nstage):
                total = f"fma(bh{j}, {ks[j]}, {total})"
            combine.append(f"{lay.at(x, i)} = {lay.at(x, i)} + {total}")
    return {
        "load_stage_sub": "\n".join(load),
        "combine_coefs": "\n".join(f"bh{j} = bw[{j}] * hn" for j in range(nstage)),
        "combine": "\n".join(combine),
    }
